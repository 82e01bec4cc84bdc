"""``solve_path(..., q_rest=)`` (issue 36 item 4): a redundant arm keeps to a preferred posture along the path (its
chains and the search's tracks drift towards ``q_rest`` in the null space), the tool on the path all the same."""

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
