"""What ``collision_free`` promises (nik/ik/collide.py): a world checks the arm itself too, ``res.collisions`` says
what overlaps, and the mesh verdict (``IKSolver(mesh_verdict=)``) judges on the meshes with coal."""

from __future__ import annotations

import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import nik
from nik.collision import collides, collision_model, collision_names


def _self_colliding(robot, n: int, seed: int) -> np.ndarray:
    """``n`` random configurations whose spheres touch each other (the arm against itself)."""
    q = robot.sample(60 * n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64).numpy()
    return q[collides(robot, q)][:n]


def test_a_world_checks_the_arm_itself_too():
    robot = nik.load_robot("ur5")
    world = nik.World().add_sphere([3.0, 3.0, 3.0], 0.1)  # far from the arm: only the arm itself can collide
    q = _self_colliding(robot, 12, seed=1)
    T = np.ascontiguousarray(robot.fk(q))
    world_only = nik.IKSolver(robot, world=world, self_collision=False).solve(T, q_near=q)
    assert (world_only.collision_free & collides(robot, world_only.q)).any()  # called free, yet self-colliding
    res = nik.IKSolver(robot, world=world).solve(T, q_near=q)
    np.testing.assert_array_equal(res.collision_free, ~collides(robot, res.q, world))
    assert (res.success <= res.collision_free).all()


def test_collisions_name_the_pairs_and_the_obstacles():
    robot = nik.load_robot("panda")
    world = nik.World().add_box([0.4, 0.0, -0.05], [1.2, 1.2, 0.1]).add_sphere([0.45, 0.25, 0.45], 0.08)
    q = robot.sample(300, generator=torch.Generator().manual_seed(2), dtype=torch.float64).numpy()
    names = collision_names(robot, q, world)
    np.testing.assert_array_equal([n is not None for n in names], collides(robot, q, world))
    selfish = [n is not None for n in collision_names(robot, q)]
    np.testing.assert_array_equal(selfish, collides(robot, q))
    model = collision_model(robot)
    pairs = {f"{a}|{b}" for a, b in model.pair_names()}
    every = {n for ns in names if ns for n in ns}
    assert any(n in pairs for n in every) and any(n.endswith("|box 0") for n in every)
    assert all(n in pairs or re.fullmatch(r"\w+\|(box [01]|sphere 0)", n) for n in every)
    alone = nik.World().add_box([0.4, 0.0, -0.05], [1.2, 1.2, 0.1])  # drop the sphere: its names go
    fewer = collision_names(robot, q, alone, self_collision=False)
    assert not any("sphere" in n for ns in fewer if ns for n in ns)

    T = np.ascontiguousarray(robot.fk(q[:20]))
    res = nik.IKSolver(robot, world=world).solve(T)
    assert len(res.collisions) == 20
    assert [c is None for c in res.collisions] == np.asarray(res.collision_free).tolist()
    assert nik.IKSolver(robot).solve(T).collisions is None  # nothing checked


def test_bad_mesh_verdict_is_one_line():
    with pytest.raises(ValueError, match="mesh_verdict must be"):
        nik.IKSolver("ur5", mesh_verdict="yes")
    # puma560: no meshes anywhere (the built-in ur5's model names example-robot-data's meshes now)
    with pytest.raises(ValueError, match="no URDF with collision meshes"):
        nik.IKSolver("puma560", world=nik.World(), mesh_verdict=True).solve(np.eye(4))
    res = nik.IKSolver("puma560", world=nik.World(), mesh_verdict="auto").solve(np.eye(4))  # no meshes: the spheres
    assert res.collision_free is not None


# -- the meshes judge (coal, example-robot-data's panda) ---------------------------------------------------------
@pytest.fixture(scope="module")
def panda_meshes():
    pytest.importorskip("coal", reason="the mesh verdict needs coal (pip install 'nik[collision-check]')")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from collisions import panda_urdf, scene
    finally:
        sys.path.pop(0)
    try:
        urdf = panda_urdf()
    except SystemExit:
        pytest.skip("example-robot-data's panda (with meshes) is not installed")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    return robot, urdf, scene(0)


def _coal(robot, urdf):
    """coal called directly, on the pairs the model checks by decision (MoveIt's SRDF's left out)."""
    from nik.collision.meshcheck import MeshCheck

    model = collision_model(robot)
    skip = [tuple(k.split("|")) for k, why in model.left_out.items() if why != "never"]
    return MeshCheck(robot, urdf, skip=skip)


def test_mesh_verdict_agrees_with_coal(panda_meshes):
    robot, urdf, world = panda_meshes
    q = robot.sample(40, generator=torch.Generator().manual_seed(3), dtype=torch.float64).numpy()
    T = np.ascontiguousarray(robot.fk(q))
    res = nik.IKSolver(robot, world=world, mesh_verdict=True).solve(T)
    coal = _coal(robot, urdf)
    np.testing.assert_array_equal(res.collision_free, ~coal.collides(res.q, world))
    for i in np.nonzero(~res.collision_free)[0]:
        assert res.collisions[i] == coal.collision_names(res.q[i : i + 1], world)[0]


def test_meshes_free_what_the_spheres_call_colliding(panda_meshes):
    robot, urdf, world = panda_meshes
    coal = _coal(robot, urdf)
    q = robot.sample(400, generator=torch.Generator().manual_seed(4), dtype=torch.float64).numpy()
    q = q[collides(robot, q, world) & ~coal.collides(q, world)][:6]  # the spheres' false alarms
    assert len(q) == 6
    T = np.ascontiguousarray(robot.fk(q))
    judged = nik.IKSolver(robot, world=world, mesh_verdict=True).solve(T, q_near=q)
    np.testing.assert_allclose(judged.q, q, atol=1e-9)  # kept: no re-solve of an answer free on the meshes
    assert judged.collision_free.all() and judged.success.all()
    assert collides(robot, judged.q, world).all()  # yet the spheres call each one colliding
    spheres = nik.IKSolver(robot, world=world).solve(T, q_near=q)
    np.testing.assert_array_equal(spheres.collision_free, ~collides(robot, spheres.q, world))
