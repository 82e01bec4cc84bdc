"""nik.ik.plan: one plan per call, honoured field by field on both backends; which network serves (a given or
installed one before the shipped one); a base or tool frame keeps the arm's network."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

import nik
from nik.lm import LMCfg

BACKENDS = ["compiled", "torch"]


def _targets(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return q, robot.fk(q)


def _raw(plan):
    """``plan`` reduced to its guess: no LM iteration, no restart, no other hypothesis, no fallback."""
    return replace(plan, max_iters=0, restarts=False, hypotheses=False, fallback="none")


def _differs(a, b) -> bool:
    return not (torch.equal(a.q, b.q) and torch.equal(a.iterations, b.iterations) and torch.equal(a.success, b.success))


def _first_hypothesis(robot, net, T):
    """``(B, dof)``: the best hypothesis of ``net`` (made for the bare arm: the built-in panda without its flange)
    for targets ``T`` of the robot's tool: given in the arm's frame, ranked by the robot's own FK (as the solver)."""
    from nik.poses import pose_error
    from nik.tolerances import score

    T_arm = T @ torch.linalg.inv(robot.tool) if robot.tool is not None else T
    hyp = net.hypotheses(T_arm.to(net.in_mean.dtype)).to(T.dtype)
    pos, rot = pose_error(T[:, None].expand(-1, hyp.shape[1], 4, 4), robot.fk(robot.clamp(hyp)))
    return hyp[torch.arange(T.shape[0]), score(pos, rot).argmin(1)]


@pytest.fixture(scope="module")
def panda():
    robot = nik.load_robot("panda")
    return robot, _targets(robot, 24, seed=71)


@pytest.mark.parametrize("backend", BACKENDS)
def test_each_field_of_the_plan_changes_the_answer_on_both_backends(panda, backend):
    robot, (q, T) = panda
    solver = nik.IKSolver(robot, backend=backend)
    base = solver.plan(backend=backend)
    assert base.source == "network" and base.fallback == "multistart" and base.restarts and base.hypotheses

    def run(plan, **kw):
        return solver.solve(T, plan=plan, **kw)

    ref = run(base)
    assert ref.source == "network" and bool(ref.success.all())
    assert run(replace(base, source="multistart", net=None)).source == "multistart"
    # the network: the raw guess is that network's best hypothesis
    other = nik.models.load_pretrained(robot) if base.net is solver.single_pose_net else solver.single_pose_net
    raw_a, raw_b = run(_raw(base)), run(_raw(replace(base, net=other)))
    assert not torch.allclose(raw_a.q, raw_b.q)
    hyp = _first_hypothesis(robot, other, T)
    torch.testing.assert_close(raw_b.q, hyp, atol=1e-4, rtol=0)
    # LM settings, iteration cap, restarts, other hypotheses, fallback, tolerances, seed
    assert _differs(run(replace(base, lm_cfg=LMCfg(iters=2, lambda0=10.0))), ref)
    bare = replace(base, hypotheses=False, fallback="none", restarts=False)
    assert int(run(replace(bare, max_iters=1)).success.sum()) < int(run(bare).success.sum())
    one = run(replace(bare, max_iters=1))
    more = run(replace(bare, max_iters=1, hypotheses=True))  # LM from the next hypotheses: more work, more found
    assert int(more.iterations.sum()) > int(one.iterations.sum()) and int(more.success.sum()) >= int(one.success.sum())
    assert int(run(replace(bare, max_iters=1, fallback="multistart")).success.sum()) > int(one.success.sum())
    multi = replace(base, source="multistart", net=None, max_iters=3, fallback="none")
    assert int(run(multi).success.sum()) > int(run(replace(multi, restarts=False)).success.sum())
    assert _differs(run(multi), run(replace(multi, seed=5)))
    assert int(run(replace(base, tol_pos=1e-9, tol_rot=1e-9)).iterations.sum()) > int(ref.iterations.sum())
    f32 = solver.solve(T.float(), plan=base)
    assert _differs(f32, solver.solve(T.float(), plan=replace(base, float32_margin=1.0)))
    near = robot.clamp(q + 0.05)
    with_near = solver.solve(T, q_near=near, plan=base)
    without = solver.solve(T, q_near=near, plan=replace(base, near=False))
    d_with = torch.linalg.vector_norm(with_near.q - near, dim=-1).sum()
    assert d_with < torch.linalg.vector_norm(without.q - near, dim=-1).sum()


def test_a_closed_form_plan_and_its_analytic_fallback_on_both_backends():
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 12, seed=72)
    for backend in BACKENDS:
        solver = nik.IKSolver(robot, analytic=False, backend=backend)
        plan = solver.plan(backend=backend)
        assert plan.source == "network" and plan.fallback == "multistart"
        tight = replace(plan, max_iters=0, hypotheses=False)
        none = solver.solve(T, plan=replace(tight, fallback="none", restarts=False))
        analytic = solver.solve(T, plan=replace(tight, fallback="analytic", restarts=False))
        assert int(analytic.success.sum()) > int(none.success.sum()) and bool(analytic.success.all())
        assert solver.solve(T, plan=replace(plan, source="analytic", net=None)).source == "analytic"


def test_float32_targets_are_refined_to_the_same_fraction_of_the_tolerance_on_both_backends(panda):
    robot, (_, T) = panda
    plans = [nik.IKSolver(robot, backend=b).plan(backend=b) for b in BACKENDS]
    assert plans[0].stage_tolerances(True) == plans[1].stage_tolerances(True) == (0.5e-4, 0.5 * plans[0].tol_rot)
    assert plans[0].stage_tolerances(False) == (plans[0].tol_pos, plans[0].tol_rot)
    for b in BACKENDS:
        res = nik.IKSolver(robot, backend=b).solve(T.float())
        assert res.q.dtype == torch.float32 and bool(res.success.all())
        assert float(res.pos_err.max()) <= 0.5e-4 * 1.01  # refined to half the tolerance, rounding aside


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_network_set_on_the_solver_serves_on_the_cpu_before_the_shipped_single_pose_one(panda, backend):
    robot, (_, T) = panda
    solver = nik.IKSolver(robot, backend=backend)
    assert solver.single_pose_net is not None
    if backend == "compiled":
        assert solver.plan(backend=backend).net is solver.single_pose_net  # shipped: the small one on the CPU
    mine = nik.models.load_pretrained(robot)  # a network of its own (a different object, the main weights)
    solver.net = mine
    plan = solver.plan(backend=backend)
    assert plan.net is mine and plan.source == "network"
    raw = solver.solve(T, plan=_raw(plan))
    assert raw.source == "network"
    torch.testing.assert_close(raw.q, _first_hypothesis(robot, mine, T), atol=1e-4, rtol=0)
    assert bool(solver.solve(T).success.all())
    solver.net = None  # no network at all, the shipped single-pose one included
    assert solver.plan(backend=backend).net is None and solver.solve(T).source == "multistart"


def test_an_installed_network_serves_on_the_cpu_before_the_shipped_single_pose_one(tmp_path, monkeypatch, panda):
    from nik.nets import registry

    robot, (_, T) = panda
    monkeypatch.setenv("NIK_HOME", str(tmp_path))
    shipped = registry.find_network(robot.arm)  # the built-in panda's network is its bare arm's (flange aside)
    registry.install(shipped, name="my_panda")
    solver = nik.IKSolver(robot)
    assert registry.find_network(robot.arm).parent == registry.user_dir()
    plan = solver.plan(backend="compiled")
    assert plan.net is solver.net and plan.net is not solver.single_pose_net
    raw = solver.solve(T, plan=_raw(plan))
    assert raw.source == "network"
    torch.testing.assert_close(raw.q, _first_hypothesis(robot, solver.net, T), atol=1e-4, rtol=0)
    res = solver.solve(T)
    assert res.source == "network" and bool(res.success.all())


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "frames",
    [
        {"base": [0.2, -0.1, 0.8, 0.9238795, 0.0, 0.0, 0.3826834]},
        {"tool": [0.0, 0.05, 0.107, 0.7071068, 0, 0, 0.7071068]},
    ],
    ids=["base", "tool"],
)
def test_a_base_or_tool_frame_keeps_the_arms_network(backend, frames):
    bare = nik.load_robot("panda")
    robot = nik.load_robot("panda", **frames)
    q, T = _targets(robot, 32, seed=73)
    solver = nik.IKSolver(robot, backend=backend)
    assert solver.has_network and solver.plan(backend=backend).net_in_arm_frame
    res = solver.solve(T)
    assert res.source == "network" and bool(res.success.all()) and bool(res.reachable.all())
    # the guess is as good as on the bare arm: the network sees the targets in the arm's frame
    raw = solver.solve(T, plan=_raw(solver.plan(backend=backend)))
    bare_solver = nik.IKSolver(bare, backend=backend)
    bare_raw = bare_solver.solve(bare.fk(q), plan=_raw(bare_solver.plan(backend=backend)))
    if "base" in frames:  # the same hypotheses, ranked alike (a base frame changes no error)
        torch.testing.assert_close(raw.q, bare_raw.q, atol=1e-4, rtol=0)
    assert float(raw.pos_err.median()) < 2 * float(bare_raw.pos_err.median()) + 1e-3
    # the same network given as a file made for the bare arm
    from nik.nets.registry import find_network

    given = nik.IKSolver(robot, checkpoint=find_network(bare.arm), backend=backend)
    assert given.plan(backend=backend).net_in_arm_frame and given.solve(T).success.all()


def test_numpy_in_gives_numpy_out_and_torch_in_gives_torch_out(panda, monkeypatch):
    from nik.ik import backends

    robot, (_, T) = panda
    solver = nik.IKSolver(robot)
    monkeypatch.setattr(backends, "torch_backend", lambda: (_ for _ in ()).throw(AssertionError("torch ran")))
    res = solver.solve(T.numpy())
    for f in ("q", "pos_err", "rot_err", "success", "iterations", "reachable"):
        assert isinstance(getattr(res, f), np.ndarray), f
    assert res.q.dtype == np.float64 and res.success.dtype == bool and bool(res.success.all())
    assert isinstance(solver.solve(T).q, torch.Tensor)
