"""FK and geometric Jacobian of the normal form ``G_0 J_1 G_1 ... J_n G_n`` for one configuration.

The robot is data, not code: one compiled kernel serves every arm. As in Pinocchio, a *model*
(constant arrays, built once per robot by :func:`chain_model`) is separate from the scratch a
kernel fills (arrays the caller allocates once and passes in):

- ``G: (n + 1, 4, 4)`` float64, the constant transforms of the normal form (metres);
- ``joints: (n, 5)`` float64, one row per joint: ``offset`` (radians, metres for a prismatic joint),
  ``lower``, ``upper`` limits, ``prismatic`` (1.0 or 0.0) and ``wraps`` (1.0 for a revolute joint
  whose range spans a full turn: a value past a limit moves by whole turns); columns ``OFFSET``,
  ``LOWER``, ``UPPER``, ``PRISMATIC``, ``WRAPS``.

Joint ``i`` is ``Rz(q_i + o_i)`` (revolute) or ``Tz(q_i + o_i)`` (prismatic). Only the top three rows
of the running transform are carried; right-multiplying by ``Rz`` mixes two columns, by ``Tz(d)``
adds ``d`` times column 2 to column 3, by ``G_i`` is a 3x4-by-4x4 product written out (36 products,
``G_i``'s last row being ``[0, 0, 0, 1]``). Nothing is allocated inside the loops, and a kernel writes only
the arrays passed to it (threads may share a model; the kernels release the GIL).

The reference implementation is the torch one of :mod:`nik.kinematics`; the tests compare the two.
"""

from __future__ import annotations

import math

import numpy as np
from numba import carray, types
from numba.extending import intrinsic

from nik.kernels._jit import kernel

__all__ = [
    "LOWER",
    "OFFSET",
    "PRISMATIC",
    "UPPER",
    "WRAPS",
    "chain_model",
    "fk",
    "fk_at",
    "fk_batch",
    "fk_jacobian",
    "fk_one_at",
]

#: Columns of the ``joints`` table.
OFFSET, LOWER, UPPER, PRISMATIC, WRAPS = 0, 1, 2, 3, 4

_TWO_PI = 2.0 * math.pi


def chain_model(G, offsets, limits, prismatic=None, *, wrap_tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The model arrays of one robot: ``G: (n + 1, 4, 4)`` and ``joints: (n, 5)``, contiguous float64.

    Args:
        G: (n + 1, 4, 4) normal-form transforms (numpy, torch or nested lists).
        offsets: (n,) joint offsets.
        limits: (n, 2) lower and upper limits (radians; metres for prismatic joints).
        prismatic: (n,) bool or None (all revolute).
        wrap_tol: a revolute joint wraps when ``upper - lower >= 2 pi - wrap_tol`` (as ``wrap_mask``).
    """
    G = np.ascontiguousarray(np.asarray(G, dtype=np.float64))
    n = G.shape[0] - 1
    if G.shape != (n + 1, 4, 4) or n < 1:
        raise ValueError(f"chain_model: G must have shape (n + 1, 4, 4) with n >= 1, got {G.shape}")
    limits = np.asarray(limits, dtype=np.float64).reshape(n, 2)
    pm = np.zeros(n, dtype=bool) if prismatic is None else np.asarray(prismatic, dtype=bool).reshape(n)
    joints = np.empty((n, 5))
    joints[:, OFFSET] = np.asarray(offsets, dtype=np.float64).reshape(n)
    joints[:, LOWER], joints[:, UPPER] = limits[:, 0], limits[:, 1]
    joints[:, PRISMATIC] = pm
    joints[:, WRAPS] = ((limits[:, 1] - limits[:, 0]) >= _TWO_PI - wrap_tol) & ~pm
    return G, np.ascontiguousarray(joints)


# ---------------------------------------------------------------------------
# building blocks (compiled into the kernels that call them)
# ---------------------------------------------------------------------------
@kernel
def _start(T, G0):
    """``T (3, 4) = G0[:3]``."""
    for r in range(3):
        for k in range(4):
            T[r, k] = G0[r, k]


@kernel
def _joint(T, prismatic, theta):
    """``T (3, 4) <- T @ Rz(theta)`` (revolute) or ``T @ Tz(theta)`` (prismatic), in place."""
    if prismatic:
        for r in range(3):
            T[r, 3] += T[r, 2] * theta
    else:
        c, s = math.cos(theta), math.sin(theta)
        for r in range(3):
            x, y = T[r, 0], T[r, 1]
            T[r, 0] = x * c + y * s
            T[r, 1] = y * c - x * s


@kernel
def _times(T, M):
    """``T (3, 4) <- T @ M`` for a rigid ``M (4, 4)`` (last row ``[0, 0, 0, 1]``), in place, written out."""
    for r in range(3):
        t0, t1, t2, t3 = T[r, 0], T[r, 1], T[r, 2], T[r, 3]
        T[r, 0] = t0 * M[0, 0] + t1 * M[1, 0] + t2 * M[2, 0]
        T[r, 1] = t0 * M[0, 1] + t1 * M[1, 1] + t2 * M[2, 1]
        T[r, 2] = t0 * M[0, 2] + t1 * M[1, 2] + t2 * M[2, 2]
        T[r, 3] = t0 * M[0, 3] + t1 * M[1, 3] + t2 * M[2, 3] + t3


@kernel
def _chain(G, joints, q, T):
    """``T (3, 4)``: the top rows of ``T(q)`` for ``q: (n,)``."""
    _start(T, G[0])
    for i in range(q.shape[0]):
        _joint(T, joints[i, PRISMATIC] != 0.0, q[i] + joints[i, OFFSET])
        _times(T, G[i + 1])


@kernel
def _chain_jacobian(G, joints, q, T, J):
    """``T (3, 4)`` and the geometric Jacobian ``J (6, n)`` (rows: linear, angular velocity).

    Joint ``i`` moves about/along the z axis ``z_i`` of the frame before its ``J_i``, through that
    frame's origin ``p_i``: column ``[z_i x (p - p_i); z_i]`` (revolute) or ``[z_i; 0]`` (prismatic).
    ``p_i`` is parked in the linear rows until ``p`` is known.
    """
    _start(T, G[0])
    n = q.shape[0]
    for i in range(n):
        for r in range(3):
            J[r, i] = T[r, 3]
            J[3 + r, i] = T[r, 2]
        _joint(T, joints[i, PRISMATIC] != 0.0, q[i] + joints[i, OFFSET])
        _times(T, G[i + 1])
    px, py, pz = T[0, 3], T[1, 3], T[2, 3]
    for i in range(n):
        zx, zy, zz = J[3, i], J[4, i], J[5, i]
        if joints[i, PRISMATIC] != 0.0:
            J[0, i], J[1, i], J[2, i] = zx, zy, zz
            J[3, i], J[4, i], J[5, i] = 0.0, 0.0, 0.0
        else:
            rx, ry, rz = px - J[0, i], py - J[1, i], pz - J[2, i]
            J[0, i] = zy * rz - zz * ry
            J[1, i] = zz * rx - zx * rz
            J[2, i] = zx * ry - zy * rx


@kernel
def _bottom_row(T):
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = 0.0, 0.0, 0.0, 1.0


# ---------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------
@kernel
def _finite(q):
    for i in range(q.shape[0]):
        if not math.isfinite(q[i]):
            return False
    return True


@kernel
def fk(G, joints, q, T):
    """FK of one configuration: ``q: (n,)`` -> ``T: (4, 4)`` (written in place; metres).

    Returns True when every joint value is finite (the caller's input check costs nothing more)."""
    _chain(G, joints, q, T)
    _bottom_row(T)
    return _finite(q)


@kernel
def fk_batch(G, joints, q, T):
    """FK of a small batch: ``q: (B, n)`` -> ``T: (B, 4, 4)`` (written in place). Returns True when every
    joint value is finite."""
    finite = True
    for b in range(q.shape[0]):
        _chain(G, joints, q[b], T[b])
        _bottom_row(T[b])
        finite = finite and _finite(q[b])
    return finite


@intrinsic
def _float64_at(typingctx, address):
    """The ``float64*`` at an integer ``address``."""
    if not isinstance(address, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return types.CPointer(types.float64)(address), codegen


@kernel
def fk_at(G, joints, address, T):
    """FK of the ``B = T.shape[0]`` configurations ``(B, n)`` stored contiguously as float64 at ``address`` ->
    ``T: (B, 4, 4)`` (written in place). Returns True when every joint value is finite.

    ``address`` is the ``data_ptr()`` of a contiguous float64 CPU tensor of ``B * n`` values, which the caller
    has checked and keeps alive during the call: one configuration goes from tensor to pose without the
    microseconds of ``Tensor.numpy()`` (:meth:`nik.Robot.fk`'s fast path)."""
    q = carray(_float64_at(address), (T.shape[0], joints.shape[0]))
    finite = True
    for b in range(T.shape[0]):
        _chain(G, joints, q[b], T[b])
        _bottom_row(T[b])
        finite = finite and _finite(q[b])
    return finite


@kernel
def fk_one_at(G, joints, address, T):
    """FK of the one configuration ``(n,)`` stored contiguously as float64 at ``address`` -> ``T: (4, 4)`` (written
    in place). Returns True when every joint value is finite. As :func:`fk_at` for one configuration, without the
    batch axis (:meth:`nik.Robot.fk` of one configuration returns ``T`` as it is)."""
    q = carray(_float64_at(address), (joints.shape[0],))
    _chain(G, joints, q, T)
    _bottom_row(T)
    return _finite(q)


@kernel
def fk_jacobian(G, joints, q, T, J):
    """FK and geometric Jacobian of one configuration: ``q: (n,)`` -> ``T: (4, 4)``, ``J: (6, n)``
    (rows: linear velocity xyz, angular velocity xyz; a prismatic joint's column is its axis, then zeros)."""
    _chain_jacobian(G, joints, q, T, J)
    _bottom_row(T)
