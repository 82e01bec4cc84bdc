"""nik.ik.backends: the one pipeline gives the same contract on the compiled backend and on torch (successes,
limits, reach flags, error messages), the network's guess serves on the compiled backend, and the choice of backend."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import nik
from nik.ik import backends, stages
from nik.poses import matrix_to_quaternion, matrix_to_rpy
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

BACKENDS = ["compiled", "torch"]


def _targets(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return q, robot.fk(q)


def _out_of_reach(robot, T):
    """``T`` with its last pose moved 3 m beyond the first joint axis (provably unreachable)."""
    T = T.clone()
    T[-1, :3, 3] = robot.G[0, :3, 3] + torch.tensor([3.0, 0.0, 0.0], dtype=T.dtype)
    return T


@pytest.fixture
def no_torch(monkeypatch):
    """The torch backend fails if called: proves the compiled backend answered."""

    def refuse(*args, **kwargs):
        raise AssertionError("the torch backend ran")

    monkeypatch.setattr(backends, "torch_backend", refuse)


@pytest.mark.parametrize("name", ["panda", "ur5"])
@pytest.mark.parametrize("checkpoint", ["auto", None], ids=["network", "no_network"])
def test_both_backends_solve_the_same_targets_inside_the_limits_and_flag_the_same_ones(name, checkpoint):
    robot = nik.load_robot(name)
    _, T = _targets(robot, 12, seed=21)
    T = _out_of_reach(robot, T)
    results = []
    for backend in BACKENDS:  # ur5 has a closed form: here its network (or none) and LM
        solver = nik.IKSolver(robot, checkpoint=checkpoint, analytic=False, backend=backend)
        with pytest.warns(UserWarning, match="beyond the reach"):
            results.append(solver.solve(T, seed=3))
    fast, slow = results
    for res in (fast, slow):
        assert res.q.shape == (12, robot.dof) and res.q.dtype == torch.float64
        assert res.success.dtype == torch.bool and res.iterations.dtype == torch.long
        assert bool(robot.within_limits(res.q).all())
        pos, rot = nik.pose_error(T, robot.fk(res.q))  # honest errors: those of the returned joints
        torch.testing.assert_close(res.pos_err, pos, atol=1e-12, rtol=0)
        torch.testing.assert_close(res.rot_err, rot, atol=1e-9, rtol=0)
        assert torch.equal(res.success, (pos <= DEFAULT_TOL_POS) & (rot <= DEFAULT_TOL_ROT))
    assert torch.equal(fast.success, slow.success)
    assert bool(fast.success[:-1].all()) and not bool(fast.success[-1])
    assert torch.equal(fast.reachable, slow.reachable) and fast.reachable.tolist() == [True] * 11 + [False]
    assert fast.source == slow.source == ("network" if checkpoint else "multistart")


def test_one_pose_takes_the_compiled_backend_with_the_same_answer_for_the_same_seed(no_torch):
    robot = nik.load_robot("panda")
    _, T = _targets(robot, 1, seed=22)
    solver = nik.IKSolver(robot, checkpoint=None)
    a, b, c = solver.solve(T[0], seed=5), solver.solve(T, seed=5), solver.solve(T, seed=6)
    assert bool(a.success.all()) and torch.equal(a.q, b.q) and torch.equal(a.iterations, b.iterations)
    assert not torch.equal(a.q, c.q)  # another seed, other starts: another point of the self-motion


def test_quaternion_and_rpy_targets_give_the_matrix_answer(no_torch):
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 3, seed=23)
    solver = nik.IKSolver(robot, analytic=False)
    ref = solver.solve(T, seed=1)
    quat = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    rpy = torch.cat([T[:, :3, 3], matrix_to_rpy(T[:, :3, :3])], dim=-1)
    for other in (quat, rpy, quat.numpy().tolist()):
        res = solver.solve(other, seed=1)
        assert bool(res.success.all())
        torch.testing.assert_close(res.q, ref.q, atol=1e-6, rtol=0)  # the same starts, poses equal to 1e-15


def test_float32_targets_get_float32_answers_inside_the_float32_limits(no_torch):
    robot = nik.load_robot("panda")
    _, T = _targets(robot, 4, seed=24)
    res = nik.IKSolver(robot).solve(T.float(), tol_pos=1e-3, tol_rot=1e-2)
    assert res.q.dtype == torch.float32 and res.pos_err.dtype == torch.float32
    assert bool(robot.within_limits(res.q).all()) and bool(res.success.all())
    pos, rot = nik.pose_error(T, robot.fk(res.q.double()))
    torch.testing.assert_close(res.pos_err.double(), pos, atol=1e-7, rtol=0)
    torch.testing.assert_close(res.rot_err.double(), rot, atol=1e-6, rtol=0)


def test_q_near_picks_the_solution_near_the_current_configuration(no_torch):
    robot = nik.load_robot("panda")
    q, T = _targets(robot, 6, seed=25)
    near = robot.clamp(q + 0.05)
    solver = nik.IKSolver(robot)
    res = solver.solve(T, q_near=near, seed=0)
    free = solver.solve(T, seed=0)
    assert bool(res.success.all()) and bool(robot.within_limits(res.q).all())
    d_near = torch.linalg.vector_norm(res.q - near, dim=-1)
    assert float(d_near.max()) < 0.3  # the solution next to q_near, not another one of the self-motion
    assert float(d_near.mean()) < float(torch.linalg.vector_norm(free.q - near, dim=-1).mean())
    assert bool((res.iterations > free.iterations).all())  # both runs are counted


def _set(r, c, v):
    def spoil(T):
        T[0, r, c] = v
        return T

    return spoil


BAD = [
    ("nan", _set(0, 3, math.nan)),
    ("skew", _set(0, 1, 0.3)),
    ("bottom", _set(3, 0, 1.0)),
    ("shape", lambda T: T[:, :3]),
    ("quat norm", lambda T: torch.tensor([[0.3, 0.1, 0.4, 2.0, 0.0, 0.0, 0.0]], dtype=torch.float64)),
    ("rpy nan", lambda T: torch.tensor([[0.3, 0.1, 0.4, 0.0, math.nan, 0.0]], dtype=torch.float64)),
]


@pytest.mark.parametrize("kind, spoil", BAD, ids=[b[0] for b in BAD])
def test_bad_targets_raise_the_same_message_on_both_backends(kind, spoil):
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 1, seed=26)
    fast_solver, slow_solver = (nik.IKSolver(robot, checkpoint=None, analytic=False, backend=b) for b in BACKENDS)
    with pytest.raises(ValueError) as fast:
        fast_solver.solve(spoil(T.clone()))
    with pytest.raises(ValueError) as slow:
        slow_solver.solve(spoil(T.clone()))
    assert str(fast.value) == str(slow.value) and "T_target" in str(fast.value)


@pytest.mark.parametrize("q_near", [[0.1, 0.2], [[0.0] * 6] * 2, [math.nan] * 6], ids=["short", "rows", "nan"])
def test_bad_q_near_and_tolerances_raise_the_same_message_on_both_backends(q_near):
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 1, seed=27)
    messages = []
    for backend in BACKENDS:
        solver = nik.IKSolver(robot, checkpoint=None, analytic=False, backend=backend)
        with pytest.raises(ValueError, match="q_near") as err:
            solver.solve(T, q_near=q_near)
        with pytest.raises(ValueError, match="tol_pos") as tol:
            solver.solve(T, tol_pos=-1.0)
        messages.append((str(err.value), str(tol.value)))
    assert messages[0] == messages[1]


def test_the_backend_is_chosen_by_input_and_configuration():
    T = torch.eye(4, dtype=torch.float64).expand(3, 4, 4)
    ur5 = nik.load_robot("ur5")
    assert backends.choose(nik.IKSolver(ur5), T).name == "compiled"  # its closed form, compiled
    assert backends.choose(nik.IKSolver(ur5, analytic=False), T).name == "compiled"  # its network, compiled
    assert backends.choose(nik.IKSolver(ur5, analytic=False, fallback="none"), T).name == "compiled"
    assert backends.choose(nik.IKSolver(ur5, refine="ipso"), T).name == "torch"  # swarms run on torch
    assert backends.choose(nik.IKSolver(ur5, refine="none"), T).name == "torch"
    assert backends.choose(nik.IKSolver(ur5, backend="torch"), T).name == "torch"
    # every CPU batch is compiled (its cost per pose does not grow with the batch)
    huge = torch.eye(4, dtype=torch.float64).expand(20_000, 4, 4)
    assert backends.choose(nik.IKSolver("panda"), huge).name == "compiled"
    assert backends.choose(nik.IKSolver(ur5), huge).name == "compiled"
    with pytest.raises(ValueError, match="backend must be"):
        nik.IKSolver(ur5, backend="gpu")
    with pytest.raises(ValueError, match="LM only"):
        nik.IKSolver(ur5, refine="pso", backend="compiled")


@pytest.mark.parametrize("name", ["panda", "xarm7"])
def test_the_network_guess_serves_on_the_compiled_backend_with_fewer_lm_iterations(name, no_torch):
    robot = nik.load_robot(name)
    _, T = _targets(robot, 40, seed=33)
    with_net = nik.IKSolver(robot).solve(T, seed=0)
    without = nik.IKSolver(robot, checkpoint=None).solve(T, seed=0)
    assert with_net.source == "network" and without.source == "multistart"
    assert bool(with_net.success.all()) and bool(robot.within_limits(with_net.q).all())
    pos, rot = nik.pose_error(T, robot.fk(with_net.q))
    assert bool(((pos <= DEFAULT_TOL_POS) & (rot <= DEFAULT_TOL_ROT)).all())
    # the network's hypotheses start LM near a solution: far fewer iterations than uniform starts
    assert float(with_net.iterations.double().mean()) < 0.5 * float(without.iterations.double().mean())
    one = nik.IKSolver(robot).solve(T[0], seed=0)  # one pose too
    assert one.source == "network" and bool(one.success.all())


def test_a_failing_best_hypothesis_is_followed_by_the_next_ones_then_uniform_restarts():
    robot = nik.load_robot("panda")
    _, T = _targets(robot, 16, seed=34)
    solver = nik.IKSolver(robot, backend="compiled")
    plan = solver.plan(tol_pos=DEFAULT_TOL_POS, tol_rot=DEFAULT_TOL_ROT, seed=0, max_iters=2)
    job = backends.compiled_backend().job(robot, plan, T, None, None)
    answers = stages.guess(plan, job)
    assert answers.hypotheses.shape == (16, 8, 7)
    scores = [nik.pose_error(T, robot.fk(torch.from_numpy(answers.hypotheses[:, k].copy()))) for k in range(8)]
    score = torch.stack([p + 0.1 * r for p, r in scores], dim=1)
    assert bool((score[:, 1:] >= score[:, :-1] - 1e-12).all())  # ranked best first by FK
    answers = stages.refine(plan, job, answers)  # 2 LM iterations from the best hypothesis: many still fail
    failing = int((~answers.ok(job)).sum())
    more = stages.more_hypotheses(plan, job, answers)
    assert failing > 0 and int((~more.ok(job)).sum()) <= failing
    done = stages.fallback(plan, job, more)
    assert bool(done.ok(job).all()) and bool((done.iterations >= more.iterations).all())


def test_numpy_targets_and_lists_are_accepted_as_float64(no_torch):
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 2, seed=29)
    solver = nik.IKSolver(robot, analytic=False)
    for form in (T.numpy(), T.numpy().tolist(), T[0].numpy()):
        res = solver.solve(form)
        numpy_in = isinstance(form, np.ndarray)  # numpy in, numpy out (interface.md round 5); lists: tensors
        assert res.q.dtype == (np.float64 if numpy_in else torch.float64) and bool(res.success.all())
        assert isinstance(res.q, np.ndarray) == numpy_in and isinstance(res.success, np.ndarray) == numpy_in


@pytest.mark.parametrize("name", ["kuka_kr", "puma560", "ur5"])
def test_closed_form_arms_get_the_closed_form_solution_on_both_backends(name):
    robot = nik.load_robot(name)
    q, T = _targets(robot, 16, seed=30)
    T = _out_of_reach(robot, T)
    near = robot.clamp(q + 0.3)
    results = []
    for backend in BACKENDS:
        solver = nik.IKSolver(robot, backend=backend)
        with pytest.warns(UserWarning, match="beyond the reach"):
            results.append((solver.solve(T), solver.solve(T, q_near=near)))
    for res in (*results[0], *results[1]):
        assert res.source == "analytic" and bool(robot.within_limits(res.q).all())
        assert res.success.tolist() == [True] * 15 + [False]
        assert int(res.iterations[:15].sum()) == 0  # exact: no LM needed
        pos, rot = nik.pose_error(T, robot.fk(res.q))
        torch.testing.assert_close(res.pos_err, pos, atol=1e-12, rtol=0)
        assert float(pos[:15].max()) < 1e-9 and float(rot[:15].max()) < 1e-9
    # with q_near the choice is the same solution (nearest, by joint motion); without, the one farthest inside
    # the limits (two wrist flips can tie on that score, so only success and limits are compared there)
    torch.testing.assert_close(results[0][1].q[:15], results[1][1].q[:15], atol=1e-9, rtol=0)
    torch.testing.assert_close(results[0][1].q[15], results[1][1].q[15], atol=1e-9, rtol=0)  # best effort too


def test_closed_form_is_compiled_for_one_pose(no_torch):
    robot = nik.load_robot("kuka_kr")
    _, T = _targets(robot, 1, seed=31)
    res = nik.IKSolver(robot).solve(T[0])
    assert res.source == "analytic" and bool(res.success.all()) and float(res.pos_err[0]) < 1e-9


def test_float32_poses_on_a_closed_form_arm_get_the_same_choice_on_both_backends():
    robot = nik.load_robot("kuka_kr")
    _, T = _targets(robot, 8, seed=32)
    T = T.float()  # a float32 rotation is orthonormal to about 1e-7: the closed form's check is 2e-5 then
    fast, slow = (nik.IKSolver(robot, backend=b).solve(T, tol_pos=1e-3, tol_rot=1e-2) for b in BACKENDS)
    assert fast.q.dtype == torch.float32 and bool(fast.success.all()) and bool(slow.success.all())
    assert bool(robot.within_limits(fast.q).all())
    torch.testing.assert_close(fast.q, slow.q, atol=1e-3, rtol=0)  # the same solution of the 8


def _approximate_spherical_wrist():
    """kuka_kr with its wrist axes missing each other by 0.1 um (like a URDF's origins rounded to float32: the
    Jaco2's miss by 8e-8 m): a spherical wrist within the tolerance of nik.analytic.geometry, not exactly."""
    definition = nik.load_robot("kuka_kr").to_definition()
    definition["name"] = "kuka_off"
    definition["G"][4][0][3] += 1e-7
    return nik.Robot.from_definition(definition)


def test_an_arm_whose_closed_form_is_approximate_gets_it_polished_on_the_compiled_backend(no_torch):
    from nik.analytic.solve import closed_form

    robot = _approximate_spherical_wrist()
    assert nik.analytic.family(robot) == "spherical_wrist" and closed_form(robot)["polish"]
    q, T = _targets(robot, 40, seed=35)
    solver = nik.IKSolver(robot, checkpoint=None)
    for res in (solver.solve(T[0]), solver.solve(T, seed=0)):
        assert res.source == "analytic" and bool(res.success.all())
        assert bool(robot.within_limits(res.q).all())
        pos, rot = nik.pose_error(T[: res.q.shape[0]], robot.fk(res.q))
        assert float(pos.max()) <= DEFAULT_TOL_POS and float(rot.max()) <= DEFAULT_TOL_ROT
        torch.testing.assert_close(res.pos_err, pos, atol=1e-12, rtol=0)
    # the ideal arm's closed form is within about the arm's deviation of a solution: LM is rarely needed
    res = solver.solve(T, seed=0)
    assert float(res.pos_err.max()) < 1e-5 and int(res.iterations.sum()) <= 40


def test_a_batch_above_ten_thousand_poses_stays_on_the_compiled_backend(no_torch):
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 10_001, seed=36)
    res = nik.IKSolver(robot).solve(T)
    assert res.source == "analytic" and res.q.shape == (10_001, 6)
    assert float(res.success.double().mean()) == 1.0 and bool(robot.within_limits(res.q).all())


URDF_PANDA = "configs/robots/urdf/panda.urdf"


@pytest.mark.parametrize("name", ["panda", "ur5", "kuka_kr", "xarm7", URDF_PANDA])
def test_the_one_call_compiled_solve_meets_the_staged_torch_answers_and_equals_the_staged_compiled_ones(name):
    """nik.kernels.driver runs the whole plan in one kernel call: the same answers as the staged compiled stages
    (bit for bit), and the contract of the staged torch backend (success, limits, reach flags, messages)."""
    import warnings
    from pathlib import Path

    robot = nik.load_robot(Path(__file__).resolve().parents[1] / name if name.endswith(".urdf") else name)
    q, T = _targets(robot, 10, seed=41)
    T = _out_of_reach(robot, T)
    for near in (None, robot.clamp(q + 0.2)):
        out, said = {}, {}
        for backend in BACKENDS:
            solver = nik.IKSolver(robot, backend=backend)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                out[backend] = solver.solve(T, seed=4, q_near=near)
            said[backend] = [str(w.message) for w in caught]
        one, slow = out["compiled"], out["torch"]
        assert said["compiled"] == said["torch"] and len(said["torch"]) == 1 and "beyond the reach" in said["torch"][0]
        assert torch.equal(one.success, slow.success) and torch.equal(one.reachable, slow.reachable)
        assert one.success[:-1].all() and not one.success[-1] and one.source == slow.source
        assert bool(robot.within_limits(one.q).all()) and bool(robot.within_limits(slow.q).all())
        solver = nik.IKSolver(robot, backend="compiled")
        plan = solver.plan(seed=4)
        be = backends.compiled_backend()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            staged = stages.run(plan, be.job(robot, plan, T, near, None))
        assert torch.equal(one.q, staged.q) and torch.equal(one.iterations, staged.iterations)
        assert torch.equal(one.success, staged.success)
