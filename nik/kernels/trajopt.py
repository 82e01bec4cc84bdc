"""Whole-trajectory optimisation: a block-banded Levenberg-Marquardt over the joints of every waypoint, compiled.

The unknown is the joint trajectory ``Q: (N, n)``, flattened waypoint by waypoint (``M = N n`` values). The
residual stacks, for the poses ``T: (N, 4, 4)``:

- **pose** (6 rows per waypoint): the LM's error ``-e`` of :func:`nik.kernels.lm._evaluate` (metres; rotation
  vector times ``rot_weight``), Jacobian the geometric one (rotation rows times ``rot_weight``; exact where the
  error vanishes, the Gauss-Newton model of the one-pose LM elsewhere);
- **velocity** (``n`` rows per step): ``sqrt(w_vel) (q_i+1 - q_i)``, and from ``qs`` to ``q_0`` and from ``q_N-1``
  to ``qe`` when given (``has_start``, ``has_end``: the fixed rows either side of a window of a longer path);
- **acceleration** (``n`` rows per inner waypoint): ``sqrt(w_acc) (q_i-1 - 2 q_i + q_i+1)``;
- **step cap** (``n`` rows per step): ``sqrt(w_step) sign(d) max(|d| - step_cap, 0)`` with ``d = q_i+1 - q_i``: a
  hinge that pushes every step under ``step_cap`` (a fraction of the path's ``max_step``);
- **limits** (``2 n`` rows per waypoint): ``sqrt(w_lim) max(lo + m - q, 0)`` and ``sqrt(w_lim) max(q - hi + m, 0)``
  with the margin ``m = margin x (hi - lo)``: a barrier near each limit;
- **posture** (``n`` rows per waypoint, only with ``w_rest > 0``): ``sqrt(w_rest) (q_i - q_rest)``, ``q_rest`` the
  ``n`` values after the options (``opts[OPTS:]``): on a redundant arm the self-motion drifts towards it;
- **collision** (``R = P + L`` rows per sample, only with a collision model: the ``*_collision`` kernels and
  :func:`trajopt` given one): ``sqrt(w_col) max(col_margin - d, 0)`` of the signed distances ``d`` of
  :func:`nik.kernels.collision.collision_residual` (self pairs and the world), at every waypoint and at
  ``col_sub - 1`` evenly spaced points inside every step (the motion between waypoints: ``q = (1 - t) q_i + t
  q_i+1``, Jacobian ``(1 - t) J`` on block ``i`` and ``t J`` on block ``i + 1``). A waypoint's rows touch only its
  own block, a step's rows the two blocks either side: the band stays as it is.

The acceleration rows couple waypoints ``i - 1, i, i + 1``, so the normal matrix ``J^T J`` is block-pentadiagonal
(``n x n`` blocks, two blocks either side of the diagonal): in scalars, a band of half-width ``b = 3 n - 1``. It is
kept in lower band storage, ``H[r, k] = A[r, r - k]`` (``H: (M, b + 1)``), factorised by a banded Cholesky and
solved in ``O(M b^2) = O(N n^3)``: the cost is linear in the waypoints.

The step is LM's (:mod:`nik.kernels.lm_step`: its damped diagonal, step cap and damping rule; the banded
factorisation here is the path's linear solver, the one band solver of nik): ``(A + lambda (diag(A) + eps)) dq =
-J^T r``, scaled so that no joint moves more than ``max_step_lm``, then clamped into the limits (the limits always
hold: a projected step); kept when the total cost ``|r|^2`` falls (lambda shrinks by 0.3), else lambda grows by 5
and the step is refactorised. It stops after
``iters`` factorisations, when a kept step lowers the cost by less than ``stall_rel`` of it, or as soon as the path
is feasible (every waypoint within ``tol_pos`` and ``tol_rot``, every step at most ``path_step``; ``tol_pos <= 0``:
never; with collision rows, also every sample at least ``col_margin / 2`` from a collision): the polish asks for a
feasible path, not for the optimum of the weights.

Options ``opts: (len OPTS,) float64`` (:func:`trajopt_options` in :mod:`nik.paths.trajopt` builds them); indices below.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER, _chain, _chain_jacobian
from nik.kernels.collision import ArmSpheres, Scene, collision_residual
from nik.kernels.lm import _residual
from nik.kernels.lm_loop import ACCEPT_LOWER, NEVER, _lm_loop, _loop_cfg, problem_kind
from nik.kernels.lm_step import _cap, _damped

__all__ = [
    "band_cholesky",
    "band_solve",
    "normal_equations",
    "normal_equations_collision",
    "path_check",
    "residuals",
    "residuals_collision",
    "trajopt",
]

ROT_WEIGHT, W_VEL, W_ACC, W_STEP, STEP_CAP, W_LIM, MARGIN, LAMBDA0, MAX_STEP_LM, EPS, STALL_REL = range(11)
TOL_POS, TOL_ROT, PATH_STEP, W_COL, COL_MARGIN, COL_SUB, W_REST = 11, 12, 13, 14, 15, 16, 17
#: length of ``opts`` (with ``W_REST > 0``, the posture's ``n`` values follow)
OPTS = 18
#: the damping rule of :func:`trajopt` (:func:`nik.kernels.lm_step._judge`): lambda times ``LAM_DOWN`` after a kept
#: step (not below ``LAM_MIN``), times ``LAM_UP`` after a rejected one; it stops once lambda exceeds ``LAM_STOP``
LAM_DOWN, LAM_UP, LAM_MIN, LAM_STOP = 0.3, 5.0, 1e-12, 1e8

#: A path's problem for :func:`nik.kernels.lm_loop._lm_loop`: the model ``G, joints``, the poses ``T (N, 4, 4)``, the
#: fixed ends ``(qs (n,), has_start, qe (n,), has_end)``, ``opts``, the collision arrays ``col``; scratch
#: ``work = (A (M, b + 1), dq (M,))`` (the factorised band and the step).
PathProblem = namedtuple("PathProblem", ["G", "joints", "T", "ends", "opts", "col", "work"])
#: A path's state: ``q (N, n)``, its band ``H (M, b + 1)`` and ``g (M,)`` (:func:`normal_equations`), ``pos, rot
#: (N,)`` (metres, radians) and ``info (1,)`` (the smallest collision distance).
PathState = namedtuple("PathState", ["q", "H", "g", "pos", "rot", "info"])


@kernel
def band_cholesky(H, b):
    """In place: ``H: (M, b + 1)`` the lower band ``H[r, k] = A[r, r - k]`` of an SPD matrix -> that of its
    Cholesky factor ``L`` (``A = L L^T``). Returns False when a pivot is not positive (``H`` is then garbage)."""
    M = H.shape[0]
    for i in range(M):
        j0 = max(0, i - b)
        for j in range(j0, i + 1):
            s = H[i, i - j]
            k0 = max(j0, j - b)
            for k in range(k0, j):
                s -= H[i, i - k] * H[j, j - k]
            if j == i:
                if not s > 0.0:
                    return False
                H[i, 0] = math.sqrt(s)
            else:
                H[i, i - j] = s / H[j, 0]
    return True


@kernel
def band_solve(L, b, g, x):
    """``x (M,)`` solving ``L L^T x = g`` for the band factor ``L: (M, b + 1)`` of :func:`band_cholesky`."""
    M = L.shape[0]
    for i in range(M):  # L y = g
        s = g[i]
        for k in range(max(0, i - b), i):
            s -= L[i, i - k] * x[k]
        x[i] = s / L[i, 0]
    for i in range(M - 1, -1, -1):  # L^T x = y
        s = x[i]
        for k in range(i + 1, min(M, i + b + 1)):
            s -= L[k, k - i] * x[k]
        x[i] = s / L[i, 0]


@kernel
def _pair(H, g, r, ia, ib, wa, wb, res):
    """Add one scalar residual ``res`` with Jacobian ``wa`` at flat index ``ia`` and ``wb`` at ``ib > ia`` (``ia <
    0``: none) to the band ``H`` and ``g = -J^T r``; returns ``res^2``."""
    H[ib, 0] += wb * wb
    g[ib] -= wb * res
    if ia >= 0:
        H[ia, 0] += wa * wa
        H[ib, ib - ia] += wa * wb
        g[ia] -= wa * res
    return res * res


@kernel
def _add_row(H, g, row, res, a, wa, b, wb):
    """Add one scalar residual ``res`` whose Jacobian is ``wa row`` on block ``a`` and ``wb row`` on block ``b > a``
    (``row: (n,)``; a block ``< 0``: none) to the band ``H`` and ``g = -J^T r``."""
    n = row.shape[0]
    for blk, w in ((a, wa), (b, wb)):
        if blk < 0:
            continue
        base = blk * n
        for x in range(n):
            g[base + x] -= w * row[x] * res
            for c in range(x + 1):
                H[base + x, x - c] += w * w * row[x] * row[c]
    if a >= 0 and b >= 0:
        off = (b - a) * n
        for x in range(n):
            for c in range(n):
                H[b * n + x, off + x - c] += wb * wa * row[x] * row[c]


@kernel
def _collision_terms(G, joints, Q, ends, opts, col, build, sums, at, info):
    """The collision rows (module docstring) added to ``sums = (H, g, r)``: to ``H, g`` with ``build``, written to
    ``r`` from ``at`` (when its length is > 0); ``info[0]``: the smallest signed distance over the samples (metres).
    ``ends``: as :data:`PathProblem`'s. Returns the cost."""
    qs, has_start, qe, has_end = ends
    H, g, r = sums
    N, n = Q.shape
    arm, scene = col  # nik.kernels.collision.ArmSpheres, Scene
    R = arm.pairs.shape[0] + arm.body_start.shape[0] - 1
    sub = max(int(opts[COL_SUB]), 1)
    sc, margin = math.sqrt(opts[W_COL]), opts[COL_MARGIN]
    keep = r.shape[0] > 0
    qx, rr, Jr = np.empty(n), np.empty(R), np.empty((R, n))
    cost = 0.0
    info[0] = np.inf
    for i in range(-1, N):  # the samples of the step from row i (qs when -1) to row i + 1 (qe when N)
        for k in range(sub):
            t = k / sub
            if (i < 0 and (not has_start or k == 0)) or (i == N - 1 and k > 0 and not has_end):
                continue
            for j in range(n):
                x0 = qs[j] if i < 0 else Q[i, j]
                x1 = x0 if k == 0 else (Q[i + 1, j] if i + 1 < N else qe[j])
                qx[j] = (1.0 - t) * x0 + t * x1
            d = collision_residual(G, joints, qx, arm, scene, margin, rr, Jr)
            info[0] = min(info[0], d)
            a, wa = (i, sc * (1.0 - t)) if i >= 0 else (-1, 0.0)
            b, wb = (i + 1, sc * t) if (k > 0 and i + 1 < N) else (-1, 0.0)
            for row in range(R):
                res = sc * rr[row]
                if keep:
                    r[at] = res
                    at += 1
                if res > 0.0:
                    cost += res * res
                    if build:
                        _add_row(H, g, Jr[row], res, a, wa, b, wb)
    return cost


@kernel
def _terms(G, joints, T, Q, ends, opts, col, build, sums, fit):
    """The residual and, with ``build``, the band ``H = J^T J`` and ``g = -J^T r`` (zeroed here) of ``sums = (H, g,
    r)``. ``r``: the residual vector written in the order of the module docstring when its length is > 0
    (:func:`residuals`). Fills ``fit = (pos, rot, info)``: ``pos, rot: (N,)`` (metres, radians) and ``info[0]``, the
    smallest signed distance of the collision samples (``inf`` without collision rows); returns the cost ``|r|^2``.
    ``ends``: as :data:`PathProblem`'s; ``col``: the collision arrays after ``q`` of
    :func:`nik.kernels.collision.collision_residual` (an empty model: no rows)."""
    qs, has_start, qe, has_end = ends
    H, g, r = sums
    pos, rot, info = fit
    N, n = Q.shape
    rw = opts[ROT_WEIGHT]
    sv, sa, sh, sl = math.sqrt(opts[W_VEL]), math.sqrt(opts[W_ACC]), math.sqrt(opts[W_STEP]), math.sqrt(opts[W_LIM])
    cap, margin = opts[STEP_CAP], opts[MARGIN]
    if build:
        H[:] = 0.0
        g[:] = 0.0
    keep = r.shape[0] > 0
    at = 0
    Tw = np.empty((3, 4))
    J = np.empty((6, n))
    e = np.empty(6)
    cost = 0.0
    for i in range(N):  # pose rows
        _chain_jacobian(G, joints, Q[i], Tw, J)
        E, pos[i], rot[i] = _residual(T[i], Tw, rw, e)
        cost += E
        if keep:
            for k in range(6):
                r[at + k] = -e[k]
            at += 6
        if build:
            for k in range(3, 6):
                for a in range(n):
                    J[k, a] *= rw
            base = i * n
            for a in range(n):
                s = 0.0
                for k in range(6):
                    s += J[k, a] * e[k]
                g[base + a] += s
                for c in range(a + 1):
                    s = 0.0
                    for k in range(6):
                        s += J[k, a] * J[k, c]
                    H[base + a, a - c] += s
    for i in range(-1, N - 1):  # velocity and step cap, from q_start (i = -1) or waypoint i to i + 1
        if i < 0 and not has_start:
            continue
        for j in range(n):
            prev = qs[j] if i < 0 else Q[i, j]
            d = Q[i + 1, j] - prev
            ia, ib = (-1 if i < 0 else i * n + j), (i + 1) * n + j
            res = sv * d
            cost += _pair(H, g, r, ia, ib, -sv, sv, res) if build else res * res
            if keep:
                r[at] = res
                at += 1
            over = abs(d) - cap
            s = sh if d > 0.0 else -sh
            res = s * over if over > 0.0 else 0.0
            if over > 0.0:
                cost += _pair(H, g, r, ia, ib, -sh, sh, res) if build else res * res
            if keep:
                r[at] = res
                at += 1
    if has_end:  # velocity and step cap from the last waypoint to the fixed qe
        for j in range(n):
            f = (N - 1) * n + j
            d = qe[j] - Q[N - 1, j]
            res = sv * d
            cost += _pair(H, g, r, -1, f, 0.0, -sv, res) if build else res * res
            if keep:
                r[at] = res
                at += 1
            over = abs(d) - cap
            res = (sh if d > 0.0 else -sh) * over if over > 0.0 else 0.0
            if over > 0.0:
                cost += _pair(H, g, r, -1, f, 0.0, -sh, res) if build else res * res
            if keep:
                r[at] = res
                at += 1
    for i in range(1, N - 1):  # acceleration
        for j in range(n):
            res = sa * (Q[i - 1, j] - 2.0 * Q[i, j] + Q[i + 1, j])
            cost += res * res
            if keep:
                r[at] = res
                at += 1
            if build:
                i0, i1, i2 = (i - 1) * n + j, i * n + j, (i + 1) * n + j
                H[i0, 0] += sa * sa
                H[i1, 0] += 4.0 * sa * sa
                H[i2, 0] += sa * sa
                H[i1, n] -= 2.0 * sa * sa
                H[i2, n] -= 2.0 * sa * sa
                H[i2, 2 * n] += sa * sa
                g[i0] -= sa * res
                g[i1] += 2.0 * sa * res
                g[i2] -= sa * res
    for i in range(N):  # limits
        for j in range(n):
            lo, hi = joints[j, LOWER], joints[j, UPPER]
            m = margin * (hi - lo)
            below, above = lo + m - Q[i, j], Q[i, j] - hi + m
            res_lo = sl * below if below > 0.0 else 0.0
            res_hi = sl * above if above > 0.0 else 0.0
            cost += res_lo * res_lo + res_hi * res_hi
            if keep:
                r[at], r[at + 1] = res_lo, res_hi
                at += 2
            if build:
                f = i * n + j
                if below > 0.0:
                    H[f, 0] += sl * sl
                    g[f] += sl * res_lo
                if above > 0.0:
                    H[f, 0] += sl * sl
                    g[f] -= sl * res_hi
    if opts[W_REST] > 0.0:  # posture
        sr = math.sqrt(opts[W_REST])
        for i in range(N):
            for j in range(n):
                res = sr * (Q[i, j] - opts[OPTS + j])
                cost += res * res
                if keep:
                    r[at] = res
                    at += 1
                if build:
                    H[i * n + j, 0] += sr * sr
                    g[i * n + j] -= sr * res
    info[0] = np.inf
    if opts[W_COL] > 0.0 and col[0].pairs.shape[0] + col[0].body_start.shape[0] > 1:
        cost += _collision_terms(G, joints, Q, ends, opts, col, build, sums, at, info)
    return cost


@kernel
def _no_collision():
    """The collision arguments of no model (no rows)."""
    arm = ArmSpheres(np.empty((0, 4)), np.empty(0, dtype=np.int64), np.zeros(1, dtype=np.int64),
                     np.empty((0, 2), dtype=np.int64), False, np.zeros(0, dtype=np.int64), np.zeros((0, 14)),
                     np.zeros(0, dtype=np.float32))  # fmt: skip
    return arm, Scene(np.empty((0, 4)), np.empty((0, 15)), np.empty((0, 7)))


@kernel
def residuals(G, joints, T, Q, qs, has_start, qe, has_end, opts, r):
    """The residual vector ``r`` (its length: :func:`nik.paths.trajopt.residual_count`) of ``Q: (N, n)``; returns
    ``|r|^2`` (for tests: finite differences of it check :func:`normal_equations`)."""
    return residuals_collision(G, joints, T, Q, qs, has_start, qe, has_end, opts, _no_collision(), r)


@kernel
def residuals_collision(G, joints, T, Q, qs, has_start, qe, has_end, opts, col, r):
    """:func:`residuals` with the collision rows of ``col`` (the arrays after ``q`` of
    :func:`nik.kernels.collision.collision_residual`, as a tuple) appended."""
    N = Q.shape[0]
    H = np.empty((1, 1))
    g = np.empty(1)
    pos, rot, info = np.empty(N), np.empty(N), np.empty(1)
    return _terms(G, joints, T, Q, (qs, has_start, qe, has_end), opts, col, False, (H, g, r), (pos, rot, info))


@kernel
def normal_equations(G, joints, T, Q, qs, has_start, qe, has_end, opts, H, g):
    """The band ``H: (N n, 3 n)`` of ``J^T J`` and ``g = -J^T r: (N n,)`` at ``Q``; returns ``|r|^2``."""
    return normal_equations_collision(G, joints, T, Q, qs, has_start, qe, has_end, opts, _no_collision(), H, g)


@kernel
def normal_equations_collision(G, joints, T, Q, qs, has_start, qe, has_end, opts, col, H, g):
    """:func:`normal_equations` with the collision rows of ``col`` (as :func:`residuals_collision`)."""
    N = Q.shape[0]
    pos, rot, info = np.empty(N), np.empty(N), np.empty(1)
    ends = (qs, has_start, qe, has_end)
    return _terms(G, joints, T, Q, ends, opts, col, True, (H, g, np.empty(0)), (pos, rot, info))


@kernel
def _feasible(Q, ends, opts, pos, rot, info):
    """Every waypoint within ``TOL_POS`` / ``TOL_ROT`` (by ``pos, rot``), every step at most ``PATH_STEP`` and every
    collision sample (``info[0]``, its smallest distance) at least ``COL_MARGIN / 2`` clear."""
    qs, has_start, qe, has_end = ends
    if not opts[TOL_POS] > 0.0 or info[0] < 0.5 * opts[COL_MARGIN]:
        return False
    N, n = Q.shape
    for i in range(N):
        if pos[i] > opts[TOL_POS] or rot[i] > opts[TOL_ROT]:
            return False
        if i > 0 or has_start:
            for j in range(n):
                if abs(Q[i, j] - (Q[i - 1, j] if i > 0 else qs[j])) > opts[PATH_STEP]:
                    return False
    if has_end:
        for j in range(n):
            if abs(qe[j] - Q[N - 1, j]) > opts[PATH_STEP]:
                return False
    return True


@kernel
def _measure_path(prob, s, bar):
    """The loop's measure of a path (:data:`PathProblem`): the band ``s.H``, ``s.g`` and the fit of ``s.q``
    (:func:`_terms`); returns ``(cost, feasible)`` (:func:`_feasible`; ``bar`` unused)."""
    cost = _terms(prob.G, prob.joints, prob.T, s.q, prob.ends, prob.opts, prob.col, True, (s.H, s.g, np.empty(0)),
                  (s.pos, s.rot, s.info))  # fmt: skip
    return cost, _feasible(s.q, prob.ends, prob.opts, s.pos, s.rot, s.info)


@kernel
def _propose_path(prob, s, lam, c):
    """The loop's proposal of a path: the damped band ``H + lambda (diag(H) + eps)`` factorised and solved (the band
    solver, :func:`band_cholesky`, :func:`band_solve`), capped (:func:`nik.kernels.lm_step._cap`), ``c.q = s.q + dq``
    clamped into the limits (a projected step); returns ``(good, inf)``."""
    A, dq = prob.work
    b = A.shape[1] - 1
    A[:] = s.H
    A[:, 0] = _damped(s.H[:, 0], lam, prob.opts[EPS], 0.0)  # the damped diagonal, as a whole column
    if not band_cholesky(A, b):
        return False, math.inf
    band_solve(A, b, s.g, dq)
    good = _cap(dq, prob.opts[MAX_STEP_LM])
    if good:
        joints = prob.joints
        N, n = s.q.shape
        for i in range(N):
            for j in range(n):
                x = s.q[i, j] + dq[i * n + j]
                c.q[i, j] = min(max(x, joints[j, LOWER]), joints[j, UPPER])
    return good, math.inf


problem_kind(PathProblem, _measure_path, _propose_path)


@kernel
def _path_state(N, n):
    """A :data:`PathState` of ``N`` waypoints of ``n`` joints on arrays of its own."""
    M = N * n
    return PathState(np.empty((N, n)), np.zeros((M, 3 * n)), np.empty(M), np.empty(N), np.empty(N), np.empty(1))


@kernel
def trajopt(G, joints, T, Q, ends, opts, iters, col, fit):
    """Optimise ``Q: (N, n)`` in place (inside the limits on entry and on return) towards the poses ``T: (N, 4, 4)``:
    the one LM loop (:func:`nik.kernels.lm_loop._lm_loop`) with the band solver (module docstring).

    ``ends = (qs, has_start, qe, has_end)``: ``qs: (n,)`` the joints before the path, counted when ``has_start``;
    ``qe: (n,)`` those after it, counted when ``has_end``. ``col``: the collision arrays (:func:`residuals_collision`;
    no rows: ``_no_collision()``, or ``W_COL`` 0). ``fit = (pos, rot, info)`` out: ``pos, rot: (N,)`` the pose errors
    of the returned ``Q`` (metres, radians); ``info[0]`` its smallest collision distance. Returns ``(factorisations,
    final cost)``. Stops after ``iters`` factorisations, on a kept step that lowers the cost by at most ``STALL_REL``
    of the new cost, on a feasible path (:func:`_feasible`, checked after a kept step) or once lambda exceeds
    ``LAM_STOP``."""
    N, n = Q.shape
    M = N * n
    prob = PathProblem(G, joints, T, ends, opts, col, (np.empty((M, 3 * n)), np.empty(M)))
    cur, other = _path_state(N, n), _path_state(N, n)
    cur.q[:] = Q
    cost, _ = _measure_path(prob, cur, math.inf)
    rel = opts[STALL_REL]  # drop <= rel * new cost  <=>  drop <= rel / (1 + rel) * old cost
    cfg = _loop_cfg(iters, opts[LAMBDA0], (LAM_DOWN, LAM_UP, LAM_MIN, math.inf), LAM_STOP, (0.0, NEVER),
                    (rel / (1.0 + rel), 0.0), ACCEPT_LOWER)  # fmt: skip
    it, cost, _, cur, _ = _lm_loop(prob, cfg, cur, other, cost, False)
    pos, rot, info = fit
    Q[:] = cur.q
    pos[:] = cur.pos
    rot[:] = cur.rot
    info[0] = cur.info[0]
    return it, cost


@kernel
def path_check(G, joints, T, Q, qs, has_start, tol_pos, tol_rot, pos, rot):
    """The pose errors ``pos, rot: (N,)`` (out, metres and radians) of ``Q: (N, n)`` against ``T: (N, 4, 4)`` by FK,
    in one call with what the polish asks: returns ``(waypoints within both tolerances, the largest step)`` (the
    largest joint motion between consecutive rows, from ``qs`` when ``has_start``)."""
    N, n = Q.shape
    Tw = np.empty((3, 4))
    e = np.empty(6)
    reached = 0
    step = 0.0
    for i in range(N):
        _chain(G, joints, Q[i], Tw)
        _, pos[i], rot[i] = _residual(T[i], Tw, 1.0, e)
        if pos[i] <= tol_pos and rot[i] <= tol_rot:
            reached += 1
        if i > 0 or has_start:
            for j in range(n):
                d = abs(Q[i, j] - (Q[i - 1, j] if i > 0 else qs[j]))
                if d > step:
                    step = d
    return reached, step
