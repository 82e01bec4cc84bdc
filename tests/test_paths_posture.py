"""``solve_path(..., q_rest=)`` and ``bounds=`` in the global search (issue 36 item 4): a redundant arm keeps to a
preferred posture along the path (its chains and the search's tracks drift towards ``q_rest`` in the null space), the
tool on the path all the same; a tolerant goal's path is searched as the classic one is."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import nik


def _line(robot, q0: torch.Tensor, n: int = 60) -> torch.Tensor:
    T = robot.fk(q0[None]).expand(n, 4, 4).clone()
    T[:, 2, 3] += torch.linspace(0.0, 0.1, n, dtype=torch.float64)
    return T


def test_a_redundant_arm_path_keeps_nearer_q_rest():
    solver = nik.IKSolver("panda")
    robot = solver.robot
    q0 = torch.tensor([0.2, 0.3, -0.2, -1.8, 0.1, 2.0, 0.5], dtype=torch.float64)
    rest = q0.clone()
    rest[0] += 0.6
    rest[2] -= 0.6
    T = _line(robot, q0)
    plain = solver.solve_path(T, q_start=q0)
    res = solver.solve_path(T, q_start=q0, q_rest=rest)
    assert bool(res.success.all()) and res.path.largest_step <= math.radians(3.0)
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= math.radians(0.1)
    d_rest = np.linalg.norm(res.q.numpy()[-1] - rest.numpy())
    d_plain = np.linalg.norm(plain.q.numpy()[-1] - rest.numpy())
    assert d_rest < 0.7 * d_plain  # 0.58 against 1.08 rad


def test_a_bad_q_rest_is_one_line():
    solver = nik.IKSolver("panda")
    T = _line(solver.robot, torch.zeros(7, dtype=torch.float64), 5)
    with pytest.raises(ValueError, match="q_rest"):
        solver.solve_path(T, q_rest=np.zeros(3))
    with pytest.raises(ValueError, match="q_rest"):
        solver.solve_path(T, q_rest="middle")


def test_a_tolerant_goal_path_is_searched_too(monkeypatch):
    """xarm7 circle from ``q_start`` with a free tool axis: the search's tracks run towards the bounds; the loop
    closes with no step above ``max_step`` (the chain alone: a 360 deg jump and a loop 102 deg open)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    try:
        from test_paths_loops import _circle, _closure_deg
    finally:
        sys.path.pop(0)
    import warnings

    import nik.paths.solve as P

    robot = nik.load_robot("xarm7")
    solver = nik.IKSolver(robot)
    T, q0 = _circle(robot, 34, 0.05, n=60)

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return solver.solve_path(T, q_start=q0, bounds="axis_z")

    res = run()
    assert bool(res.success.all()) and res.path.closed
    assert _closure_deg(robot, res.q.numpy()) <= 0.1
    assert res.path.largest_step <= res.path.max_step
    monkeypatch.setattr(P, "_smooth", lambda *a, **k: True)  # the chain alone
    chain = run()
    assert chain.path.largest_step > res.path.largest_step
