"""nik.kernels.closed.pick, the one rule that chooses among closed-form solutions, against the torch reference."""

from __future__ import annotations

import math

import pytest
import torch
from pick_reference import choose

import nik
from nik.analytic import solve
from nik.ik.guesses import analytic_guess


def _targets(robot, n: int, seed: int) -> torch.Tensor:
    """FK poses of uniform configurations, a quarter of them moved out of reach (no valid solution there)."""
    T = robot.fk(robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64))
    T[: n // 4, :3, 3] *= 3.0
    return T


@pytest.mark.parametrize("name", ["ur5", "kuka_kr", "puma560"])
@pytest.mark.parametrize("near", [False, True])
def test_the_compiled_choice_is_the_torch_references(name, near):
    robot = nik.load_robot(name)
    T = _targets(robot, 48, 5)
    q_near = robot.sample(48, generator=torch.Generator().manual_seed(6), dtype=torch.float64) if near else None
    sols, valid = solve(robot, T)
    assert 0 < int(valid.any(-1).sum()) < 48  # both kinds of target: some solution valid, none valid
    got = analytic_guess(robot, T, q_near=q_near)
    ref = choose(robot, T, sols, valid, q_near)
    torch.testing.assert_close(got, ref, atol=1e-9, rtol=0)


def test_the_choice_keeps_the_targets_dtype_and_the_limits():
    robot = nik.load_robot("kuka_kr")
    T = _targets(robot, 16, 7).float()
    q = analytic_guess(robot, T, q_near=torch.full((16, 6), math.pi / 2, dtype=torch.float32))
    assert q.dtype == torch.float32
    assert bool(robot.within_limits(q).all())
