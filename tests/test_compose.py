"""Constraints compose (issue 34; nik/ik/collide/): every mix of bounds, q_rest, world and self-collision in
``solve`` (compiled and torch backends) and ``solve_all``, and with a user's term and manipulability in
``solve_path`` too, judged here by FK round trip, the joint limits and the sphere check
(:func:`nik.collision.collides`), never by ``res.success`` alone."""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.collision import collides
from nik.poses import pose_error, rotation_modes, tool_error

TOL_POS, TOL_ROT = 1e-4, math.radians(0.1)
#: every subset of the four constraints: (bounds, q_rest, world, self-collision)
SUBSETS = list(itertools.product((None, "axis_z"), (None, "mid"), (False, True), (False, True)))


def _world() -> nik.World:
    """A table under the panda and three obstacles around it: 20-40 % of the plain answers collide."""
    world = nik.World().add_box([0.0, 0.0, -0.05], [2.0, 2.0, 0.1])
    world.add_box([0.45, 0.25, 0.35], [0.12, 0.12, 0.12]).add_sphere([0.35, -0.3, 0.5], 0.06)
    return world.add_capsule([0.2, 0.4, 0.6], [-0.1, 0.45, 0.55], 0.05)


def _free_targets(name: str, n: int):
    """The robot, the world, and the poses of ``n`` random configurations free of the world and of the arm itself
    (every target has a collision-free answer: its own configuration)."""
    robot, world = nik.load_robot(name), _world()
    q = robot.sample(8 * n, generator=torch.Generator().manual_seed(4), dtype=torch.float64).numpy()
    q = q[~collides(robot, q, world)][:n]
    return robot, world, np.ascontiguousarray(robot.fk(torch.from_numpy(q)).numpy())


@pytest.fixture(scope="module")
def panda():
    """A redundant arm (7 joints: ``q_rest`` moves its answers) and 12 free targets."""
    return _free_targets("panda", 12)


@pytest.fixture(scope="module")
def ur5():
    """An arm with a closed form (``solve_all``: its 8 branches; with ``axis_z`` the free angle sampled) and a free
    target."""
    return _free_targets("ur5", 1)


def _honest(robot, T: np.ndarray, q: np.ndarray, bounds, world, self_on: bool) -> np.ndarray:
    """``(B,)`` bool: ``q`` reaches ``T`` (within the tolerances, or every tool axis inside the bounds, by FK), lies
    inside the joint limits and is free where a check is asked (world and / or the arm itself)."""
    qt = torch.as_tensor(q, dtype=torch.float64)
    Tt, Tq = torch.as_tensor(T, dtype=torch.float64), robot.fk(qt)
    if bounds is None:
        pos, rot = pose_error(Tt, Tq)
        ok = (pos <= TOL_POS) & (rot <= TOL_ROT)
    else:  # axis_z: position per axis tol_pos / sqrt(3), the z axis's tilt per axis tol_rot / sqrt(2)
        half = torch.tensor([TOL_POS / 3**0.5] * 3 + [TOL_ROT / 2**0.5] * 2 + [math.inf], dtype=torch.float64)
        half = half.expand(len(T), 6)
        ok = (tool_error(Tt, Tq, rotation_modes(half)).abs() <= half).all(-1)
    lim = robot.limits.double()
    ok = (ok & ((qt >= lim[:, 0]) & (qt <= lim[:, 1])).all(-1)).numpy()
    if world or self_on:
        ok &= ~collides(robot, q, world, self_collision=self_on)
    return ok


def _near(q: np.ndarray, q_rest: np.ndarray) -> np.ndarray:
    return np.linalg.norm(q - q_rest, axis=-1)


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize(("bounds", "rest", "use_world", "self_on"), SUBSETS)
def test_solve_composes_every_mix(panda, backend, bounds, rest, use_world, self_on):
    robot, world, T = panda
    world = world if use_world else None
    solver = nik.IKSolver(robot, backend=backend, self_collision=self_on, mesh_verdict=False)
    Tin = T if backend == "compiled" else torch.from_numpy(T)
    res = solver.solve(Tin, bounds=bounds, q_rest=rest, world=world)
    q, success = np.asarray(res.q), np.asarray(res.success)
    honest = _honest(robot, T, q, bounds, world, self_on)
    assert (success <= honest).all()  # every success flagged is one by FK, the limits and the spheres
    assert honest.mean() >= 11 / 12  # every target has a free answer: its own configuration
    if world is not None or self_on:
        np.testing.assert_array_equal(
            np.asarray(res.collision_free), ~collides(robot, q, world, self_collision=self_on)
        )
    if bounds is not None:  # axis_err is the error of the returned q (the free twist's entry: 0 or the twist)
        modes = torch.from_numpy(np.full(len(T), 2))
        d = tool_error(torch.from_numpy(T), robot.fk(torch.from_numpy(q.astype(np.float64))), modes).numpy()
        np.testing.assert_allclose(np.asarray(res.axis_err)[:, :5], d[:, :5], atol=1e-9)
    if rest is not None:  # nearer the posture than the same call without it (a 7-joint arm: it moves)
        mid = robot.limits.double().mean(1).numpy()
        plain = solver.solve(Tin, bounds=bounds, world=world)
        both = success & np.asarray(plain.success)
        d_rest, d_plain = _near(q[both], mid), _near(np.asarray(plain.q)[both], mid)
        # per target at least as near, but for a colliding answer: solved again from another start (the answer
        # moved towards the posture), it may settle a little farther (2.6e-4 rad seen on the shipped panda model)
        assert (d_rest <= d_plain + 1e-3).all()
        assert d_rest.mean() < d_plain.mean() - 0.05


def test_the_world_bites(panda, ur5):
    """Without the world some of the answers collide: the matrices test the collision re-solve."""
    robot, world, T = panda
    for bounds in (None, "axis_z"):
        q = np.asarray(nik.IKSolver(robot, self_collision=False).solve(T, bounds=bounds, q_rest="mid").q)
        assert collides(robot, q, world).any()
    robot, world, T = ur5
    for bounds in (None, "axis_z"):
        q = nik.IKSolver(robot, self_collision=False).solve_all(T, bounds=bounds, n_starts=32).numpy()
        assert collides(robot, q, world).any() and not collides(robot, q, world).all()


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize(("bounds", "rest", "use_world", "self_on"), SUBSETS)
def test_solve_all_composes_every_mix(ur5, backend, bounds, rest, use_world, self_on):
    robot, world, T = ur5
    world = world if use_world else None
    solver = nik.IKSolver(robot, backend=backend, self_collision=self_on, mesh_verdict=False)
    Tin = torch.from_numpy(T[:1]) if backend == "torch" else T[:1]
    Q = solver.solve_all(Tin, bounds=bounds, q_rest=rest, world=world, n_starts=32)
    q = Q.numpy()
    assert q.shape[0] >= 1  # the target's own configuration is free: some free solution is found
    assert _honest(robot, np.repeat(T[:1], len(q), 0), q, bounds, world, self_on).all()
    if rest is not None:  # nearest first, and the nearest at least as near as without the posture (a free axis moves)
        mid = robot.limits.double().mean(1).numpy()
        d = _near(q, mid)
        assert (np.diff(d) >= 0).all()
        plain = solver.solve_all(Tin, bounds=bounds, world=world, n_starts=32).numpy()
        assert d[0] <= _near(plain, mid).min() + 1e-9


#: every subset of the six of issue 46: (bounds, q_rest, world, self-collision, a user's term, manipulability)
SIX = list(
    itertools.product((None, "axis_z"), (None, "mid"), (False, True), (False, True), (False, True), (False, True))
)
#: the user's term: the first joint inside +-2.3 rad (most answers meet it; those that do not must be moved)
Q0_MAX = 2.3


def _first_joint_inside(q: torch.Tensor) -> torch.Tensor:
    return (q[:, :1].abs() - Q0_MAX).clamp(min=0.0)


def _costs(robot, user: bool, manip: bool):
    costs = [nik.costs.custom(_first_joint_inside, name="first_joint_inside")] if user else []
    return (costs + [nik.costs.manipulability(robot, weight=0.1)] if manip else costs) or None


def _user_ok(q: np.ndarray, user: bool) -> np.ndarray:
    return np.abs(q[:, 0]) <= Q0_MAX + 1e-6 if user else np.ones(len(q), dtype=bool)


@pytest.mark.parametrize(("bounds", "rest", "use_world", "self_on", "user", "manip"), SIX)
def test_solve_solve_all_and_solve_path_compose_every_mix_of_six(panda, ur5, bounds, rest, use_world, self_on, user,
                                                                 manip):  # fmt: skip
    """Issue 46: each of the 64 mixes in ``solve`` (panda, 12 targets), ``solve_all`` (ur5, one target) and
    ``solve_path`` (panda, a 6-waypoint path from a free configuration, given as ``q_start``), success judged by FK,
    the limits, the spheres and the user's term, never by ``res.success`` alone."""
    robot, world, T = panda
    world = world if use_world else None
    solver = nik.IKSolver(robot, self_collision=self_on, mesh_verdict=False)
    kw = dict(bounds=bounds, q_rest=rest, world=world, costs=_costs(robot, user, manip))
    res = solver.solve(T, **kw)
    q, success = np.asarray(res.q), np.asarray(res.success)
    honest = _honest(robot, T, q, bounds, world, self_on) & _user_ok(q, user)
    assert (success <= honest).all() and honest.mean() >= 10 / 12

    probe, uworld, Tu = ur5
    Q = (
        nik.IKSolver(probe, self_collision=self_on, mesh_verdict=False)
        .solve_all(
            Tu[:1], n_starts=32, **dict(kw, world=uworld if use_world else None, costs=_costs(probe, user, manip))
        )
        .numpy()
    )
    assert Q.shape[0] >= 1
    assert (_honest(probe, np.repeat(Tu[:1], len(Q), 0), Q, bounds, uworld if use_world else None, self_on)
            & _user_ok(Q, user)).all()  # fmt: skip

    q0 = torch.from_numpy(q[honest][0])
    qs = robot.clamp(q0 + torch.linspace(0.0, 1.0, 6, dtype=torch.float64)[:, None] * 0.02)
    Tp = robot.fk(qs).numpy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        path = solver.solve_path(Tp, q0, **kw)  # from the arm's joints at the first waypoint, as a planner calls it
    qp, ok = path.q.numpy(), np.asarray(path.success)
    free_path = _honest(robot, Tp, qp, bounds, world, self_on) & _user_ok(qp, user)
    assert (ok <= free_path).all() and ok.mean() >= 5 / 6
