"""Targets as the solver takes them: poses in any accepted form brought to ``(B, 4, 4)``, ``q_near`` brought
to ``(B, dof)``, and tolerances checked: the one place where the input of :meth:`nik.IKSolver.solve` is validated,
whichever backend then computes.

- :func:`as_poses` / :func:`as_q_near`: torch tensors (the torch backend), raising the one-line ``ValueError``
  of each bad input and warning about suspected degrees;
- :func:`pose_array` / :func:`q_near_array`: the same for the compiled backend, as float64 numpy arrays. Input
  that passes the compiled checks (:mod:`nik.kernels.poses`: finite, orthonormal, unit quaternions within
  :data:`QUAT_NORM_TOL`, no angle that looks like degrees) is returned at once; any other input goes through
  :func:`as_poses` / :func:`as_q_near`, which raise (or warn) with their messages, so both backends refuse the
  same input with the same words.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.kernels import background as _background
from nik.poses import (
    DEGREES_SUSPECT,
    ORTHONORMAL_TOL,
    POSE_DIMS,
    make_pose,
    quaternion_to_matrix,
    rpy_to_matrix,
    validate_joints,
    validate_pose,
    warn_degrees,
    xyzw_to_wxyz,
)

__all__ = ["QUAT_NORM_TOL", "as_poses", "as_q_near", "check_tolerances", "pose_array", "q_near_array"]

#: Largest accepted deviation of a quaternion's norm from 1; nearer ones are normalised.
QUAT_NORM_TOL = 1e-2


def as_poses(T_target, representation: str | None = None, *, name: str = "T_target") -> torch.Tensor:
    """Bring targets to ``(B, 4, 4)`` homogeneous poses, validated.

    Args:
        T_target: ``(B, 4, 4)`` matrices, ``(B, 7)`` xyz + quaternion (w, x, y, z) or ``(B, 6)``
            xyz + roll-pitch-yaw (paper C: ``R = Rz(yaw) Ry(pitch) Rx(roll)``), metres and radians;
            a tensor, a numpy array or nested lists. A single pose ``(4, 4)``, ``(7,)`` or ``(6,)``
            is taken as B = 1. Non-tensor input and integer tensors become float64.
        representation: ``"matrix"``, ``"quat"``, ``"quat_xyzw"`` (xyz + quaternion (x, y, z, w), the order of ROS
            messages) or ``"rpy"``; None infers it from the shape (a row of 7 is ``"quat"``: w first).

    Returns:
        ``(B, 4, 4)`` floating-point poses (dtype and device of a floating tensor input).

    Warns:
        UserWarning: a roll, pitch or yaw beyond 2 pi (degrees given as radians?).

    Raises:
        ValueError: wrong shape, NaN/inf, a quaternion whose norm is 0 or further than
            :data:`QUAT_NORM_TOL` from 1, a non-orthonormal rotation; the message names the field and row.
    """
    if isinstance(T_target, torch.Tensor):
        T = T_target if T_target.is_floating_point() else T_target.to(torch.float64)
    else:
        try:
            T = torch.as_tensor(np.asarray(T_target, dtype=np.float64))
        except (TypeError, ValueError) as err:
            raise ValueError(f"{name}: expected numbers (poses), got {type(T_target).__name__}: {err}") from err
    if representation is None:
        representation = _representation(tuple(T.shape))
        if representation is None:
            raise ValueError(
                f"{name}: cannot tell the pose form from shape {tuple(T.shape)}; expected (B, 4, 4), "
                "(B, 7) xyz + quaternion (w, x, y, z) or (B, 6) xyz + roll-pitch-yaw"
            )
    if representation == "matrix":
        if T.ndim == 2 and T.shape == (4, 4):
            T = T.unsqueeze(0)
        if T.ndim != 3 or T.shape[-2:] != (4, 4):
            raise ValueError(f"{name}: expected shape (B, 4, 4) for 4x4 poses, got {tuple(T.shape)}")
        return validate_pose(T, name=name)
    if representation not in ("quat", "quat_xyzw", "rpy"):
        raise ValueError(
            f"{name}: representation must be 'matrix', 'quat', 'quat_xyzw' or 'rpy', got {representation!r}"
        )
    width = POSE_DIMS[representation]
    if T.ndim == 1:
        T = T.unsqueeze(0)
    if T.ndim != 2 or T.shape[-1] != width:
        raise ValueError(
            f"{name}: a {representation!r} pose has {width} numbers per row; expected shape (B, {width}), "
            f"got {tuple(T.shape)}"
        )
    order = "(x, y, z, w)" if representation == "quat_xyzw" else "(w, x, y, z)"
    if representation == "quat_xyzw":
        T, representation = xyzw_to_wxyz(T), "quat"
    fields = ("x, y, z", f"quaternion {order}" if representation == "quat" else "roll, pitch, yaw")
    for label, part in zip(fields, (T[:, :3], T[:, 3:]), strict=True):
        bad = ~torch.isfinite(part).all(dim=-1)
        if bool(bad.any()):
            raise ValueError(f"{name}: row {int(bad.nonzero()[0])}: {label} contains NaN or inf")
    p, rot = T[:, :3], T[:, 3:]
    if representation == "quat":
        norm = torch.linalg.vector_norm(rot, dim=-1)
        bad = (norm - 1).abs() > QUAT_NORM_TOL
        if bool(bad.any()):
            i = int(bad.nonzero()[0])
            raise ValueError(
                f"{name}: row {i}: quaternion {order} has norm {float(norm[i]):.6g}; "
                f"a unit quaternion is expected (norm within {QUAT_NORM_TOL:g} of 1 is normalised)"
            )
        R = quaternion_to_matrix(rot / norm[:, None])
    else:
        warn_degrees(rot, name=name, rpy=True, stacklevel=4)
        R = rpy_to_matrix(rot)
    return validate_pose(make_pose(R, p), name=name)


def _representation(shape: tuple) -> str | None:
    """The pose form a shape implies (``matrix``, ``quat``, ``rpy``), or None."""
    if len(shape) >= 2 and shape[-2:] == (4, 4):
        return "matrix"
    if len(shape) >= 1 and shape[-1] == POSE_DIMS["quat"]:
        return "quat"
    if len(shape) >= 1 and shape[-1] == POSE_DIMS["rpy"]:
        return "rpy"
    return None


_FLOATS = (torch.float64, torch.float32)


def pose_array(
    T_target, representation: str | None = None, *, name: str = "T_target"
) -> tuple[np.ndarray, torch.dtype]:
    """``(T: (B, 4, 4) float64 numpy, dtype of the answer)`` for CPU targets (see the module docstring).

    The answer's dtype is the input's for a float32 or float64 tensor, else float64. Raises what
    :func:`as_poses` raises (``name`` in its messages). A tensor not on the CPU is refused (``ValueError``): the
    compiled backend does not take it."""
    if isinstance(T_target, torch.Tensor):
        if T_target.device.type != "cpu":
            raise ValueError(f"pose_array: targets on {T_target.device}, expected the CPU")
        dtype = T_target.dtype if T_target.dtype in _FLOATS else torch.float64
        a = T_target.detach().numpy() if T_target.dtype in _FLOATS else None
    else:
        dtype = torch.float64
        try:
            a = np.asarray(T_target, dtype=np.float64)
        except (TypeError, ValueError):
            a = None
    T = None if a is None or _background.BUSY else _checked_poses(a, representation)  # BUSY: kernels compile
    if T is None:  # the torch checks word the error, or accept with a warning (degrees?)
        T = as_poses(T_target, representation, name=name).detach().to(torch.float64).numpy()
    return np.ascontiguousarray(T), dtype


_KP = None


def _pose_kernels():
    """:mod:`nik.kernels.poses`, imported on first use (``import nik`` does not import numba)."""
    global _KP
    if _KP is None:
        from nik.kernels import poses

        _KP = poses
    return _KP


def _checked_poses(a: np.ndarray, representation: str | None) -> np.ndarray | None:
    """``(B, 4, 4)`` float64 when ``a`` passes every check of :func:`as_poses` without a warning, else None."""
    kp = _pose_kernels()

    rep = representation if representation is not None else _representation(a.shape)
    if rep == "matrix":
        a = a[None] if a.ndim == 2 else a
        if a.ndim != 3 or a.shape[1:] != (4, 4) or a.shape[0] == 0:
            return None
    elif rep in ("quat", "quat_xyzw", "rpy"):
        a = a[None] if a.ndim == 1 else a
        if a.ndim != 2 or a.shape[1] != POSE_DIMS[rep] or a.shape[0] == 0:
            return None
        if rep == "quat_xyzw":
            a, rep = xyzw_to_wxyz(a), "quat"
        if rep == "rpy" and np.abs(a[:, 3:]).max() > DEGREES_SUSPECT:
            return None
    else:
        return None
    if a.dtype != np.float64 or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a, dtype=np.float64)
    if rep != "matrix":
        T = np.empty((a.shape[0], 4, 4))
        if not (kp.quat_poses(a, QUAT_NORM_TOL, T) if rep == "quat" else kp.rpy_poses(a, T)):
            return None
        a = T
    return a if kp.poses_ok(a, ORTHONORMAL_TOL) else None


def q_near_array(q_near, B: int, robot, *, name: str = "q_near") -> np.ndarray | None:
    """``q_near`` as ``(B, dof)`` float64 numpy for the compiled backend (None stays None); raises and warns as
    :func:`as_q_near` (``name`` in its messages: ``q_start`` of a path is checked here too)."""
    if q_near is None:
        return None
    dof = robot.dof
    a = None
    if isinstance(q_near, torch.Tensor):
        if q_near.device.type == "cpu" and q_near.is_floating_point():
            a = q_near.detach().numpy()
    else:
        try:
            a = np.asarray(q_near, dtype=np.float64)
        except (TypeError, ValueError):
            a = None
    if a is not None:
        if a.ndim == 1 and a.shape[0] == dof:
            a = np.broadcast_to(a, (B, dof))
        if a.shape != (B, dof) or not np.isfinite(a).all() or np.abs(a).max() > DEGREES_SUSPECT:
            a = None  # the torch checks word it (or warn about degrees)
    if a is None:
        probe = torch.empty(B, 4, 4, dtype=torch.float64)
        lim = robot.limits
        return as_q_near(q_near, probe, dof, prismatic=robot.prismatic, limits=lim, name=name).numpy().copy()
    return np.ascontiguousarray(a, dtype=np.float64)


def check_tolerances(tol_pos: float, tol_rot: float) -> None:
    """Raise ``ValueError`` unless both tolerances are numbers >= 0 (NaN and negatives are refused)."""
    for name, value, unit in (("tol_pos", tol_pos, "metres"), ("tol_rot", tol_rot, "radians")):
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected a number >= 0 ({unit}), got {value!r}") from None
        if math.isnan(v) or v < 0:
            raise ValueError(f"{name}: expected a number >= 0 ({unit}), got {value!r}")


def as_q_near(
    q_near,
    T: torch.Tensor,
    dof: int,
    *,
    prismatic: torch.Tensor | None = None,
    limits: torch.Tensor | None = None,
    name: str = "q_near",
) -> torch.Tensor | None:
    """``q_near`` (None, ``(dof,)`` or ``(B, dof)``, radians; a tensor, array or list) as ``(B, dof)`` in the
    dtype and device of ``T: (B, 4, 4)``; None stays None. Raises ``ValueError`` naming a bad shape or value;
    warns when a revolute joint (``prismatic: (dof,)`` marks the others) lies beyond 2 pi and outside its
    ``limits: (dof, 2)`` (degrees?)."""
    if q_near is None:
        return None
    B = T.shape[0]
    q = q_near if isinstance(q_near, torch.Tensor) else torch.as_tensor(np.asarray(q_near, dtype=np.float64))
    validate_joints(q, dof, name=name)
    warn_degrees(q, name=name, prismatic=prismatic, limits=limits, stacklevel=4)
    q = q.to(dtype=T.dtype, device=T.device)
    if q.ndim == 1:
        q = q.expand(B, -1)
    if q.shape != (B, dof):
        raise ValueError(f"{name}: expected shape ({dof},) or ({B}, {dof}), got {tuple(q.shape)}")
    return q
