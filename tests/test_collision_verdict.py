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
    world_only = nik.IKSolver(robot, world=world, self_collision=False, mesh_verdict=False).solve(T, q_near=q)
    assert (world_only.collision_free & collides(robot, world_only.q)).any()  # called free, yet self-colliding
    res = nik.IKSolver(robot, world=world, mesh_verdict=False).solve(T, q_near=q)
    np.testing.assert_array_equal(res.collision_free, ~collides(robot, res.q, world))
    assert (res.success <= res.collision_free).all()


@pytest.mark.long
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
    pytest.importorskip("coal", reason="the mesh verdict needs coal (pip install 'nik-ik[collision-check]')")
    bench = _bench_collisions()
    try:
        urdf = bench.panda_urdf()
    except SystemExit:
        pytest.skip("example-robot-data's panda (with meshes) is not installed")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    return robot, urdf, bench.scene(0)


def _bench_collisions():
    """benchmarks/collisions.py as a module: its example-robot-data panda (``panda_urdf``) and its scene (``scene``:
    a table and 10 boxes, spheres and capsules)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        import collisions
    finally:
        sys.path.pop(0)
    return collisions


def _false_alarms(robot, coal, world) -> np.ndarray:
    """``(6, dof)``: seeded configurations the spheres call colliding in ``world`` and ``coal`` calls free."""
    q = robot.sample(400, generator=torch.Generator().manual_seed(4), dtype=torch.float64).numpy()
    q = q[collides(robot, q, world) & ~coal.collides(q, world)][:6]
    assert len(q) == 6
    return q


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
    q = _false_alarms(robot, coal, world)
    T = np.ascontiguousarray(robot.fk(q))
    # the model is fitted to these meshes (no pair left out by sampling): the spheres steer (each answer solved
    # again), the meshes judge; where the spheres cannot free one, the call's own answer (free on the meshes) stands
    judged = nik.IKSolver(robot, world=world, mesh_verdict=True).solve(T, q_near=q)
    assert judged.collision_free.all() and judged.success.all()
    np.testing.assert_array_equal(judged.collision_free, ~coal.collides(judged.q, world))
    spheres = nik.IKSolver(robot, world=world, mesh_verdict=False).solve(T, q_near=q)
    np.testing.assert_array_equal(spheres.collision_free, ~collides(robot, spheres.q, world))


def test_without_the_cover_an_answer_free_on_the_meshes_is_kept(panda_meshes):
    """A model with a pair left out by sampling ("never"): the meshes check that pair, the spheres do not, so the
    spheres' "free" promises nothing; every answer is checked on the meshes and only those colliding there are
    solved again."""
    from nik.collision.meshcheck import mesh_check, spheres_cover

    _, urdf, world = panda_meshes
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")  # its own: the model attached below stays with it
    model = _with_never(collision_model(robot))
    nik.collision.set_collision_model(robot, model)
    assert not spheres_cover(model, mesh_check(robot, model))
    coal = _coal(robot, urdf)
    q = _false_alarms(robot, coal, world)
    T = np.ascontiguousarray(robot.fk(q))
    judged = nik.IKSolver(robot, world=world, mesh_verdict=True).solve(T, q_near=q)
    np.testing.assert_allclose(judged.q, q, atol=1e-9)  # kept: no re-solve of an answer free on the meshes
    assert judged.collision_free.all() and judged.success.all()
    assert collides(robot, judged.q, world).all()  # yet the spheres call each one colliding


def _with_never(model):
    """``model`` with its first pair left out as if by sampling (``"never"``)."""
    pair = model.pair_names()[0]
    out = model.with_pairs(remove=[pair])
    out.left_out["|".join(sorted(pair, key=model.links.index))] = "never"
    return out


# -- the spheres cover the meshes they were fitted to: coal judges only what they call colliding -------------------
@pytest.fixture(scope="module")
def builtin_panda():
    """The built-in panda, its shipped model (fitted to example-robot-data's meshes) and the verdict's mesh check."""
    pytest.importorskip("coal", reason="the mesh verdict needs coal (pip install 'nik-ik[collision-check]')")
    from nik.collision.meshcheck import fitted_urdf, mesh_check

    robot = nik.load_robot("panda")
    model = collision_model(robot)
    if fitted_urdf(model) is None:
        pytest.skip("example-robot-data's panda (with meshes) is not installed")
    return robot, model, mesh_check(robot, model, required=True)


def test_the_spheres_cover_only_the_meshes_they_were_fitted_to(builtin_panda):
    from nik.collision.meshcheck import fitted_urdf, mesh_check, spheres_cover
    from nik.collision.model import CollisionModel
    from nik.ik.collide import setup

    robot, model, mesh = builtin_panda
    world = nik.World().add_box([0.5, 0.0, 0.1], [0.1, 0.1, 0.1])
    urdf = fitted_urdf(model)
    assert mesh.urdf.resolve() == urdf.resolve()
    assert all(why != "never" for why in model.left_out.values())
    assert spheres_cover(model, mesh) and setup(robot, world, None, "auto").covered
    assert setup(robot, world, None, urdf).covered  # the same file named explicitly
    spelled = CollisionModel(**{**model.__dict__, "source": f"urdf:{urdf.parent / '..' / 'urdf' / urdf.name}"})
    assert spheres_cover(spelled, mesh)  # "urdf:PATH" resolving to the same file
    other = setup(robot, world, None, urdf.parent / "panda_collision.urdf")  # another URDF of the arm
    assert other.mesh is not None and not other.covered
    capsules = CollisionModel(**{**model.__dict__, "source": "capsules"})
    assert not spheres_cover(capsules, mesh)
    never = _with_never(model)
    assert not spheres_cover(never, mesh_check(robot, never))
    assert setup(robot, world, None, False).mesh is None


def _mesh_free_targets(robot, mesh, world, n: int, seed: int) -> np.ndarray:
    """Poses of ``n`` random configurations the meshes call free in ``world``."""
    q = robot.sample(3 * n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64).numpy()
    return np.ascontiguousarray(robot.fk(q[~mesh.collides(q, world)][:n]))


def test_coal_judges_only_what_the_spheres_call_colliding(builtin_panda, monkeypatch):
    from nik.collision.meshcheck import MeshCheck

    robot, _, mesh = builtin_panda
    world = _bench_collisions().scene(2)
    T = _mesh_free_targets(robot, mesh, world, 400, seed=2)
    asked = []
    for attr in ("collides", "collision_names"):
        monkeypatch.setattr(MeshCheck, attr, _recorded(getattr(MeshCheck, attr), asked))
    judged = nik.IKSolver(robot, world=world, mesh_verdict="auto").solve(T)
    monkeypatch.undo()
    Q = np.concatenate(asked)
    assert len(Q) > 0  # some answers the spheres call colliding were judged
    assert collides(robot, Q, world).all()  # coal was asked about nothing the spheres call free
    assert len(Q) < 0.1 * len(T)  # (not one check per answer)
    np.testing.assert_array_equal(judged.collision_free, ~mesh.collides(judged.q, world))  # coal on every answer
    assert (judged.success <= judged.collision_free).all()
    spheres = nik.IKSolver(robot, world=world, mesh_verdict=False).solve(T)
    assert (judged.success >= spheres.success).all()  # target by target: the meshes never turn success to failure
    np.testing.assert_array_equal(judged.q[spheres.success], spheres.q[spheres.success])  # the spheres steered


def _recorded(fn, asked: list):
    """``fn`` (a :class:`MeshCheck` method taking ``Q``), recording the configurations it is asked about."""

    def recorded(self, Q, *a, **k):
        asked.append(np.array(Q, dtype=np.float64).reshape(-1, self.robot.dof))
        return fn(self, Q, *a, **k)

    return recorded


def _hand_over_a_block(robot, mesh, gap: float):
    """``(q, world)``: the first seeded configuration with the hand pointing down, away from the base, over a block
    (8 x 8 cm, 5 cm high) whose top lies ``gap`` metres below the lowest mesh point above it, where the spheres call
    that colliding (and the meshes free)."""
    from nik.collision.urdf import frames_at, urdf_bodies

    bodies = [b for b in urdf_bodies(robot, mesh.urdf) if b.frame > 0]
    q = robot.sample(400, generator=torch.Generator().manual_seed(0), dtype=torch.float64).numpy()
    T = robot.fk(q)
    down = np.flatnonzero((T[:, 2, 2] < -0.9) & (T[:, 2, 3] > 0.2) & (np.hypot(T[:, 0, 3], T[:, 1, 3]) > 0.4))
    for i in down:
        F = frames_at(robot, q[i])
        points = np.concatenate([b.triangles.reshape(-1, 3) @ F[b.frame][:3, :3].T + F[b.frame][:3, 3] for b in bodies])
        tip = T[i, :3, 3]
        top = points[np.hypot(points[:, 0] - tip[0], points[:, 1] - tip[1]) < 0.08, 2].min() - gap
        world = nik.World().add_box([tip[0], tip[1], top - 0.025], [0.08, 0.08, 0.05])
        if collides(robot, q[i : i + 1], world)[0] and not mesh.collides(q[i : i + 1], world)[0]:
            return q[i], world
    raise AssertionError("no such configuration among the samples")


@pytest.mark.parametrize("terms", [{}, {"q_rest": "mid"}, {"bounds": "axis_z"}])
def test_an_answer_only_the_spheres_call_colliding_succeeds(builtin_panda, terms):
    """The hand 1 mm above a block: free on the meshes, colliding for the spheres at the pose itself (so every answer
    of the pose collides for them); with the meshes judging, the call's own answer stands."""
    robot, _, mesh = builtin_panda
    q, world = _hand_over_a_block(robot, mesh, gap=0.001)
    assert not mesh.collides(q[None], world)[0] and collides(robot, q[None], world)[0]
    T = np.ascontiguousarray(robot.fk(q[None]))
    spheres = nik.IKSolver(robot, world=world, mesh_verdict=False).solve(T, **terms)
    assert not spheres.success[0]  # the spheres free no answer at the pose
    judged = nik.IKSolver(robot, world=world, mesh_verdict="auto").solve(T, **terms)
    assert judged.success[0] and judged.collision_free[0] and judged.collisions[0] is None
    assert not mesh.collides(judged.q, world)[0] and collides(robot, judged.q, world)[0]
    assert judged.pos_err[0] <= 1e-3


def test_mesh_check_asks_coal_only_about_pairs_whose_bounding_spheres_meet(panda_meshes, monkeypatch):
    """The broad phase of MeshCheck.collides / collision_names: the same verdict and names as coal asked about every
    checked pair and every moving link against every obstacle, with far fewer coal queries."""
    from nik.collision.meshcheck import MeshCheck

    robot, urdf, _ = panda_meshes
    rot = np.eye(4)
    rot[:3, :3] = [[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]]  # a box turned about z
    rot[:3, 3] = [0.35, -0.3, 0.35]
    world = (nik.World().add_box([0.4, 0.0, -0.05], [1.2, 1.2, 0.1]).add_box(rot, [0.3, 0.1, 0.2])
             .add_sphere([0.0, 0.45, 0.5], 0.1).add_capsule([0.5, 0.3, 0.2], [0.3, 0.5, 0.7], 0.05))  # fmt: skip
    check = _coal(robot, urdf)
    q = robot.sample(60, generator=torch.Generator().manual_seed(7), dtype=torch.float64).numpy()
    obstacles = check._world_geoms(world)
    every, names = [], []
    for x in q:  # the reference: coal on every pair, every link and obstacle
        tf = check._transforms(x)
        pairs = [f"{check.links[a]}|{check.links[b]}" for a, b in check.pairs
                 if check._hit(check._geoms[a], tf[a], check._geoms[b], tf[b])]  # fmt: skip
        links = [f"{check.links[k]}|{name}" for k, g in enumerate(check._geoms) if check.frames[k] > 0
                 for og, ot, name in obstacles if check._hit(g, tf[k], og, ot)]  # fmt: skip
        every.append(bool(pairs or links))
        names.append(sorted(pairs + links) or None)
    asked = []
    hit = MeshCheck._hit
    monkeypatch.setattr(MeshCheck, "_hit", lambda self, *a: asked.append(1) or hit(self, *a))
    verdict = check.collides(q, world)
    assert 0 < verdict.sum() < len(q)
    np.testing.assert_array_equal(verdict, every)
    free = int((~verdict).sum())  # a free configuration asks every pair and link the broad phase leaves
    assert len(asked) < 0.5 * free * (len(check.pairs) + sum(f > 0 for f in check.frames) * len(obstacles))
    assert check.collision_names(q, world) == names
