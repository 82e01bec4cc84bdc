"""The points that draw an arm: its base, the origin of every joint frame and the tool, from FK.

Joint ``i`` of the normal form ``G_0 J_1 G_1 ... J_n G_n`` turns about the z axis of the frame
``F_i = G_0 J_1 G_1 ... G_{i-1}`` (:func:`nik.kinematics.chain_joint_frames`); its origin lies on the axis,
so it is fixed both in the link before the joint and in the link after it. A straight segment between the
origins of consecutive joint frames is therefore a rigid part of one link (of constant length, but for a
prismatic joint's travel): drawn as a capsule, a robot without meshes (DH, POE) still reads as an arm.
"""

from __future__ import annotations

import torch

from nik.kinematics import chain_joint_frames
from nik.poses import validate_joints

__all__ = ["arm_points"]


def arm_points(robot, q: torch.Tensor) -> torch.Tensor:
    """Points of the arm's polyline in the base frame, metres.

    Args:
        robot: a :class:`nik.Robot`.
        q: (..., dof) joint values (radians; metres for prismatic joints).

    Returns:
        ``(..., dof + 2, 3)`` float64: the base origin, the origin of each joint's frame (in chain order) and
        the tool point. Consecutive points may coincide (a DH frame on the previous joint's axis); drawers
        skip segments of zero length.
    """
    q = torch.as_tensor(q, dtype=torch.float64)
    validate_joints(q, robot.dof)
    batch = q.shape[:-1]
    flat = q.reshape(-1, robot.dof)
    T, _, points = chain_joint_frames(flat, robot.G, robot.offsets, prismatic=robot.prismatic_or_none)
    base = torch.zeros(flat.shape[0], 1, 3, dtype=torch.float64)
    out = torch.cat([base, points.transpose(1, 2), T[:, None, :, 3]], dim=1)
    return out.reshape(*batch, robot.dof + 2, 3)
