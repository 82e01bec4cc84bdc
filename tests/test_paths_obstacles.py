"""``solve_path`` among obstacles (issue 36): the colliding stretch of a path re-planned by the path optimisation with
collision rows (nik.paths.trajopt.avoid_path), the motion between waypoints checked."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.collision import collides, link_frames


def _line_past_a_box(seed: int = 0, N: int = 200, robot=None):
    """A 25 cm tool line on the panda whose plain answer (from ``q_start``) sweeps the elbow through a small box
    placed 10 cm off the elbow, away from the shoulder-wrist axis, at least 20 cm from the tool's line."""
    robot = nik.load_robot("panda") if robot is None else robot
    solver = nik.IKSolver(robot, mesh_verdict=False)
    rng = np.random.default_rng(seed)
    lim = robot.limits.numpy()
    mid = lim.mean(1)
    while True:
        q0 = mid + 0.6 * (rng.uniform(lim[:, 0], lim[:, 1]) - mid)
        d = rng.normal(size=3)
        d *= 0.25 / np.linalg.norm(d)
        T = np.repeat(robot.fk(q0)[None], N, 0)
        T[:, :3, 3] += np.linspace(0, 1, N)[:, None] * d
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plain = solver.solve_path(T, q_start=q0)
        if not plain.success.all():
            continue
        q = plain.q.numpy()
        fr = link_frames(robot, torch.from_numpy(q[N // 2 : N // 2 + 1]))[0]
        elbow, sh, wr = (fr[k, :3, 3].numpy() for k in (4, 2, 6))
        if np.linalg.norm(T[:, :3, 3] - elbow, axis=1).min() < 0.2:
            continue
        ax = (wr - sh) / np.linalg.norm(wr - sh)
        out = elbow - sh - ((elbow - sh) @ ax) * ax
        world = nik.World().add_box(elbow + 0.1 * out / np.linalg.norm(out), [0.02, 0.02, 0.02])
        if collides(robot, q, world, self_collision=False).any():
            return robot, solver, T, q0, world, q


def test_a_path_whose_plain_answer_collides_is_found_free():
    robot, solver, T, q0, world, plain = _line_past_a_box()
    assert collides(robot, plain, world, self_collision=False).sum() > 10  # the plain motion crosses the box
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning: every waypoint reached, free, no jump
        res = solver.solve_path(T, q_start=q0, world=world)
    q = res.q.numpy()
    assert res.success.all() and res.collision_free.all()
    rows = np.concatenate([q0[None], q])
    t = np.linspace(0.0, 1.0, 9)[None, :, None]
    motion = (rows[:-1, None] + t * np.diff(rows, axis=0)[:, None]).reshape(-1, robot.dof)
    assert not collides(robot, motion, world, self_collision=False).any()  # between the waypoints too
    assert res.path.largest_step <= math.radians(10.0)
    pos, rot = nik.pose_error(torch.from_numpy(T), robot.fk(res.q))
    assert float(pos.max()) <= 0.5e-4 and float(rot.max()) <= math.radians(0.05)  # half the tolerances


def test_the_worst_error_of_a_path_is_below_half_the_tolerance():
    """The last polish aims at half the tolerances (nik.paths.solve.PATH_MARGIN): the worst waypoint is not at the
    threshold (the same line without the box: its chain answers sit up to 0.084 mm off without that polish)."""
    robot, solver, T, q0, _, _ = _line_past_a_box()
    res = solver.solve_path(T, q_start=q0)
    pos, rot = nik.pose_error(torch.from_numpy(T), robot.fk(res.q))
    assert res.success.all() and res.path.largest_step <= math.radians(10.0)
    assert float(pos.max()) <= 0.5e-4 and float(rot.max()) <= math.radians(0.05)


def test_a_path_past_a_box_is_free_on_the_meshes():
    """The same problem on example-robot-data's panda (its sphere model fitted to its meshes): the plain answer hits
    the box by the meshes (coal), the answer among obstacles does not, at any waypoint."""
    pytest.importorskip("coal", reason="the mesh check needs coal (pip install 'nik-ik[collision-check]')")
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from collisions import panda_urdf
    finally:
        sys.path.pop(0)
    try:
        urdf = panda_urdf()
    except SystemExit:
        pytest.skip("example-robot-data's panda (with meshes) is not installed")
    from nik.collision.meshcheck import MeshCheck
    from nik.collision.model import srdf_disabled, srdf_of

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    robot, solver, T, q0, world, plain = _line_past_a_box(robot=robot)
    mesh = MeshCheck(robot, urdf, skip=list(srdf_disabled(srdf_of(urdf))))
    assert mesh.collides(plain, world, self_collision=False).any()
    res = solver.solve_path(T, q_start=q0, world=world)
    assert res.success.all() and not mesh.collides(res.q.numpy(), world, self_collision=False).any()


def test_closing_a_loop_among_obstacles_keeps_it_free_by_blending_over_its_tail(panda_circle_chain):
    """``_close_loop`` among obstacles: the blend of a loop's gap over the whole path (free space's rule) would move
    the first half's rows into a small box placed just inside one of the spheres of that blend (and clear of the
    chain's own motion, 3 mm and more); with the world it keeps no blend that collides: it closes the loop over the
    last half only (rows before it unchanged), free at every waypoint and inside every step."""
    from nik.collision.check import collision_model
    from nik.collision.distance import sphere_centers
    from nik.ik import collide
    from nik.paths import solve as P
    from nik.paths.trajopt import TrajCfg, path_collisions

    robot, q0, T, model, run, q, its = panda_circle_chain
    N = len(T)
    assert P._closure(q, model.wraps) > math.radians(5.0)  # the chain drifts: the loop is open
    whole, _ = P._close_loop(run, q, its, math.radians(10.0))  # no world: the blend over the whole path
    assert P._closure(whole, model.wraps) <= P.PATH_CLOSE_TOL

    cm = collision_model(robot)
    radii = np.asarray(cm.radii)
    rows = np.concatenate([q0[None], q])
    motion = (rows[:-1, None] + np.linspace(0, 1, 9)[None, :, None] * np.diff(rows, axis=0)[:, None]).reshape(-1, 7)
    c_q = sphere_centers(cm, robot, torch.from_numpy(motion)).numpy().reshape(-1, 3)
    r_q = np.tile(radii, len(motion))
    c_old = sphere_centers(cm, robot, torch.from_numpy(whole[: N // 2])).numpy()
    c_new = sphere_centers(cm, robot, torch.from_numpy(q[: N // 2])).numpy()
    moved = np.linalg.norm(c_old - c_new, axis=-1)
    box = None
    for i, s in zip(*np.unravel_index(np.argsort(-moved, axis=None)[:200], moved.shape), strict=True):
        p = c_old[i, s] + (radii[s] - 0.003) * (c_old[i, s] - c_new[i, s]) / moved[i, s]  # inside the blend's sphere
        if (np.linalg.norm(c_q - p, axis=1) - r_q).min() > 0.004:  # clear of the chain's motion
            box = p
            break
    assert box is not None
    world = nik.World().add_box(box, [0.002] * 3)
    col = collide.setup(robot, world, False).arguments(robot)[1]

    def hits(x):
        return np.logical_or(*path_collisions(model, x, q0, col, TrajCfg.col_sub))

    assert not hits(q).any() and hits(whole).any()  # the whole-path blend runs into the box
    out, _ = P._close_loop(run, q, its, math.radians(10.0), col)
    assert P._closure(out, model.wraps) <= P.PATH_CLOSE_TOL  # closed ...
    assert not hits(out).any()  # ... and free
    np.testing.assert_array_equal(out[: N // 2], q[: N // 2])  # the blend over the tail only
    assert P._final_check(run, out)[2].all()
    assert np.abs(np.diff(out, axis=0)).max() <= math.radians(10.0)
