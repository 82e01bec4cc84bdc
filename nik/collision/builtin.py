"""The built-in arms' shipped collision models: spheres fitted to their vendors' collision meshes.

``configs/robots/collision/NAME.collision.json`` holds, for the built-ins ``panda``, ``ur5`` and ``xarm7``, spheres
fitted to example-robot-data's collision meshes of the same arm (``benchmarks/collision_builtin_fit.py`` writes
them; sources, licences, sphere counts and overreach in that folder's README and docs/collisions.md). Nothing is
fitted or downloaded at run time: the files are read from the package, checked against their SHA-256
(:data:`CHECKSUMS`; a changed file is refused with one line), and matched to a robot by its arm's frames
(choice): the robot's frames after each joint, base and tool frames left out (:func:`frames_key`), so the
built-in with another end link, a tool or a base keeps its model, and a URDF of the same arm with float noise
does not (it has its own geometry, or capsules). A robot with a base gets the model's base-link spheres moved
by it (nik's frame 0 is the world frame; the others already carry the base).

``kuka_kr`` and ``puma560`` have no vendor meshes here (example-robot-data has neither): they keep capsules, and
:func:`nik.collision.collision_model` says so in a :class:`nik.errors.CollisionModelWarning` once per robot.

:func:`erd_path` finds a file of example-robot-data (``pip install -e ".[urdf-tests]"``) or gives None; the mesh
check (:mod:`nik.collision.meshcheck`) uses it for a model whose source is ``"example-robot-data:REL"``.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

__all__ = ["BUILTIN_MESHES", "CHECKSUMS", "MODEL_DIR", "builtin_model_data", "erd_path", "frames_key"]


def _model_dir() -> Path:
    from nik.robots.config import BUILTIN_DIR

    return BUILTIN_DIR / "collision"


#: where the shipped models are
MODEL_DIR = _model_dir()

#: built-in name -> (URDF, SRDF) inside example-robot-data's ``robots`` folder, the meshes they were fitted to
BUILTIN_MESHES = {
    "panda": ("panda_description/urdf/panda.urdf", "panda_description/srdf/panda.srdf"),
    "ur5": ("ur_description/urdf/ur5_joint_limited_robot.urdf", "ur_description/srdf/ur5_joint_limited_robot.srdf"),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "xarm_description/srdf/xarm7.srdf"),
}

#: SHA-256 of each shipped file (``benchmarks/collision_builtin_fit.py`` prints them)
CHECKSUMS = {
    "panda": "42887410091c8d80c51d958318b5012e649f3d5e9b077462c8c099380686d741",
    "ur5": "9f5534e289d54fae985ef62d4477fc9df5ba610373e9d48519194f25ad686bde",
    "xarm7": "2c2dc805aefec117833dec0e94d76b4e508fb45fa9638367c6046623c4da5eb8",
}


def erd_path(rel: str) -> Path | None:
    """``rel`` inside example-robot-data's ``robots`` folder, or None where that package (or file) is missing. The
    folder is looked up once per process (:func:`_erd_robots`: the package metadata scan took ~130 us, on every
    solve with a mesh verdict); the file's existence every call."""
    root = _erd_robots()
    if root is None:
        return None
    path = root / rel
    return path if path.is_file() else None


@functools.cache
def _erd_robots() -> Path | None:
    """example-robot-data's ``robots`` folder, or None where the package is not installed (looked up once: a package
    installed later in the same process is not seen)."""
    import importlib.metadata

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def frames_key(robot) -> str:
    """Hash of ``robot``'s frames after each joint without base and tool: ``G[0..dof-1]`` of its bare arm, the
    offsets and the joint types (rounded to 1e-9)."""
    arm = robot.arm
    h = hashlib.sha256()
    for arr in (arm.G.numpy()[:-1], arm.offsets.numpy()):
        h.update((np.round(arr, 9) + 0.0).astype("<f8").tobytes())
    h.update(arm.prismatic.numpy().astype("u1").tobytes())
    return h.hexdigest()[:16]


_SHIPPED: dict[str, dict | None] = {}


def _shipped(name: str) -> dict | None:
    """The shipped model ``name`` as its file's JSON (checked), memoised; None where the file is absent."""
    if name not in _SHIPPED:
        path = MODEL_DIR / f"{name}.collision.json"
        if not path.is_file():
            _SHIPPED[name] = None
        else:
            data = path.read_bytes()
            digest = hashlib.sha256(data).hexdigest()
            if digest != CHECKSUMS.get(name):
                raise ValueError(
                    f"shipped collision model {path}: checksum {digest[:16]}... is not the one recorded "
                    f"({CHECKSUMS.get(name, '')[:16]}...); reinstall nik or rerun benchmarks/collision_builtin_fit.py"
                )
            _SHIPPED[name] = json.loads(data)
    return _SHIPPED[name]


def builtin_model_data(robot) -> tuple[str, dict] | None:
    """``(name, JSON)`` of the shipped model of ``robot``'s arm (matched by :func:`frames_key`), or None;
    :func:`nik.collision.collision_model` makes it ``robot``'s (its hash; base-link spheres moved by its base)."""
    key = frames_key(robot)
    for name in CHECKSUMS:
        data = _shipped(name)
        if data is not None and (data.get("options") or {}).get("frames_key") == key:
            return name, data
    return None
