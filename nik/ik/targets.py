"""Targets as the solver takes them: poses in any accepted form brought to ``(B, 4, 4)``, ``q_near`` brought
to ``(B, dof)``, and tolerances checked."""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.poses import (
    POSE_DIMS,
    make_pose,
    quaternion_to_matrix,
    rpy_to_matrix,
    validate_joints,
    validate_pose,
    warn_degrees,
)

__all__ = ["QUAT_NORM_TOL", "as_poses", "as_q_near", "check_tolerances"]

#: Largest accepted deviation of a quaternion's norm from 1; nearer ones are normalised.
QUAT_NORM_TOL = 1e-2


def as_poses(T_target, representation: str | None = None, *, name: str = "T_target") -> torch.Tensor:
    """Bring targets to ``(B, 4, 4)`` homogeneous poses, validated.

    Args:
        T_target: ``(B, 4, 4)`` matrices, ``(B, 7)`` xyz + quaternion (w, x, y, z) or ``(B, 6)``
            xyz + roll-pitch-yaw (paper C: ``R = Rz(yaw) Ry(pitch) Rx(roll)``), metres and radians;
            a tensor, a numpy array or nested lists. A single pose ``(4, 4)``, ``(7,)`` or ``(6,)``
            is taken as B = 1. Non-tensor input and integer tensors become float64.
        representation: ``"matrix"``, ``"quat"`` or ``"rpy"``; None infers it from the shape.

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
        if T.ndim >= 2 and T.shape[-2:] == (4, 4):
            representation = "matrix"
        elif T.ndim >= 1 and T.shape[-1] == POSE_DIMS["quat"]:
            representation = "quat"
        elif T.ndim >= 1 and T.shape[-1] == POSE_DIMS["rpy"]:
            representation = "rpy"
        else:
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
    if representation not in ("quat", "rpy"):
        raise ValueError(f"{name}: representation must be 'matrix', 'quat' or 'rpy', got {representation!r}")
    width = POSE_DIMS[representation]
    if T.ndim == 1:
        T = T.unsqueeze(0)
    if T.ndim != 2 or T.shape[-1] != width:
        raise ValueError(
            f"{name}: a {representation!r} pose has {width} numbers per row; expected shape (B, {width}), "
            f"got {tuple(T.shape)}"
        )
    fields = ("x, y, z", "quaternion (w, x, y, z)" if representation == "quat" else "roll, pitch, yaw")
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
                f"{name}: row {i}: quaternion (w, x, y, z) has norm {float(norm[i]):.6g}; "
                f"a unit quaternion is expected (norm within {QUAT_NORM_TOL:g} of 1 is normalised)"
            )
        R = quaternion_to_matrix(rot / norm[:, None])
    else:
        warn_degrees(rot, name=name, rpy=True, stacklevel=4)
        R = rpy_to_matrix(rot)
    return validate_pose(make_pose(R, p), name=name)


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
    q_near, T: torch.Tensor, dof: int, *, prismatic: torch.Tensor | None = None, limits: torch.Tensor | None = None
) -> torch.Tensor | None:
    """``q_near`` (None, ``(dof,)`` or ``(B, dof)``, radians; a tensor, array or list) as ``(B, dof)`` in the
    dtype and device of ``T: (B, 4, 4)``; None stays None. Raises ``ValueError`` naming a bad shape or value;
    warns when a revolute joint (``prismatic: (dof,)`` marks the others) lies beyond 2 pi and outside its
    ``limits: (dof, 2)`` (degrees?)."""
    if q_near is None:
        return None
    B = T.shape[0]
    q = q_near if isinstance(q_near, torch.Tensor) else torch.as_tensor(np.asarray(q_near, dtype=np.float64))
    validate_joints(q, dof, name="q_near")
    warn_degrees(q, name="q_near", prismatic=prismatic, limits=limits, stacklevel=4)
    q = q.to(dtype=T.dtype, device=T.device)
    if q.ndim == 1:
        q = q.expand(B, -1)
    if q.shape != (B, dof):
        raise ValueError(f"q_near: expected shape ({dof},) or ({B}, {dof}), got {tuple(q.shape)}")
    return q
