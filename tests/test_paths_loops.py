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
    detection the first waypoint is within ``max_step`` of ``q_start`` (main: 136, 229, 175 deg), and the loop
    closes, every waypoint reached."""
    robot = _kinova()
    T, q0 = _circle(robot, seed, radius)
    res = _solve(nik.IKSolver(robot), T, q0)
    q = res.q.numpy()
    assert res.path.closed
    assert np.abs(q[0] - q0.numpy()).max() <= res.path.max_step
    assert _closure_deg(robot, q) <= 0.1
    assert bool(res.success.all())
