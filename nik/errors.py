"""Error classes of nik. All derive from ``ValueError`` so callers may catch either; and its warning classes."""

from __future__ import annotations


class NikError(ValueError):
    """Base class of every error nik raises on bad input."""


class RobotDefinitionError(NikError):
    """A robot name, file or definition is unknown or malformed."""


class DatasetError(NikError):
    """A dataset is missing, corrupt, or does not match the robot it is used with."""


class CheckpointError(NikError):
    """A checkpoint is missing, corrupt, or was made for another robot."""


class CheckpointNotFoundError(CheckpointError, FileNotFoundError):
    """A network or checkpoint file that does not exist: a :class:`CheckpointError` (as every load failure is) and a
    ``FileNotFoundError``, so callers catching either see it."""


class RobotDefinitionWarning(UserWarning):
    """A robot loaded, with a choice the user should know of (the default tool link of a URDF left a gripper
    out of the arm, or several links fitted)."""


class CollisionModelWarning(RobotDefinitionWarning):
    """A robot's collision model is an approximation (capsules along the links: no collision meshes known for it);
    the message says how to give radii or meshes."""
