"""Cost terms (nik/costs/), the LM over a problem of terms (nik/lm/problem.py) and ``costs=`` of the solver."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.collision import collides, link_frames
from nik.lm.problem import PathProblem, Problem, solve_problem


def _fd(fn, q: torch.Tensor, h: float = 1e-6) -> torch.Tensor:
    """``(B, m, dof)`` central differences of ``fn: (B, dof) -> (B, m)``."""
    cols = []
    for j in range(q.shape[1]):
        dq = torch.zeros_like(q)
        dq[:, j] = h
        cols.append((fn(q + dq) - fn(q - dq)) / (2 * h))
    return torch.stack(cols, dim=-1)


def _configs(robot, n: int, seed: int) -> torch.Tensor:
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


def _elbow_z(robot, q) -> torch.Tensor:
    return link_frames(robot, torch.as_tensor(q, dtype=torch.float64))[:, 4, 2, 3]


@pytest.fixture(scope="module")
def panda():
    return nik.load_robot("panda")


# -- each term: its Jacobian against finite differences of its residual, and against the compiled kernel ---------------
def test_pose_term_matches_finite_differences_and_the_compiled_kernel(panda):
    q = _configs(panda, 6, 0)
    T = panda.fk(_configs(panda, 6, 1))
    term = nik.costs.pose(panda, T)
    r, J = term.evaluate(q)
    torch.testing.assert_close(r, term.residual(q), atol=1e-12, rtol=0)
    torch.testing.assert_close(J, _fd(term.residual, q), atol=1e-6, rtol=0)
    rk, Jk = term.compiled(q.numpy())
    np.testing.assert_allclose(r.numpy(), rk, atol=1e-12)
    np.testing.assert_allclose(J.numpy(), Jk, atol=1e-10)
    assert not term.check(q).any() and term.check(_configs(panda, 6, 1)).all()


def test_bounded_pose_term_matches_finite_differences_outside_its_zone_and_the_kernel(panda):
    from nik.costs.pose import DEAD_ZONE
    from nik.kernels.lm import DEAD_ZONE as KERNEL_DEAD_ZONE

    assert DEAD_ZONE == KERNEL_DEAD_ZONE
    q = _configs(panda, 6, 2)
    T = panda.fk(_configs(panda, 6, 3))
    bounds = (1e-3, 1e-3, math.inf, 1e-2, 1e-2, math.inf)  # tool z free in translation and rotation
    term = nik.costs.bounded_pose(panda, T, bounds)
    r, J = term.evaluate(q)
    torch.testing.assert_close(r, term.residual(q), atol=1e-12, rtol=0)
    assert (r[:, [2, 5]] == 0).all() and (J[:, [2, 5]] == 0).all()  # free rows
    live = r[:, [0, 1, 3, 4]].abs() > 1e-3  # rows outside their dead zone: the residual's own derivative
    assert live.all()
    torch.testing.assert_close(J, _fd(term.residual, q), atol=1e-6, rtol=0)
    rk, Jk = term.compiled(q.numpy())
    np.testing.assert_allclose(r.numpy(), rk, atol=1e-12)
    np.testing.assert_allclose(J.numpy(), Jk, atol=1e-10)


def test_limits_and_posture_terms_match_finite_differences(panda):
    q = _configs(panda, 5, 4)
    lim = nik.costs.limits(panda)
    out = q.clone()
    out[0, 1] = panda.limits[1, 1] + 0.2
    out[1, 3] = panda.limits[3, 0] - 0.1
    r, J = lim.evaluate(out)
    assert torch.allclose(r[0, 1], torch.tensor(0.2, dtype=torch.float64)) and r[1, 3] < 0
    assert lim.check(out).tolist() == [False, False, True, True, True]
    torch.testing.assert_close(J, _fd(lim.residual, out), atol=1e-6, rtol=0)
    assert panda.within_limits(lim.project(out)).all()
    post = nik.costs.posture(panda, "mid", weight=0.3)
    r, J = post.evaluate(q)
    mid = panda.limits.double().mean(1)
    torch.testing.assert_close(r, q - mid, atol=1e-12, rtol=0)
    torch.testing.assert_close(J, _fd(post.residual, q), atol=1e-6, rtol=0)
    assert post.check(q).all() and not post.hard  # a preference


def test_collision_term_matches_the_compiled_rows_and_finite_differences(panda):
    world = nik.World().add_box([0.45, 0.0, 0.4], [0.2, 0.2, 0.2]).add_sphere([0.0, 0.4, 0.6], 0.1)
    term = nik.costs.collision(panda, world, margin=0.05)
    q = _configs(panda, 40, 5)
    r, J = term.evaluate(q)  # float64 CPU: the compiled kernel's rows and Jacobian
    torch.testing.assert_close(r, term.residual(q), atol=1e-9, rtol=0)  # the torch twin
    fd = _fd(term.residual, q, h=1e-7)
    rows = (r > 1e-4) & (fd.abs().amax(-1) < 50)  # active rows away from a switch of the minimising pair
    assert rows.sum() >= 10
    torch.testing.assert_close(J[rows], fd[rows], atol=1e-4, rtol=0)
    hit = collides(panda, q, world)
    assert torch.equal(term.check(q), ~hit) and hit.any() and (~hit).any()


@pytest.mark.parametrize("name", ["panda", "ur5", "stanford"])  # 7 joints, 6 joints, a prismatic joint
def test_manipulability_term_compiled_rows_match_the_torch_twin_and_finite_differences(name):
    from nik.costs.manipulability import EPS, measure
    from nik.kernels.manipulability import EPS as KERNEL_EPS

    assert EPS == KERNEL_EPS
    robot = nik.load_robot(name)
    term = nik.costs.manipulability(robot, weight=0.2)
    q = _configs(robot, 8, 40)
    rk, Jk = term.compiled(q.numpy())  # the numba kernel
    r = term.residual(q)  # the torch twin
    J = robot.jacobian(q)
    w = torch.linalg.det(J @ J.transpose(-1, -2)).sqrt()  # Yoshikawa's measure written out here
    torch.testing.assert_close(measure(robot, q), w, atol=1e-12, rtol=1e-9)
    np.testing.assert_allclose(rk[:, 0], (1.0 / (w + EPS)).numpy(), rtol=1e-8)
    np.testing.assert_allclose(r.detach().numpy(), rk, rtol=1e-8)
    fd = _fd(term.residual, q, h=1e-7)
    np.testing.assert_allclose(Jk, fd.numpy(), rtol=1e-4, atol=1e-6 * np.abs(fd.numpy()).max())
    _, Ja = nik.costs.term.autograd_jacobian(term.residual, q)
    np.testing.assert_allclose(Jk, Ja.numpy(), rtol=1e-6, atol=1e-9 * np.abs(Ja.numpy()).max())
    re, Je = term.evaluate(q)  # float64 CPU: the kernel's
    np.testing.assert_allclose(Je.numpy(), Jk, atol=0, rtol=0)
    assert term.check(q).all() and not term.hard  # a preference
    with pytest.raises(ValueError, match="weight"):
        nik.costs.manipulability(robot, weight=-1.0)


def test_smoothness_and_step_cap_match_finite_differences():
    g = torch.Generator().manual_seed(6)
    path = torch.cumsum(0.1 * torch.randn(7, 3, generator=g, dtype=torch.float64), 0)
    q0 = torch.zeros(3, dtype=torch.float64)
    for term in (nik.costs.smoothness(q0, w_vel=0.5, w_acc=2.0), nik.costs.step_cap(q0, max_step=0.12)):
        r, J = term.evaluate(path)
        flat = path.reshape(1, -1)
        fd = _fd(lambda x, t=term: t.residual(x.reshape(7, 3)), flat)
        torch.testing.assert_close(J, fd, atol=1e-6, rtol=0)
    cap = nik.costs.step_cap(q0, max_step=0.12)
    steps = torch.cat([path[:1] - q0, path[1:] - path[:-1]]).abs().amax(-1)
    assert torch.equal(cap.check(path), steps <= 0.12) and not cap.check(path).all()


def test_custom_term_autograd_and_given_jacobian_agree_with_finite_differences(panda):
    q = _configs(panda, 4, 7)

    def fn(x):
        return torch.stack([torch.sin(x[:, 0]) * x[:, 1], x[:, 2] ** 2], dim=-1)

    def jac(x):
        J = torch.zeros(x.shape[0], 2, x.shape[1], dtype=x.dtype)
        J[:, 0, 0], J[:, 0, 1] = torch.cos(x[:, 0]) * x[:, 1], torch.sin(x[:, 0])
        J[:, 1, 2] = 2 * x[:, 2]
        return J

    auto = nik.costs.custom(fn, name="two")
    given = nik.costs.custom(fn, name="two", jacobian=jac)
    torch.testing.assert_close(auto.jacobian(q), _fd(fn, q), atol=1e-7, rtol=0)
    torch.testing.assert_close(given.jacobian(q), auto.jacobian(q), atol=1e-12, rtol=0)
    assert auto.name == "two" and auto.hard and not nik.costs.custom(fn, tol=math.inf).hard


@pytest.mark.parametrize(
    ("fn", "message"),
    [
        (lambda q: q[:, 0].reshape(1, -1), "residual has shape"),
        (lambda q: q[:, :1] * float("nan"), "NaN"),
        (lambda q: q.detach().numpy(), "must be a torch tensor"),
    ],
)
def test_bad_custom_output_is_one_line(panda, fn, message):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 3, 8))
    with pytest.raises(ValueError, match=message) as err:
        solver.solve(T, costs=[nik.costs.custom(fn, name="bad")])
    assert "\n" not in str(err.value) and "'bad'" in str(err.value)


def test_bad_costs_arguments_are_one_line(panda):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 1, 9))
    for costs, message in (([lambda q: q], "costs\\[0\\]: expected a cost term"), ("x", "expected a list"),
                           ([nik.costs.smoothness()], "path term")):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            solver.solve(T, costs=costs)
    for kw, message in (({"weight": -1.0}, "weight"), ({"tol": float("nan")}, "tol"), ({"jacobian": 3}, "jacobian")):
        with pytest.raises(ValueError, match=message):
            nik.costs.custom(lambda q: q, **kw)
    with pytest.raises(ValueError, match="callable"):
        nik.costs.custom(3)


# -- the problem's LM -----------------------------------------------------------------------------------------------
def test_posture_never_costs_the_pose(panda):
    """A heavy posture pulls the first pass off the pose; the second pass (constraints alone) puts it back."""
    q_true = _configs(panda, 6, 10)
    T = panda.fk(q_true)
    terms = [nik.costs.pose(panda, T), nik.costs.posture(panda, "mid", weight=1.0)]
    out = solve_problem(Problem(terms, nik.costs.limits(panda)), q_true)
    assert out.ok.all()
    pos, rot = nik.pose_error(T, panda.fk(out.x))
    assert (pos <= 1e-4).all() and (rot <= 1.745e-3).all()
    mid = panda.limits.double().mean(1)
    d_new, d_old = (out.x - mid).norm(dim=1), (q_true - mid).norm(dim=1)
    assert (d_new <= d_old + 1e-9).all() and (d_new < d_old - 0.05).sum() >= 4  # nearer the rest posture
    assert panda.within_limits(out.x).all()


# -- costs= in the solver ---------------------------------------------------------------------------------------------
def test_a_user_term_moves_the_elbow_above_a_plane_and_keeps_the_pose(panda):
    """panda is redundant: the elbow may rise in the null space of the pose; a hinge term asks it to. The targets
    are those whose own configuration holds the elbow 1 cm or more above the plain answer's, the plane's height
    halfway between: the term can be met (by that configuration) and the plain answer misses it."""
    solver = nik.IKSolver(panda)
    q_true = _configs(panda, 48, 11)
    T = panda.fk(q_true)
    plain = solver.solve(T)
    z_true, z_plain = _elbow_z(panda, q_true), _elbow_z(panda, plain.q)
    keep = (z_true > z_plain + 0.01).nonzero()[:, 0][:5]
    assert keep.numel() == 5
    T, h = T[keep], 0.5 * (z_true + z_plain)[keep]
    term = nik.costs.custom(lambda q: (h - _elbow_z(panda, q)).clamp(min=0)[:, None], name="elbow_above")
    res = solver.solve(T, costs=[term])
    assert (_elbow_z(panda, plain.q[keep]) < h).all()
    assert res.success.all() and res.unmet == [None] * 5
    assert (_elbow_z(panda, res.q) >= h - 1e-6).all()
    assert (res.pos_err <= 1e-4).all() and (res.rot_err <= 1.745e-3).all()
    pos, rot = nik.pose_error(T, panda.fk(res.q))  # FK round trip of the returned joints
    assert (pos <= 1e-4).all() and (rot <= 1.745e-3).all() and panda.within_limits(res.q).all()


def test_tool_above_a_plane_with_its_own_axis_free_changes_the_answer(panda):
    """With translation along the tool's z free (bounds), "keep the tool above z = h" has room to act. Each target
    is a configuration's tool pose moved 3 cm back along its own (near vertical, upward) z axis, so that
    configuration meets the goal 2 cm above the target; the plain answer stays at the target."""
    q = _configs(panda, 64, 12)
    T0 = panda.fk(q)
    up = (T0[:, 2, 2] > 0.8).nonzero()[:, 0][:4]
    assert up.numel() == 4
    back = torch.eye(4, dtype=torch.float64)
    back[2, 3] = -0.03
    T = T0[up] @ back
    solver = nik.IKSolver(panda)
    bounds = (1e-4, 1e-4, math.inf, 1e-3, 1e-3, 1e-3)
    plain = solver.solve(T, bounds=bounds)
    h = T[:, 2, 3] + 0.02
    term = nik.costs.custom(lambda x: (h - panda.fk(x)[:, 2, 3]).clamp(min=0)[:, None], name="tool_above")
    res = solver.solve(T, bounds=bounds, costs=[term])
    assert plain.success.all() and (panda.fk(plain.q)[:, 2, 3] < h).all()
    assert res.success.all()
    assert (panda.fk(res.q)[:, 2, 3] >= h - 1e-6).all()
    assert (res.axis_err.abs() <= torch.tensor(bounds, dtype=torch.float64)).all()  # still within the goal


def test_a_term_that_cannot_be_met_fails_with_a_reason(panda):
    """The tool itself above its target's height cannot hold with the full pose: success False, the term named."""
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 1, 13))
    h = T[:, 2, 3] + 0.05
    term = nik.costs.custom(lambda x: (h - panda.fk(x)[:, 2, 3]).clamp(min=0)[:, None], name="tool_above")
    with pytest.warns(UserWarning, match="tool_above"):
        res = solver.solve(T, costs=[term])
    assert not res.success.any()
    assert all(u is not None and any("tool_above" in w for w in u) for u in res.unmet)
    assert (res.pos_err <= 1e-4).all()  # the pipeline's answer stands: it reaches the pose


def test_numpy_in_numpy_out_with_costs(panda):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 2, 14)).numpy()
    res = solver.solve(T, costs=[nik.costs.custom(lambda q: q[:, :1] * 0.0, name="zero")])
    assert isinstance(res.q, np.ndarray) and isinstance(res.success, np.ndarray) and res.success.all()


def test_solve_all_keeps_only_solutions_that_meet_the_term(panda):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 1, 15))
    plain = solver.solve_all(T, n_starts=32)
    z = _elbow_z(panda, plain)
    h = float(z.median())
    term = nik.costs.custom(lambda q: (h - _elbow_z(panda, q)).clamp(min=0)[:, None], name="elbow_above")
    Q = solver.solve_all(T, n_starts=32, costs=[term])
    assert (z < h).any() and Q.shape[0] >= 1
    assert (_elbow_z(panda, Q) >= h - 1e-6).all()
    pos, rot = nik.pose_error(T.expand(Q.shape[0], 4, 4), panda.fk(Q))
    assert (pos <= 1e-4).all() and (rot <= 1.745e-3).all()


@pytest.mark.long
def test_solve_path_with_a_user_term(panda):
    q0 = _configs(panda, 1, 1)[0]
    qs = panda.clamp(q0 + torch.linspace(0, 1, 10, dtype=torch.float64)[:, None] * 0.3)
    T = panda.fk(qs)
    solver = nik.IKSolver(panda)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = solver.solve_path(T)
    h = float(_elbow_z(panda, plain.q).min()) + 0.02
    term = nik.costs.custom(lambda q: (h - _elbow_z(panda, q)).clamp(min=0)[:, None], name="elbow_above")
    res = solver.solve_path(T, costs=[term])
    assert (_elbow_z(panda, plain.q) < h).any()
    assert res.success.all() and res.unmet == [None] * 10
    assert (_elbow_z(panda, res.q) >= h - 1e-6).all()
    pos, rot = nik.pose_error(T, panda.fk(res.q))
    assert (pos <= 1e-4).all() and (rot <= 1.745e-3).all()
    assert res.path.largest_step <= res.path.max_step and res.path.continuous


def test_path_problem_block_jacobian_matches_finite_differences(panda):
    """The path problem stacks per-waypoint Jacobians block by block: against differences of the stacked rows."""
    qs = _configs(panda, 3, 16)
    T = panda.fk(_configs(panda, 3, 17))
    prob = PathProblem([nik.costs.pose(panda, T), nik.costs.smoothness()], nik.costs.limits(panda), 3, panda.dof)
    x = qs.reshape(1, -1)
    _, J = prob.evaluate(x)
    torch.testing.assert_close(J, _fd(lambda y: prob.evaluate(y)[0], x), atol=1e-6, rtol=0)


def test_a_user_term_and_a_world_together(panda):
    """The problem holds the collision rows beside the user's term: the answers are collision-free (the solver's
    verdict), meet the term and reach the pose."""
    world = nik.World().add_box([0.0, 0.0, -0.05], [2.0, 2.0, 0.1]).add_sphere([0.35, -0.3, 0.5], 0.06)
    q_own = _configs(panda, 64, 18)
    q_own = q_own[~torch.as_tensor(collides(panda, q_own, world))]
    T = panda.fk(q_own)
    solver = nik.IKSolver(panda, world=world, mesh_verdict=False)
    plain = solver.solve(T)
    z_own, z_plain = _elbow_z(panda, q_own), _elbow_z(panda, plain.q)
    keep = (z_own > z_plain + 0.01).nonzero()[:, 0][:3]
    assert keep.numel() == 3
    T, h = T[keep], 0.5 * (z_own + z_plain)[keep]
    term = nik.costs.custom(lambda q: (h - _elbow_z(panda, q)).clamp(min=0)[:, None], name="elbow_above")
    res = solver.solve(T, costs=[term])
    assert res.success.all() and res.collision_free.all() and not collides(panda, res.q, world).any()
    assert (_elbow_z(panda, res.q) >= h - 1e-6).all() and (res.pos_err <= 1e-4).all()


@pytest.mark.long
def test_solve_path_with_a_user_term_bounds_a_world_and_timing(panda):
    world = nik.World().add_box([0.0, 0.0, -0.05], [2.0, 2.0, 0.1])
    solver = nik.IKSolver(panda, world=world, mesh_verdict=False)
    line = torch.linspace(0, 1, 10, dtype=torch.float64)[:, None] * 0.3
    for q0 in _configs(panda, 32, 1):
        # the path of a straight joint motion free of the table; the plane at its lowest elbow, so that the motion
        # itself meets every term (a witness), and a path whose plain answer dips below the plane somewhere
        qs = panda.clamp(q0 + line)
        if collides(panda, qs, world).any():
            continue
        T, h = panda.fk(qs), float(_elbow_z(panda, qs).min()) - 1e-3
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plain = solver.solve_path(T, q_start=q0, bounds="axis_z")
        if plain.success.all() and (_elbow_z(panda, plain.q) < h).any():
            break
    else:
        pytest.fail("no path among 32 whose plain answer dips below its plane")
    term = nik.costs.custom(lambda q: (h - _elbow_z(panda, q)).clamp(min=0)[:, None], name="elbow_above")
    res = solver.solve_path(T, q_start=q0, bounds="axis_z", costs=[term], timing=True)
    assert res.success.all() and res.collision_free.all() and not collides(panda, res.q, world).any()
    assert (_elbow_z(panda, res.q) >= h - 1e-6).all() and res.path.t is not None
    steps = torch.cat([res.q[:1] - q0, res.q[1:] - res.q[:-1]]).abs().amax(-1)
    assert (steps <= res.path.max_step).all()
    from nik.ik.bounds import parse_bounds
    from nik.poses import within_bounds

    half = torch.from_numpy(parse_bounds("axis_z").expand(10))
    assert within_bounds(T, panda.fk(res.q), half).all()


# -- built-in terms given via costs= take their keyword's compiled route ---------------------------------------------
def _same(a, b) -> bool:
    return torch.equal(torch.as_tensor(a.q), torch.as_tensor(b.q)) and torch.equal(a.success, b.success)


def test_builtin_terms_via_costs_give_the_keyword_answers(panda):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 12, 50))
    assert _same(solver.solve(T, costs=[nik.costs.posture(panda, "mid", weight=0.3)]),
                 solver.solve(T, q_rest="mid", rest_weight=0.3))  # fmt: skip
    bounds = (1e-3, 1e-3, 1e-3, math.inf, math.inf, math.inf)
    assert _same(solver.solve(T, costs=[nik.costs.bounded_pose(panda, T, bounds), nik.costs.limits(panda)]),
                 solver.solve(T, bounds=bounds))  # fmt: skip
    assert _same(solver.solve(T, costs=[nik.costs.pose(panda, T, tol_pos=1e-3)]), solver.solve(T, tol_pos=1e-3))
    from dataclasses import replace

    plan = solver.plan(backend="compiled")
    manip = solver.solve(T, costs=[nik.costs.manipulability(panda, weight=0.2)])
    assert _same(manip, solver.solve(T, plan=replace(plan, manipulability=0.2)))
    Q = solver.solve_all(T[:1], costs=[nik.costs.posture(panda, "mid")])
    assert torch.equal(Q, solver.solve_all(T[:1], q_rest="mid"))


def test_a_custom_term_beside_builtin_terms_gives_the_keyword_answers(panda):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 4, 51))
    term = nik.costs.custom(lambda q: (q[:, :1] - 3.0).clamp(min=0), name="j1_below_3")  # met by every answer
    a = solver.solve(T, costs=[nik.costs.posture(panda, "mid"), term])
    b = solver.solve(T, q_rest="mid", costs=[term])
    assert _same(a, b) and a.success.all()


def test_a_posture_term_and_q_rest_together_is_one_line(panda):
    solver = nik.IKSolver(panda)
    T = panda.fk(_configs(panda, 1, 52))
    with pytest.raises(ValueError, match="posture term and q_rest= both given"):
        solver.solve(T, q_rest="mid", costs=[nik.costs.posture(panda, "mid")])
    with pytest.raises(ValueError, match="two 'manipulability' terms"):
        solver.solve(T, costs=[nik.costs.manipulability(panda), nik.costs.manipulability(panda)])


@pytest.mark.parametrize("name", ["panda", "ur5"])  # the null-space step (7 joints); the closed form's branch (6)
def test_manipulability_term_raises_the_measure_and_keeps_success(name):
    from nik.costs.manipulability import measure

    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot)
    T = robot.fk(_configs(robot, 30, 53))
    plain = solver.solve(T)
    res = solver.solve(T, costs=[nik.costs.manipulability(robot, weight=0.2)])
    assert torch.equal(res.success, plain.success) and res.success.all()
    w0, w1 = measure(robot, plain.q), measure(robot, res.q)
    assert (w1 >= w0 * (1 - 1e-9)).all() and w1.mean() > 1.1 * w0.mean()
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    assert (pos <= 1e-4).all() and (rot <= 1.745e-3).all()


def test_manipulability_term_in_solve_all_and_solve_path(panda):
    from nik.costs.manipulability import measure

    solver = nik.IKSolver(panda)
    q0 = _configs(panda, 1, 54)[0]
    T0 = panda.fk(q0)
    Q = solver.solve_all(T0[None], n_starts=32, costs=[nik.costs.manipulability(panda)])
    w = measure(panda, Q)
    assert Q.shape[0] >= 2 and (w[:-1] >= w[1:]).all()  # highest first
    path = T0.repeat(12, 1, 1).clone()
    path[:, 0, 3] += torch.linspace(0, 0.06, 12, dtype=torch.float64)
    plain = solver.solve_path(path, q0)
    res = solver.solve_path(path, q0, costs=[nik.costs.manipulability(panda)])
    assert res.success.all() and plain.success.all()
    assert measure(panda, res.q).mean() > measure(panda, plain.q).mean()
    assert res.path.largest_step <= res.path.max_step
