"""Pose representations, pose errors and input validation.

Every function is batched over leading dimensions and keeps the dtype and device
of its input. Conventions:

- a pose is a homogeneous 4x4 matrix ``T: (..., 4, 4)``, metres;
- a quaternion is ``(w, x, y, z)`` with ``w >= 0`` on output (unit norm); the representation ``quat_xyzw`` takes
  and gives it as ``(x, y, z, w)`` instead, the order of ROS messages (``geometry_msgs/Quaternion``), scipy and
  Eigen's coefficients (:func:`xyzw_to_wxyz`);
- roll-pitch-yaw follows paper C eq. (3): ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``,
  ``roll = atan2(o_z, a_z)``, ``pitch = atan2(-n_z, sqrt(n_x^2 + n_y^2))``, ``yaw = atan2(n_y, n_x)``
  (``n, o, a`` the columns of ``R``);
- the 6D rotation representation (Zhou et al. 2019) is the first two columns of ``R``,
  stacked as ``(r11, r21, r31, r12, r22, r32)``.

The ground floor beside :mod:`nik.kinematics`: this module imports nothing from nik.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import torch

__all__ = [
    "ORTHONORMAL_TOL",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "matrix_to_rpy",
    "rpy_to_matrix",
    "matrix_to_rot6d",
    "rot6d_to_matrix",
    "pose_to_vector",
    "vector_to_pose",
    "make_pose",
    "rotation_angle",
    "pose_error",
    "rotation_vector",
    "rotation_modes",
    "tool_error",
    "bounded_error",
    "within_bounds",
    "validate_pose",
    "validate_joints",
    "validate_quaternion",
    "warn_degrees",
    "xyzw_to_wxyz",
    "POSE_DIMS",
]

#: Largest accepted ``max |R^T R - I|`` (and ``|det R - 1|``) for a pose given to nik.
#: Rotations computed in float32 carry errors of about 1e-6, so 1e-4 accepts them
#: while rejecting anything that is not a rotation (a scaled or sheared matrix).
ORTHONORMAL_TOL = 1e-4

#: Length of the vector form of a pose for each representation.
POSE_DIMS = {"quat": 7, "quat_xyzw": 7, "rpy": 6, "rot6d": 9, "matrix": 12}


def xyzw_to_wxyz(v):
    """A ``quat_xyzw`` pose vector ``(..., 7)`` (x, y, z, qx, qy, qz, qw: ROS order) as a ``quat`` one (x, y, z, qw,
    qx, qy, qz); a tensor or a numpy array, a copy in the same type."""
    return v[..., [0, 1, 2, 6, 3, 4, 5]]


def make_pose(R: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """Assemble ``T: (..., 4, 4)`` from ``R: (..., 3, 3)`` and ``p: (..., 3)``."""
    # numpy's rule, not torch.broadcast_shapes: its first call imports sympy (about a second)
    batch = np.broadcast_shapes(tuple(R.shape[:-2]), tuple(p.shape[:-1]))
    T = torch.zeros(*batch, 4, 4, dtype=R.dtype, device=R.device)
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def matrix_to_quaternion(R: torch.Tensor) -> torch.Tensor:
    """Rotation ``R: (..., 3, 3)`` -> unit quaternion ``(..., 4)`` (w, x, y, z), ``w >= 0``.

    Shepperd's method: of the four candidate formulas, use the one whose pivot
    (``1 + trace`` or ``1 + 2 R_ii - trace``) is largest, so the division is never by a small number.
    """
    m = R
    r00, r11, r22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    tr = r00 + r11 + r22
    pivots = torch.stack([1 + tr, 1 + 2 * r00 - tr, 1 + 2 * r11 - tr, 1 + 2 * r22 - tr], dim=-1)
    # Candidate quaternions, each scaled by 4 * its pivot component.
    r01, r02, r10, r12, r20, r21 = m[..., 0, 1], m[..., 0, 2], m[..., 1, 0], m[..., 1, 2], m[..., 2, 0], m[..., 2, 1]
    c0 = torch.stack([1 + tr, r21 - r12, r02 - r20, r10 - r01], -1)
    c1 = torch.stack([r21 - r12, 1 + 2 * r00 - tr, r01 + r10, r02 + r20], -1)
    c2 = torch.stack([r02 - r20, r01 + r10, 1 + 2 * r11 - tr, r12 + r21], -1)
    c3 = torch.stack([r10 - r01, r02 + r20, r12 + r21, 1 + 2 * r22 - tr], -1)
    cands = torch.stack([c0, c1, c2, c3], dim=-2)  # (..., 4, 4)
    best = pivots.argmax(dim=-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    return torch.where(q[..., :1] < 0, -q, q)


def quaternion_to_matrix(quat: torch.Tensor) -> torch.Tensor:
    """Quaternion ``(..., 4)`` (w, x, y, z) -> rotation ``(..., 3, 3)``. The quaternion is normalised first."""
    q = quat / torch.linalg.vector_norm(quat, dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    ]
    return torch.stack(rows, dim=-1).reshape(*q.shape[:-1], 3, 3)


def matrix_to_rpy(R: torch.Tensor) -> torch.Tensor:
    """Rotation ``(..., 3, 3)`` -> ``(roll, pitch, yaw)`` ``(..., 3)`` radians, paper C eq. (3)."""
    roll = torch.atan2(R[..., 2, 1], R[..., 2, 2])
    pitch = torch.atan2(-R[..., 2, 0], torch.sqrt(R[..., 0, 0] ** 2 + R[..., 1, 0] ** 2))
    yaw = torch.atan2(R[..., 1, 0], R[..., 0, 0])
    return torch.stack([roll, pitch, yaw], dim=-1)


def rpy_to_matrix(rpy: torch.Tensor) -> torch.Tensor:
    """``(roll, pitch, yaw)`` ``(..., 3)`` -> ``R = Rz(yaw) Ry(pitch) Rx(roll)`` ``(..., 3, 3)``."""
    cr, cp, cy = torch.cos(rpy).unbind(-1)
    sr, sp, sy = torch.sin(rpy).unbind(-1)
    rows = [
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    ]
    return torch.stack(rows, dim=-1).reshape(*rpy.shape[:-1], 3, 3)


def matrix_to_rot6d(R: torch.Tensor) -> torch.Tensor:
    """Rotation ``(..., 3, 3)`` -> 6D representation ``(..., 6)``: first column, then second column."""
    return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)


def rot6d_to_matrix(r6: torch.Tensor) -> torch.Tensor:
    """6D representation ``(..., 6)`` -> rotation ``(..., 3, 3)`` by Gram-Schmidt."""
    a, b = r6[..., :3], r6[..., 3:]
    x = a / torch.linalg.vector_norm(a, dim=-1, keepdim=True)
    b = b - (x * b).sum(-1, keepdim=True) * x
    y = b / torch.linalg.vector_norm(b, dim=-1, keepdim=True)
    z = torch.linalg.cross(x, y, dim=-1)
    return torch.stack([x, y, z], dim=-1)


def pose_to_vector(T: torch.Tensor, representation: str = "quat") -> torch.Tensor:
    """``T: (..., 4, 4)`` -> xyz followed by the rotation in ``representation``.

    ``quat``: (..., 7) xyz + (w, x, y, z); ``quat_xyzw``: (..., 7) xyz + (x, y, z, w); ``rpy``: (..., 6) xyz +
    roll-pitch-yaw;
    ``rot6d``: (..., 9) xyz + 6D; ``matrix``: (..., 12) xyz + the 9 rotation entries row by row.
    """
    p, R = T[..., :3, 3], T[..., :3, :3]
    if representation == "quat":
        rot = matrix_to_quaternion(R)
    elif representation == "quat_xyzw":
        rot = matrix_to_quaternion(R)[..., [1, 2, 3, 0]]
    elif representation == "rpy":
        rot = matrix_to_rpy(R)
    elif representation == "rot6d":
        rot = matrix_to_rot6d(R)
    elif representation == "matrix":
        rot = R.reshape(*R.shape[:-2], 9)
    else:
        raise ValueError(f"unknown pose representation {representation!r}; expected one of {sorted(POSE_DIMS)}")
    return torch.cat([p, rot], dim=-1)


def vector_to_pose(v: torch.Tensor, representation: str = "quat") -> torch.Tensor:
    """Inverse of :func:`pose_to_vector`: ``(..., D)`` -> ``T: (..., 4, 4)``."""
    if representation not in POSE_DIMS:
        raise ValueError(f"unknown pose representation {representation!r}; expected one of {sorted(POSE_DIMS)}")
    if v.shape[-1] != POSE_DIMS[representation]:
        raise ValueError(
            f"a {representation!r} pose has {POSE_DIMS[representation]} numbers per row, got shape {tuple(v.shape)}"
        )
    p, rot = v[..., :3], v[..., 3:]
    if representation == "quat":
        R = quaternion_to_matrix(rot)
    elif representation == "quat_xyzw":
        R = quaternion_to_matrix(rot[..., [3, 0, 1, 2]])
    elif representation == "rpy":
        R = rpy_to_matrix(rot)
    elif representation == "rot6d":
        R = rot6d_to_matrix(rot)
    else:
        R = rot.reshape(*rot.shape[:-1], 3, 3)
    return make_pose(R, p)


def rotation_angle(R: torch.Tensor) -> torch.Tensor:
    """Angle of the rotation ``R: (..., 3, 3)`` in radians, in [0, pi].

    Computed as ``atan2(|vee(R - R^T)| / 2, (trace - 1) / 2)``: accurate near 0 (where
    ``arccos`` loses half the digits and its derivative blows up) and never NaN for
    ``trace`` slightly beyond [-1, 3]. Near pi the sine term is small and the cosine
    term carries the angle, so the result is also accurate there.
    """
    vee = torch.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], dim=-1)
    sin = 0.5 * torch.linalg.vector_norm(vee, dim=-1)
    cos = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1)
    return torch.atan2(sin, cos)


def pose_error(T_target: torch.Tensor, T: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Position and geodesic rotation error between poses.

    Args:
        T_target: (..., 4, 4) wanted poses.
        T: (..., 4, 4) reached poses (broadcast against ``T_target``).

    Returns:
        ``(pos_err, rot_err)``, each ``(...,)``: Euclidean distance of the positions in metres,
        and the angle of ``R_target^T R`` in radians (geodesic distance on SO(3)).
    """
    pos_err = torch.linalg.vector_norm(T[..., :3, 3] - T_target[..., :3, 3], dim=-1)
    R_rel = T_target[..., :3, :3].transpose(-1, -2) @ T[..., :3, :3]
    return pos_err, rotation_angle(R_rel)


def rotation_vector(R: torch.Tensor) -> torch.Tensor:
    """Rotation vector ``(..., 3)`` (unit axis times the angle in [0, pi]) of ``R: (..., 3, 3)``; differentiable.

    Through the unit quaternion (Shepperd's method, ``w >= 0``): ``2 atan2(|v|, w) v / |v|``, with the limit
    ``2 v / w`` near the identity (where the gradient is finite too); accurate at every angle, pi included.
    """
    quat = matrix_to_quaternion(R)
    w, v = quat[..., :1], quat[..., 1:]
    nv2 = (v * v).sum(-1, keepdim=True)
    small = nv2 < 1e-14
    nv = torch.sqrt(torch.where(small, torch.ones_like(nv2), nv2))
    scale = torch.where(small, 2.0 / w.clamp_min(1e-12), 2.0 * torch.atan2(nv, w) / nv)
    return v * scale


#: :func:`rotation_modes` codes: no rotation axis free; (0, 1, 2: rotation about that tool axis free); all free.
ROT_BOUNDED, ROT_FREE = -1, 3


def rotation_modes(bounds: torch.Tensor) -> torch.Tensor:
    """Which rotation a row of ``bounds: (..., 6)`` leaves free (``inf`` entries 3..5): ``(...,)`` long.

    ``-1``: none (the rotation vector is bounded per axis); ``0, 1, 2``: rotation about that tool axis;
    ``3``: all rotation (two or three free axes: rotations about two tool axes compose every orientation, so a
    bound left on the third one could never bind; :func:`nik.ik.bounds.parse_bounds` refuses that case).
    """
    free = torch.isinf(bounds[..., 3:])
    n = free.sum(-1)
    k = free.to(torch.long).argmax(-1)
    return torch.where(n == 0, ROT_BOUNDED, torch.where(n == 1, k, ROT_FREE))


def _swing(v: torch.Tensor, k: int) -> torch.Tensor:
    """Swing vector ``(..., 3)`` (component ``k`` zero) turning the tool axis ``e_k`` onto ``v: (..., 3)``.

    ``s = phi / sin(phi) * (e_k x v)`` with ``sin(phi) = |e_k x v|``, ``phi = atan2(|e_k x v|, v_k)``: the angle
    between the axes on the axis perpendicular to both (the limit ``f = 1`` when they are parallel; a half turn
    about axis ``i`` when they are opposite).
    """
    i, j = (k + 1) % 3, (k + 2) % 3
    vi, vj, vk = v[..., i], v[..., j], v[..., k]
    s2 = vi * vi + vj * vj
    small = s2 < 1e-14
    sn = torch.sqrt(torch.where(small, torch.ones_like(s2), s2))
    f = torch.where(small, torch.ones_like(s2), torch.atan2(sn, vk) / sn)
    flip = small & (vk < 0)  # the axis turned over: a half turn about an axis of its own choosing
    out = [None, None, None]
    out[i] = torch.where(flip, torch.full_like(vk, math.pi), -f * vj)
    out[j] = torch.where(flip, torch.zeros_like(vk), f * vi)
    out[k] = torch.zeros_like(vk)
    return torch.stack(out, dim=-1)


def tool_error(T_target: torch.Tensor, T: torch.Tensor, modes: torch.Tensor | None = None) -> torch.Tensor:
    """The error of ``T`` against ``T_target`` per axis of the target's tool frame, TRAC-IK's convention: ``(..., 6)``.

    Position ``R_t^T (p - p_t)`` (metres, along the target tool's x, y, z), then the rotation (radians):

    - ``modes`` -1 (or None): the rotation vector of ``R_t^T R`` (TRAC-IK's ``diffRelative``), per tool axis;
    - ``modes`` k in 0, 1, 2 (rotation about tool axis k free): the *swing* of tool axis k, the rotation vector of
      the shortest rotation taking the target's axis k onto the reached one (its angle is the angle between the
      two axes; component k zero), and in entry k the *twist* about that axis (``R_t^T R = swing * Rk(twist)``).
      A free axis needs this: the rotation vector's components mix twist and tilt (``Rz(a) Rx(b)`` has
      ``x, y`` components that depend on ``a``, and they jump where ``a`` passes pi), so dropping its ``z``
      component neither measures the tilt of the tool axis nor lets the twist go free;
    - ``modes`` 3: zeros (every rotation axis is free: nothing is measured).

    ``T_target, T: (..., 4, 4)`` (or ``(..., 3, 4)``; broadcast); ``modes: (...,)`` long (:func:`rotation_modes`).
    Differentiable.
    """
    Rt = T_target[..., :3, :3]
    Rt_T = Rt.transpose(-1, -2)
    dp = (Rt_T @ (T[..., :3, 3] - T_target[..., :3, 3]).unsqueeze(-1)).squeeze(-1)
    R_rel = Rt_T @ T[..., :3, :3]
    rot = rotation_vector(R_rel)
    if modes is not None and bool((modes >= 0).any()):
        quat = matrix_to_quaternion(R_rel)
        for k in range(3):
            sel = (modes == k).unsqueeze(-1)
            if not bool(sel.any()):
                continue
            twist = 2.0 * torch.atan2(quat[..., 1 + k], quat[..., 0])
            twist = torch.remainder(twist + math.pi, 2 * math.pi) - math.pi
            sw = _swing(R_rel[..., :, k], k)
            sw = torch.cat([sw[..., :k], twist.unsqueeze(-1), sw[..., k + 1 :]], dim=-1)
            rot = torch.where(sel, sw, rot)
        rot = torch.where((modes == ROT_FREE).unsqueeze(-1), torch.zeros_like(rot), rot)
    return torch.cat([dp, rot], dim=-1)


def bounded_error(T_target: torch.Tensor, T: torch.Tensor, bounds: torch.Tensor) -> torch.Tensor:
    """Excess of :func:`tool_error` beyond ``bounds: (..., 6)`` (half-widths, metres then radians; ``inf`` = free):
    ``(..., 6)``, ``sign(d) * max(|d| - bound, 0)``, zero inside. Differentiable (a dead zone)."""
    b = bounds.to(dtype=T.dtype, device=T.device)
    d = tool_error(T_target, T, rotation_modes(b))
    out = torch.where(d.abs() > b, d - torch.copysign(torch.where(torch.isinf(b), 0.0, b), d), 0.0)
    return torch.where(torch.isinf(b), 0.0, out)


def within_bounds(T_target: torch.Tensor, T: torch.Tensor, bounds: torch.Tensor) -> torch.Tensor:
    """``(...,)`` bool: every axis of :func:`tool_error` inside its bound (``|d_i| <= bounds_i``; ``inf`` = free)."""
    b = bounds.to(dtype=T.dtype, device=T.device)
    d = tool_error(T_target, T, rotation_modes(b))
    return (d.abs() <= b).all(-1)


def _fail(name: str, what: str) -> ValueError:
    return ValueError(f"{name}: {what}")


#: Radians beyond this magnitude are most likely degrees (2 pi, with room for rounding at a +-2 pi joint limit).
DEGREES_SUSPECT = 2 * math.pi * (1 + 1e-6)


def warn_degrees(
    angles: torch.Tensor,
    *,
    name: str,
    rpy: bool = False,
    prismatic: torch.Tensor | None = None,
    limits: torch.Tensor | None = None,
    stacklevel: int = 3,
) -> None:
    """``UserWarning`` when an angle of ``angles: (..., k)`` (radians) lies beyond 2 pi: most likely degrees.

    ``rpy``: the values are roll, pitch, yaw (the message shows the row's three); else joint values:
    ``prismatic: (k,)`` bool marks lengths (metres) the check leaves alone, and with ``limits: (k, 2)`` a value
    inside its joint's range is no suspect (a joint may turn further than 2 pi). The first suspect is named
    (row and joint, counted from 1); the values are used as given.
    """
    a = angles.detach().reshape(-1, angles.shape[-1])
    big = a.abs() > DEGREES_SUSPECT
    if prismatic is not None and bool(prismatic.any()):
        big &= ~prismatic.to(device=a.device, dtype=torch.bool)
    if limits is not None:
        lim = limits.to(device=a.device, dtype=a.dtype)
        big &= (a < lim[:, 0]) | (a > lim[:, 1])
    if not bool(big.any()):
        return
    row, col = (int(v) for v in big.nonzero()[0])
    if rpy:
        vals = ", ".join(f"{float(v):.6g}" for v in a[row])
        what = f"row {row}: roll, pitch, yaw = ({vals}) lie"
    else:
        what = f"row {row}, joint {col + 1} = {float(a[row, col]):.6g} lies"
    warnings.warn(
        f"{name}: {what} beyond 2 pi; nik reads angles in radians: were degrees given? (convert with math.radians)",
        UserWarning,
        stacklevel=stacklevel,
    )


def _one_pose_ok(T: torch.Tensor, tol: float) -> bool:
    """True when the CPU pose ``T: (4, 4)`` passes every check of :func:`validate_pose`."""
    import numpy as np

    a = T.numpy()
    if not np.isfinite(a).all() or np.abs(a[3] - (0.0, 0.0, 0.0, 1.0)).max() > tol:
        return False
    R = a[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > tol:
        return False
    return abs(float(np.linalg.det(R)) - 1.0) <= tol


def validate_pose(T: torch.Tensor, *, name: str = "T_target", tol: float = ORTHONORMAL_TOL) -> torch.Tensor:
    """Check that ``T: (..., 4, 4)`` holds finite rigid transforms; return it unchanged.

    Rejects, with a ``ValueError`` naming ``name`` and the offending row: a non-tensor or
    wrong shape, NaN/inf, a bottom row other than ``[0, 0, 0, 1]``, and rotations with
    ``max |R^T R - I| > tol`` or ``|det R - 1| > tol`` (``tol`` defaults to :data:`ORTHONORMAL_TOL`).
    """
    if not isinstance(T, torch.Tensor):
        raise _fail(name, f"expected a torch.Tensor of shape (..., 4, 4), got {type(T).__name__}")
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise _fail(name, f"expected shape (..., 4, 4), got {tuple(T.shape)}")
    if not T.is_floating_point():
        raise _fail(name, f"expected a floating-point tensor, got {T.dtype}")
    flat = T.detach().reshape(-1, 4, 4)
    if flat.shape[0] == 1 and flat.device.type == "cpu" and _one_pose_ok(flat[0], tol):
        return T  # one pose: the same checks in numpy (torch's per-op overhead dominates here)
    bad = ~torch.isfinite(flat).all(dim=(-1, -2))
    if bad.any():
        raise _fail(name, f"pose {int(bad.nonzero()[0])} contains NaN or inf")
    bottom = flat[:, 3, :] - torch.tensor([0, 0, 0, 1], dtype=flat.dtype, device=flat.device)
    bad = bottom.abs().amax(-1) > tol
    if bad.any():
        i = int(bad.nonzero()[0])
        raise _fail(name, f"pose {i} has bottom row {flat[i, 3].tolist()}, expected [0, 0, 0, 1]")
    R = flat[:, :3, :3]
    eye = torch.eye(3, dtype=R.dtype, device=R.device)
    ortho = (R.transpose(-1, -2) @ R - eye).abs().amax(dim=(-1, -2))
    bad = ortho > tol
    if bad.any():
        i = int(bad.nonzero()[0])
        raise _fail(name, f"rotation of pose {i} is not orthonormal (|R^T R - I| = {float(ortho[i]):.3g} > {tol:g})")
    det = torch.linalg.det(R)
    bad = (det - 1).abs() > tol
    if bad.any():
        i = int(bad.nonzero()[0])
        raise _fail(name, f"rotation of pose {i} has det {float(det[i]):.6g}, expected +1 (a reflection?)")
    return T


def validate_quaternion(quat: torch.Tensor, *, name: str = "quaternion", tol: float = 1e-3) -> torch.Tensor:
    """Return ``quat: (..., 4)`` normalised; reject NaN/inf and norms farther than ``tol`` from 1."""
    if not torch.isfinite(quat).all():
        raise _fail(name, "contains NaN or inf")
    norm = torch.linalg.vector_norm(quat, dim=-1)
    bad = (norm - 1).abs() > tol
    if bad.any():
        i = int(bad.reshape(-1).nonzero()[0])
        value = float(norm.reshape(-1)[i])
        raise _fail(name, f"row {i} has norm {value:.6g}; a unit quaternion (w, x, y, z) is expected")
    return quat / norm[..., None]


def validate_joints(q: torch.Tensor, dof: int, *, name: str = "q") -> torch.Tensor:
    """Check that ``q: (..., dof)`` is a finite floating-point tensor; return it unchanged."""
    if not isinstance(q, torch.Tensor):
        raise _fail(name, f"expected a torch.Tensor of shape (..., {dof}), got {type(q).__name__}")
    if q.ndim < 1 or q.shape[-1] != dof:
        raise _fail(name, f"expected shape (..., {dof}) (one value per joint), got {tuple(q.shape)}")
    if not q.is_floating_point():
        raise _fail(name, f"expected a floating-point tensor (radians), got {q.dtype}")
    if not torch.isfinite(q.detach()).all():
        raise _fail(name, "contains NaN or inf joint values")
    return q
