"""Where networks live, and which one an arm gets: the shipped folder and the user's folder, indexed by hash.

Two folders hold network pairs (:mod:`nik.nets.pair`):

1. the **user folder**: ``$NIK_HOME/networks`` when ``NIK_HOME`` is set, else
   ``$XDG_DATA_HOME/nik/networks`` (``~/.local/share/nik/networks``); ``nik train --install`` and
   :func:`install` copy networks there;
2. the **shipped folder** inside the package (``nik/nets/weights``).

:func:`find_network` picks, for a robot, the pair whose recorded ``robot_hash`` equals the robot's
definition hash (the name does not matter: the same arm loaded from its URDF under another name gets the
same network), else the definition hash of its bare arm (:attr:`nik.Robot.arm_hash`: base and tool frames left
out, so a robot with frames, such as the built-in ur5 and panda with their vendors' flanges, keeps its arm's
network; :func:`nik.nets.pair.load_pair` then builds it for the bare arm); the user folder comes first, so an
installed network replaces a shipped one for its arm. Within a folder a pair made for the robot itself wins over
one made for its bare arm, then a pair named after the robot, then the newest. The index reads only the JSON files
(a few kB each) and is cached per file (path, size, modification time).

Where no hash matches, :func:`find_same_arm` finds a pair made for the same arm under another definition: an arm
loaded from another file of the same robot (other link and joint names, float noise in the placements, another
normal form) or ending at another link a fixed transform away (a hand or TCP link past the network's flange):
compared by FK on a fixed set of configurations (:func:`nik.robots.frames.tool_between`), the difference of end
links given back as a tool frame.

A pair whose JSON says ``"role": "single_pose"`` is a small network made to guess poses cheaply on the CPU
(:mod:`nik.ik.plan`): :func:`find_network` never returns it; :func:`find_single_pose_network` finds it,
by the same rules.

:func:`list_networks`, :func:`install` and :func:`remove` are what ``nik networks`` calls: the pairs of both
folders with their arm, hash, kind and recorded error; a checked copy into the user folder; the removal of an
installed pair (never of a shipped one).
"""

from __future__ import annotations

import json
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from nik.errors import CheckpointError
from nik.nets.pair import pair_paths, read_pair_meta, recover_pairs, single_pose_companion, write_pair_files

__all__ = [
    "SHIPPED_DIR",
    "SINGLE_POSE",
    "NetworkInfo",
    "find_network",
    "find_same_arm",
    "find_single_pose_network",
    "index",
    "install",
    "list_networks",
    "remove",
    "role_of",
    "search_dirs",
    "user_dir",
]

#: The ``role`` of a small network for single poses.
SINGLE_POSE = "single_pose"

#: The networks shipped inside the package.
SHIPPED_DIR = Path(__file__).resolve().parent / "weights"

_CACHE: dict[Path, tuple[tuple[int, int], str | None, str | None]] = {}
_ARMS: dict[Path, tuple[tuple[int, int], object]] = {}


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
        if d != SHIPPED_DIR:
            recover_pairs(d)  # an install or removal killed half-way: finished or undone before anything is read
        for js in sorted(d.glob("*.json")):
            if js.name.startswith("."):  # staged by a replacement in progress (nik.nets.pair.write_pair_files)
                continue
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
    targets = [robot.definition_hash]
    if robot.arm is not robot:
        targets.append(robot.arm_hash)
    for d in search_dirs() if dirs is None else dirs:
        pairs = index([d])
        for st, h in pairs:
            if h is None and st.stem == robot.name:
                read_pair_meta(st)  # raises the one-line reason
        for target in targets:
            hits = [st for st, h in pairs if h == target and role_of(st) == role]
            if hits:
                hits.sort(key=lambda p: (p.stem != robot.name, -p.stat().st_mtime_ns))
                return hits[0]
    return None


def _stored_arm(js: Path):
    """The robot a pair's JSON records (``robot_definition``; cached per file), or None where unreadable."""
    from nik.robots.model import Robot

    try:
        st = js.stat()
        key = (st.st_size, st.st_mtime_ns)
        hit = _ARMS.get(js)
        if hit is not None and hit[0] == key:
            return hit[1]
        meta = json.loads(js.read_text())
        arm = Robot.from_definition(meta["robot_definition"])
        arm = arm if arm.definition_hash == meta.get("robot_hash") else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        key, arm = None, None
    if key is not None:
        _ARMS[js] = (key, arm)
    return arm


def find_same_arm(robot, dirs: list[Path] | None = None, *, role: str | None = None):
    """``(path, arm, tool)`` of a network made for the same arm as ``robot`` under another definition (module
    docstring): ``robot`` is ``arm`` (the network's, rebuilt from its JSON) followed by the fixed ``(4, 4)``
    ``tool``; None where there is none. ``role``: as :func:`find_single_pose_network` (None: the main network)."""
    from nik.robots.frames import tool_between

    for d in search_dirs() if dirs is None else dirs:
        for st, h in index([d]):
            if h is None or role_of(st) != role:
                continue
            arm = _stored_arm(st.with_suffix(".json"))
            if arm is None or arm.dof != robot.dof:
                continue
            tool = tool_between(robot, arm)
            if tool is not None:
                return st, arm, tool
    return None


def install(path: str | Path, *, name: str | None = None, directory: str | Path | None = None) -> Path:
    """Copy the pair at ``path`` into the user folder (or ``directory``) as ``<name>.safetensors`` + ``.json``
    (default name: the robot's recorded name), and the single-pose network it names beside it as ``<name>_one``
    (:func:`nik.nets.pair.single_pose_companion`); the copy is checked (:func:`nik.nets.pair.load_pair`) first and
    replaces an installed pair of that name so that a kill at any instant leaves the old or the new one whole
    (:func:`nik.nets.pair.write_pair_files`). Returns the installed ``.safetensors``."""
    from nik.nets.pair import load_pair

    st, js = pair_paths(path)
    meta = read_pair_meta(st)
    load_pair(st)  # never install a damaged file
    name = _plain_name(name or meta.get("robot") or st.stem, "install")
    d = Path(directory) if directory is not None else user_dir()
    d.mkdir(parents=True, exist_ok=True)
    one = single_pose_companion(st)
    text = js.read_text()
    if one is not None:  # its single-pose network goes with it, as <name>_one
        load_pair(one)
        meta["single_pose_network"] = f"{name}_one.safetensors"
        text = json.dumps(meta, indent=2) + "\n"
    # the bytes written are checked against the JSON's checksum again (the source may change after load_pair)
    out = write_pair_files(d / f"{name}.safetensors", st.read_bytes(), text)
    if one is not None:
        write_pair_files(d / f"{name}_one.safetensors", one.read_bytes(), one.with_suffix(".json").read_text())
    return out


@dataclass(frozen=True)
class NetworkInfo:
    """One pair of the user or the shipped folder, as :func:`list_networks` reads it from its JSON."""

    name: str  # the file name without suffix: what :func:`remove` takes
    robot: str  # the arm it was trained for (recorded name; matched by robot_hash, not by this)
    robot_hash: str  # definition hash of that arm ("" where the JSON is unreadable)
    kind: str  # net.kind: multihead | branch_heads | plain ...
    pos_mm: float | None  # recorded validation error, best hypothesis, median position (mm); None: not recorded
    rot_deg: float | None  # the same, rotation (deg)
    path: Path  # the .safetensors file
    where: str  # "installed" (user folder) | "shipped" (inside the package)
    problem: str = ""  # why the JSON cannot be read (a damaged pair is listed with it, not hidden)


def _info(st: Path, where: str) -> NetworkInfo:
    try:
        meta = read_pair_meta(st)
    except (CheckpointError, OSError) as err:
        return NetworkInfo(st.stem, "?", "", "?", None, None, st, where, problem=str(err).splitlines()[0])
    val = meta.get("validation") or {}
    net = meta.get("net") or {}

    def number(key: str) -> float | None:
        v = val.get(key)
        return float(v) if isinstance(v, (int, float)) else None

    return NetworkInfo(
        name=st.stem,
        robot=str(meta.get("robot", "?")),
        robot_hash=str(meta["robot_hash"]),
        kind=(str(net.get("kind", "?")) if isinstance(net, dict) else "?")
        + (" (single pose)" if meta.get("role") == SINGLE_POSE else ""),
        pos_mm=number("best_pos_mm_median"),
        rot_deg=number("best_rot_deg_median"),
        path=st,
        where=where,
    )


def list_networks() -> list[NetworkInfo]:
    """Every pair of the user folder (``installed``), then of the shipped folder (``shipped``), each sorted by
    name: the order :func:`find_network` searches them in."""
    return [
        _info(st, where) for where, d in (("installed", user_dir()), ("shipped", SHIPPED_DIR)) for st, _ in index([d])
    ]


def _plain_name(name: str, what: str) -> str:
    name = str(name)
    for suffix in (".safetensors", ".json"):
        name = name.removesuffix(suffix)
    if not name or Path(name).name != name or name.startswith("."):
        raise CheckpointError(f"{what}: the name must be a plain file name, got {name!r}")
    return name


def remove(name: str, *, directory: str | Path | None = None) -> list[Path]:
    """Delete the installed pair ``name`` (``NAME.safetensors`` + ``NAME.json``, either suffix accepted) from the
    user folder (or ``directory``); returns the files removed.

    Raises:
        CheckpointError: ``name`` is not a plain file name, or names a network shipped with nik (those are part of
            the package; an installed network for the same arm replaces one).
        FileNotFoundError: no installed pair of that name (the message lists the installed ones).
    """
    name = _plain_name(name, "remove")
    d = Path(directory) if directory is not None else user_dir()
    recover_pairs(d)
    files = [p for p in (d / f"{name}.safetensors", d / f"{name}.json") if p.is_file()]
    if not files:
        if (SHIPPED_DIR / f"{name}.json").is_file():
            raise CheckpointError(
                f"{name!r} is shipped with nik ({SHIPPED_DIR}), not installed: a shipped network cannot be removed "
                "(install another one for the same arm to replace it)"
            )
        have = sorted(st.stem for st, _ in index([d]))
        raise FileNotFoundError(f"no installed network {name!r} in {d} (installed: {', '.join(have) or 'none'})")
    # the JSON first, renamed to a name no run restores: from then on the pair is gone (a weights file without
    # its JSON is never listed), whatever instant a kill lands at
    js, doomed = d / f"{name}.json", d / f".{name}.del-{os.getpid()}-{secrets.token_hex(4)}.json"
    if js.is_file():
        os.rename(js, doomed)
    (d / f"{name}.safetensors").unlink(missing_ok=True)
    doomed.unlink(missing_ok=True)
    for p in files:
        _CACHE.pop(p, None)
    return files
