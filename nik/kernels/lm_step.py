"""The one Levenberg-Marquardt step of nik's compiled solvers, and its accept/reject and damping rule.

The one compiled LM loop (:mod:`nik.kernels.lm_loop`) takes its steps and updates its damping here. The problem of a
step, for ``q: (n,)``::

    minimise  |e - J dq|^2 + w2 |r + Jr dq|^2 + w_prior2 |q + dq - q_prior|^2 + lam dq^T (diag(A) + eps) dq
              + eps |dq|^2

with the residual rows ``J: (m, n)``, ``e: (m,)`` (``e`` = target - reached, the sign of :mod:`nik.kernels.lm`),
optional extra rows ``Jr: (R, n)``, ``r: (R,)`` (``r`` = residual, e.g. the collision rows of
:mod:`nik.kernels.collision_lm`; only the rows with ``r != 0`` enter the sums) and an optional prior row towards
``q_prior`` (:func:`nik.kernels.driver.near_prior`, :func:`nik.kernels.driver.rest_posture`). ``A`` is the normal
matrix of the rows (the prior's ``w_prior2 I`` is a ridge: it is not scaled by ``lam``). Solved by
:func:`_cholesky_solve` (a failed factorisation is a failed step); a joint on a limit that the descent pushes further
out is held (:func:`hold`), and the step is solved once more when the solution pushes a joint out
(:func:`pushes_out`); then scaled so that no joint moves more than ``max_step`` (:func:`_cap`).

The rule after a step (:func:`_judge`): a candidate is kept when the step succeeded and its cost is lower (or the
caller's ``done`` says it is an answer); lambda then shrinks by ``down`` (not below ``lo``), else grows by ``up``
(not above ``hi``). A kept step that lowers the cost by less than ``stall_rel`` of it counts as a stall
(:func:`_stalled`).

Who calls it: the proposals of the one LM loop (:mod:`nik.kernels.lm_loop`): :func:`nik.kernels.lm._propose_dense`
(one pose: :func:`_dense_step` with the state's extra rows, e.g. the collision rows, and the problem's prior row;
``None`` where there are none: numba prunes those branches at compile time, so the hot one-pose step does no work for
them) and :func:`nik.kernels.driver._propose_rest` (the null-space posture: the prior ``q + z`` with weight
``damping``, no Marquardt damping, no joint held, no cap: a step above ``max_step`` is refused there). The path's
proposal (:func:`nik.kernels.trajopt._propose_path`, ``M = N n`` unknowns) has a block-banded normal matrix, and a
dense ``M x M`` Cholesky would cost ``O(M^3)`` against the band's ``O(M b^2)``, so its linear solver is the band
solver (``band_cholesky``, ``band_solve``); it shares :func:`_damped` (the damped diagonal, without the ``eps``
ridge: ``ridge = 0``) and :func:`_cap`, and clamps its joints into the limits after the step (a projected step)
rather than holding them. The loop applies :func:`_judge` and :func:`_stalled`.

The sums are written in a fixed order, so a given problem gets the same answer bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER

__all__ = ["hold", "pushes_out"]


@kernel
def _cholesky(A, m, ridge):
    """``A[:m, :m] + ridge I`` (symmetric positive definite) factorised in place, ``L L^T`` in its lower triangle: the
    one dense factorisation of the kernels (the LM step, :mod:`nik.kernels.manipulability`). Returns False when a
    pivot is not positive or not finite."""
    for j in range(m):
        d = A[j, j] + ridge
        for k in range(j):
            d -= A[j, k] * A[j, k]
        if not d > 0.0 or not math.isfinite(d):
            return False
        d = math.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, m):
            v = A[i, j]
            for k in range(j):
                v -= A[i, k] * A[j, k]
            A[i, j] = v / d
    return True


@kernel
def _cholesky_solve(A, b, x):
    """Solve ``A x = b`` for a symmetric positive definite ``A (n, n)`` (overwritten by its Cholesky factor,
    lower triangle, :func:`_cholesky`). Returns False when a pivot is not positive or not finite."""
    n = b.shape[0]
    if not _cholesky(A, n, 0.0):
        return False
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
def hold(q, joints, g, dq, A):
    """The active set at the limits, in place on the normal equations ``A (n, n) dq = g (n,)``: a joint on a limit
    that the descent direction ``g`` or the previous solution ``dq`` (zeros on a first pass) pushes further out is
    held (its row and column left out, ``g_i = 0``)."""
    n = q.shape[0]
    for i in range(n):
        lo, hi = q[i] <= joints[i, LOWER], q[i] >= joints[i, UPPER]
        if (lo and (g[i] < 0.0 or dq[i] < 0.0)) or (hi and (g[i] > 0.0 or dq[i] > 0.0)):
            for k in range(n):
                A[i, k] = 0.0
                A[k, i] = 0.0
            A[i, i] = 1.0
            g[i] = 0.0


@kernel
def pushes_out(q, joints, dq):
    """Whether the step ``dq (n,)`` moves a joint that sits on a limit further out (it would be clamped, and the
    others moved as if it were not: the step is solved again with that joint held, :func:`hold`)."""
    for i in range(q.shape[0]):
        if (q[i] <= joints[i, LOWER] and dq[i] < 0.0) or (q[i] >= joints[i, UPPER] and dq[i] > 0.0):
            return True
    return False


@kernel
def _damped(a, lam, eps, ridge):
    """A damped diagonal entry of the normal matrix: ``a + lam (a + eps) + ridge`` (Marquardt's scaling)."""
    return a + (lam * (a + eps) + ridge)


@kernel
def _cap(dq, max_step):
    """``dq (M,)`` scaled in place so that no entry exceeds ``max_step`` in size; False if an entry is not finite."""
    big = 0.0
    for i in range(dq.shape[0]):
        if not math.isfinite(dq[i]):
            return False
        big = max(big, abs(dq[i]))
    if big > max_step:
        f = max_step / big
        for i in range(dq.shape[0]):
            dq[i] *= f
    return True


@kernel(inline="always")
def _normal_equations(J, e, rows, prior, q, A, g, m):
    """``A = J^T J + w2 Jr_a^T Jr_a`` and ``g = J^T e - w2 Jr_a^T r_a - w_prior2 (q - q_prior)`` over the first ``m``
    rows of ``J``, the active extra rows ``rows = (Jr, r, w2, active, R)`` (``a = active[:R]``; ``None``: none) and
    the prior ``prior = (q_prior, w_prior2)`` (``None``: none; see :func:`_dense_step`)."""
    n = q.shape[0]
    for i in range(n):
        v = 0.0
        if prior is not None:
            q_prior, w_prior2 = prior
            v = -w_prior2 * (q[i] - q_prior[i])
        for k in range(m):
            v += J[k, i] * e[k]
        if rows is not None:
            Jr, r, w2, active, R = rows
            for t in range(R):
                k = active[t]
                v -= w2 * Jr[k, i] * r[k]
        g[i] = v
        for c in range(i + 1):
            a = 0.0
            for k in range(m):
                a += J[k, i] * J[k, c]
            if rows is not None:
                Jr, r, w2, active, R = rows
                for t in range(R):
                    k = active[t]
                    a += w2 * Jr[k, i] * Jr[k, c]
            A[i, c] = a
            A[c, i] = a


@kernel
def _dense_step(J, e, extra, prior, q, joints, lam, eps, max_step, work):
    """The damped, limit-aware step ``work[2] = dq (n,)`` of the module docstring; False if it failed.

    ``J (m, n), e (m,)``: the residual rows; ``extra = (Jr (R, n), r (R,), w2)``: extra rows with weight ``w2``
    (``None``: none); ``prior = (q_prior (n,), w_prior2)``: the prior row (``None``: none; numba prunes both at
    compile time). Scratch ``work = (A (n, n), g (n,), dq (n,))``."""
    if extra is None:
        return _held_step(J, e, None, prior, q, joints, lam, eps, max_step, work)
    Jr, r, w2 = extra
    active = np.empty(r.shape[0], dtype=np.int64)  # the rows that push (most are 0), in order
    R = 0
    for k in range(r.shape[0]):
        if r[k] != 0.0:
            active[R] = k
            R += 1
    return _held_step(J, e, (Jr, r, w2, active, R), prior, q, joints, lam, eps, max_step, work)


@kernel
def _held_step(J, e, rows, prior, q, joints, lam, eps, max_step, work):
    """:func:`_dense_step` once the active extra rows ``rows = (Jr, r, w2, active, R)`` are known: the normal
    equations, the joints held at their limits (solved once more when the solution pushes one out), the damped solve,
    the cap. Six rows (a pose) take a copy of the sums with that count fixed at compile time (their loops
    unrolled)."""
    A, g, dq = work
    n = q.shape[0]
    m = J.shape[0]
    ridge = eps
    if prior is not None:
        ridge = prior[1] + eps
    for i in range(n):
        dq[i] = 0.0
    for _ in range(2):
        if m == 6:
            _normal_equations(J, e, rows, prior, q, A, g, 6)
        else:
            _normal_equations(J, e, rows, prior, q, A, g, m)
        hold(q, joints, g, dq, A)
        for i in range(n):
            A[i, i] = _damped(A[i, i], lam, eps, ridge)
        if not _cholesky_solve(A, g, dq):
            return False
        if not pushes_out(q, joints, dq):
            break
    return _cap(dq, max_step)


@kernel
def _judge(good, E, Ec, done, lam, down, up, lo, hi):
    """The accept/reject and damping rule: ``(kept, lam)``. A candidate of cost ``Ec`` is kept when the step was
    ``good`` and ``Ec < E`` or it is ``done`` (an answer); lambda then becomes ``max(lam down, lo)``, else
    ``min(lam up, hi)``."""
    kept = good and (Ec < E or done)
    if kept:
        return True, max(lam * down, lo)
    return False, min(lam * up, hi)


@kernel
def _stalled(kept, E, Ec, stall, stall_rel):
    """The stall count after a step: 0 after a kept step that lowers the cost ``E`` by at least ``stall_rel E``,
    else one more."""
    return 0 if kept and E - Ec >= stall_rel * E else stall + 1
