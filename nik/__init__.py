"""nik: learned inverse kinematics for robot arms.

robot -> FK -> dataset -> trained network -> swarm refinement -> result.
The public names are listed in ``__all__``; submodules (``nik.data``, ``nik.analytic``, ...)
are imported on first attribute access so that ``import nik`` stays light (it imports no torch).
"""

from __future__ import annotations

import importlib

from nik.errors import (
    CheckpointError,
    CollisionModelWarning,
    DatasetError,
    NikError,
    RobotDefinitionError,
    RobotDefinitionWarning,
)

__version__ = "0.1.0"

_SUBMODULES = {
    "analytic",
    "cli",
    "collision",
    "costs",
    "data",
    "evaluate",
    "ik",
    "kernels",
    "kinematics",
    "learn",
    "lm",
    "models",
    "paths",
    "nets",
    "poses",
    "robots",
    "swarm",
    "threads",
    "tolerances",
    "view",
}
# torch is imported with the first of these, not by ``import nik`` (``nik --help`` stays light)
_LAZY = {
    "IKSolver": "nik.solver",
    "World": "nik.collision",
    "IKResult": "nik.ik",
    "set_threads": "nik.threads",
    "pose_error": "nik.poses",
    "Robot": "nik.robots",
    "builtin_robots": "nik.robots",
    "load_robot": "nik.robots",
}

__all__ = [
    "CheckpointError",
    "CollisionModelWarning",
    "DatasetError",
    "IKResult",
    "IKSolver",
    "NikError",
    "Robot",
    "RobotDefinitionError",
    "RobotDefinitionWarning",
    "World",
    "__version__",
    "builtin_robots",
    "load_robot",
    "pose_error",
    "set_threads",
    *sorted(_SUBMODULES),
]


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"nik.{name}")
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'nik' has no attribute {name!r}")
