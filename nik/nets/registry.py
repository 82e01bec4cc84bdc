"""Where networks live, and which one an arm gets: the shipped folder and the user's folder, indexed by hash.

Two folders hold network pairs (:mod:`nik.nets.pair`):

1. the **user folder**: ``$NIK_HOME/networks`` when ``NIK_HOME`` is set, else
   ``$XDG_DATA_HOME/nik/networks`` (``~/.local/share/nik/networks``); ``nik train --install`` and
   :func:`install` copy networks there;
2. the **shipped folder** inside the package (``nik/nets/weights``).

:func:`find_network` picks, for a robot, the pair whose recorded ``robot_hash`` equals the robot's
definition hash (the name does not matter: the same arm loaded from its URDF under another name gets the
same network); the user folder comes first, so an installed network replaces a shipped one for its arm.
Within a folder a pair named after the robot wins, then the newest. The index reads only the JSON files
(a few kB each) and is cached per file (path, size, modification time).

A pair whose JSON says ``"role": "single_pose"`` is a small network made to guess one or a few poses cheaply
(:mod:`nik.ik.networks`): :func:`find_network` never returns it; :func:`find_single_pose_network` finds it, by the
same rules.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from nik.errors import CheckpointError
from nik.nets.pair import pair_paths, read_pair_meta

__all__ = ["SHIPPED_DIR", "SINGLE_POSE", "find_network", "find_single_pose_network", "index", "install", "role_of",
           "search_dirs", "user_dir"]

#: The ``role`` of a small network for single poses.
SINGLE_POSE = "single_pose"

#: The networks shipped inside the package.
SHIPPED_DIR = Path(__file__).resolve().parent / "weights"

_CACHE: dict[Path, tuple[tuple[int, int], str | None, str | None]] = {}


def user_dir() -> Path:
    """The user's network folder (module docstring); not created here."""
    home = os.environ.get("NIK_HOME")
    if home:
        return Path(home).expanduser() / "networks"
    data = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(data).expanduser() / "nik" / "networks"


def search_dirs() -> list[Path]:
    """The folders searched for networks, first match wins: the user folder, then the shipped one."""
    return [user_dir(), SHIPPED_DIR]


def _facts_of(js: Path) -> tuple[str | None, str | None]:
    """``(robot_hash, role)`` recorded in ``js`` (cached); None for what the JSON does not say or cannot be read."""
    try:
        st = js.stat()
    except OSError:
        return None, None
    key = (st.st_size, st.st_mtime_ns)
    hit = _CACHE.get(js)
    if hit is not None and hit[0] == key:
        return hit[1], hit[2]
    try:
        meta = json.loads(js.read_text())
        value, role = meta.get("robot_hash"), meta.get("role")
        value = value if isinstance(value, str) else None
        role = role if isinstance(role, str) else None
    except (OSError, ValueError, AttributeError):
        value, role = None, None
    _CACHE[js] = (key, value, role)
    return value, role


def _hash_of(js: Path) -> str | None:
    """The ``robot_hash`` recorded in ``js`` (cached), or None where the JSON is unreadable."""
    return _facts_of(js)[0]


def role_of(path: Path) -> str | None:
    """The ``role`` a pair's JSON records (``"single_pose"`` or None)."""
    return _facts_of(Path(path).with_suffix(".json"))[1]


def index(dirs: list[Path] | None = None) -> list[tuple[Path, str | None]]:
    """Every pair in ``dirs`` (default :func:`search_dirs`), in search order: ``(NAME.safetensors, robot_hash)``;
    the hash is None where the JSON cannot be read."""
    out = []
    for d in search_dirs() if dirs is None else dirs:
        if not d.is_dir():
            continue
        for js in sorted(d.glob("*.json")):
            st = js.with_suffix(".safetensors")
            if st.exists():
                out.append((st, _hash_of(js)))
    return out


def find_network(robot, dirs: list[Path] | None = None) -> Path | None:
    """The ``.safetensors`` of the network for ``robot`` (module docstring), or None.

    Raises:
        CheckpointError: the JSON of a pair named after the robot is unreadable (a damaged file is said,
            not skipped); other unreadable JSONs are skipped.
    """
    return _find(robot, dirs, None)


def find_single_pose_network(robot, dirs: list[Path] | None = None) -> Path | None:
    """The ``.safetensors`` of the single-pose network (``"role": "single_pose"``) for ``robot``, or None."""
    return _find(robot, dirs, SINGLE_POSE)


def _find(robot, dirs, role) -> Path | None:
    target = robot.definition_hash
    for d in search_dirs() if dirs is None else dirs:
        pairs = index([d])
        hits = [st for st, h in pairs if h == target and role_of(st) == role]
        for st, h in pairs:
            if h is None and st.stem == robot.name:
                read_pair_meta(st)  # raises the one-line reason
        if hits:
            hits.sort(key=lambda p: (p.stem != robot.name, -p.stat().st_mtime_ns))
            return hits[0]
    return None


def install(path: str | Path, *, name: str | None = None, directory: str | Path | None = None) -> Path:
    """Copy the pair at ``path`` into the user folder (or ``directory``) as ``<name>.safetensors`` + ``.json``
    (default name: the robot's recorded name); the copy is checked (:func:`nik.nets.pair.load_pair`) first.
    Returns the installed ``.safetensors``."""
    from nik.nets.pair import load_pair

    st, js = pair_paths(path)
    meta = read_pair_meta(st)
    load_pair(st)  # never install a damaged file
    name = name or meta.get("robot") or st.stem
    if not name or Path(name).name != name:
        raise CheckpointError(f"install: the name must be a plain file name, got {name!r}")
    d = Path(directory) if directory is not None else user_dir()
    d.mkdir(parents=True, exist_ok=True)
    dst_st, dst_js = d / f"{name}.safetensors", d / f"{name}.json"
    for src, dst in ((st, dst_st), (js, dst_js)):
        tmp = dst.with_name(f".{dst.name}.tmp{os.getpid()}")
        shutil.copyfile(src, tmp)
        tmp.replace(dst)
    return dst_st
