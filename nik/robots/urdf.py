"""URDF arms through pytorch-kinematics (the only module of nik that imports it).

pytorch-kinematics parses the file and gives the serial chain from the root to the tool
link; nik then converts that chain once into its own FK normal form, so a URDF arm runs
on nik's FK like any other.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import re
from pathlib import Path

import numpy as np
import torch

from nik.errors import RobotDefinitionError
from nik.poses import rpy_to_matrix
from nik.robots.model import NormalFormBuilder, Robot

__all__ = ["URDF_CACHE_FORMAT", "load_urdf", "default_end_link", "build_pk_chain"]

#: Version of the cached parse results (bump when the conversion to the normal form changes).
URDF_CACHE_FORMAT = 1


_XML_DECLARATION = re.compile(r"^\s*<\?xml[^>]*\?>")


def _no_declaration(text: str) -> str:
    """``text`` without a leading ``<?xml ... encoding=...?>``: lxml refuses str input that declares an encoding."""
    return _XML_DECLARATION.sub("", text, count=1)


def _parse_chain(text: str, source: str):
    import pytorch_kinematics as pk

    text = _no_declaration(text)

    try:
        with contextlib.redirect_stderr(io.StringIO()):  # the parser prints notes on unknown tags
            return pk.build_chain_from_urdf(text)
    except Exception as err:
        raise RobotDefinitionError(f"{source}: not a readable URDF ({type(err).__name__}: {err})") from err


def default_end_link(text: str, source: str = "URDF") -> str:
    """The child link of the last joint of the longest chain of revolute joints (first found on ties)."""
    chain = _parse_chain(text, source)
    best = (0, None)

    def visit(frame, count):
        nonlocal best
        if frame.joint.joint_type == "revolute":
            count += 1
            if count > best[0]:
                best = (count, frame.link.name)
        for child in frame.children:
            visit(child, count)

    visit(chain._root, 0)
    if best[1] is None:
        raise RobotDefinitionError(f"{source}: has no revolute joints")
    return best[1]


def build_pk_chain(text: str, end_link: str, root_link: str = ""):
    """pytorch-kinematics ``SerialChain`` from the root (or ``root_link``) to ``end_link``."""
    import pytorch_kinematics as pk

    with contextlib.redirect_stderr(io.StringIO()):
        return pk.build_serial_chain_from_urdf(_no_declaration(text), end_link, root_link)


def load_urdf(
    path: str | Path,
    *,
    end_link: str | None = None,
    root_link: str | None = None,
    name: str | None = None,
    origins: str = "pk",
) -> Robot:
    """Load a serial arm of revolute and prismatic joints from a URDF file.

    Args:
        path: the ``.urdf`` file.
        end_link: the tool link; default :func:`default_end_link`.
        root_link: the base link; default the URDF's root.
        name: robot name; default the URDF's ``<robot name>``.

        origins: where the fixed joint transforms come from. ``"pk"`` (default): the transforms
            pytorch-kinematics parsed, so nik and pytorch-kinematics agree to machine precision on
            the same file. pytorch-kinematics converts ``rpy`` through float32, so those transforms
            carry errors up to about 1e-7 (0.1 micrometre, 1e-7 rad) for angles such as pi/2;
            ``"float64"`` recomputes every ``<origin>`` from the file in float64 (exact FK, which then
            differs from pytorch-kinematics' by that much).

    Continuous joints get limits [-pi, pi]. A prismatic joint between base and tool becomes a
    prismatic joint of the robot (its value in metres along its axis, limits from the file, which
    must give them); fixed joints are merged into the constant transforms.

    The result is kept in nik's user cache folder (``$XDG_CACHE_HOME/nik/robots``, default
    ``~/.cache/nik/robots``) under the SHA-256 of the file's text, these arguments, the installed
    pytorch-kinematics and :data:`URDF_CACHE_FORMAT`, with a checksum verified on load: importing
    pytorch-kinematics and parsing cost about half a second, reading the cached normal form a millisecond.
    An unwritable cache folder only means parsing every time.
    """
    if origins not in ("pk", "float64"):
        raise ValueError(f"origins must be 'pk' or 'float64', got {origins!r}")
    path = Path(path)
    if not path.is_file():
        raise RobotDefinitionError(f"URDF file not found: {path}")
    text = path.read_text()
    key = _cache_key(text, end_link, root_link, name, origins)
    robot = _cached_robot(key, path)
    if robot is None:
        robot = _parse_robot(path, text, end_link, root_link, name, origins)
        _store_robot(key, robot)
    return robot


def _parse_robot(path: Path, text: str, end_link, root_link, name, origins) -> Robot:
    """:func:`load_urdf` without the cache: pytorch-kinematics parses ``text``, nik builds the normal form."""
    chain = _parse_chain(text, str(path))
    end_link = end_link or default_end_link(text, str(path))
    links = {f.link.name for f in _frames(chain._root)}
    for role, link in (("end_link", end_link), ("root_link", root_link)):
        if link is not None and link not in links:
            raise RobotDefinitionError(f"{path}: {role} {link!r} is not a link of this URDF (links: {sorted(links)})")
    try:
        serial = build_pk_chain(text, end_link, root_link or "")
    except Exception as err:
        raise RobotDefinitionError(f"{path}: cannot build a chain to {end_link!r}: {err}") from err

    urdf = _parse_urdf(text) if origins == "float64" else None
    builder = NormalFormBuilder()
    names, limits = [], []
    for frame in serial._serial_frames[1:]:
        if urdf is not None:
            joint = urdf.joint_map[frame.joint.name]
            builder.fixed(_origin_matrix(joint.origin))
        else:
            for offset in (frame.link.offset, frame.joint.offset):
                if offset is not None:
                    builder.fixed(offset.get_matrix()[0].double().numpy())
        jtype = frame.joint.joint_type
        if jtype in ("revolute", "prismatic"):
            axis = frame.joint.axis.double().numpy() if urdf is None else _axis(urdf.joint_map[frame.joint.name])
            builder.joint(axis, prismatic=jtype == "prismatic")
            names.append(frame.joint.name)
            lim = frame.joint.limits
            if lim is None or lim[0] >= lim[1]:
                if jtype == "prismatic":
                    raise RobotDefinitionError(
                        f"{path}: prismatic joint {frame.joint.name!r} needs <limit lower=... upper=...> "
                        "with lower < upper (metres)"
                    )
                limits.append([-math.pi, math.pi])
            else:
                limits.append([float(lim[0]), float(lim[1])])
    if not names:
        raise RobotDefinitionError(f"{path}: no revolute or prismatic joint between the root and {end_link!r}")
    if name is None:
        m = re.search(r'<robot[^>]*\bname\s*=\s*"([^"]+)"', text)
        name = m.group(1) if m else path.stem
    return Robot(
        name,
        builder.finish(),
        np.zeros(len(names)),
        np.array(limits),
        names,
        end_link=end_link,
        source=str(path),
        prismatic=builder.prismatic,
    )


# ---------------------------------------------------------------------------
# the cache of parsed arms
# ---------------------------------------------------------------------------
def _cache_key(text: str, end_link, root_link, name, origins) -> str:
    import importlib.util

    spec = importlib.util.find_spec("pytorch_kinematics")
    stamp = ""
    if spec is not None and spec.origin:  # a reinstalled pytorch-kinematics is a new key
        st = os.stat(spec.origin)
        stamp = f"{spec.origin}:{st.st_size}:{st.st_mtime_ns}"
    h = hashlib.sha256(text.encode())
    h.update(json.dumps([end_link, root_link, name, origins, URDF_CACHE_FORMAT, stamp]).encode())
    return h.hexdigest()


def _cache_file(key: str) -> Path:
    from nik.kernels.cache import cache_home

    return cache_home() / "robots" / f"{key[:32]}.json"


def _cached_robot(key: str, path: Path) -> Robot | None:
    """The robot stored under ``key`` (its ``source`` set to ``path``), or None when absent, unreadable or its
    checksum or key does not match."""
    try:
        doc = json.loads(_cache_file(key).read_text())
        body = json.dumps(doc["robot"], sort_keys=True)
        if doc.get("key") != key or doc.get("sha256") != hashlib.sha256(body.encode()).hexdigest():
            return None
        d = doc["robot"]
        return Robot(
            d["name"],
            np.asarray(d["G"], dtype=np.float64),
            d["offsets"],
            d["limits"],
            d["joint_names"],
            end_link=d.get("end_link"),
            source=str(path),
            prismatic=d.get("prismatic"),
        )
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _store_robot(key: str, robot: Robot) -> None:
    """Write ``robot``'s definition under ``key`` (temporary name, then rename); silently skipped when the
    folder is not writable."""
    d = robot.to_definition()
    body = json.dumps(d, sort_keys=True)
    doc = {"format": URDF_CACHE_FORMAT, "key": key, "sha256": hashlib.sha256(body.encode()).hexdigest(), "robot": d}
    target = _cache_file(key)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(doc))
        tmp.replace(target)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()


def _parse_urdf(text: str):
    from pytorch_kinematics.urdf_parser_py.urdf import URDF

    with contextlib.redirect_stderr(io.StringIO()):
        return URDF.from_xml_string(_no_declaration(text))


def _axis(joint) -> np.ndarray:
    return np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=float)


def _origin_matrix(origin) -> np.ndarray:
    """URDF ``<origin xyz rpy>`` -> 4x4 float64: translation, then R = Rz(yaw) Ry(pitch) Rx(roll)."""
    T = np.eye(4)
    if origin is None:
        return T
    if origin.rpy is not None:
        T[:3, :3] = rpy_to_matrix(torch.tensor(origin.rpy, dtype=torch.float64)).numpy()
    if origin.xyz is not None:
        T[:3, 3] = origin.xyz
    return T


def _frames(root):
    yield root
    for child in root.children:
        yield from _frames(child)
