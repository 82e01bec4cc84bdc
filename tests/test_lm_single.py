"""tests/lm_reference.py (the numpy one-pose LM the tests compare with) agrees with nik's FK, its Jacobian and LM."""

from __future__ import annotations

import pytest
import torch
from lm_reference import SingleLM

import nik


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


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7"])
def test_compiled_lm_takes_the_same_steps_as_the_numpy_reference(name):
    """From the same starts, without restarts, the compiled kernel and the independent numpy LM end at the same
    joints (to rounding) after the same number of iterations: one algorithm, written twice."""
    import numpy as np
    from lm_reference import lm_solve_one

    from nik.lm import LMCfg
    from nik.lm.compiled import CompiledLM

    robot = nik.load_robot(name)
    cfg, ref, lm = LMCfg(), SingleLM.from_robot(robot), CompiledLM.of(robot)
    g = torch.Generator().manual_seed(3)
    qt = robot.sample(12, generator=g, dtype=torch.float64)
    T = robot.fk(qt).numpy()
    lo, hi = robot.limits.double().numpy().T
    q0 = np.clip((qt + 0.3 * torch.randn(qt.shape, generator=g, dtype=torch.float64)).numpy(), lo, hi)
    run = lm.solve(T, q0, tol_pos=1e-4, tol_rot=1.745e-3, seed=0, restarts=False)
    assert run.converged.sum() >= 10  # the comparison covers converged runs, not only stalled ones
    for i in range(12):
        q, its = lm_solve_one(
            ref, T[i], q0[i], cfg=cfg, tol_pos=1e-4, tol_rot=1.745e-3, first_iters=cfg.iters, restarts=0, sample=None
        )
        assert its == int(run.iterations[i])
        np.testing.assert_allclose(run.q[i], q, atol=1e-9, rtol=0)


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


def test_prismatic_joint_in_the_numpy_kernel_matches_the_normal_form_product():
    # T = G0 Rz(q1) G1 Tz(q2 + o2) G2 (h1's prismatic convention); Jacobian by finite differences
    from types import SimpleNamespace

    import numpy as np

    G = np.tile(np.eye(4), (3, 1, 1))
    G[0, :3, 3] = [0.1, 0.0, 0.2]
    G[1, :3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # the slide axis turned to -y of the base
    G[1, :3, 3] = [0.3, 0.0, 0.0]
    G[2, :3, 3] = [0.0, 0.05, 0.1]
    robot = SimpleNamespace(
        G=torch.tensor(G),
        dof=2,
        offsets=torch.tensor([0.0, 0.02]),
        limits=torch.tensor([[-3.0, 3.0], [0.0, 0.5]], dtype=torch.float64),
        prismatic=torch.tensor([False, True]),
    )
    model = SingleLM.from_robot(robot)

    def product(q):
        c, s = np.cos(q[0]), np.sin(q[0])
        Rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        Tz = np.eye(4)
        Tz[2, 3] = q[1] + 0.02
        return G[0] @ Rz @ G[1] @ Tz @ G[2]

    q = np.array([0.7, 0.23])
    T, J = model.fk_jacobian(q)
    np.testing.assert_allclose(T, product(q), atol=1e-12)
    np.testing.assert_allclose(model.fk_many(q[None])[0], product(q), atol=1e-12)
    h = 1e-6
    for j in range(2):
        dq = np.zeros(2)
        dq[j] = h
        dT = (product(q + dq) - product(q - dq)) / (2 * h)
        np.testing.assert_allclose(J[:3, j], dT[:3, 3], atol=1e-8)
        W = dT[:3, :3] @ T[:3, :3].T  # skew matrix of the angular velocity
        np.testing.assert_allclose(J[3:, j], [W[2, 1], W[0, 2], W[1, 0]], atol=1e-8)
    assert not model.wrap[1]
