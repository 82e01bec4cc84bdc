"""nik: learned inverse kinematics for robot arms.

robot -> FK -> dataset -> trained network -> swarm refinement -> result.
The public names are listed in ``__all__``; submodules (``nik.data``, ``nik.analytic``, ...)
are imported on first attribute access so that ``import nik`` stays light (it imports no torch).
So are the modules of every package of nik: after a plain ``import nik``, ``nik.collision.meshcheck.mesh_check``
works as the docs write it (:class:`_Package`), the module imported when the name is first read.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys
import types

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


class _Package(types.ModuleType):
    """The module type of nik's packages (``nik.collision``, ``nik.ik.backends``, ...): an attribute that is none of
    the package's names but one of its modules (``nik.collision.meshcheck``) imports that module on first read, as
    ``import nik.collision.meshcheck`` would. A package's own ``__getattr__`` (its lazy public names) is asked
    first. An import error inside the module is raised as it is (a missing optional dependency names itself)."""

    def __getattr__(self, name: str):
        if not name.startswith("__"):
            full = f"{self.__name__}.{name}"
            try:
                return importlib.import_module(full)
            except ModuleNotFoundError as err:
                if err.name != full:
                    raise
        raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")


class _PackageLoader(importlib.machinery.SourceFileLoader):
    """Loads a package of nik as a :class:`_Package` (its ``__init__.py`` runs as usual)."""

    def create_module(self, spec):
        return _Package(spec.name)


class _PackageFinder:
    """Finds nik's modules as Python's path finder does, giving its packages :class:`_PackageLoader` (first in
    ``sys.meta_path``; any other name is left to the finders after it)."""

    @staticmethod
    def find_spec(fullname, path=None, target=None):
        if not fullname.startswith(f"{__name__}.") or path is None:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        loader = getattr(spec, "loader", None)
        if (
            spec is not None
            and spec.submodule_search_locations is not None
            and type(loader) is (importlib.machinery.SourceFileLoader)
        ):
            spec.loader = _PackageLoader(loader.name, loader.path)
        return spec


if not any(isinstance(f, _PackageFinder) for f in sys.meta_path):
    sys.meta_path.insert(0, _PackageFinder())
