"""Tolerant goals: parsing (nik.ik.bounds), the error per tool axis (nik.poses, nik.kernels.lm), LM with bounds
(compiled and batched) and closed forms with a free tool axis (nik.ik.free_axis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import nik
from nik.ik.bounds import bounds_from_cli, parse_bounds
from nik.ik.free_axis import _about, closed_form_free_axis
from nik.ik.goals import rest_target
from nik.lm.batched import bounded_residual
from nik.lm.batched import lm_solve as torch_lm
from nik.poses import bounded_error, rotation_modes, tool_error, within_bounds

INF = math.inf


def _kernels():
    from nik.kernels import lm

    return lm


def _rot(k: int, angle) -> torch.Tensor:
    """(..., 4, 4) rotations about axis k by ``angle: (...,)``."""
    angle = torch.as_tensor(angle, dtype=torch.float64)
    return _about(k, angle.reshape(-1)).reshape(*angle.shape, 4, 4)


def _log_reference(R: np.ndarray) -> np.ndarray:
    """Rotation vector of one rotation by the axis-angle formula (float64, angles below pi)."""
    c = np.clip((np.trace(R) - 1) / 2, -1, 1)
    th = math.acos(c)
    if th < 1e-12:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return th * w / (2 * math.sin(th))


# ---------------------------------------------------------------------------
# parsing
# ---------------------------------------------------------------------------
def test_shorthands_free_their_axes_and_keep_the_tolerances_as_norms():
    pos = parse_bounds("position", tol_pos=1e-4, tol_rot=1e-3)
    assert np.isinf(pos.half[0, 3:]).all() and pos.position_only
    np.testing.assert_allclose(np.linalg.norm(pos.half[0, :3]), 1e-4)
    for k, name in enumerate(("axis_x", "axis_y", "axis_z")):
        b = parse_bounds(name, tol_pos=1e-4, tol_rot=1e-3)
        assert np.isinf(b.half[0, 3 + k]) and np.isfinite(np.delete(b.half[0], 3 + k)).all()
        assert int(b.rot_mode[0]) == k
        np.testing.assert_allclose(np.linalg.norm(np.delete(b.half[0, 3:], k)), 1e-3)
    assert parse_bounds(None) is None


def test_six_numbers_are_one_goal_and_a_b_by_6_array_one_per_target():
    one = parse_bounds((1e-3, 1e-3, 1e-3, 0.01, 0.01, INF), batch=4)
    assert not one.per_target and one.expand(4).shape == (4, 6) and int(one.modes(4)[2]) == 2
    t = one.as_tensor(4, like=torch.zeros(1, dtype=torch.float32))
    assert t.dtype == torch.float32 and t.shape == (4, 6) and rotation_modes(t).tolist() == [2] * 4
    rows = torch.tensor([[1e-3] * 6, [1e-3] * 3 + [INF] * 3, [1e-3] * 5 + [INF]], dtype=torch.float64)
    per = parse_bounds(rows, batch=3)
    assert per.per_target and per.modes(3).tolist() == [-1, 3, 2]
    with pytest.raises(ValueError, match="3 rows for 5 targets"):
        parse_bounds(rows, batch=5)


@pytest.mark.parametrize(
    ("bounds", "match"),
    [
        ((1e-3, -1e-3, 0, 0, 0, 0), "y = -0.001 is negative"),
        ((1e-3, 1e-3, 0, -INF, 0, 0), "rx = -inf is negative"),
        ((1e-3, 1e-3, 0, math.nan, 0, 0), "rx is NaN"),
        ((1e-3, 1e-3, 0), r"expected 6 numbers .* got shape \(3,\)"),
        (np.zeros((2, 3, 6)), "got shape"),
        ("axis_w", "unknown shorthand 'axis_w'"),
        ("position only", "unknown shorthand"),
        ((0, 0, 0, INF, INF, 1e-3), "rotation free about rx and ry but bounded about rz"),
        (("a", 1, 2, 3, 4, 5), "expected 6 numbers"),
        ([[1e-3] * 6, [1e-3, 1e-3, 1e-3, 0.1, INF, INF]], "bounded about rx of target 1"),
    ],
)
def test_bad_bounds_are_one_line_errors(bounds, match):
    with pytest.raises(ValueError, match=match) as err:
        parse_bounds(bounds)
    assert "\n" not in str(err.value)


def test_cli_bounds_are_millimetres_and_degrees_and_the_options_exclude_one_another():
    b = bounds_from_cli(["0.1", "0.2", "free", "1", "2", "inf"])
    np.testing.assert_allclose(b.half[0, :2], [1e-4, 2e-4])
    np.testing.assert_allclose(b.half[0, 3:5], np.radians([1, 2]))
    assert np.isinf(b.half[0, [2, 5]]).all()
    assert int(bounds_from_cli(free_axis=["z"]).rot_mode[0]) == 2
    assert bounds_from_cli(position_only=True).position_only
    assert bounds_from_cli() is None
    for kwargs, match in [
        ({"bounds": ["1"] * 6, "position_only": True}, "--bounds and --position-only exclude one another"),
        ({"position_only": True, "free_axis": "z"}, "exclude one another"),
        ({"free_axis": ["z", "z"]}, "--free-axis z given twice"),
        ({"free_axis": ["x", "z"]}, "--free-axis given twice"),
        ({"free_axis": "w"}, "expected x, y or z"),
        ({"bounds": ["1"] * 5}, "expected 6 values"),
        ({"bounds": ["1", "1", "1", "1", "1", "lots"]}, "rz = 'lots' is not a number"),
        ({"bounds": ["-1", "1", "1", "1", "1", "1"]}, "x = -1 mm: expected a half-width >= 0"),
        ({"bounds": ["1", "1", "1", "1", "nan", "1"]}, "ry = nan deg"),
    ]:
        with pytest.raises(ValueError, match=match):
            bounds_from_cli(**kwargs)


# ---------------------------------------------------------------------------
# the error per tool axis
# ---------------------------------------------------------------------------
def test_tool_error_is_trac_iks_error_in_the_target_tool_frame():
    robot = nik.load_robot("panda")
    g = torch.Generator().manual_seed(0)
    q = robot.sample(2 * 16, generator=g, dtype=torch.float64)
    Tt, T = robot.fk(q[:16]), robot.fk(q[16:])
    d = tool_error(Tt, T)
    for b in range(16):
        Rt, R = Tt[b, :3, :3].numpy(), T[b, :3, :3].numpy()
        np.testing.assert_allclose(d[b, :3].numpy(), Rt.T @ (T[b, :3, 3] - Tt[b, :3, 3]).numpy(), atol=1e-12)
        ref = _log_reference(Rt.T @ R)
        if np.linalg.norm(ref) < 3.0:  # away from pi, where the reference formula is exact
            np.testing.assert_allclose(d[b, 3:].numpy(), ref, atol=1e-9)


@pytest.mark.parametrize("k", [0, 1, 2])
def test_a_free_axis_measures_the_tilt_of_that_axis_whatever_the_twist(k):
    """``Rk(a) Ri(b)``: the tool axis k is tilted by |b| whatever the twist a; the swing says |b|, the rotation
    vector's other components do not (why a free axis cannot just drop one component)."""
    i = (k + 1) % 3
    Tt = torch.eye(4, dtype=torch.float64).expand(7, 4, 4)
    twist = torch.tensor([0.0, 0.5, 1.5, 2.5, 3.0, -3.1, math.pi - 1e-6], dtype=torch.float64)
    T = _rot(k, twist) @ _rot(i, torch.full((7,), 0.2, dtype=torch.float64))
    d = tool_error(Tt, T, torch.full((7,), k))
    others = [3 + i, 3 + (k + 2) % 3]
    torch.testing.assert_close(d[:, others].norm(dim=-1), torch.full((7,), 0.2, dtype=torch.float64))
    torch.testing.assert_close(d[:, 3 + k], twist.clone().clamp(-math.pi, math.pi), atol=1e-9, rtol=0)
    rv = tool_error(Tt, T)[:, others].norm(dim=-1)
    assert float((rv - 0.2).abs().max()) > 0.1
    bounds = torch.zeros(6, dtype=torch.float64)
    bounds[3:] = 0.21
    bounds[3 + k] = INF
    assert bool(within_bounds(Tt, T, bounds).all())
    assert not bool(within_bounds(Tt, T, bounds.clone().fill_(0.14).index_fill(0, torch.tensor([3 + k]), INF)).any())


@pytest.mark.parametrize("mode", [-1, 2])
def test_a_half_turn_is_never_inside_small_bounds(mode):
    """At a half turn the rotation vector's antisymmetric part vanishes and the swing's axis is undefined: both
    errors must still say pi, in torch and in the kernel."""
    lm = _kernels()
    robot = nik.load_robot("ur5")
    G, joints = robot.chain_arrays()
    q = torch.zeros(1, 6, dtype=torch.float64)
    T = robot.fk(q)
    Tt = T @ _rot(0, torch.tensor([math.pi], dtype=torch.float64))
    d_t = tool_error(Tt, T, torch.tensor([mode]))
    d_k = np.empty((1, 6))
    lm.bounded_errors(G, joints, Tt.numpy(), q.numpy(), np.array([mode], dtype=np.int64), d_k)
    for d in (d_t[0, 3:].numpy(), d_k[0, 3:]):
        assert np.linalg.norm(np.delete(d, 2) if mode == 2 else d) == pytest.approx(math.pi, abs=1e-6)


def test_bounded_error_is_the_excess_beyond_each_bound_and_zero_on_free_axes():
    Tt = torch.eye(4, dtype=torch.float64)[None]
    T = Tt.clone()
    T[0, :3, 3] = torch.tensor([0.003, -0.001, 0.5], dtype=torch.float64)
    bounds = torch.tensor([0.002, 0.002, INF, 0.1, 0.1, 0.1], dtype=torch.float64)
    torch.testing.assert_close(bounded_error(Tt, T, bounds)[0], torch.tensor([0.001, 0, 0, 0, 0, 0.0]).double())
    assert not bool(within_bounds(Tt, T, bounds)[0])
    assert bool(within_bounds(Tt, T, bounds + torch.tensor([0.0011, 0, 0, 0, 0, 0]).double())[0])
    assert rotation_modes(torch.tensor([[0, 0, 0, 1, 1, INF], [0, 0, 0, INF, INF, INF]])).tolist() == [2, 3]


@pytest.mark.parametrize("k", [-1, 2])
def test_bounded_error_is_differentiable_through_fk(k):
    robot = nik.load_robot("panda")
    g = torch.Generator().manual_seed(1)
    q = robot.sample(3, generator=g, dtype=torch.float64)
    Tt = robot.fk(q + 0.3)
    bounds = torch.tensor([1e-4] * 6, dtype=torch.float64)
    if k >= 0:
        bounds[3 + k] = INF
    x = q.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: bounded_error(Tt, robot.fk(x), bounds), (x,))


@pytest.mark.parametrize("mode", [-1, 0, 1, 2, 3])
def test_the_kernels_error_is_the_torch_error(mode):
    robot = nik.load_robot("ur5")
    G, joints = robot.chain_arrays()
    g = torch.Generator().manual_seed(2)
    q = robot.sample(20, generator=g, dtype=torch.float64)
    Tt = robot.fk(q + 0.4 * torch.randn(q.shape, generator=g, dtype=torch.float64))
    modes = np.full(20, mode, dtype=np.int64)
    d = np.empty((20, 6))
    _kernels().bounded_errors(G, joints, Tt.numpy(), q.numpy(), modes, d)
    ref = tool_error(Tt, robot.fk(q), torch.from_numpy(modes))
    if 0 <= mode <= 2:
        ref[:, 3 + mode] = 0.0  # the kernel leaves the twist out (it is free)
    np.testing.assert_allclose(d, ref.numpy(), atol=1e-10)


@pytest.mark.parametrize("mode", [-1, 0, 1, 2])
def test_the_residual_jacobian_matches_finite_differences(mode):
    """Kernel and torch: the Jacobian of the error (rows outside their dead zone: of the residual itself)."""
    lm = _kernels()
    robot = nik.load_robot("panda")
    G, joints = robot.chain_arrays()
    g = torch.Generator().manual_seed(3)
    q = robot.sample(4, generator=g, dtype=torch.float64)
    Tt = robot.fk(q + 0.3 * torch.randn(q.shape, generator=g, dtype=torch.float64))
    bnd = np.full(6, 1e-6)
    if mode >= 0:
        bnd[3 + mode] = INF
    n, h, rw, B = robot.dof, 1e-6, 0.5, 4
    bounds, modes = np.tile(bnd, (B, 1)), np.full(B, mode, dtype=np.int64)
    e, J = np.empty((B, 6)), np.empty((B, 6, n))
    lm.bounded_residuals(G, joints, Tt.numpy(), q.numpy(), bounds, modes, rw, e, J)
    fd = np.empty((B, 6, n))
    for i in range(n):
        ep, em, scratch = np.empty((B, 6)), np.empty((B, 6)), np.empty((B, 6, n))
        for sign, out in ((1, ep), (-1, em)):
            x = q.numpy().copy()
            x[:, i] += sign * h
            lm.bounded_residuals(G, joints, Tt.numpy(), x, bounds, modes, rw, out, scratch)
        fd[:, :, i] = -(ep - em) / (2 * h)
    np.testing.assert_allclose(J, fd, atol=1e-7)
    if mode >= 0:
        assert not J[:, 3 + mode].any()
    Tq, Jq = robot.fk_and_jacobian(q)
    _, Jr, _, _, _, _ = bounded_residual(Tt, Tq[:, :3], Jq, torch.from_numpy(bounds), rw)
    np.testing.assert_allclose(Jr.numpy(), J, atol=1e-9)


# ---------------------------------------------------------------------------
# LM with bounds
# ---------------------------------------------------------------------------
CASES = {
    "bounded": (1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3),
    "loose": (5e-3, 2e-3, 1e-3, 0.05, 0.02, 0.1),
    "free_rx": (1e-4, 1e-4, 1e-4, INF, 1e-3, 1e-3),
    "free_ry": (1e-4, 1e-4, 1e-4, 1e-3, INF, 1e-3),
    "free_rz": (1e-4, 1e-4, 1e-4, 1e-3, 1e-3, INF),
    "position": (1e-4, 1e-4, 1e-4, INF, INF, INF),
    "free_z": (1e-4, 1e-4, INF, 1e-3, 1e-3, 1e-3),
}


def _targets(robot, bounds, B, seed):
    """Reachable targets, turned about their free rotation axis by a random angle and moved along a free position
    axis: still reachable (by the configuration they came from) within the bounds."""
    g = torch.Generator().manual_seed(seed)
    q = robot.sample(B, generator=g, dtype=torch.float64)
    T = robot.fk(q)
    for k in range(3):
        if math.isinf(bounds[3 + k]):
            T = T @ _rot(k, (torch.rand(B, generator=g, dtype=torch.float64) * 2 - 1) * math.pi)
        if math.isinf(bounds[k]):
            shift = torch.zeros(B, 4, 4, dtype=torch.float64)
            shift[:, k, 3] = 0.2 * (torch.rand(B, generator=g, dtype=torch.float64) - 0.5)
            T = T @ (torch.eye(4, dtype=torch.float64) + shift)
    q0 = q + 0.3 * torch.randn(q.shape, generator=g, dtype=torch.float64)
    return T, q0


@pytest.mark.parametrize("name", ["panda", "ur5"])
@pytest.mark.parametrize("case", list(CASES))
def test_lm_reaches_the_bounds_and_torch_and_kernel_agree(name, case):
    lm = _kernels()
    robot = nik.load_robot(name)
    G, joints = robot.chain_arrays()
    B = 24
    T, q0 = _targets(robot, CASES[case], B, seed=list(CASES).index(case))
    bounds = np.tile(CASES[case], (B, 1))
    modes = lm.rotation_modes(bounds)
    opts, iopts = lm.lm_options()
    out = [np.empty((B, robot.dof)), np.empty(B, np.int64), np.empty(B, bool), np.empty(B), np.empty(B)]
    # with restarts: every target reached, checked by FK
    args = (G, joints, T.numpy(), q0.numpy(), (bounds, modes), opts, iopts)
    lm.lm_solve_bounded(*args, np.full(B, 50), lm.seed_state(0), tuple(out))
    assert out[2].all()
    assert bool(robot.within_limits(torch.from_numpy(out[0])).all())
    assert bool(within_bounds(T, robot.fk(torch.from_numpy(out[0])), torch.from_numpy(bounds)).all())
    # without restarts, the same starts: the torch LM takes the same steps
    lm.lm_solve_bounded(*args, np.zeros(B, np.int64), lm.seed_state(0), tuple(out))
    q_t, it_t = torch_lm(robot, T, q0, restarts=0, bounds=torch.from_numpy(bounds))
    ok_t = within_bounds(T, robot.fk(q_t), torch.from_numpy(bounds))
    assert ok_t.numpy().tolist() == out[2].tolist()
    assert out[2].mean() >= 0.75
    assert it_t.numpy().tolist() == out[1].tolist()
    apart = np.abs(q_t.numpy() - out[0]).max(1) > 1e-7
    assert apart.sum() <= 1, f"torch and kernel answers apart on targets {np.flatnonzero(apart).tolist()}"
    np.testing.assert_allclose(q_t.numpy()[~apart], out[0][~apart], atol=1e-7)
    for b in np.flatnonzero(apart):
        _assert_a_knife_edge_at_a_limit(lm, robot, T[b : b + 1], q0[b : b + 1], bounds[b : b + 1], int(out[1][b]))


def _assert_a_knife_edge_at_a_limit(lm, robot, T, q0, bounds, iterations):
    """Torch and kernel took the same steps up to the last one, whose active set hung on the sign of rounding: a
    joint at its limit whose gradient is zero but for rounding (e.g. panda's last joint, whose axis holds the
    flange, once the rotation rows are inside their dead zone: no residual row moves it), so whether the step holds
    it there (``g_i`` pointing out) is either branch. Both answers are then correct (the caller checks them)."""
    opts, iopts = lm.lm_options(first_iters=iterations - 1)
    out = [np.empty((1, robot.dof)), np.empty(1, np.int64), np.empty(1, bool), np.empty(1), np.empty(1)]
    G, joints = robot.chain_arrays()
    args = (G, joints, T.numpy(), q0.numpy(), (bounds, lm.rotation_modes(bounds)), opts, iopts)
    lm.lm_solve_bounded(*args, np.zeros(1, np.int64), lm.seed_state(0), tuple(out))
    q_t, _ = torch_lm(robot, T, q0, restarts=0, bounds=torch.from_numpy(bounds), max_iters=iterations - 1)
    np.testing.assert_allclose(q_t.numpy(), out[0], atol=1e-7)  # the same steps until the last one
    e, J = np.empty((1, 6)), np.empty((1, 6, robot.dof))
    lm.bounded_residuals(G, joints, T.numpy(), out[0], bounds, lm.rotation_modes(bounds), opts[lm.ROT_WEIGHT], e, J)
    g = J[0].T @ e[0]
    lo, hi = robot.limits.numpy().T
    at_limit = (out[0][0] <= lo) | (out[0][0] >= hi)
    assert (at_limit & (np.abs(g) <= 1e-12 * np.abs(g).max())).any()


def test_position_only_reaches_every_reachable_position_on_kuka_kr():
    lm = _kernels()
    robot = nik.load_robot("kuka_kr")
    G, joints = robot.chain_arrays()
    B = 300
    g = torch.Generator().manual_seed(4)
    T = robot.fk(robot.sample(B, generator=g, dtype=torch.float64))
    T[:, :3, :3] = nik.poses.quaternion_to_matrix(torch.randn(B, 4, generator=g, dtype=torch.float64))
    goal = parse_bounds("position", batch=B)
    bounds = goal.expand(B)
    opts, iopts = lm.lm_options(first_starts=8)
    out = [np.empty((B, 6)), np.empty(B, np.int64), np.empty(B, bool), np.empty(B), np.empty(B)]
    q0 = np.zeros((B, 6))
    args = (G, joints, T.numpy(), q0, (bounds, goal.modes(B)), opts, iopts)
    lm.lm_solve_bounded(*args, np.full(B, 100), lm.seed_state(1), tuple(out))
    reached = robot.fk(torch.from_numpy(out[0]))
    assert bool(within_bounds(T, reached, torch.from_numpy(bounds)).all())
    assert float((reached[:, :3, 3] - T[:, :3, 3]).norm(dim=-1).max()) <= 1e-4


# ---------------------------------------------------------------------------
# closed forms with a free tool axis
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["kuka_kr", "ur5"])
def test_a_pose_out_of_reach_at_its_orientation_is_solved_with_the_tool_axis_free(name):
    """A tool 0.25 m off the flange: turning about the tool's z axis moves the wrist; poses that no closed-form
    solution reaches at the given orientation are solved when the rotation about z is free."""
    robot = nik.load_robot(name, tool=[0.25, 0, 0.1, 1, 0, 0, 0])
    g = torch.Generator().manual_seed(6)
    T0 = robot.fk(robot.sample(64, generator=g, dtype=torch.float64))
    T = T0 @ _rot(2, torch.full((64,), math.radians(175.0), dtype=torch.float64))
    _, valid = nik.analytic.solve(robot, T)
    out_of_reach = ~valid.any(-1)
    assert int(out_of_reach.sum()) >= 5
    res = closed_form_free_axis(robot, T[out_of_reach])
    assert bool(res.success.all()) and not bool(res.refined.any())
    assert bool(robot.within_limits(res.q).all())
    goal = torch.from_numpy(parse_bounds("axis_z").half[0])
    assert bool(within_bounds(T[out_of_reach], robot.fk(res.q), goal).all())
    assert bool(res.valid.any(-1).all()) and bool((res.gamma.abs() > 0).all())
    # the compiled bounded LM (no closed form, uniform starts) finds them feasible too
    lm = _kernels()
    G, joints = robot.chain_arrays()
    m = int(out_of_reach.sum())
    half = parse_bounds("axis_z").expand(m)
    opts, iopts = lm.lm_options(first_starts=8)
    out = [np.empty((m, 6)), np.empty(m, np.int64), np.empty(m, bool), np.empty(m), np.empty(m)]
    Tn = np.ascontiguousarray(T[out_of_reach].numpy())
    lm.lm_solve_bounded(G, joints, Tn, np.zeros((m, 6)), (half, lm.rotation_modes(half)), opts, iopts,
                        np.full(m, 200), lm.seed_state(0), tuple(out))  # fmt: skip
    assert bool(within_bounds(T[out_of_reach], robot.fk(torch.from_numpy(out[0])), goal).all())
    # one sample (the given orientation): nothing closed-form; the bounded LM from the clamped candidates serves
    res1 = closed_form_free_axis(robot, T[out_of_reach][:5], samples=1)
    assert bool(res1.refined.all()) and bool(res1.success.all())


def test_closed_form_free_axis_refuses_goals_without_one_free_rotation_axis():
    robot = nik.load_robot("ur5")
    T = robot.fk(robot.sample(2, generator=torch.Generator().manual_seed(0), dtype=torch.float64))
    for bounds in ("position", (1e-4,) * 6, None):
        with pytest.raises(ValueError, match="exactly one rotation axis free"):
            closed_form_free_axis(robot, T, bounds=bounds)


# ---------------------------------------------------------------------------
# the solver: bounds= and q_rest= on both backends (nik.ik.goals)
# ---------------------------------------------------------------------------
_URDF_ARM = "configs/robots/urdf/xarm7.urdf"  # a URDF arm without a closed form
SOLVER_CASES = {
    "bounded": (1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3),
    "free_rz": (1e-4, 1e-4, 1e-4, 1e-3, 1e-3, INF),
    "free_rx": (1e-4, 1e-4, 1e-4, INF, 1e-3, 1e-3),
    "free_x": (INF, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3),
    "position": (1e-4, 1e-4, 1e-4, INF, INF, INF),
}


def _robot(name):
    from pathlib import Path

    return nik.load_robot(Path(__file__).resolve().parents[1] / _URDF_ARM if name == "xarm7_urdf" else name)


def _honest(robot, T, res, bounds):
    """Success measured independently: FK of the answer, the torch bounded error; a success never outside."""
    q = torch.as_tensor(res.q, dtype=torch.float64)
    assert bool(robot.within_limits(q).all())
    half = torch.as_tensor(np.broadcast_to(np.asarray(bounds, dtype=np.float64), (T.shape[0], 6)).copy())
    inside = within_bounds(T, robot.fk(q), half)
    ok = torch.as_tensor(res.success)
    assert bool((inside | ~ok).all()), "a success outside the bounds"
    assert inside.tolist() == ok.tolist()
    assert float(bounded_error(T, robot.fk(q), half).abs().amax(-1)[ok].sum()) == 0.0
    return ok


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize("name", ["panda", "ur5", "kuka_kr", "xarm7_urdf"])
@pytest.mark.parametrize("case", list(SOLVER_CASES))
def test_solve_with_bounds_succeeds_inside_them_by_fk_on_both_backends(name, case, backend):
    robot = _robot(name)
    bounds = SOLVER_CASES[case]
    T, _ = _targets(robot, bounds, 12, seed=len(case))  # turned about a free axis, moved along a free position axis
    res = nik.IKSolver(robot, backend=backend).solve(T.numpy(), bounds=bounds, seed=1)
    assert isinstance(res.q, np.ndarray) and res.axis_err.shape == (12, 6)
    ok = _honest(robot, T, res, bounds)
    assert bool(ok.all())
    # the classic errors stay the classic errors: a free axis shows there
    pos, rot = nik.poses.pose_error(T, robot.fk(torch.from_numpy(res.q)))
    np.testing.assert_allclose(res.pos_err, pos.numpy(), atol=1e-9)
    np.testing.assert_allclose(res.rot_err, rot.numpy(), atol=1e-9)


@pytest.mark.parametrize("name", ["ur5", "kuka_kr"])
def test_closed_forms_and_lm_solve_the_same_free_axis_goals(name):
    """A tool off the flange, targets turned about the tool's z: the closed-form arm (free-axis closed form as the
    guess) and the same arm without its closed form (LM only) solve the same targets, on both backends."""
    robot = nik.load_robot(name, tool=[0.25, 0, 0.1, 1, 0, 0, 0])
    g = torch.Generator().manual_seed(3)
    T = robot.fk(robot.sample(24, generator=g, dtype=torch.float64)) @ _rot(
        2, (torch.rand(24, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    )
    got = {}
    for analytic in (True, False):
        for backend in ("compiled", "torch"):
            solver = nik.IKSolver(robot, checkpoint=None, analytic=analytic, backend=backend)
            res = solver.solve(T, bounds="axis_z", seed=0)
            assert res.source == ("analytic" if analytic else "multistart")
            got[analytic, backend] = _honest(robot, T, res, parse_bounds("axis_z").half[0]).tolist()
    assert len({tuple(v) for v in got.values()}) == 1 and all(got[True, "compiled"])


def test_solve_all_with_a_free_axis_gives_distinct_solutions_inside_the_bounds():
    robot = nik.load_robot("ur5")
    T = robot.fk(robot.sample(1, generator=torch.Generator().manual_seed(2), dtype=torch.float64))
    half = torch.from_numpy(parse_bounds("axis_z").half)
    for analytic in (True, False):
        solver = nik.IKSolver(robot, checkpoint=None, analytic=analytic)
        every = solver.solve_all(T, bounds="axis_z", n_starts=64)
        exact = solver.solve_all(T, n_starts=64)
        assert every.shape[0] > exact.shape[0] >= 1
        assert bool(within_bounds(T.expand(every.shape[0], 4, 4), robot.fk(every), half).all())
        assert bool(robot.within_limits(every).all())


@pytest.mark.parametrize(
    "bounds,match",
    [
        ((1, 1, 1, -1, 1, 1), "negative"),
        ((1, 1, 1, math.nan, 1, 1), "NaN"),
        ("axis_w", "unknown shorthand"),
        ((1, 1, 1, INF, INF, 1), "two axes"),
    ],
)
def test_solve_refuses_bad_bounds_in_one_line(bounds, match):
    solver = nik.IKSolver("ur5")
    T = solver.robot.fk(torch.zeros(1, 6, dtype=torch.float64))
    with pytest.raises(ValueError, match=match) as err:
        solver.solve(T, bounds=bounds)
    assert "\n" not in str(err.value)


def test_cli_solve_takes_bounds_in_mm_and_degrees_and_refuses_bad_ones(capsys):
    from nik.cli import main

    robot = nik.load_robot("ur5")
    T = robot.fk(torch.tensor([[0.3, -1.0, 1.2, -0.5, 1.1, 0.4]], dtype=torch.float64))
    T = T @ _rot(2, torch.tensor([2.0], dtype=torch.float64))
    pose = [*T[0, :3, 3].tolist(), *nik.poses.matrix_to_quaternion(T[0, :3, :3]).tolist()]
    args = ["solve", "--robot", "ur5", "--json", "--pose", *map(repr, pose)]
    assert main(args + ["--bounds", "0.1", "0.1", "0.1", "0.1", "0.1", "free"]) == 0
    out = __import__("json").loads(capsys.readouterr().out)
    q = torch.tensor([out["results"][0]["q_si"]], dtype=torch.float64)
    bounds = (1e-4, 1e-4, 1e-4, math.radians(0.1), math.radians(0.1), INF)
    assert bool(within_bounds(T, robot.fk(q), torch.tensor(bounds, dtype=torch.float64)))
    assert main(args + ["--position-only"]) == 0
    capsys.readouterr()
    for bad, word in ((["--bounds", "1", "1", "1", "-1", "1", "1"], "half-width"), (["--free-axis", "w"], "x, y or z"),
                      (["--free-axis", "z", "--position-only"], "exclude")):  # fmt: skip
        assert main(args + bad) == 2
        err = capsys.readouterr().err
        assert err.startswith("nik solve: error:") and err.count("\n") == 1 and word in err


FIVE_JOINTS = """\
name: five_joints
convention: dh
unit: mm
angles: deg
joints:
  - {alpha: 90, a: 0, d: 120, limits: [-170, 170]}
  - {alpha: 0, a: 110, d: 0, offset: 90, limits: [-100, 100]}
  - {alpha: 0, a: 130, d: 0, limits: [-140, 140]}
  - {alpha: 90, a: 0, d: 0, offset: 90, limits: [-100, 100]}
  - {alpha: 0, a: 0, d: 100, limits: [-170, 170]}
"""


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_position_only_solves_every_reachable_position_of_a_five_joint_arm(tmp_path, backend):
    arm = tmp_path / "five.yaml"
    arm.write_text(FIVE_JOINTS)
    robot = nik.load_robot(arm)
    g = torch.Generator().manual_seed(5)
    T = robot.fk(robot.sample(100, generator=g, dtype=torch.float64))  # reachable positions (by construction)
    T[:, :3, :3] = nik.poses.quaternion_to_matrix(torch.randn(100, 4, generator=g, dtype=torch.float64))
    res = nik.IKSolver(robot, backend=backend).solve(T, bounds="position")
    ok = _honest(robot, T, res, parse_bounds("position").half[0])
    assert bool(ok.all())
    assert float(torch.as_tensor(res.pos_err).max()) <= 1e-4


# ---------------------------------------------------------------------------
# preferred postures
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_a_rest_posture_moves_panda_towards_it_without_costing_accuracy(backend):
    robot = nik.load_robot("panda")
    g = torch.Generator().manual_seed(7)
    T = robot.fk(robot.sample(40, generator=g, dtype=torch.float64))
    solver = nik.IKSolver(robot, backend=backend)
    for q_rest in (robot.sample(1, generator=g, dtype=torch.float64)[0], "mid"):
        rest = torch.from_numpy(rest_target(robot, q_rest, 40))
        plain = solver.solve(T, seed=0)
        moved = solver.solve(T, seed=0, q_rest=q_rest, rest_weight=0.2)
        assert bool(plain.success.all()) and bool(moved.success.all())
        pos, rot = nik.poses.pose_error(T, robot.fk(moved.q))  # every success still within tolerance by FK
        assert float(pos.max()) <= 1e-4 and float(rot.max()) <= math.radians(0.1)
        assert bool(robot.within_limits(moved.q).all())
        d0, d1 = (plain.q - rest).norm(dim=-1), (moved.q - rest).norm(dim=-1)
        # one null-space direction (self-motion): nearer on every target, and moved on most
        assert bool((d1 <= d0 + 1e-9).all()) and float((d1 < d0 - 1e-3).double().mean()) >= 0.5


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_a_rest_posture_changes_nothing_on_a_six_joint_arm_without_a_free_axis(backend):
    robot = nik.load_robot("kuka_kr")
    g = torch.Generator().manual_seed(8)
    T = robot.fk(robot.sample(20, generator=g, dtype=torch.float64))
    solver = nik.IKSolver(robot, backend=backend)
    plain = solver.solve(T, seed=0)
    moved = solver.solve(T, seed=0, q_rest="mid")
    assert bool(moved.success.all())
    torch.testing.assert_close(moved.q, plain.q, atol=1e-5, rtol=0)
    # under a free tool axis the same arm has a null space: the posture moves it
    free = solver.solve(T, seed=0, bounds="axis_z")
    free_rest = solver.solve(T, seed=0, bounds="axis_z", q_rest="mid")
    _honest(robot, T, free_rest, parse_bounds("axis_z").half[0])
    rest = torch.from_numpy(rest_target(robot, "mid", 20))
    assert float((free_rest.q - rest).norm(dim=-1).mean()) < float((free.q - rest).norm(dim=-1).mean())


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_per_target_bounds_and_float32_tensors_are_measured_against_the_asked_bounds(backend):
    robot = nik.load_robot("ur5")
    g = torch.Generator().manual_seed(9)
    T = robot.fk(robot.sample(6, generator=g, dtype=torch.float64))
    T = T @ _rot(0, torch.full((6,), 0.5, dtype=torch.float64))  # turned about x: only the free-x rows allow it
    half = np.tile(np.array([1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3]), (6, 1))
    half[::2, 3] = INF
    solver = nik.IKSolver(robot, backend=backend)
    res = solver.solve(T.float(), bounds=half)
    assert isinstance(res.q, torch.Tensor) and res.q.dtype == torch.float32
    ok = within_bounds(T, robot.fk(res.q.double()), torch.from_numpy(half))
    assert ok.tolist() == res.success.tolist()
    assert bool(res.success[::2].all())  # the free-x targets: solved
    with pytest.raises(ValueError, match="rows for 6 targets"):
        solver.solve(T, bounds=half[:4])


def test_bad_q_rest_is_a_one_line_error():
    solver = nik.IKSolver("panda")
    T = solver.robot.fk(torch.zeros(1, 7, dtype=torch.float64))
    for q_rest, match in (("middle", "'mid'"), ([0.0] * 6, "shape"), ([math.nan] * 7, "NaN")):
        with pytest.raises(ValueError, match=match) as err:
            solver.solve(T, q_rest=q_rest)
        assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="rest_weight"):
        solver.solve(T, q_rest="mid", rest_weight=0.0)


def test_the_compiled_bounded_solve_searches_the_free_axis_on_the_compiled_closed_form(monkeypatch):
    """Issue 37 item 6: the free-axis search of a compiled bounded solve runs the numba closed form (main: torch's
    ``closed_form_free_axis``, 36 angles x 8 branches per target, milliseconds a target); its start lands inside the
    bounds in a few LM iterations, with no uniform restarts."""
    import nik.ik.free_axis

    def refuse(*args, **kwargs):
        raise AssertionError("the torch free-axis closed form ran")

    monkeypatch.setattr(nik.ik.free_axis, "closed_form_free_axis", refuse)
    robot = nik.load_robot("ur5", tool=[0.25, 0, 0.1, 1, 0, 0, 0])
    g = torch.Generator().manual_seed(6)
    T = robot.fk(robot.sample(64, generator=g, dtype=torch.float64))
    T = T @ _rot(2, torch.full((64,), math.radians(175.0), dtype=torch.float64))
    _, valid = nik.analytic.solve(robot, T)
    out_of_reach = ~valid.any(-1)
    assert int(out_of_reach.sum()) >= 5  # these need the free angle
    res = nik.IKSolver(robot, backend="compiled").solve(T.numpy(), bounds="axis_z", seed=0)
    assert bool(res.success.all())
    assert _honest(robot, T, res, parse_bounds("axis_z").half[0]).all()
    assert int(res.iterations[out_of_reach.numpy()].max()) <= 10
