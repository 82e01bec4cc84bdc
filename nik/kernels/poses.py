"""Target poses checked and converted for the compiled path: the checks of ``nik.poses.validate_pose`` and the
conversions of ``nik.poses.quaternion_to_matrix`` / ``rpy_to_matrix``, on ``(B, ...)`` float64 arrays.

A few small numpy calls cost microseconds each (``np.linalg.det`` alone about ten); these loops cost
nanoseconds per pose. They answer yes or no: the torch code stays the one that explains what is wrong. They
write only their output arguments and release the GIL.
"""

from __future__ import annotations

import math

from numba import carray

from nik.kernels._jit import kernel
from nik.kernels.chain import _float64_at

__all__ = ["pose_at", "poses_ok", "quat_poses", "reach_flags", "rpy_poses"]


@kernel
def poses_ok(T, tol):
    """True when every ``T[b]: (4, 4)`` is finite with bottom row ``[0, 0, 0, 1]``, ``max |R^T R - I| <= tol``
    and ``|det R - 1| <= tol``."""
    for b in range(T.shape[0]):
        P = T[b]
        for r in range(4):
            for c in range(4):
                if not math.isfinite(P[r, c]):
                    return False
        if abs(P[3, 0]) > tol or abs(P[3, 1]) > tol or abs(P[3, 2]) > tol or abs(P[3, 3] - 1.0) > tol:
            return False
        for i in range(3):
            for j in range(3):
                v = P[0, i] * P[0, j] + P[1, i] * P[1, j] + P[2, i] * P[2, j] - (1.0 if i == j else 0.0)
                if abs(v) > tol:
                    return False
        det = (
            P[0, 0] * (P[1, 1] * P[2, 2] - P[1, 2] * P[2, 1])
            - P[0, 1] * (P[1, 0] * P[2, 2] - P[1, 2] * P[2, 0])
            + P[0, 2] * (P[1, 0] * P[2, 1] - P[1, 1] * P[2, 0])
        )
        if abs(det - 1.0) > tol:
            return False
    return True


@kernel
def pose_at(address, tol, T):
    """One ``(4, 4)`` pose stored contiguously as float64 at ``address`` copied into ``T: (1, 4, 4)``; returns
    :func:`poses_ok` of it. ``address`` is the ``data_ptr()`` of a contiguous float64 CPU tensor of 16 values that the
    caller has checked and keeps alive during the call: a tensor pose read without the microseconds of
    ``Tensor.numpy()`` (:mod:`nik.ik.backends.one_pose`)."""
    P = carray(_float64_at(address), (4, 4))
    for r in range(4):
        for c in range(4):
            T[0, r, c] = P[r, c]
    return poses_ok(T, tol)


@kernel
def quat_poses(v, tol, T):
    """``v: (B, 7)`` xyz + quaternion (w, x, y, z) -> ``T: (B, 4, 4)`` (normalised quaternion); False when a value
    is not finite or a quaternion's norm is farther than ``tol`` from 1."""
    for b in range(v.shape[0]):
        for k in range(7):
            if not math.isfinite(v[b, k]):
                return False
        norm = math.sqrt(v[b, 3] ** 2 + v[b, 4] ** 2 + v[b, 5] ** 2 + v[b, 6] ** 2)
        if abs(norm - 1.0) > tol:
            return False
        w, x, y, z = v[b, 3] / norm, v[b, 4] / norm, v[b, 5] / norm, v[b, 6] / norm
        P = T[b]
        P[0, 0], P[0, 1], P[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        P[1, 0], P[1, 1], P[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        P[2, 0], P[2, 1], P[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
        _finish(P, v[b])
    return True


@kernel
def rpy_poses(v, T):
    """``v: (B, 6)`` xyz + roll-pitch-yaw -> ``T: (B, 4, 4)``, ``R = Rz(yaw) Ry(pitch) Rx(roll)``; False when a
    value is not finite."""
    for b in range(v.shape[0]):
        for k in range(6):
            if not math.isfinite(v[b, k]):
                return False
        cr, cp, cy = math.cos(v[b, 3]), math.cos(v[b, 4]), math.cos(v[b, 5])
        sr, sp, sy = math.sin(v[b, 3]), math.sin(v[b, 4]), math.sin(v[b, 5])
        P = T[b]
        P[0, 0], P[0, 1], P[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
        P[1, 0], P[1, 1], P[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
        P[2, 0], P[2, 1], P[2, 2] = -sp, cp * sr, cp * cr
        _finish(P, v[b])
    return True


@kernel
def _finish(P, v):
    P[0, 3], P[1, 3], P[2, 3] = v[0], v[1], v[2]
    P[3, 0], P[3, 1], P[3, 2], P[3, 3] = 0.0, 0.0, 0.0, 1.0


@kernel
def reach_flags(T, center, radius, slack, out):
    """``out: (B,)`` bool: ``|p_b - center| / radius <= 1 + slack`` (the reach bound); returns True when all are."""
    every = True
    for b in range(T.shape[0]):
        dx, dy, dz = T[b, 0, 3] - center[0], T[b, 1, 3] - center[1], T[b, 2, 3] - center[2]
        out[b] = math.sqrt(dx * dx + dy * dy + dz * dz) / radius <= 1.0 + slack
        every = every and out[b]
    return every
