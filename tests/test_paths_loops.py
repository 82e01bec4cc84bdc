"""``solve_path`` on closed loops and from ``q_start`` (issue 36 item 1): a closed path closes (last row = first, modulo
whole turns on joints that wrap) and its first waypoint is reached from ``q_start`` without a jump, whatever the arm."""

from __future__ import annotations

import importlib.metadata
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import nik


def _circle(robot, seed: int, radius: float, n: int = 40) -> tuple[torch.Tensor, torch.Tensor]:
    """``(T (n, 4, 4), q0 (dof,))``: a full circle (random plane, orientation fixed) through FK of a random
    configuration ``q0``, the arm's configuration before the path; its last pose equals its first."""
    gen = torch.Generator().manual_seed(seed)
    q0 = robot.sample(1, generator=gen, dtype=torch.float64)[0]
    T0 = robot.fk(q0[None])[0]
    u, v = torch.linalg.qr(torch.randn(3, 2, generator=gen, dtype=torch.float64))[0].T
    a = torch.linspace(0.0, 2 * math.pi, n, dtype=torch.float64)
    T = T0.expand(n, 4, 4).clone()
    T[:, :3, 3] = T0[:3, 3] + radius * ((1 - torch.cos(a))[:, None] * u - torch.sin(a)[:, None] * v)
    return T, q0


def _closure_deg(robot, q: np.ndarray) -> float:
    """Largest joint difference between the last row and the first, degrees, modulo whole turns on joints whose range
    exceeds a full turn."""
    d = np.abs(q[-1] - q[0])
    lim = robot.limits.numpy()
    wraps = lim[:, 1] - lim[:, 0] > 2 * math.pi
    d[wraps] = np.abs(np.remainder(d[wraps] + math.pi, 2 * math.pi) - math.pi)
    return math.degrees(float(d.max()))


def _solve(solver, T, q0, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solver.solve_path(T, q_start=q0, **kw)


def _kinova():
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip('example-robot-data not installed (pip install -e ".[urdf-tests]")')
    robots = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    path = robots / "kinova_description/robots/kinova.urdf"
    if not path.is_file():
        pytest.skip("kinova.urdf is not in this version of example-robot-data")
    return nik.load_robot(path, end_link="j2s6s200_end_effector")


@pytest.mark.parametrize("seed, radius", [(10, 0.1), (20, 0.05), (25, 0.05)])
def test_a_kinova_loop_from_q_start_starts_without_a_jump_and_closes(seed, radius):
    """Kinova Gen2 (an approximate closed form whose branches may miss ``q_start``'s posture): with the default loop
    detection the first waypoint is within ``max_step`` of ``q_start`` (main: 136, 229, 175 deg), every pose is
    reached by FK, and no step above ``max_step`` joins two successful waypoints. These loops cannot be followed from
    ``q_start``'s posture without a reconfiguration (main: steps of 140 and 104, 107 and 33, 176 and 174 deg, the
    second closing the loop, every waypoint flagged reached): since issue 49 item 3 the waypoint a jump leads into
    counts as not reached, and a loop that closes only by a larger jump than the open path takes is left open (said
    in the warning); one that closes, closes exactly."""
    robot = _kinova()
    T, q0 = _circle(robot, seed, radius)
    res = _solve(nik.IKSolver(robot), T, q0)
    q, ok = res.q.numpy(), res.success.numpy()
    assert np.abs(q[0] - q0.numpy()).max() <= res.path.max_step
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= math.radians(0.1)
    steps = np.abs(np.diff(q, axis=0)).max(axis=1)
    jump = steps > res.path.max_step
    assert not (ok[1:] & ok[:-1] & jump).any()
    np.testing.assert_array_equal(ok, np.concatenate([[True], ~jump]))
    if res.path.closed:
        assert _closure_deg(robot, q) <= 0.1
    else:
        assert "the loop is left open" in res.path.warning
        assert res.path.closure == pytest.approx(math.radians(_closure_deg(robot, q)), abs=1e-9)


@pytest.mark.parametrize("seed", [8, 18, 34])
def test_a_redundant_arm_circle_from_q_start_closes_without_a_jump_at_the_start(seed):
    """xarm7 (7 joints, no closed form): a full circle from ``q_start`` ends where it started (main: 16, 21, 12 deg
    off, the chain drifting in the null space or jumping), every waypoint reached, the first waypoint within
    ``max_step`` of ``q_start`` and no step above it (seed 34: main jumped 360 deg)."""
    robot = nik.load_robot("xarm7")
    T, q0 = _circle(robot, seed, 0.05, n=60)
    res = _solve(nik.IKSolver(robot), T, q0)
    q = res.q.numpy()
    assert res.path.closed and bool(res.success.all())
    assert _closure_deg(robot, q) <= 0.1
    assert np.abs(q[0] - q0.numpy()).max() <= res.path.max_step
    assert res.path.largest_step <= res.path.max_step


def _chain_only(monkeypatch):
    """solve_path without the global search: the plain LM chain's answer (main's), for comparison."""
    import nik.paths.solve as P

    monkeypatch.setattr(P, "_smooth", lambda *a: True)


@pytest.mark.parametrize("arm", ["xarm7", "panda"])
def test_the_search_is_never_worse_than_the_chain(arm, monkeypatch):
    """On open paths (circles with ``closed=False``, from ``q_start``), the global search's answer reaches at least
    as many waypoints as the plain chain and, where it reaches as many, its largest step is no larger; on some it is
    strictly better (xarm7 seed 15: the chain jumps a full turn, the search 7 deg)."""
    robot = nik.load_robot(arm)
    solver = nik.IKSolver(robot)
    better = 0
    for seed in (4, 11, 15, 22, 34):
        T, q0 = _circle(robot, seed, 0.05, n=60)
        with monkeypatch.context() as m:
            _chain_only(m)
            chain = _solve(solver, T, q0, closed=False)
        res = _solve(solver, T, q0, closed=False)
        n_c, n_s = int(chain.success.sum()), int(res.success.sum())
        assert n_s >= n_c
        if n_s == n_c:
            assert res.path.largest_step <= chain.path.largest_step + 1e-9
        better += n_s > n_c or res.path.largest_step < chain.path.largest_step - math.radians(1.0)
    if arm == "xarm7":
        assert better >= 1


def test_an_xarm7_circle_the_search_left_at_3_5_deg_is_followed_in_steps_under_3_deg_and_closed(xarm7_circle_37):
    """Path 37 of benchmarks/paths.py's xarm7 stream (a 5 cm circle, orientation fixed, from ``q_start``): the search
    alone answered with a 3.5 deg step; a witness in steps under 3 deg exists (the benchmark's oracle: 3.0 deg). The
    whole-path optimisation towards 2 deg steps now follows it: every waypoint within 0.1 mm / 0.1 deg by FK, every
    step from ``q_start`` on <= 3 deg, and the loop still closed (last row == first)."""
    robot, q0, T = xarm7_circle_37
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = nik.IKSolver(robot).solve_path(T, q_start=q0)
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= math.radians(0.1)
    steps = np.abs(np.diff(np.concatenate([q0.numpy()[None], res.q.numpy()]), axis=0)).max()
    assert steps <= math.radians(3.0)
    assert res.path.closure <= math.radians(0.1)


@pytest.mark.parametrize("seed, radius", [(0, 0.4), (3, 0.6), (10, 0.4)])
def test_a_ur5_loop_out_of_reach_in_the_middle_is_neither_closed_nor_continued_by_a_jump(seed, radius):
    """Issue 49 item 3: ur5 circles whose middle leaves the reach (no ``q_start``, loop detected). Main closed them
    with a 180-196 deg step between two reached waypoints and went on with 15 deg steps between others, every such
    waypoint flagged reached. Now: no step above ``max_step`` between two successful neighbours; ``success`` is FK's
    verdict except where a reached waypoint is reached only by such a step from a reached one; the loop, which closes
    only by a jump here, is left open: ``res.path.closed`` False, ``closure`` the gap, the warning says it."""
    from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

    robot = nik.load_robot("ur5")
    T, _ = _circle(robot, seed, radius, n=120)
    with pytest.warns(UserWarning) as caught:
        res = nik.IKSolver(robot).solve_path(T)
    q, ok = res.q.numpy(), res.success.numpy()
    pe, re = nik.pose_error(T, robot.fk(res.q))
    fk = ((pe <= DEFAULT_TOL_POS) & (re <= DEFAULT_TOL_ROT)).numpy()
    assert not fk.all()  # the middle is out of reach
    max_step = res.path.max_step
    steps = np.abs(np.diff(q, axis=0)).max(axis=1)
    assert not (ok[1:] & ok[:-1] & (steps > max_step)).any()
    jump = np.concatenate([[False], fk[1:] & fk[:-1] & (steps > max_step)])
    np.testing.assert_array_equal(ok, fk & ~jump)
    assert [r == "reached only by a step above max_step from the waypoint before" for r in res.path.reasons] == list(
        jump
    )
    message = str(caught[0].message)
    assert not res.path.closed
    assert res.path.closure == pytest.approx(np.abs(q[-1] - q[0]).max(), abs=1e-9)  # ur5's joints: +-180 deg
    assert res.path.closure > max_step and "the loop is left open" in message
    if jump.any():
        assert f"waypoint {int(np.argmax(jump | ~fk))} of 120" in message
