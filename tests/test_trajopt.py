"""Whole-trajectory optimisation (nik.paths.trajopt, nik.kernels.trajopt): the banded solve, the objective's Jacobian,
a redundant-arm path the waypoint chain cannot follow, and the polish that never makes a path worse."""

import math
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.ik.model import model_of
from nik.kernels.trajopt import band_cholesky, band_solve, normal_equations, residuals
from nik.paths.trajopt import TrajCfg, optimise_path, polish_path, residual_count, trajopt_options

TOL_POS, TOL_ROT = 1e-4, math.radians(0.1)


def _fd_jacobian(residuals_into, Q: np.ndarray, R: int, h: float = 1e-6) -> np.ndarray:
    """``(R, Q.size)``: central differences of ``residuals_into(Q, r)`` (which writes ``R`` residuals into ``r``)."""
    J = np.empty((R, Q.size))
    for f in range(Q.size):
        cols = []
        for step in (h, -h):
            Qs = Q.copy()
            Qs.flat[f] += step
            rs = np.empty(R)
            residuals_into(Qs, rs)
            cols.append(rs)
        J[:, f] = (cols[0] - cols[1]) / (2 * h)
    return J


def _dense(H: np.ndarray) -> np.ndarray:
    """The symmetric matrix of the lower band ``H[r, k] = A[r, r - k]``."""
    M, w = H.shape
    A = np.zeros((M, M))
    for r in range(M):
        for k in range(min(w, r + 1)):
            A[r, r - k] = A[r - k, r] = H[r, k]
    return A


def test_banded_cholesky_solve_equals_a_dense_solve():
    rng = np.random.default_rng(0)
    M, half = 60, 4
    B = np.zeros((M, M))
    for i in range(M):
        lo = max(0, i - half)
        B[i, lo : i + 1] = rng.normal(size=i + 1 - lo)
    B[np.arange(M), np.arange(M)] = np.abs(np.diag(B)) + 3.0  # well conditioned
    A = B @ B.T  # SPD, half-bandwidth 2 * half
    b = 2 * half
    H = np.array([[A[r, r - k] if r >= k else 0.0 for k in range(b + 1)] for r in range(M)])
    assert band_cholesky(H, b)
    g = rng.normal(size=M)
    x = np.empty(M)
    band_solve(H, b, g, x)
    np.testing.assert_allclose(x, np.linalg.solve(A, g), rtol=1e-9, atol=1e-10)


def test_banded_cholesky_refuses_a_matrix_that_is_not_positive_definite():
    H = np.array([[1.0, 0.0], [1.0, 2.0], [-4.0, 0.0]])  # diag (1, 1, -4), one off-diagonal 2
    assert not band_cholesky(H, 1)


def test_normal_equations_match_finite_differences_of_the_residual():
    """``J^T J`` and ``-J^T r`` of the kernel against the finite-difference Jacobian of the residual vector, at a
    path whose poses are met exactly (the geometric Jacobian is the exact derivative there) but whose steps exceed
    the cap and whose joints sit near their limits (every other term active)."""
    robot = nik.load_robot("panda")
    m = model_of(robot)
    rng = np.random.default_rng(1)
    N, n = 5, robot.dof
    Q = rng.uniform(m.lo, m.hi, size=(N, n))
    Q[2] = m.lo + 1e-3
    Q[3] = m.hi - 1e-3
    T = np.ascontiguousarray(robot.fk(torch.from_numpy(Q)).numpy())
    opts = trajopt_options(TrajCfg(w_vel=0.3, w_acc=0.2, w_step=0.5, w_lim=0.7), math.radians(10.0))
    qs = np.clip(Q[0] + 0.3, m.lo, m.hi)
    qe = np.clip(Q[-1] - 0.3, m.lo, m.hi)
    R = residual_count(N, n, True, True)
    r = np.empty(R)
    cost = residuals(m.G, m.joints, T, Q, qs, True, qe, True, opts, r)
    assert cost == pytest.approx((r**2).sum())
    assert np.abs(r[: 6 * N]).max() < 1e-12 and np.abs(r[6 * N :]).max() > 0.1
    J = _fd_jacobian(lambda Qs, rs: residuals(m.G, m.joints, T, Qs, qs, True, qe, True, opts, rs), Q, R)
    H, g = np.empty((N * n, 3 * n)), np.empty(N * n)
    assert normal_equations(m.G, m.joints, T, Q, qs, True, qe, True, opts, H, g) == pytest.approx(cost)
    np.testing.assert_allclose(_dense(H), J.T @ J, atol=1e-6)
    np.testing.assert_allclose(g, -J.T @ r, atol=1e-6)


def _check(robot, T, q, q0):
    """``(every waypoint within 0.1 mm / 0.1 deg by FK and inside the limits, largest step from q0 on)``."""
    qt = torch.from_numpy(np.ascontiguousarray(q))
    pe, re = nik.pose_error(T, robot.fk(qt))
    lo, hi = robot.limits.double().T
    ok = bool(((pe <= TOL_POS) & (re <= TOL_ROT)).all() and ((qt >= lo) & (qt <= hi)).all())
    steps = np.abs(np.diff(np.concatenate([q0.numpy()[None], q]), axis=0)).max()
    return ok, float(steps)


def test_optimisation_follows_a_redundant_path_the_waypoint_chain_cannot(monkeypatch, xarm7_circle_37):
    import nik.paths.solve as P

    monkeypatch.setattr(P, "_smooth", lambda *a: True)  # the chain alone: no global search...
    monkeypatch.setattr(P, "_flatten", lambda run, q, *a: q)  # ...and no 2 deg flattening (solve_path's own rescues)
    robot, q0, T = xarm7_circle_37
    max_step = math.radians(3.0)
    solver = nik.IKSolver(robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        chain = solver.solve_path(T, q_start=q0, max_step=math.radians(10.0))  # the chain alone: no step is > 10
    ok, step = _check(robot, T, chain.q.numpy(), q0)
    assert step > max_step  # the chain cannot keep its steps under 3 deg
    res = optimise_path(model_of(robot), T.numpy(), chain.q.numpy(), q_start=q0.numpy(), max_step=max_step)
    ok, step = _check(robot, T, res.q, q0)
    assert ok and step <= max_step
    assert (res.pos_err <= TOL_POS).all() and (res.rot_err <= TOL_ROT).all()
    q, pos, rot = polish_path(  # the path stage: optimised because a step exceeds max_step, kept because feasible
        model_of(robot), T.numpy(), chain.q.numpy(), q0.numpy(), tol_pos=TOL_POS, tol_rot=TOL_ROT, max_step=max_step
    )
    ok, step = _check(robot, T, q, q0)
    assert ok and step <= max_step


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_polish_never_worsens_a_feasible_path(name):
    """Random smooth joint paths (so feasible: the poses are their FK) with noise added to some waypoints: the
    polished path keeps every waypoint that was within tolerance and its largest step does not grow."""
    robot = nik.load_robot(name)
    m = model_of(robot)
    rng = np.random.default_rng(2)
    for trial in range(6):
        a, b = rng.uniform(0.2, 0.8, size=(2, robot.dof))
        s = np.linspace(0.0, 1.0, 40)[:, None]
        Q = m.lo + (a + (b - a) * s * 0.3) * (m.hi - m.lo)
        T = np.ascontiguousarray(robot.fk(torch.from_numpy(Q)).numpy())
        noisy = Q.copy()
        if trial % 2:
            noisy[rng.integers(0, 40, size=3)] += rng.normal(scale=1e-3, size=(3, robot.dof))
            noisy = np.clip(noisy, m.lo, m.hi)
        out, pe, re = polish_path(
            m, T, noisy, None, tol_pos=TOL_POS, tol_rot=TOL_ROT, max_step=math.radians(10), always=True
        )
        pos, rot = (x.numpy() for x in nik.pose_error(torch.from_numpy(T), robot.fk(torch.from_numpy(noisy))))
        pos2, rot2 = (x.numpy() for x in nik.pose_error(torch.from_numpy(T), robot.fk(torch.from_numpy(out))))
        was = (pos <= TOL_POS) & (rot <= TOL_ROT)
        now = (pos2 <= TOL_POS) & (rot2 <= TOL_ROT)
        assert now[was].all() and now.sum() >= was.sum()
        assert np.abs(np.diff(out, axis=0)).max() <= np.abs(np.diff(noisy, axis=0)).max()
        assert ((out >= m.lo) & (out <= m.hi)).all()
        np.testing.assert_allclose(pe, pos2, atol=1e-12)  # the errors returned are those of the path returned
        np.testing.assert_allclose(re, rot2, atol=1e-12)


def test_optimise_path_refuses_poses_that_do_not_match_the_path():
    robot = nik.load_robot("panda")
    Q = np.zeros((4, robot.dof))
    with pytest.raises(ValueError, match="T must have shape"):
        optimise_path(model_of(robot), np.tile(np.eye(4), (3, 1, 1)), Q)


def test_collision_rows_match_finite_differences():
    """The collision rows of the path optimisation (waypoints and samples inside the steps, a box and self pairs):
    ``J^T J`` and ``-J^T r`` of :func:`normal_equations_collision` against finite differences of
    :func:`residuals_collision`, on a path some of whose samples sit inside the box."""
    from nik.collision import link_frames
    from nik.ik.collide import setup
    from nik.kernels.trajopt import normal_equations_collision, residuals_collision

    robot = nik.load_robot("panda")
    m = model_of(robot)
    rng = np.random.default_rng(4)
    N, n = 4, robot.dof
    Q = rng.uniform(0.5 * m.lo, 0.5 * m.hi, size=(N, n))
    elbow = link_frames(robot, torch.from_numpy(Q[1:2]))[0, 4, :3, 3].numpy()
    world = nik.World().add_box(elbow + [0.13, 0.07, 0.04], [0.2, 0.25, 0.3])  # off its medial planes
    _, col = setup(robot, world, True).arguments(robot)
    T = np.ascontiguousarray(robot.fk(torch.from_numpy(Q)).numpy())
    opts = trajopt_options(TrajCfg(w_col=2.0, col_margin=0.03, col_sub=3), math.radians(10.0))
    qs = np.clip(Q[0] + 0.1, m.lo, m.hi)
    rows = len(col[0].pairs) + len(col[0].body_start) - 1  # col = (ArmSpheres, Scene)
    R = residual_count(N, n, True, False, rows=rows, sub=3)
    r = np.empty(R)
    cost = residuals_collision(m.G, m.joints, T, Q, qs, True, Q[0], False, opts, col, r)
    assert cost == pytest.approx((r**2).sum())
    assert np.abs(r[R - rows * (N + 2 * N) :]).max() > 0.01  # collision rows are active
    J = _fd_jacobian(
        lambda Qs, rs: residuals_collision(m.G, m.joints, T, Qs, qs, True, Q[0], False, opts, col, rs), Q, R, h=1e-7
    )
    H, g = np.empty((N * n, 3 * n)), np.empty(N * n)
    assert normal_equations_collision(m.G, m.joints, T, Q, qs, True, Q[0], False, opts, col, H, g) == pytest.approx(
        cost
    )
    np.testing.assert_allclose(_dense(H), J.T @ J, atol=1e-5)
    np.testing.assert_allclose(g, -J.T @ r, atol=1e-5)


def test_posture_rows_match_finite_differences():
    """With a posture (``q_rest``) the residual has ``dof`` more rows per waypoint, ``sqrt(w_rest) (q_i - q_rest)``,
    and the normal equations stay the Jacobian's (finite differences)."""
    robot = nik.load_robot("panda")
    m = model_of(robot)
    rng = np.random.default_rng(2)
    N, n = 4, robot.dof
    Q = rng.uniform(m.lo, m.hi, size=(N, n))
    T = np.ascontiguousarray(robot.fk(torch.from_numpy(Q)).numpy())
    rest = 0.5 * (m.lo + m.hi)
    cfg = TrajCfg(w_vel=0.3, w_acc=0.2, w_rest=0.4)
    opts = trajopt_options(cfg, math.radians(10.0), q_rest=rest)
    qs = np.clip(Q[0] + 0.3, m.lo, m.hi)
    R = residual_count(N, n, True, False, rest=True)
    assert R == residual_count(N, n, True, False) + N * n
    r = np.empty(R)
    cost = residuals(m.G, m.joints, T, Q, qs, True, qs, False, opts, r)
    assert cost == pytest.approx((r**2).sum())
    plain = np.empty(R - N * n)
    residuals(m.G, m.joints, T, Q, qs, True, qs, False, trajopt_options(cfg, math.radians(10.0)), plain)
    np.testing.assert_allclose(r[len(plain) :], math.sqrt(0.4) * (Q - rest).ravel(), atol=1e-12)
    J = _fd_jacobian(lambda Qs, rs: residuals(m.G, m.joints, T, Qs, qs, True, qs, False, opts, rs), Q, R)
    H, g = np.empty((N * n, 3 * n)), np.empty(N * n)
    normal_equations(m.G, m.joints, T, Q, qs, True, qs, False, opts, H, g)
    np.testing.assert_allclose(_dense(H), J.T @ J, atol=1e-6)
    np.testing.assert_allclose(g, -J.T @ r, atol=1e-6)


def test_q_rest_pulls_the_optimised_path_nearer(xarm7_circle_37):
    """The whole-path optimisation of a redundant arm's path with a posture ends nearer it than without (the
    self-motion moves), with every waypoint still within the tolerances (FK) and every step within max_step."""
    robot, q0, T = xarm7_circle_37
    m = model_of(robot)
    Tn = np.ascontiguousarray(T.numpy())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        Q0 = nik.IKSolver(robot).solve_path(T, q_start=q0).q.numpy()
    rest = Q0.mean(axis=0) + np.where(np.arange(robot.dof) % 2 == 0, 0.4, -0.4)
    rest = np.clip(rest, m.lo, m.hi)
    kw = {"max_step": math.radians(10.0), "cfg": TrajCfg(iters=60)}
    free = optimise_path(m, Tn, Q0, q_start=q0.numpy(), **kw)
    pulled = optimise_path(m, Tn, Q0, q_start=q0.numpy(), q_rest=rest, **kw)
    far = lambda Q: float(np.linalg.norm(Q - rest, axis=1).mean())  # noqa: E731
    assert far(pulled.q) < far(free.q) - 0.05
    for res in (free, pulled):
        ok, step = _check(robot, T, res.q, q0)
        assert ok and step <= math.radians(10.0)


def test_the_path_stage_keeps_a_loop_closed(panda_circle_chain):
    """``polish_path(closed=True)``: a panda loop closed by a 17 deg jump back to its first row (the search's answer
    where no track comes back) is smoothed without opening the loop: the step from the last row back to the first
    counts as a step. Without ``closed`` the same optimisation removes the jump by leaving the loop 16 deg open."""
    _, q0, T, model, _, q, _ = panda_circle_chain
    jumped = q.copy()
    jumped[-1] = q[0]  # the last pose is the first: closed, by a jump into the last row
    max_step = math.radians(10.0)
    assert np.abs(jumped[-1] - jumped[-2]).max() > max_step

    def steps(x):
        return np.abs(np.diff(np.concatenate([q0[None], x]), axis=0)).max(), np.abs(x[-1] - x[0]).max()

    kw = {"tol_pos": 1e-4, "tol_rot": math.radians(0.1), "max_step": max_step}
    opened, _, _ = polish_path(model, T, jumped, q0, **kw)
    assert steps(opened)[0] <= max_step and steps(opened)[1] > max_step  # smooth, but the loop is open
    kept, pos, rot = polish_path(model, T, jumped, q0, closed=True, **kw)
    step, gap = steps(kept)
    assert step <= max_step and gap <= max_step  # smooth, and the loop still closes without a jump
    assert (pos <= 1e-4).all() and (rot <= math.radians(0.1)).all()
