"""URDF arms through pytorch-kinematics (the only module of nik that imports it).

A URDF file holds much that kinematics never reads (visuals, materials, textures, collisions, inertias,
transmissions, gazebo and sensor tags) and pytorch-kinematics' parser rejects a file if any of that is
incomplete, or if the file opens with an XML declaration naming its encoding. So nik first reduces the file to
its kinematics (:func:`kinematic_urdf`: ``<robot name>``, ``<link name>`` and each joint's type, origin, axis,
parent, child and limit), read from bytes by the standard XML parser; pytorch-kinematics then parses that and
gives the serial chain from the root to the tool link; nik converts that chain once into its own FK normal form,
so a URDF arm runs on nik's FK like any other.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import hashlib
import io
import json
import math
import os
import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from nik.errors import RobotDefinitionError, RobotDefinitionWarning
from nik.poses import rpy_to_matrix
from nik.robots.frames import with_frames
from nik.robots.model import NormalFormBuilder, Robot
from nik.robots.names import did_you_mean

__all__ = [
    "GRIPPER_WORDS",
    "TOOL_LINK_KINDS",
    "URDF_CACHE_FORMAT",
    "EndLinkChoice",
    "build_pk_chain",
    "choose_end_link",
    "default_end_link",
    "kinematic_urdf",
    "load_urdf",
    "set_surroundings",
]

#: Version of the cached parse results (bump when the conversion to the normal form changes).
#: 3: conventional names preferred, grippers left out; 4: a hand link (Baxter's) is one; 5: the joints' speed limits
URDF_CACHE_FORMAT = 5

#: joint types of the URDF format; floating and planar joints are kept as fixed (an error only on the arm's chain)
_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
_ORIGIN_ATTRS = ("xyz", "rpy")


def _local(tag) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _kinematic_tree(data: str | bytes, source: str) -> tuple[ET.Element, set[str]]:
    """The ``<robot>`` reduced to links and joints, and the names of its floating / planar joints."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as err:
        raise RobotDefinitionError(f"{source}: not a readable URDF (XML: {err})") from err
    if _local(root.tag) != "robot":
        raise RobotDefinitionError(f"{source}: root element is <{_local(root.tag)}>, expected <robot>")
    ns = root.tag[: -len("robot")]
    out = ET.Element("robot", name=root.get("name", ""))
    links, joints, free = set(), [], set()
    for el in root:
        if el.tag == ns + "link":
            name = el.get("name")
            if not name:
                raise RobotDefinitionError(f"{source}: a <link> has no name")
            link = ET.SubElement(out, "link", name=name)
            origin = el.find(ns + "origin")  # a link-level origin (not standard URDF) moves the link in pk
            if origin is not None:
                ET.SubElement(link, "origin", {k: origin.get(k) for k in _ORIGIN_ATTRS if origin.get(k) is not None})
            links.add(name)
        elif el.tag == ns + "joint":
            joints.append(el)
    if not joints:
        raise RobotDefinitionError(f"{source}: has no joints (links: {sorted(links)})")
    for el in joints:
        name, jtype = el.get("name"), el.get("type")
        if not name:
            raise RobotDefinitionError(f"{source}: a <joint> has no name")
        if jtype not in _JOINT_TYPES:
            raise RobotDefinitionError(
                f"{source}: joint {name!r} has unknown type {jtype!r} (expected one of {', '.join(_JOINT_TYPES)})"
            )
        if jtype in ("floating", "planar"):
            free.add(name)
            jtype = "fixed"
        joint = ET.SubElement(out, "joint", name=name, type=jtype)
        for role in ("parent", "child"):
            ref = el.find(ns + role)
            link = ref.get("link") if ref is not None else None
            if not link:
                raise RobotDefinitionError(f"{source}: joint {name!r} has no <{role} link=...>")
            if link not in links:
                raise RobotDefinitionError(f"{source}: joint {name!r}: {role} link {link!r} is not declared")
            ET.SubElement(joint, role, link=link)
        origin = el.find(ns + "origin")
        if origin is not None:
            ET.SubElement(joint, "origin", {k: origin.get(k) for k in _ORIGIN_ATTRS if origin.get(k) is not None})
        axis = el.find(ns + "axis")
        if axis is not None and axis.get("xyz") is not None:
            ET.SubElement(joint, "axis", xyz=axis.get("xyz"))
        limit = el.find(ns + "limit")
        if limit is not None:  # effort and velocity play no part; the parser wants them
            attrs = {k: limit.get(k) for k in ("lower", "upper") if limit.get(k) is not None}
            ET.SubElement(joint, "limit", attrs, effort=limit.get("effort", "0"), velocity=limit.get("velocity", "0"))
    return out, free


def kinematic_urdf(data: str | bytes, source: str = "URDF") -> str:
    """A URDF reduced to what kinematics reads, as a string pytorch-kinematics' parser accepts.

    ``data`` is the file's bytes (best: the XML declaration then says how to decode them) or text. Kept: the
    robot's name, every link's name, each joint's name, type, ``origin`` (xyz, rpy), ``axis``, ``parent``,
    ``child`` and ``limit`` (lower, upper). Floating and planar joints become fixed (:func:`load_urdf` refuses
    one between the root and the tool link). Raises :class:`RobotDefinitionError` naming a malformed link or
    joint.
    """
    return ET.tostring(_kinematic_tree(data, source)[0], encoding="unicode")


def _parse_chain(text: str, source: str):
    import pytorch_kinematics as pk

    try:
        with contextlib.redirect_stderr(io.StringIO()):  # the parser prints notes on unknown tags
            return pk.build_chain_from_urdf(text)
    except Exception as err:
        raise RobotDefinitionError(f"{source}: not a readable URDF ({type(err).__name__}: {err})") from err


#: A joint whose name (any case) contains one of these, or has the word ``hand``, is a gripper or hand joint:
#: the default rule never counts it as an arm joint.
GRIPPER_WORDS = ("gripper", "finger", "jaw", "knuckle", "thumb")

#: Conventional tool-link names, best first: a tool link is picked by the first kind its name fits
#: (``*tcp*``, ``*end_effector*``, ``tool0``, a word ``ee`` or ``eef``, a word ``flange``, a word ``tool``, the
#: hand: a word ``hand`` followed by nothing or ``link`` only, as Baxter's flange ``right_hand_link``, not the
#: sensors on it, ``right_hand_camera_link``; the words of ``arm_tool_link`` are arm, tool, link, of
#: ``gripperMover`` gripper, mover).
TOOL_LINK_KINDS = ("*tcp*", "*end_effector*", "tool0", "ee|eef", "flange", "tool", "hand")


@dataclass(frozen=True)
class EndLinkChoice:
    """How :func:`choose_end_link` picked a URDF's default tool link.

    ``link``: the tool link. ``arm_end``: the child link of the arm's last joint (interface.md's fallback).
    ``arm_joints``: how many revolute joints the arm has up to ``arm_end``. ``candidates``: every link at the
    end of the arm with a conventional tool-link name, best first. ``left_out``: names of the moving joints
    past ``arm_end`` (grippers, fingers), not part of the arm.
    """

    link: str
    arm_end: str
    arm_joints: int
    candidates: tuple[str, ...] = ()
    left_out: tuple[str, ...] = ()

    def note(self) -> str | None:
        """One line for the user when the choice left joints out or had several candidates; else None."""
        parts = []
        if len(self.candidates) > 1 and self.link != "tool0":  # tool0 (ROS-Industrial's flange) said nothing more
            parts.append(
                f"candidates {', '.join(self.candidates)} (preferred in the order {', '.join(TOOL_LINK_KINDS)})"
            )
        if self.left_out:
            names = ", ".join(self.left_out[:6]) + (
                f" and {len(self.left_out) - 6} more" if len(self.left_out) > 6 else ""
            )
            parts.append(f"left out of the arm: joint(s) {names}, which move past link {self.arm_end!r}")
        if not parts:
            return None
        return (
            f"default tool link {self.link!r}, {self.arm_joints} revolute arm joints; "
            + "; ".join(parts)
            + "; pass end_link (--end-link) to choose another"
        )


def _words(name: str) -> set[str]:
    """The lower-case words of a name, split at non-alphanumerics and camel case (``jointGripper``: joint,
    gripper; ``LHand``: l, hand)."""
    return set(_word_list(name))


def _word_list(name: str) -> list[str]:
    """The lower-case words of a name in order (:func:`_words`)."""
    split = re.sub(r"([A-Z])([A-Z][a-z])", r"\1_\2", re.sub(r"([a-z0-9])([A-Z])", r"\1_\2", name))
    return [w for w in re.split(r"[^a-z0-9]+", split.lower()) if w]


def _is_gripper_joint(name: str) -> bool:
    low = name.lower()
    return any(word in low for word in GRIPPER_WORDS) or "hand" in _words(name)


def _tool_kind(link: str) -> int | None:
    """Index in :data:`TOOL_LINK_KINDS` of the first kind ``link`` fits, or None."""
    low, words = link.lower(), _words(link)
    fits = (
        "tcp" in low,
        "end_effector" in low or "endeffector" in low,
        low == "tool0",
        bool(words & {"ee", "eef"}),
        "flange" in words,
        "tool" in words,
        _is_hand_link(link),
    )
    return next((i for i, fit in enumerate(fits) if fit), None)


def _is_hand_link(link: str) -> bool:
    words = _word_list(link)
    return "hand" in words and set(words[words.index("hand") + 1 :]) <= {"link"}


def choose_end_link(data: str | bytes, source: str = "URDF") -> EndLinkChoice:
    """The default tool link of a URDF (its bytes or text), and how it was found.

    1. The arm: the longest chain of revolute (or continuous) joints from the root, not counting gripper joints
       (a name containing one of :data:`GRIPPER_WORDS`, any case, or the word ``hand``; they count when
       every revolute joint is one); the first such chain in file order on ties. ``arm_end`` is the child
       link of its last joint.
    2. The tool link: of ``arm_end`` and the links reached from it through fixed joints only, the first by
       the kinds of :data:`TOOL_LINK_KINDS` (``*tcp*``, ``*end_effector*``, ``tool0``, ``ee`` or ``eef`` as
       a word of the name, ``flange`` as a word, ``tool`` as a word); within a kind the nearest to
       ``arm_end``, then file order.
    3. Otherwise ``arm_end`` itself: the last link of the longest chain of revolute joints.

    Moving joints past ``arm_end`` are left out of the arm (:attr:`EndLinkChoice.left_out`).
    """
    tree, free = _kinematic_tree(data, source)
    chain = _parse_chain(ET.tostring(tree, encoding="unicode"), source)
    frames = list(_frames(chain._root))
    revolute = [f for f in frames if f.joint.joint_type == "revolute"]
    if not revolute:
        raise RobotDefinitionError(f"{source}: has no revolute joints")
    skip = not all(_is_gripper_joint(f.joint.name) for f in revolute)  # gripper joints count only when all are
    best = (0, None)

    def visit(frame, count):
        nonlocal best
        if frame.joint.joint_type == "revolute" and not (skip and _is_gripper_joint(frame.joint.name)):
            count += 1
            if count > best[0]:
                best = (count, frame)
        for child in frame.children:
            visit(child, count)

    visit(chain._root, 0)
    count, end = best
    found, order = [], 0
    todo = [(end, 0)]
    while todo:  # breadth first through fixed joints from the arm's end
        frame, depth = todo.pop(0)
        kind = _tool_kind(frame.link.name)
        if kind is not None:
            found.append((kind, depth, order, frame.link.name))
        order += 1
        todo += [(c, depth + 1) for c in frame.children if c.joint.joint_type == "fixed" and c.joint.name not in free]
    found.sort()
    hand = TOOL_LINK_KINDS.index("hand")
    if found and found[0][0] != hand:  # the hand is the last resort: never a candidate next to a tool link
        found = [f for f in found if f[0] != hand]
    left_out = tuple(f.joint.name for f in _frames(end) if f is not end and f.joint.joint_type != "fixed")
    candidates = tuple(name for *_, name in found)
    return EndLinkChoice(candidates[0] if candidates else end.link.name, end.link.name, count, candidates, left_out)


def default_end_link(data: str | bytes, source: str = "URDF") -> str:
    """The default tool link of a URDF: :attr:`EndLinkChoice.link` of :func:`choose_end_link`."""
    return choose_end_link(data, source).link


def build_pk_chain(data: str | bytes, end_link: str, root_link: str = ""):
    """pytorch-kinematics ``SerialChain`` from the root (or ``root_link``) to ``end_link`` of a URDF's bytes or text."""
    import pytorch_kinematics as pk

    with contextlib.redirect_stderr(io.StringIO()):
        return pk.build_serial_chain_from_urdf(kinematic_urdf(data), end_link, root_link)


def load_urdf(
    path: str | Path,
    *,
    end_link: str | None = None,
    root_link: str | None = None,
    name: str | None = None,
    origins: str = "pk",
    base=None,
    tool=None,
    srdf: bool | str | Path = True,
    joint_values: Mapping[str, float] | None = None,
) -> Robot:
    """Load a serial arm of revolute and prismatic joints from a URDF file.

    Args:
        path: the ``.urdf`` file.
        end_link: the tool link; default :func:`choose_end_link` (a conventional tool link at the end of the
            arm, gripper joints left out); a :class:`nik.errors.RobotDefinitionWarning` names the joints it
            left out and the candidates when several links fit.
        root_link: the base link; default the URDF's root.
        name: robot name; default the URDF's ``<robot name>``.
        base, tool: frames (``(4, 4)`` or ``(7,)`` xyz + quaternion w, x, y, z; metres) of the root link in the
            world and of the tool centre point in ``end_link``'s frame: FK is ``base @ T_end_link(q) @ tool``
            (:mod:`nik.robots.frames`).

        origins: where the fixed joint transforms come from. ``"pk"`` (default): the transforms
            pytorch-kinematics parsed, so nik and pytorch-kinematics agree to machine precision on
            the same file. pytorch-kinematics converts ``rpy`` through float32, so those transforms
            carry errors up to about 1e-7 (0.1 micrometre, 1e-7 rad) for angles such as pi/2;
            ``"float64"`` recomputes every ``<origin>`` from the file in float64 (exact FK, which then
            differs from pytorch-kinematics' by that much).
        srdf, joint_values: the rest of the robot, for its collision model, the mesh check and the viewer
            (:func:`set_surroundings`: kept as :attr:`Robot.srdf` and :attr:`Robot.joint_values`).

    Continuous joints get limits [-pi, pi]. A prismatic joint between base and tool becomes a
    prismatic joint of the robot (its value in metres along its axis, limits from the file, which
    must give them); fixed joints are merged into the constant transforms.

    :attr:`Robot.vel_limits` are the arm joints' ``<limit velocity=...>`` (rad/s, m/s) when every arm joint gives a
    positive one (a missing or zero velocity, a common placeholder, means unknown: then None); a negative or
    non-finite velocity is a :class:`RobotDefinitionError` naming the joint. URDF has no acceleration limit:
    :attr:`Robot.acc_limits` is None (a YAML robot file pointing at the URDF may give both, :mod:`nik.robots.config`).

    The result is kept in nik's user cache folder (``$XDG_CACHE_HOME/nik/robots``, default
    ``~/.cache/nik/robots``) under the SHA-256 of the file's bytes, these arguments, the installed
    pytorch-kinematics and :data:`URDF_CACHE_FORMAT`, with a checksum verified on load: importing
    pytorch-kinematics and parsing cost about half a second, reading the cached normal form a millisecond.
    An unwritable cache folder only means parsing every time.
    """
    if origins not in ("pk", "float64"):
        raise ValueError(f"origins must be 'pk' or 'float64', got {origins!r}")
    path = Path(path)
    if not path.is_file():
        raise RobotDefinitionError(f"URDF file not found: {path}")
    data = path.read_bytes()
    key = _cache_key(data, end_link, root_link, name, origins)
    hit = _cached_robot(key, path)
    if hit is None:
        robot, choice = _parse_robot(path, data, end_link, root_link, name, origins)
        _store_robot(key, robot, choice)
    else:
        robot, choice = hit
    note = choice.note() if choice is not None else None
    if note:
        warnings.warn(f"{path.name}: {note}", RobotDefinitionWarning, stacklevel=2)
    return set_surroundings(with_frames(robot, base=base, tool=tool), data, srdf=srdf, joint_values=joint_values)


def set_surroundings(robot: Robot, data: bytes | None, *, srdf=True, joint_values=None) -> Robot:
    """``robot`` with its SRDF choice and the values of the joints outside its chain, checked against the URDF's
    bytes ``data`` (None: a robot without a URDF, which takes neither), set as attributes:

    - :attr:`Robot.srdf`: ``True`` (search for MoveIt's SRDF beside the URDF: ``NAME.srdf`` there, or in a
      sibling ``srdf/`` folder, or that folder's single ``*.srdf``; :func:`nik.collision.model.find_srdf`),
      ``False`` (none) or the :class:`~pathlib.Path` of the SRDF to read (it must exist);
    - :attr:`Robot.joint_values`: ``{joint: value}`` (radians, metres) of joints of the URDF outside the arm's
      chain (the other arm of a two-armed robot, a head, a torso lift, fingers), placed there for self-collision,
      the mesh check and the viewer; the joints not named stand at 0, or the middle of their range where 0 is
      outside it (:func:`nik.collision.urdf.rest_value`). Each name must be a moving joint of the URDF outside
      the chain and its value finite and within the joint's limits: otherwise a one-line
      :class:`RobotDefinitionError` (an unknown name lists the closest names).
    """
    where = robot.source or robot.name
    if srdf is True or srdf is False:
        choice = srdf
    elif isinstance(srdf, (str, Path)):
        choice = Path(srdf)
        if data is None:
            raise RobotDefinitionError(f"{where}: srdf applies to URDF robots (this one has no URDF)")
        if not choice.is_file():
            raise RobotDefinitionError(f"SRDF file not found: {choice}")
    else:
        raise RobotDefinitionError(f"srdf must be True, False or a path, got {type(srdf).__name__}")
    values = {}
    if joint_values:
        if not isinstance(joint_values, Mapping):
            raise RobotDefinitionError(
                f"joint_values must be a mapping {{joint name: value}}, got {type(joint_values).__name__}"
            )
        if data is None:
            raise RobotDefinitionError(f"{where}: joint_values applies to URDF robots (this one has no URDF)")
        values = _joint_values(data, robot, joint_values, where)
    robot.srdf = choice
    robot.joint_values = values
    return robot


def _joint_values(data: bytes, robot: Robot, given: Mapping, where: str) -> dict[str, float]:
    """``given`` checked against the URDF's joints (:func:`set_surroundings`), as ``{name: float}``."""
    tree, _ = _kinematic_tree(data, where)
    joints = {el.get("name"): el for el in tree.iter("joint")}
    out = {}
    for name, value in given.items():
        if name not in joints:
            close = difflib.get_close_matches(str(name), list(joints), n=3, cutoff=0.6)
            hint = (
                f"closest: {', '.join(close)}" if close else f"{len(joints)} joints, e.g. {', '.join(list(joints)[:4])}"
            )
            raise RobotDefinitionError(f"{where}: joint_values: no joint {name!r} in this URDF ({hint})")
        if name in robot.joint_names:
            raise RobotDefinitionError(
                f"{where}: joint_values: {name!r} is a joint of the arm (its value is the configuration q)"
            )
        el = joints[name]
        if el.get("type") == "fixed":
            raise RobotDefinitionError(f"{where}: joint_values: joint {name!r} is fixed (it has no value)")
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v):
            raise RobotDefinitionError(f"{where}: joint_values: {name!r} must be a finite number, got {value!r}")
        limit = el.find("limit")
        if el.get("type") != "continuous" and limit is not None and "lower" in limit.attrib and "upper" in limit.attrib:
            lo, hi = float(limit.get("lower")), float(limit.get("upper"))
            if lo < hi and not lo - 1e-9 <= v <= hi + 1e-9:
                raise RobotDefinitionError(
                    f"{where}: joint_values: {name!r} = {v:g} is outside its limits [{lo:g}, {hi:g}]"
                )
        out[str(name)] = v
    return out


def _parse_robot(path: Path, data: bytes, end_link, root_link, name, origins) -> tuple[Robot, EndLinkChoice | None]:
    """:func:`load_urdf` without the cache or frames: the file reduced to its kinematics, parsed by
    pytorch-kinematics, converted to the normal form; and how the default tool link was chosen (or None)."""
    tree, free = _kinematic_tree(data, str(path))
    text = ET.tostring(tree, encoding="unicode")
    chain = _parse_chain(text, str(path))
    choice = None
    if not end_link:
        choice = choose_end_link(text, str(path))
        end_link = choice.link
    links = {f.link.name for f in _frames(chain._root)}
    for role, link in (("end_link", end_link), ("root_link", root_link)):
        if link is not None and link not in links:
            hint = f"; {did_you_mean(link, links)}" if did_you_mean(link, links) else ""
            listed = f"(links: {sorted(links)})"
            raise RobotDefinitionError(f"{path}: {role} {link!r} is not a link of this URDF{hint} {listed}")
    try:
        serial = build_pk_chain(text, end_link, root_link or "")
    except Exception as err:
        raise RobotDefinitionError(f"{path}: cannot build a chain to {end_link!r}: {err}") from err

    on_chain = [f.joint.name for f in serial._serial_frames[1:] if f.joint.name in free]
    if on_chain:
        raise RobotDefinitionError(
            f"{path}: joint {on_chain[0]!r} is floating or planar; nik models revolute and prismatic joints only"
        )
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
        name = tree.get("name") or path.stem
    robot = Robot(
        name,
        builder.finish(),
        np.zeros(len(names)),
        np.array(limits),
        names,
        end_link=end_link,
        source=str(path),
        prismatic=builder.prismatic,
        vel_limits=_joint_speeds(tree, names, str(path)),
    )
    return robot, choice


def _joint_speeds(tree: ET.Element, names: list[str], source: str) -> list[float] | None:
    """The ``<limit velocity>`` of the joints ``names`` (rad/s, m/s), or None when one of them gives none or 0
    (unknown); a negative or non-finite velocity of one of them is an error naming the joint."""
    given = {}
    for joint in tree.iter("joint"):
        limit = joint.find("limit")
        given[joint.get("name")] = limit.get("velocity", "0") if limit is not None else "0"
    speeds = []
    for name in names:
        text = given.get(name, "0")
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not math.isfinite(v) or v < 0:
            raise RobotDefinitionError(
                f"{source}: joint {name!r}: <limit velocity={text!r}> must be a finite number >= 0 (rad/s, m/s; "
                "0: unknown)"
            )
        speeds.append(v)
    return speeds if all(v > 0 for v in speeds) else None


# ---------------------------------------------------------------------------
# the cache of parsed arms
# ---------------------------------------------------------------------------
def _cache_key(data: bytes, end_link, root_link, name, origins) -> str:
    import importlib.util

    spec = importlib.util.find_spec("pytorch_kinematics")
    stamp = ""
    if spec is not None and spec.origin:  # a reinstalled pytorch-kinematics is a new key
        st = os.stat(spec.origin)
        stamp = f"{spec.origin}:{st.st_size}:{st.st_mtime_ns}"
    h = hashlib.sha256(data)
    h.update(json.dumps([end_link, root_link, name, origins, URDF_CACHE_FORMAT, stamp]).encode())
    return h.hexdigest()


def _cache_file(key: str) -> Path:
    from nik.kernels.cache import cache_home

    return cache_home() / "robots" / f"{key[:32]}.json"


def _cached_robot(key: str, path: Path) -> tuple[Robot, EndLinkChoice | None] | None:
    """The robot stored under ``key`` (its ``source`` set to ``path``) and how its default tool link was chosen,
    or None when absent, unreadable or its checksum or key does not match."""
    try:
        doc = json.loads(_cache_file(key).read_text())
        body = json.dumps([doc["robot"], doc.get("choice")], sort_keys=True)
        if doc.get("key") != key or doc.get("sha256") != hashlib.sha256(body.encode()).hexdigest():
            return None
        d = doc["robot"]
        robot = Robot(
            d["name"],
            np.asarray(d["G"], dtype=np.float64),
            d["offsets"],
            d["limits"],
            d["joint_names"],
            end_link=d.get("end_link"),
            source=str(path),
            prismatic=d.get("prismatic"),
            vel_limits=d.get("vel_limits"),
            acc_limits=d.get("acc_limits"),
        )
        c = doc.get("choice")
        if c is not None:
            c = EndLinkChoice(**{**c, "candidates": tuple(c["candidates"]), "left_out": tuple(c["left_out"])})
        return robot, c
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _store_robot(key: str, robot: Robot, choice: EndLinkChoice | None) -> None:
    """Write ``robot``'s definition and how its default tool link was chosen under ``key`` (temporary name, then
    rename); silently skipped when the folder is not writable."""
    d = robot.to_definition()
    for rate in ("vel_limits", "acc_limits"):  # outside the definition (not kinematics); cached with it
        value = getattr(robot, rate)
        if value is not None:
            d[rate] = value.tolist()
    c = None if choice is None else dataclasses.asdict(choice)
    body = json.dumps([d, c], sort_keys=True)
    sha = hashlib.sha256(body.encode()).hexdigest()
    doc = {"format": URDF_CACHE_FORMAT, "key": key, "sha256": sha, "robot": d, "choice": c}
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
        return URDF.from_xml_string(text)


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
