"""Yoshikawa's manipulability of one configuration and its exact gradient, compiled (the kernel of
:func:`nik.costs.manipulability`).

``w(q) = sqrt(det(J J^T))`` with ``J: (6, n)`` the geometric Jacobian of the tool in the base frame (rows linear then
angular velocity, :func:`nik.kernels.chain._chain_jacobian`); for an arm of fewer than 6 joints ``sqrt(det(J^T J))``
(both are the product of ``J``'s singular values). The gradient of ``log w`` is exact, from the derivative of the
geometric Jacobian itself: with ``z_k`` the axis of joint ``k`` and ``J_i = [v_i; o_i]`` column ``i``,

- ``dJ_i / dq_k = [z_k x v_i; z_k x o_i]`` for a revolute joint ``k`` before ``i`` (``k < i``: column ``i`` turns
  with it),
- ``dJ_i / dq_k = [z_i x v_k; 0]`` for a revolute joint ``i`` at or before ``k`` (``i <= k``: the tool moves by
  ``v_k``),
- 0 otherwise (a prismatic joint turns nothing),

and ``d log w / dq_k = sum_i M_i . dJ_i/dq_k`` with ``M = (J J^T)^-1 J`` (``J (J^T J)^-1`` below 6 joints), solved
by a Cholesky factorisation of the ``6 x 6`` (``n x n``) matrix (:func:`nik.kernels.lm_step._cholesky`, the LM
step's); one that will not factorise (a singular configuration) is factorised again with a ridge of :data:`RIDGE`
times its trace, so the direction stays finite.
The torch twin (:class:`nik.costs.manipulability.ManipulabilityTerm`) is the reference the tests compare against.
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import PRISMATIC, _chain_jacobian
from nik.kernels.lm_step import _cholesky

__all__ = ["EPS", "RIDGE", "manipulability_rows"]

#: The residual is ``1 / (w + EPS)`` (PyRoki's ``manipulability_cost`` form): finite at a singularity.
EPS = 1e-6
#: Ridge of the Cholesky factorisation, a fraction of the matrix's trace (the gradient at a singularity).
RIDGE = 1e-12


@kernel
def _cross_dot(m0, m1, m2, a0, a1, a2, b0, b1, b2):
    """``m . (a x b)``."""
    return m0 * (a1 * b2 - a2 * b1) + m1 * (a2 * b0 - a0 * b2) + m2 * (a0 * b1 - a1 * b0)


@kernel
def _gram(J, A, m):
    """``A (m, m)``: ``J J^T`` (``m = 6``) or ``J^T J`` (``m = n < 6``) of ``J (6, n)``."""
    n = J.shape[1]
    for a in range(m):
        for c in range(m):
            v = 0.0
            if n >= 6:
                for i in range(n):
                    v += J[a, i] * J[c, i]
            else:
                for r in range(6):
                    v += J[r, a] * J[r, c]
            A[a, c] = v


@kernel
def _manipulability(J, joints, A, M, grad):
    """``w`` of the geometric Jacobian ``J (6, n)``, and ``grad (n,)`` = the gradient of ``log w`` (module
    docstring); scratch ``A (6, 6)``, ``M (6, n)``. A configuration whose matrix will not factorise: ``w = 0`` and a
    zero gradient."""
    n = J.shape[1]
    m = 6 if n >= 6 else n
    _gram(J, A, m)
    tr = 0.0
    for a in range(m):
        tr += A[a, a]
    if not _cholesky(A, m, 0.0):  # singular: once more with the ridge, from A again
        _gram(J, A, m)
        if not _cholesky(A, m, RIDGE * tr):
            for i in range(n):
                grad[i] = 0.0
            return 0.0
    logdet = 0.0
    for j in range(m):
        logdet += 2.0 * math.log(A[j, j])
    # M = A^-1 J (n >= 6: columns of J solved) or (J A^-1) = (A^-1 J^T)^T (n < 6: rows of J solved)
    cols = n if n >= 6 else 6
    for c in range(cols):
        for i in range(m):  # L y = b
            v = J[i, c] if n >= 6 else J[c, i]
            for k in range(i):
                v -= A[i, k] * (M[k, c] if n >= 6 else M[c, k])
            if n >= 6:
                M[i, c] = v / A[i, i]
            else:
                M[c, i] = v / A[i, i]
        for i in range(m - 1, -1, -1):  # L^T x = y
            v = M[i, c] if n >= 6 else M[c, i]
            for k in range(i + 1, m):
                v -= A[k, i] * (M[k, c] if n >= 6 else M[c, k])
            if n >= 6:
                M[i, c] = v / A[i, i]
            else:
                M[c, i] = v / A[i, i]
    for k in range(n):
        g = 0.0
        k_rev = joints[k, PRISMATIC] == 0.0
        for i in range(n):
            if i > k and k_rev:  # column i turns with joint k
                g += _cross_dot(M[0, i], M[1, i], M[2, i], J[3, k], J[4, k], J[5, k], J[0, i], J[1, i], J[2, i])
                g += _cross_dot(M[3, i], M[4, i], M[5, i], J[3, k], J[4, k], J[5, k], J[3, i], J[4, i], J[5, i])
            elif i <= k and joints[i, PRISMATIC] == 0.0:  # the tool moves by v_k about the axis of joint i
                g += _cross_dot(M[0, i], M[1, i], M[2, i], J[3, i], J[4, i], J[5, i], J[0, k], J[1, k], J[2, k])
        grad[k] = g
    return math.exp(0.5 * logdet)


@kernel
def manipulability_rows(G, joints, Q, r, Jr):
    """The compiled residual of :func:`nik.costs.manipulability` for ``Q: (B, n)``: ``r (B, 1) = 1 / (w + EPS)`` and
    its exact Jacobian ``Jr (B, 1, n) = -w / (w + EPS)^2 grad(log w)`` (unweighted)."""
    B, n = Q.shape
    T, J = np.empty((3, 4)), np.empty((6, n))
    A, M, grad = np.empty((6, 6)), np.empty((6, n)), np.empty(n)
    for b in range(B):
        _chain_jacobian(G, joints, Q[b], T, J)
        w = _manipulability(J, joints, A, M, grad)
        r[b, 0] = 1.0 / (w + EPS)
        f = -w / ((w + EPS) * (w + EPS))
        for i in range(n):
            Jr[b, 0, i] = f * grad[i]
