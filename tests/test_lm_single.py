"""nik.swarm.lm_single: the numpy lean path for one pose agrees with the batched kernels and solves."""

from __future__ import annotations

import pytest
import torch

import nik
from nik.swarm.lm_single import SingleLM


@pytest.mark.parametrize("name", ["panda", "ur5", "kuka_kr"])
def test_fk_and_jacobian_match_the_batched_kernels(name):
    robot = nik.load_robot(name)
    model = SingleLM.from_robot(robot)
    q = robot.sample(5, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    T_ref, J_ref = robot.fk_and_jacobian(q)
    for i in range(5):
        T, J = model.fk_jacobian(q[i].numpy())
        torch.testing.assert_close(torch.from_numpy(T[:3]), T_ref[i, :3], atol=1e-12, rtol=0)
        torch.testing.assert_close(torch.from_numpy(J), J_ref[i], atol=1e-12, rtol=0)
    torch.testing.assert_close(torch.from_numpy(model.fk_many(q.numpy())), robot.fk(q), atol=1e-12, rtol=0)


def test_one_pose_per_call_is_solved_inside_the_limits_and_reproducibly():
    robot = nik.load_robot("panda")
    q, T = robot.sample(12, generator=torch.Generator().manual_seed(7), dtype=torch.float64), None
    T = robot.fk(q)
    solver = nik.IKSolver(robot)
    for i in range(12):
        a = solver.solve(T[i : i + 1], seed=100 + i)
        b = solver.solve(T[i], seed=100 + i)
        assert bool(a.success.all()) and bool(robot.within_limits(a.q).all())
        assert torch.equal(a.q, b.q)
        pos, rot = nik.pose_error(T[i : i + 1], robot.fk(a.q))
        torch.testing.assert_close(pos, a.pos_err, atol=1e-12, rtol=1e-6)
        torch.testing.assert_close(rot, a.rot_err, atol=1e-12, rtol=1e-6)
