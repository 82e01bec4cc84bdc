"""Damped Levenberg-Marquardt for one pose, with joint limits and seeded restarts, compiled.

The algorithm is the one of the batched torch LM and its numpy one-pose version (the error, the
Marquardt-scaled damping, the active set at the limits, the stall test, restarts from uniform
configurations), written for one target and compiled once for every robot (the model arrays of
:mod:`nik.kernels.chain` are passed in).

Error of a configuration (6-vector, base frame)::

    e = [p* - p ;  w * log(R* R^T)]        (metres; w = rot_weight, metres per radian)

with the rotation vector's angle taken as ``atan2(|sin|, cos)``. Step::

    dq = (J^T J + lambda (diag(J^T J) + eps) + eps I)^-1 J^T e

by a Cholesky factorisation written out (a failed factorisation is a rejected step), scaled so that
no joint moves more than ``max_step``, then brought inside the limits (a wrapping joint moves by whole
turns, the others are clamped). A joint held at a limit that the descent direction pushes further out
is left out of the step (active set). A step is kept only when it lowers ``|e|^2``; lambda then
shrinks by ``lambda_down``, else grows by ``lambda_up``. A start is spent after ``stall_iters``
iterations in a row that lower ``|e|^2`` by less than the fraction ``stall_rel``, or after its
iteration limit; then, while restarts are left, a fresh start is drawn uniformly inside the limits.

Random numbers come from a splitmix64 stream whose state (``rng: (1,) uint64``) the caller seeds:
same seed, same answer, and no global random state is touched.

Options are two small arrays (:func:`lm_options` builds them from keywords):
``opts: float64`` (indices ``ROT_WEIGHT ... TOL_ROT``) and ``iopts: int64`` (``FIRST_ITERS ... FIRST_STARTS``);
the restart budget is per target (a target proven out of reach gets none).
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER, WRAPS, _chain, _chain_jacobian

__all__ = ["lm_options", "lm_solve", "pose_errors", "seed_state", "uniform_configurations"]

# entries of opts (float64) and iopts (int64), see lm_options
ROT_WEIGHT, LAMBDA0, LAMBDA_UP, LAMBDA_DOWN, LAMBDA_MIN, LAMBDA_MAX = 0, 1, 2, 3, 4, 5
EPS, MAX_STEP, STALL_REL, TOL_POS, TOL_ROT = 6, 7, 8, 9, 10
FIRST_ITERS, ITERS, STALL_ITERS, FIRST_STARTS, TAIL_AFTER, TAIL_ITERS, TAIL_STALL_ITERS = range(7)

_TWO_PI = 2.0 * math.pi
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV_2_53 = 1.0 / 9007199254740992.0
_STREAM = np.uint64(0xD1B54A32D192ED03)  # separates the random streams of the targets of one call


def lm_options(
    *,
    rot_weight: float = 0.5,
    lambda0: float = 1e-3,
    lambda_up: float = 5.0,
    lambda_down: float = 0.3,
    lambda_min: float = 1e-9,
    lambda_max: float = 1e6,
    eps: float = 1e-9,
    max_step: float = 0.5,
    stall_rel: float = 1e-3,
    tol_pos: float = 1e-4,
    tol_rot: float = math.radians(0.1),
    first_iters: int = 25,
    iters: int = 25,
    stall_iters: int = 4,
    first_starts: int = 0,
    tail_after: int | None = None,
    tail_iters: int | None = None,
    tail_stall_iters: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(opts, iopts)`` for :func:`lm_solve` (defaults: those of the batched LM's ``LMCfg`` and nik's one
    tolerance, 0.1 mm / 0.1 deg).

    Units: ``rot_weight`` m/rad, ``eps`` m^2, ``max_step`` rad (m for prismatic joints), ``tol_pos`` m,
    ``tol_rot`` rad. ``first_iters``: iteration limit of the first start, ``iters``: of each restart;
    ``first_starts``: when > 0, the first start is the best
    (by pose error) of that many uniform configurations instead of ``q0``. The restarts after the first
    ``tail_after`` (default: none) run ``tail_iters`` iterations at most and stop after ``tail_stall_iters``
    without progress (defaults ``iters`` and ``stall_iters``): longer runs for the hard targets that are left.
    """
    opts = np.empty(11)
    opts[[ROT_WEIGHT, LAMBDA0, LAMBDA_UP, LAMBDA_DOWN, LAMBDA_MIN, LAMBDA_MAX]] = (
        rot_weight, lambda0, lambda_up, lambda_down, lambda_min, lambda_max
    )  # fmt: skip
    opts[[EPS, MAX_STEP, STALL_REL, TOL_POS, TOL_ROT]] = eps, max_step, stall_rel, tol_pos, tol_rot
    iopts = np.empty(7, dtype=np.int64)
    iopts[[FIRST_ITERS, ITERS, STALL_ITERS, FIRST_STARTS]] = first_iters, iters, stall_iters, first_starts
    iopts[[TAIL_AFTER, TAIL_ITERS, TAIL_STALL_ITERS]] = (
        2**62 if tail_after is None else tail_after,
        iters if tail_iters is None else tail_iters,
        stall_iters if tail_stall_iters is None else tail_stall_iters,
    )
    if (iopts < 0).any():
        raise ValueError(f"lm_options: iteration counts and starts must be >= 0, got {iopts.tolist()}")
    return opts, iopts


def seed_state(seed: int) -> np.ndarray:
    """The random state ``(1,) uint64`` of a seed (any Python int; taken modulo 2^64)."""
    return np.array([int(seed) & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64)


@kernel
def _work_size(n):
    """Length of :func:`lm_solve`'s scratch for ``n`` joints: ``36 + 12 n + n^2 + 5 n`` float64."""
    return 36 + 12 * n + n * n + 5 * n


# ---------------------------------------------------------------------------
# building blocks
# ---------------------------------------------------------------------------
@kernel
def _copy(src, dst):
    """``dst[:] = src`` for 1-D arrays, as a plain loop."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@kernel
def _uniform(rng):
    """The next number of the splitmix64 stream in ``[0, 1)`` (53 bits); ``rng: (1,) uint64`` advances."""
    z = rng[0] + _GOLDEN
    rng[0] = z
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    z = z ^ (z >> _S31)
    return float(z >> _S11) * _INV_2_53


@kernel
def _draw(joints, rng, q):
    """``q (n,)`` uniform inside the limits."""
    for i in range(q.shape[0]):
        lo, hi = joints[i, LOWER], joints[i, UPPER]
        q[i] = min(max(lo + _uniform(rng) * (hi - lo), lo), hi)


@kernel
def _bounds(joints, q):
    """``q (n,)`` brought inside the limits in place: wrapping joints by whole turns, the others clamped."""
    for i in range(q.shape[0]):
        lo, hi, x = joints[i, LOWER], joints[i, UPPER], q[i]
        if joints[i, WRAPS] != 0.0:
            up = max(math.ceil((lo - x) / _TWO_PI), 0.0)
            down = max(math.ceil((x - hi) / _TWO_PI), 0.0)
            x = x + _TWO_PI * (up - down)
        q[i] = min(max(x, lo), hi)


@kernel
def _residual(Tt, T, rw, e):
    """Weighted error ``e (6,)`` of the pose ``T (3, 4)`` against ``Tt (4, 4)``; returns
    ``(|e|^2, position error m, rotation angle rad)``."""
    dx, dy, dz = Tt[0, 3] - T[0, 3], Tt[1, 3] - T[1, 3], Tt[2, 3] - T[2, 3]
    # M = R* R^T, only what the rotation vector needs
    m01 = Tt[0, 0] * T[1, 0] + Tt[0, 1] * T[1, 1] + Tt[0, 2] * T[1, 2]
    m02 = Tt[0, 0] * T[2, 0] + Tt[0, 1] * T[2, 1] + Tt[0, 2] * T[2, 2]
    m10 = Tt[1, 0] * T[0, 0] + Tt[1, 1] * T[0, 1] + Tt[1, 2] * T[0, 2]
    m12 = Tt[1, 0] * T[2, 0] + Tt[1, 1] * T[2, 1] + Tt[1, 2] * T[2, 2]
    m20 = Tt[2, 0] * T[0, 0] + Tt[2, 1] * T[0, 1] + Tt[2, 2] * T[0, 2]
    m21 = Tt[2, 0] * T[1, 0] + Tt[2, 1] * T[1, 1] + Tt[2, 2] * T[1, 2]
    m00 = Tt[0, 0] * T[0, 0] + Tt[0, 1] * T[0, 1] + Tt[0, 2] * T[0, 2]
    m11 = Tt[1, 0] * T[1, 0] + Tt[1, 1] * T[1, 1] + Tt[1, 2] * T[1, 2]
    m22 = Tt[2, 0] * T[2, 0] + Tt[2, 1] * T[2, 1] + Tt[2, 2] * T[2, 2]
    sx, sy, sz = 0.5 * (m21 - m12), 0.5 * (m02 - m20), 0.5 * (m10 - m01)
    c = 0.5 * (m00 + m11 + m22 - 1.0)
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    theta = math.atan2(sn, c)
    scale = rw * (theta / sn if sn > 1e-12 else 1.0)
    e[0], e[1], e[2] = dx, dy, dz
    e[3], e[4], e[5] = sx * scale, sy * scale, sz * scale
    pos2 = dx * dx + dy * dy + dz * dz
    return pos2 + (rw * theta) ** 2, math.sqrt(pos2), theta


@kernel
def _evaluate(G, joints, q, Tt, rw, T, J, e):
    """FK, Jacobian (rotation rows times ``rw``) and error of ``q``; returns ``(E, pos, rot)``."""
    _chain_jacobian(G, joints, q, T, J)
    for r in range(3, 6):
        for i in range(q.shape[0]):
            J[r, i] *= rw
    return _residual(Tt, T, rw, e)


@kernel
def _cholesky_solve(A, b, x):
    """Solve ``A x = b`` for a symmetric positive definite ``A (n, n)`` (overwritten by its Cholesky factor,
    lower triangle). Returns False when a pivot is not positive or not finite."""
    n = b.shape[0]
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= A[j, k] * A[j, k]
        if not d > 0.0 or not math.isfinite(d):
            return False
        d = math.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, n):
            v = A[i, j]
            for k in range(j):
                v -= A[i, k] * A[j, k]
            A[i, j] = v / d
    for i in range(n):  # L y = b
        v = b[i]
        for k in range(i):
            v -= A[i, k] * x[k]
        x[i] = v / A[i, i]
    for i in range(n - 1, -1, -1):  # L^T x = y
        v = x[i]
        for k in range(i + 1, n):
            v -= A[k, i] * x[k]
        x[i] = v / A[i, i]
    return True


@kernel
def _step(J, e, q, joints, lam, eps, max_step, A, g, dq):
    """The damped, limit-aware step ``dq (n,)`` from ``J (6, n)`` and ``e (6,)``; False if it failed."""
    n = q.shape[0]
    for i in range(n):
        v = 0.0
        for r in range(6):
            v += J[r, i] * e[r]
        g[i] = v
        for k in range(i + 1):
            a = 0.0
            for r in range(6):
                a += J[r, i] * J[r, k]
            A[i, k] = a
            A[k, i] = a
    # active set: a joint at a limit pushed further out by the descent direction is held
    for i in range(n):
        held = (q[i] <= joints[i, LOWER] and g[i] < 0.0) or (q[i] >= joints[i, UPPER] and g[i] > 0.0)
        if held:
            for k in range(n):
                A[i, k] = 0.0
                A[k, i] = 0.0
            A[i, i] = 1.0
            g[i] = 0.0
    for i in range(n):
        A[i, i] += lam * (A[i, i] + eps) + eps
    if not _cholesky_solve(A, g, dq):
        return False
    big = 0.0
    for i in range(n):
        if not math.isfinite(dq[i]):
            return False
        big = max(big, abs(dq[i]))
    if big > max_step:
        f = max_step / big
        for i in range(n):
            dq[i] *= f
    return True


@kernel
def _best_uniform(G, joints, Tt, rw, m, rng, q, cand, T, e):
    """``q (n,)``: the best of ``m`` uniform configurations by ``|e|^2``."""
    best = math.inf
    for _ in range(m):
        _draw(joints, rng, cand)
        _chain(G, joints, cand, T)
        E, _, _ = _residual(Tt, T, rw, e)
        if E < best:
            best = E
            _copy(cand, q)


# ---------------------------------------------------------------------------
# the kernel
# ---------------------------------------------------------------------------
@kernel
def _lm_one(G, joints, Tt, q0, opts, iopts, restarts, rng, q, work):
    """LM for one target ``Tt (4, 4)`` (see :func:`lm_solve`); returns ``(iterations, converged, pos, rot)``."""
    n = q0.shape[0]
    rw, tol_pos, tol_rot = opts[ROT_WEIGHT], opts[TOL_POS], opts[TOL_ROT]
    lambda0, lam_up, lam_down = opts[LAMBDA0], opts[LAMBDA_UP], opts[LAMBDA_DOWN]
    lam_min, lam_max, eps, max_step = opts[LAMBDA_MIN], opts[LAMBDA_MAX], opts[EPS], opts[MAX_STEP]
    stall_rel = opts[STALL_REL]
    iters, stall_iters, tail_after = iopts[ITERS], iopts[STALL_ITERS], iopts[TAIL_AFTER]
    # scratch views
    o = 0
    T = work[o : o + 12].reshape((3, 4))
    o += 12
    Tc = work[o : o + 12].reshape((3, 4))
    o += 12
    e = work[o : o + 6]
    o += 6
    ec = work[o : o + 6]
    o += 6
    J = work[o : o + 6 * n].reshape((6, n))
    o += 6 * n
    Jc = work[o : o + 6 * n].reshape((6, n))
    o += 6 * n
    A = work[o : o + n * n].reshape((n, n))
    o += n * n
    g = work[o : o + n]
    o += n
    dq = work[o : o + n]
    o += n
    qc = work[o : o + n]
    o += n
    best_q = work[o : o + n]
    o += n
    cand = work[o : o + n]

    if iopts[FIRST_STARTS] > 0:
        _best_uniform(G, joints, Tt, rw, iopts[FIRST_STARTS], rng, q, cand, T, e)
    else:
        _copy(q0, q)
    _bounds(joints, q)
    limit = iopts[FIRST_ITERS]
    total = 0
    best_E, best_pos, best_rot = math.inf, math.inf, math.inf
    for start in range(restarts + 1):
        stall_limit = stall_iters
        if start > 0:
            _draw(joints, rng, q)
            limit = iters
            if start > tail_after:
                limit, stall_limit = iopts[TAIL_ITERS], iopts[TAIL_STALL_ITERS]
        E, pos, rot = _evaluate(G, joints, q, Tt, rw, T, J, e)
        lam = lambda0
        stall = 0
        for _ in range(limit):
            if pos <= tol_pos and rot <= tol_rot:
                break
            good = _step(J, e, q, joints, lam, eps, max_step, A, g, dq)
            total += 1
            Ec = math.inf
            if good:
                for i in range(n):
                    qc[i] = q[i] + dq[i]
                _bounds(joints, qc)
                Ec, posc, rotc = _evaluate(G, joints, qc, Tt, rw, Tc, Jc, ec)
            if good and Ec < E:
                stall = 0 if E - Ec >= stall_rel * E else stall + 1
                _copy(qc, q)
                _copy(Jc.ravel(), J.ravel())
                _copy(ec, e)
                E, pos, rot = Ec, posc, rotc
                lam = max(lam * lam_down, lam_min)
            else:
                stall += 1
                lam = min(lam * lam_up, lam_max)
            if stall >= stall_limit:
                break
        if pos <= tol_pos and rot <= tol_rot:
            return total, True, pos, rot
        if E < best_E:
            best_E, best_pos, best_rot = E, pos, rot
            _copy(q, best_q)
    _copy(best_q, q)
    return total, False, best_pos, best_rot


@kernel
def lm_solve(G, joints, Tt, q0, opts, iopts, restarts, seed, q, iterations, converged, pos, rot):
    """Levenberg-Marquardt towards each target ``Tt[b]`` from ``q0[b]`` (or from the best of ``first_starts``
    uniform configurations), restarting from uniform configurations while the target is not reached.

    Args:
        G, joints: the model (:func:`nik.kernels.chain.chain_model`).
        Tt: (B, 4, 4) target poses, metres.
        q0: (B, n) first starts (brought inside the limits first); ignored when ``iopts[FIRST_STARTS] > 0``.
        opts, iopts: options (:func:`lm_options`).
        restarts: (B,) int64, fresh uniform starts each target may draw at most (0 for one proven out of reach).
        seed: (1,) uint64 (:func:`seed_state`); target ``b`` draws from its own stream of it, so its answer
            depends on the seed and ``b`` only.
        q: (B, n) out: the answers, inside the limits: the first start within tolerance, else the start with
            the lowest error (best effort).
        iterations: (B,) int64 out: LM iterations spent (all starts).
        converged: (B,) bool out: ``q`` is within both tolerances.
        pos, rot: (B,) float64 out: position (m) and rotation (rad) error of ``q``.

    The scratch is allocated here, per call (measured: no slower than a buffer kept by the caller, within
    0.1 us of a 4.4 us one-pose call), so threads sharing one model run side by side.
    """
    scratch = np.empty(_work_size(q0.shape[1]))
    rng = np.empty(1, dtype=np.uint64)
    for b in range(Tt.shape[0]):
        rng[0] = seed[0] ^ (np.uint64(b) * _STREAM)
        iterations[b], converged[b], pos[b], rot[b] = _lm_one(
            G, joints, Tt[b], q0[b], opts, iopts, restarts[b], rng, q[b], scratch
        )


@kernel
def pose_errors(G, joints, Tt, q, pos, rot):
    """Position (m) and geodesic rotation (rad) errors ``pos, rot: (B,)`` of configurations ``q: (B, n)`` against
    ``Tt: (B, 4, 4)`` (the FK of the kernels; the angle as ``atan2(|sin|, cos)``)."""
    T = np.empty((3, 4))
    e = np.empty(6)
    for b in range(q.shape[0]):
        _chain(G, joints, q[b], T)
        _, pos[b], rot[b] = _residual(Tt[b], T, 1.0, e)


@kernel
def uniform_configurations(joints, rng, q):
    """``q: (m, n)`` filled with configurations uniform inside the limits (the stream of ``rng``)."""
    for k in range(q.shape[0]):
        _draw(joints, rng, q[k])
