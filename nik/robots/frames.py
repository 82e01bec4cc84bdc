"""Base and tool (TCP) frames of an arm, folded into its normal form.

Every arm is ``T(q) = G_0 J_1 G_1 ... J_n G_n`` (:mod:`nik.kinematics`). A base frame ``B`` (the pose of
the arm's root in the user's frame) and a tool frame ``X`` (the tool centre point in the frame of the last
link, the flange) make it ``B T(q) X``: nik folds them into the first and last constant factors,
``G_0 <- B G_0`` and ``G_n <- G_n X``. So every consumer of the normal form, the torch FK, the compiled
kernels, the swarms, LM, the closed forms and their family detection, sees the frames with no change of
its own, and the definition hash (over ``G``) differs exactly when a frame is not the identity.

A frame is given as a ``(4, 4)`` homogeneous transform or a ``(7,)`` vector ``x, y, z`` (metres) and a
unit quaternion ``w, x, y, z``; anything else, a non-finite entry, a rotation that is not orthonormal or
a quaternion whose norm is not 1 is a ``ValueError`` of one line naming the frame.
"""

from __future__ import annotations

import numpy as np
import torch

from nik.errors import RobotDefinitionError
from nik.poses import ORTHONORMAL_TOL, quaternion_to_matrix, validate_pose

__all__ = ["QUATERNION_TOL", "SAME_ARM_TOL", "adopt_arm", "as_frame", "tool_between", "with_frames"]

#: Largest accepted ``| |quaternion| - 1 |`` (four decimals typed by hand); the quaternion is then normalised.
QUATERNION_TOL = 1e-3

#: Rotations that depart from orthonormal by more than this (but within the accepted ORTHONORMAL_TOL)
#: are projected onto the nearest rotation, so the stored frame is a rigid transform to float64 rounding.
_PROJECT_ABOVE = 1e-12

#: Largest difference (metres, and entries of the rotation) between two arms' poses, on every configuration of
#: :func:`tool_between`'s fixed set, for them to count as the same arm: far above the float noise of equivalent
#: files (1e-9: the panda of example-robot-data against the built-in one), far below any real difference.
SAME_ARM_TOL = 1e-6

#: How many fixed configurations (seeded, uniform within the limits) :func:`tool_between` compares FK on.
_SAME_ARM_CONFIGS = 16


def as_frame(value, *, name: str = "tool") -> np.ndarray | None:
    """``value``, a ``(4, 4)`` transform or ``(7,)`` xyz + quaternion (w, x, y, z), metres -> ``(4, 4)`` float64.

    None stays None. Raises :class:`nik.RobotDefinitionError` (a ``ValueError``) naming ``name`` when the
    value is not a finite rigid transform.
    """
    if value is None:
        return None
    try:
        if isinstance(value, torch.Tensor):
            value = value.detach().cpu().double().numpy()
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise RobotDefinitionError(
            f"{name}: expected a (4, 4) transform or (7,) x y z qw qx qy qz, got {value!r}"
        ) from err
    if a.shape == (7,):
        if not np.isfinite(a).all():
            raise RobotDefinitionError(f"{name}: contains NaN or inf ({a.tolist()})")
        norm = float(np.linalg.norm(a[3:]))
        if abs(norm - 1.0) > QUATERNION_TOL:
            raise RobotDefinitionError(
                f"{name}: quaternion (w, x, y, z) {a[3:].tolist()} has norm {norm:.6g}, expected 1"
            )
        T = np.eye(4)
        T[:3, :3] = quaternion_to_matrix(torch.from_numpy(a[3:] / norm)).numpy()
        T[:3, 3] = a[:3]
        return T
    if a.shape != (4, 4):
        raise RobotDefinitionError(
            f"{name}: expected a (4, 4) transform or (7,) x y z qw qx qy qz (metres), got shape {a.shape}"
        )
    try:
        validate_pose(torch.from_numpy(a), name=name, tol=ORTHONORMAL_TOL)
    except ValueError as err:
        raise RobotDefinitionError(str(err).replace("pose 0", "the frame")) from None
    R = a[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > _PROJECT_ABOVE:
        u, _, vt = np.linalg.svd(R)
        a[:3, :3] = u @ vt
    a[3] = (0.0, 0.0, 0.0, 1.0)
    return a


def with_frames(robot, *, base=None, tool=None):
    """A copy of ``robot`` whose FK is ``base @ robot.fk(q) @ tool`` (each frame as in :func:`as_frame`).

    None (or absent) leaves that side as it is; with neither, ``robot`` itself is returned. The frames are
    folded into ``G`` (module docstring) and recorded, composed with any the robot already had, in
    :attr:`Robot.base` / :attr:`Robot.tool`.
    """
    B, X = as_frame(base, name="base"), as_frame(tool, name="tool")
    if B is None and X is None:
        return robot
    from nik.robots.model import Robot

    G = robot.G.numpy().copy()
    if B is not None:
        G[0] = B @ G[0]
    if X is not None:
        G[-1] = G[-1] @ X
    out = Robot(
        robot.name,
        G,
        robot.offsets,
        robot.limits,
        robot.joint_names,
        end_link=robot.end_link,
        source=robot.source,
        prismatic=robot.prismatic,
        vel_limits=robot.vel_limits,
        acc_limits=robot.acc_limits,
    )
    out.flange_link, out.flange = robot.flange_link, robot.flange
    out.base = _compose(B, robot.base, left=True)
    out.tool = _compose(X, robot.tool, left=False)
    out._arm = robot.arm  # the exact bare arm (its hash matches its networks: Robot.arm_hash)
    for key in ("srdf", "joint_values"):  # the rest of the robot (nik.robots.urdf.set_surroundings)
        if key in robot.__dict__:
            setattr(out, key, robot.__dict__[key])
    return out


def _compose(new: np.ndarray | None, old: torch.Tensor | None, *, left: bool) -> torch.Tensor | None:
    if new is None:
        return old
    if old is None:
        return torch.from_numpy(new)
    old = old.numpy()
    return torch.from_numpy(new @ old if left else old @ new)


def tool_between(robot, arm, *, tol: float = SAME_ARM_TOL) -> np.ndarray | None:
    """The fixed ``(4, 4)`` transform ``X`` with ``robot.fk(q) == arm.fk(q) @ X`` for every ``q``, or None where
    ``robot`` is not ``arm`` with a tool (other joints, types, limits or placements, or another base): the same arm
    whatever file, names or normal form it came from. Compared by FK on a fixed, seeded set of configurations
    within the limits (within ``tol``: float noise of equivalent files passes); ``X`` from the first of them."""
    if robot.dof != arm.dof or not torch.equal(robot.prismatic, arm.prismatic):
        return None
    if float((robot.limits - arm.limits).abs().max()) > tol:
        return None
    q = robot.sample(_SAME_ARM_CONFIGS, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    mine, theirs = robot.fk(q).numpy(), arm.fk(q).numpy()
    X = np.linalg.inv(theirs[0]) @ mine[0]
    X[3] = (0.0, 0.0, 0.0, 1.0)
    if np.abs(theirs @ X - mine).max() > tol:
        return None
    return X


def adopt_arm(robot, arm, tool: np.ndarray) -> None:
    """Record that ``robot`` (a robot without frames of its own) is ``arm`` with the tool frame ``tool``
    (:func:`tool_between`): :attr:`Robot.tool` becomes ``tool`` and :attr:`Robot.arm` becomes ``arm``, so the
    networks made for ``arm`` serve ``robot`` in the arm's frame. ``G`` (its FK and definition hash) is unchanged."""
    if robot.base is not None or robot.tool is not None:
        raise ValueError(f"robot {robot.name!r} has frames of its own; adopt_arm takes a bare robot")
    robot.tool = torch.as_tensor(tool, dtype=torch.float64).clone()
    robot._arm = arm
