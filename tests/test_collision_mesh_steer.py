"""The meshes steer where the spheres refuse (nik/ik/collide/mesh_step.py): a target whose free answers all look
colliding to the sphere model is found with the mesh rows (coal), judged free by the meshes at margin 0."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import nik
from nik.collision import collides, collision_model


@pytest.fixture(scope="module")
def refused_target():
    """The built-in panda, a target ``T (1, 4, 4)`` of a configuration ``q*`` free on the meshes, and a world: a
    small sphere 16 mm from the hand's mesh at ``q*`` (inside the hand's spheres, which overreach by centimetres:
    every answer, its hand fixed by the pose, collides by the spheres) and a ball where the plain answer's elbow
    is (so the call's own answer collides on the meshes too)."""
    pytest.importorskip("coal", reason="the mesh step needs coal (pip install 'nik-ik[collision-check]')")
    from nik.collision.meshcheck import MeshCheck, fitted_urdf

    robot = nik.load_robot("panda")
    urdf = fitted_urdf(collision_model(robot))
    if urdf is None:
        pytest.skip("example-robot-data's panda (with meshes) is not installed")
    q_star = np.array([[-0.386, -0.335, 1.614, -2.512, 0.547, 1.668, -0.916]])
    world = nik.World().add_sphere([0.1609, 0.4009, 0.3185], 0.02).add_sphere([0.24, -0.005, 0.554], 0.06)
    meshes = MeshCheck(robot, urdf)  # an independent check of the same meshes (every pair but adjacent ones)
    assert not meshes.collides(q_star, world)[0] and collides(robot, q_star, world)[0]
    return robot, np.ascontiguousarray(robot.fk(q_star)), world, meshes


def test_target_refused_by_the_spheres_is_found_with_the_meshes(refused_target):
    from nik.ik.collide import CollideCfg

    robot, T, world, meshes = refused_target
    solver = nik.IKSolver(robot, world=world)  # mesh_verdict="auto": coal judges
    res = solver.solve(T)
    q = np.asarray(res.q, dtype=np.float64)
    assert res.success[0] and res.collision_free[0] and res.pos_err[0] <= 1e-4 and res.rot_err[0] <= 1e-3
    assert not meshes.collides(q, world)[0]  # free on the meshes at margin 0
    assert collides(robot, q, world)[0]  # an answer the spheres alone would refuse

    f32 = solver.solve(torch.from_numpy(T.astype(np.float32)))  # float32 tensors: judged as returned (rounded)
    assert f32.q.dtype == torch.float32 and bool(f32.success[0]) and bool(f32.collision_free[0])
    assert not meshes.collides(f32.q.double().numpy(), world)[0]

    solver.collide_cfg = CollideCfg(mesh_steer=False)  # without the mesh step: refused
    off = solver.solve(T)
    assert not off.success[0]
    assert not nik.IKSolver(robot, world=world, mesh_verdict=False).solve(T).success[0]  # the spheres judging


def test_mesh_step_from_a_free_start_off_the_goal_ends_at_its_first_answer(refused_target, monkeypatch):
    """A start free on the meshes but 1-2 cm off the pose (the sphere re-solve's compromise): the mesh step reaches
    the goal with the rows at margin 0 and stops at its first iterate on the goal and free (a few coal evaluations,
    not a descent to the margin's minimum and another from there), judged by an independent coal check."""
    from nik.collision.mesh_distance import MeshDistance
    from nik.ik.collide import CollideCfg, setup
    from nik.ik.collide.mesh_step import MeshStep, mesh_step
    from nik.ik.model import model_of

    robot, T, world, meshes = refused_target
    plan = nik.IKSolver(robot, world=world).plan()
    model = model_of(robot, plan.lm_cfg)
    step = MeshStep(plan, setup(robot, world, None, "auto"), CollideCfg(), False, model.lo32, model.hi32)
    q_star = np.array([[-0.386, -0.335, 1.614, -2.512, 0.547, 1.668, -0.916]])
    evaluations = []
    rows_at = MeshDistance.rows_at
    monkeypatch.setattr(MeshDistance, "rows_at", lambda self, Q, m: evaluations.append(m) or rows_at(self, Q, m))
    for j, delta in ((0, -0.02), (3, 0.01), (6, -0.01)):
        start = q_star.copy()
        start[0, j] += delta
        assert not meshes.collides(start, world)[0]
        evaluations.clear()
        q, ok = mesh_step(robot, step, T, start, start)
        assert ok[0] and not meshes.collides(q, world)[0]
        assert plan.tol_pos >= float(np.linalg.norm(robot.fk(q)[0, :3, 3] - T[0, :3, 3]))
        assert len(evaluations) <= 4 and set(evaluations) == {0.0}  # measured: 2-3 (7-8 through the margin first)
