"""Robot definitions from YAML files (DH, modified DH, screw axes, or a pointer to a URDF),
and :func:`load_robot`, which resolves built-in names and paths.

YAML schema (see ``shared/spec/interface.md``)::

    name: my_arm
    description: free text (for instance where the table comes from)
    convention: dh | mdh | poe
    unit: mm | m              # lengths (default m)
    angles: deg | rad         # angles: alpha, theta, revolute offset and limits (default rad)
    base: {position: [x, y, z], rpy: [r, p, y]}     # optional: T = base @ arm @ tool (any convention, URDF too)
    tool: {position: [x, y, z], rpy: [r, p, y]}     # optional: the tool (TCP) in the flange's frame
    flange: {link: tool0, position: [x, y, z], rpy: [r, p, y]}   # optional: the flange in the last link's frame
    joints:
      - {alpha: -90, a: 0, d: 0, offset: 0, limits: [-160, 160], name: j1}   # dh / mdh, revolute
      - {type: prismatic, alpha: 0, a: 0, d: 0, theta: 0, limits: [300, 900]}  # dh / mdh, prismatic
      - {axis: [0, 0, 1], point: [0, 0, 0], limits: [-180, 180]}            # poe, revolute
      - {type: prismatic, axis: [0, 0, 1], limits: [0, 500]}                 # poe, prismatic
    home: {position: [x, y, z], rotation: [[...], [...], [...]]}           # poe only
    vel_limits: [v1, v2, ...]   # optional, one per joint: largest joint speeds (file's units per second)
    acc_limits: [a1, a2, ...]   # optional: largest joint accelerations (file's units per second squared)

Joint fields:

- ``type``: ``revolute`` (default) or ``prismatic``.
- ``name``: the joint's name (default ``joint<i>``, counting from 1); it appears in
  :attr:`Robot.joint_names` and in the CLI's tables.
- Revolute joint: the joint variable ``q`` (radians in the API) is the DH angle, ``theta = q + offset``;
  ``offset`` (file's angle unit, default 0) may also be written ``theta`` (the same number: the DH
  angle at ``q = 0``; give one of them, not both). ``limits`` (file's angle unit, default
  ``[-180, 180]`` deg) bound ``q``.
- Prismatic joint: the variable ``q`` (metres in the API) is added to the DH length,
  ``d_total = d + offset + q`` (dh, mdh), or is a translation by ``q + offset`` along ``axis`` (poe).
  ``d`` (default 0) and ``offset`` (default 0) are in the file's length unit, as are the ``limits``
  (required: a slide has no natural default range), which bound ``q``. ``theta`` (dh, mdh; file's
  angle unit, default 0) is the joint's constant DH angle. In poe, ``point`` may be given and plays
  no part (a translation has no axis position).
- ``vel``, ``acc`` (optional, > 0): the joint's largest speed and acceleration in the file's units per second
  (per second squared): ``angles: deg`` means deg/s (deg/s^2) for a revolute joint, ``unit: mm`` means mm/s
  (mm/s^2) for a prismatic one. Give them for every joint or for none; they become :attr:`Robot.vel_limits` /
  :attr:`Robot.acc_limits` (SI). The top-level ``vel_limits`` / ``acc_limits`` lists say the same in one line
  (not both ways in one file); in a file pointing at a URDF they replace the URDF's ``<limit velocity>``
  (a URDF has no acceleration limit). Zero, negative or non-finite values are errors naming the joint; none
  of this changes the kinematics or the definition hash.

or, for an arm described by a URDF: ``{name: ..., urdf: path/relative/to/this/file.urdf,
end_link: ..., root_link: ..., base: ..., tool: ...}``. Unknown keys are errors, so a typo never goes unnoticed.

Frames (``base``, ``tool``, and ``home`` of poe): ``position`` (the file's length unit) and at most one of
``rpy`` (the file's angle unit, ``R = Rz(yaw) Ry(pitch) Rx(roll)``), ``rotation`` (3x3 rows) or
``quaternion`` (w, x, y, z). ``base`` places the arm's first frame (the URDF's root link) in the world,
``tool`` the tool centre point in the frame of the last link (the URDF's ``end_link``); both are folded into
the normal form (:mod:`nik.robots.frames`). :func:`load_robot`'s ``base=`` / ``tool=`` replace the file's.

``flange`` (``link``: its name, and a frame's fields) is the vendor's flange, the frame a pose means, in the
frame of the file's last link (``end_link``): the built-in ur5 and panda end their trained chain at
``wrist_3_link`` / ``panda_link7`` and name ``tool0`` / ``panda_link8`` this way, so that the shipped networks
(matched on the chain without its frames) stay valid. FK is then ``base @ T_end_link(q) @ flange @ tool``: a
``tool`` (the file's or ``tool=``) is given in the flange's frame; :attr:`Robot.flange_link` and
:attr:`Robot.flange` record it. A given ``end_link=`` names the link poses mean and drops the
flange (it belongs to the file's ``end_link``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from nik.errors import RobotDefinitionError
from nik.poses import rpy_to_matrix
from nik.robots.frames import as_frame, with_frames
from nik.robots.model import Robot, dh_chain, mdh_chain, poe_chain
from nik.robots.names import did_you_mean
from nik.robots.rates import check_rates
from nik.robots.yamlfile import load_yaml_file

__all__ = ["BUILTIN_DIR", "builtin_robots", "load_robot", "robot_from_config"]

#: Folder of the built-in robot files (``configs/robots`` at the repository root).
BUILTIN_DIR = Path(__file__).resolve().parents[2] / "configs" / "robots"

_TOP_KEYS = {
    "name",
    "convention",
    "unit",
    "angles",
    "joints",
    "home",
    "base",
    "tool",
    "urdf",
    "end_link",
    "root_link",
    "description",
    "flange",
    "vel_limits",
    "acc_limits",
}
_DH_KEYS = {"alpha", "a", "d", "offset", "limits", "name", "theta", "type", "vel", "acc"}
_POE_KEYS = {"axis", "point", "offset", "limits", "name", "type", "vel", "acc"}
_JOINT_TYPES = ("revolute", "prismatic")


def builtin_robots() -> list[str]:
    """Names of the robots shipped in ``configs/robots``."""
    return sorted(p.stem for p in BUILTIN_DIR.glob("*.yaml") if _is_robot_file(p))


def _names_builtin(name_or_path) -> bool:
    """Whether ``name_or_path`` is written as a plain name (a built-in's, when one is called so), not as a path:
    a ``str`` without a folder separator, a leading ``.`` or a robot-file suffix (``./panda``, ``panda.yaml`` and
    a :class:`~pathlib.Path` that exists are paths)."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path):
        return not name_or_path.exists() and name_or_path.parent == Path(".")
    seps = {"/", "\\"}
    return not any(sep in text for sep in seps) and not text.startswith(".") and "." not in text


_SHADOW_WARNED: set[str] = set()


def _warn_shadowed(name: str) -> None:
    """Say once per name that a file or folder of the working directory named like a built-in is not what loads."""
    if name in _SHADOW_WARNED:
        return
    _SHADOW_WARNED.add(name)
    import warnings

    from nik.errors import RobotDefinitionWarning

    warnings.warn(
        f"{name!r} is the built-in arm; the {name!r} in the working directory is not loaded "
        f"(write ./{name}, or the robot file's path with its .yaml/.urdf suffix, to load a file)",
        RobotDefinitionWarning,
        stacklevel=3,
    )


def _is_robot_file(path: Path) -> bool:
    try:
        data = load_yaml_file(path)
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and ("joints" in data or "urdf" in data)


def load_robot(
    name_or_path,
    *,
    end_link: str | None = None,
    base=None,
    tool=None,
    root_link: str | None = None,
    srdf=True,
    joint_values=None,
) -> Robot:
    """Load a robot by built-in name, YAML file or URDF file.

    Args:
        name_or_path: a built-in name (:func:`builtin_robots`), a ``.yaml``/``.yml`` robot file,
            a ``.urdf`` file, or a :class:`Robot` (returned as is, or with the frames below). A built-in's name
            is the built-in arm even where a file or folder of that name is in the working directory (a
            :class:`nik.RobotDefinitionWarning` says so once, and how to load the file: ``./panda``); a path
            (``./panda``, ``robots/panda``, ``panda.yaml``) is always read as a file.
        end_link: for URDF arms, the tool link. Default (:func:`nik.robots.urdf.choose_end_link`):

            1. the arm is the longest chain of revolute joints from the root, gripper and hand joints not
               counted (names containing ``gripper``, ``finger``, ``jaw``, ``knuckle`` or ``thumb``, any case, or
               the word ``hand``); the first on ties;
            2. of the last arm joint's child link and the links reached from it through fixed joints only, the
               first whose name is ``*tcp*``, else ``*end_effector*``, else ``tool0``, else has a word ``ee`` or
               ``eef`` (``ee_link``, ``link_eef``), else a word ``flange``, else a word ``tool``
               (``arm_tool_link``); the nearest to the arm's end within a kind, then file order;
            3. else that child link: the last link of the longest chain of revolute joints.

            The moving joints past the arm (a gripper's) are left out; a :class:`nik.RobotDefinitionWarning`
            names them, and the candidates where several links fit. Built-in arms name their ``end_link``.
        base: the pose of the robot's base (first frame, a URDF's root link) in your world frame.
        root_link: for URDF arms, the link the chain starts from (default the URDF's root; a robot file's
            ``root_link:``). On a mobile manipulator (TIAGo, PR2: the torso lift is a joint of the chain from the
            root) ``root_link="torso_lift_link"`` gives the arm alone, its poses in that link's frame.
        tool: the tool centre point (TCP) in the frame of the flange: the last link (``end_link``), or the
            vendor's flange a robot file names (``flange:``; the built-in ur5's ``tool0``, panda's
            ``panda_link8``). Each a ``(4, 4)`` transform or ``(7,)`` x, y, z (metres) and quaternion w, x, y, z;
            FK is then ``base @ T(q) @ tool`` for every solver (:mod:`nik.robots.frames`), replacing a robot
            file's own ``base:`` / ``tool:``. The definition hash changes with a frame other than the identity, so a
            network trained without it is not used for it.
        srdf: for URDF arms, MoveIt's SRDF whose disabled link pairs the collision model leaves out: a path (that
            file), True (default: search beside the URDF, ``NAME.srdf``, or in a sibling ``srdf/`` folder,
            ``NAME.srdf`` or its single ``*.srdf``; the one used is logged on ``nik.collision`` and kept in the
            model's ``options["srdf_file"]``) or False (none). Kept as ``robot.srdf``.
        joint_values: for URDF arms, ``{joint name: value}`` (radians, metres) of joints outside the arm's chain
            (the other arm, a head, a torso lift, fingers): the rest of the robot stands there for self-collision,
            the mesh check and the viewer; joints not named stand at 0, or the middle of their range where 0 is
            outside it. Kept as ``robot.joint_values``. A name that is not a moving joint of the URDF outside the
            chain is a one-line error naming the closest names.

    Raises:
        RobotDefinitionError (a ValueError) naming the robot or file and what is wrong (a frame that is not a
        finite rigid transform included).
    """
    if isinstance(name_or_path, Robot):
        return with_frames(name_or_path, base=base, tool=tool)
    if not isinstance(name_or_path, (str, Path)):
        raise RobotDefinitionError(f"load_robot expects a name or a path, got {type(name_or_path).__name__}")
    base, tool = as_frame(base, name="base"), as_frame(tool, name="tool")
    text = str(name_or_path)
    path = Path(text)
    named_builtin = _names_builtin(name_or_path) and _is_robot_file(BUILTIN_DIR / f"{text}.yaml")
    if named_builtin and path.exists():
        _warn_shadowed(text)
    if not named_builtin and (path.suffix.lower() in {".urdf", ".yaml", ".yml"} or path.exists()):
        if path.is_dir():
            raise RobotDefinitionError(f"{text} is a folder, not a robot file (.yaml or .urdf)")
        if not path.is_file():
            raise RobotDefinitionError(f"robot file not found: {path}")
        if path.suffix.lower() == ".urdf":
            from nik.robots.urdf import load_urdf

            return load_urdf(
                path, end_link=end_link, root_link=root_link, base=base, tool=tool, srdf=srdf, joint_values=joint_values
            )
        robot = robot_from_file(path, end_link=end_link, base=base, tool=tool, root_link=root_link)
        return _surroundings(robot, srdf, joint_values)
    builtin = BUILTIN_DIR / f"{text}.yaml"
    if builtin.is_file() and _is_robot_file(builtin):
        robot = robot_from_file(builtin, end_link=end_link, base=base, tool=tool, root_link=root_link)
        return _surroundings(robot, srdf, joint_values)
    hint = did_you_mean(text, builtin_robots())
    raise RobotDefinitionError(
        f"unknown robot {text!r}: {hint + ' It is ' if hint else ''}not a built-in ({', '.join(builtin_robots())}) "
        "and not a robot file"
    )


def _surroundings(robot: Robot, srdf, joint_values) -> Robot:
    """``robot`` (from a robot file) with ``srdf`` / ``joint_values`` (:func:`nik.robots.urdf.set_surroundings`),
    checked against the URDF the file points at (none: only the defaults are accepted)."""
    if srdf is True and not joint_values:
        return robot
    from nik.robots.urdf import set_surroundings

    urdf = Path(robot.source) if robot.source and Path(robot.source).suffix.lower() == ".urdf" else None
    data = urdf.read_bytes() if urdf is not None and urdf.is_file() else None
    return set_surroundings(robot, data, srdf=srdf, joint_values=joint_values)


def robot_from_file(
    path: str | Path, *, end_link: str | None = None, base=None, tool=None, root_link: str | None = None
) -> Robot:
    """Load a YAML robot file; see the module docstring for the schema."""
    path = Path(path)
    data = load_yaml_file(path, RobotDefinitionError)
    return robot_from_config(
        data, source=str(path), base_dir=path.parent, end_link=end_link, base=base, tool=tool, root_link=root_link
    )


def robot_from_config(
    data,
    *,
    source: str = "robot config",
    base_dir: Path | None = None,
    end_link: str | None = None,
    base=None,
    tool=None,
    root_link: str | None = None,
) -> Robot:
    """Build a :class:`Robot` from a parsed YAML mapping; ``base`` / ``tool`` / ``root_link`` (as in
    :func:`load_robot`) replace the mapping's."""
    if not isinstance(data, dict):
        raise RobotDefinitionError(f"{source}: expected a mapping at the top level, got {type(data).__name__}")
    _no_unknown(data, _TOP_KEYS, source)
    length, angle = _units(data, source)
    frames = {
        key: as_frame(given, name=key)
        if given is not None
        else _frame(data.get(key), length, angle, f"{source}: {key}")
        for key, given in (("base", base), ("tool", tool))
    }
    flange = None
    if data.get("flange") is not None and end_link is None:  # the tool (TCP) is given in the flange's frame
        flange_link, flange = _flange(data["flange"], length, angle, f"{source}: flange")
        frames["tool"] = flange if frames["tool"] is None else flange @ frames["tool"]
    if "urdf" in data:
        from nik.robots.urdf import load_urdf

        urdf = Path(data["urdf"])
        if not urdf.is_absolute() and base_dir is not None:
            urdf = base_dir / urdf
        robot = load_urdf(
            urdf,
            end_link=end_link or data.get("end_link"),
            root_link=root_link or data.get("root_link"),
            name=data.get("name"),
            **frames,
        )
    elif root_link is not None:
        raise RobotDefinitionError(
            f"{source}: root_link applies to URDF arms; {data.get('name') or 'this robot'} is defined by joint "
            "parameters (no links to choose from)"
        )
    else:
        robot = with_frames(_chain_from_config(data, source, length, angle), **frames)
    if flange is not None:
        robot.flange_link, robot.flange = flange_link, torch.from_numpy(flange)
    return _with_rates(robot, data, source, length, angle)


def _with_rates(robot: Robot, data: dict, source: str, length: float, angle: float) -> Robot:
    """``robot`` with the file's joint speed and acceleration limits (``vel`` / ``acc`` per joint or the top-level
    ``vel_limits`` / ``acc_limits``, file's units per second), in SI; the robot as it is where the file gives none."""
    joints = data.get("joints") if isinstance(data.get("joints"), list) else []
    per_unit = np.array([length if p else angle for p in robot.prismatic.tolist()])
    for key, field in (("vel_limits", "vel"), ("acc_limits", "acc")):
        given = [j.get(field) if isinstance(j, dict) else None for j in joints]
        per_joint = any(v is not None for v in given)
        if per_joint and key in data:
            raise RobotDefinitionError(f"{source}: give '{key}' or '{field}' per joint, not both")
        if per_joint:
            missing = [i for i, v in enumerate(given) if v is None]
            if missing:
                i = missing[0]
                raise RobotDefinitionError(
                    f"{source}: joints[{i}] ({robot.joint_names[i]}): missing '{field}' (give it for every joint or "
                    "none)"
                )
            values = given
        elif key in data:
            values = data[key]
        else:
            continue
        try:
            raw = check_rates(values, robot.dof, what=key if not per_joint else field, names=robot.joint_names)
        except ValueError as err:
            raise RobotDefinitionError(f"{source}: {err}") from None
        setattr(robot, key, raw * torch.from_numpy(per_unit))
    return robot


def _units(data: dict, source: str) -> tuple[float, float]:
    """Metres per length unit and radians per angle unit of a robot file (``unit``, ``angles``)."""
    unit = data.get("unit", "m")
    if unit not in ("mm", "m"):
        raise RobotDefinitionError(f"{source}: unit must be 'mm' or 'm', got {unit!r}")
    angles = data.get("angles", "rad")
    if angles not in ("deg", "rad"):
        raise RobotDefinitionError(f"{source}: angles must be 'deg' or 'rad', got {angles!r}")
    return (1e-3 if unit == "mm" else 1.0), (math.pi / 180 if angles == "deg" else 1.0)


def _chain_from_config(data: dict, source: str, length: float, angle: float) -> Robot:
    """The robot of a dh / mdh / poe mapping, without its base and tool frames."""
    name = data.get("name") or Path(source).stem
    convention = data.get("convention")
    if convention not in ("dh", "mdh", "poe"):
        raise RobotDefinitionError(f"{source}: convention must be one of dh, mdh, poe; got {convention!r}")

    joints = data.get("joints")
    if not isinstance(joints, list) or not joints:
        raise RobotDefinitionError(f"{source}: 'joints' must be a non-empty list")
    n = len(joints)
    limits = np.empty((n, 2))
    offsets = np.zeros(n)
    theta = np.zeros(n)  # constant DH angle of prismatic joints
    prismatic = [False] * n
    names = []
    for i, j in enumerate(joints):
        where = f"{source}: joints[{i}]"
        if not isinstance(j, dict):
            raise RobotDefinitionError(f"{where}: expected a mapping, got {j!r}")
        _no_unknown(j, _DH_KEYS if convention in ("dh", "mdh") else _POE_KEYS, where)
        names.append(str(j.get("name", f"joint{i + 1}")))
        jtype = j.get("type", "revolute")
        if jtype not in _JOINT_TYPES:
            raise RobotDefinitionError(f"{where} ({names[-1]}): type must be 'revolute' or 'prismatic', got {jtype!r}")
        if jtype == "prismatic":
            prismatic[i] = True
            limits[i] = _limits(_required(j, "limits", where), where) * length
            offsets[i] = _number(j.get("offset", 0.0), f"{where}: offset") * length
            theta[i] = _number(j.get("theta", 0.0), f"{where}: theta") * angle
        else:
            if "offset" in j and "theta" in j:
                raise RobotDefinitionError(
                    f"{where}: give 'offset' or 'theta' (the same quantity for a revolute joint), not both"
                )
            limits[i] = _limits(j.get("limits", [-math.pi / angle, math.pi / angle]), where) * angle
            offsets[i] = _number(j.get("offset", j.get("theta", 0.0)), f"{where}: offset") * angle

    if convention in ("dh", "mdh"):
        if "home" in data:
            raise RobotDefinitionError(f"{source}: 'home' belongs to convention poe, not {convention}")
        alpha = [
            _number(_required(j, "alpha", f"{source}: joints[{i}]"), f"{source}: joints[{i}].alpha") * angle
            for i, j in enumerate(joints)
        ]
        a = [
            _number(_required(j, "a", f"{source}: joints[{i}]"), f"{source}: joints[{i}].a") * length
            for i, j in enumerate(joints)
        ]
        d = [
            _number(
                j.get("d", 0.0) if prismatic[i] else _required(j, "d", f"{source}: joints[{i}]"),
                f"{source}: joints[{i}].d",
            )
            * length
            for i, j in enumerate(joints)
        ]
        builder = dh_chain if convention == "dh" else mdh_chain
        G = builder(alpha, a, d, prismatic=prismatic, theta=theta)
    else:
        axes, points = [], []
        for i, j in enumerate(joints):
            where = f"{source}: joints[{i}]"
            axis = _vector(_required(j, "axis", where), 3, f"{where}.axis")
            if np.linalg.norm(axis) < 1e-9:
                raise RobotDefinitionError(f"{where}.axis: must be non-zero")
            axes.append(axis / np.linalg.norm(axis))
            point = j.get("point", [0.0, 0.0, 0.0]) if prismatic[i] else _required(j, "point", where)
            points.append(_vector(point, 3, f"{where}.point") * length)
        home = _frame(_required(data, "home", source), length, angle, f"{source}: home")
        G = poe_chain(axes, points, home, prismatic=prismatic)
    return Robot(str(name), G, offsets, limits, names, source=source, prismatic=prismatic)


# ---------------------------------------------------------------------------
# Field checks: each raises RobotDefinitionError naming the field
# ---------------------------------------------------------------------------
def _no_unknown(mapping: dict, allowed: set[str], where: str) -> None:
    unknown = set(map(str, mapping)) - allowed
    if unknown:
        hints = [h for h in (did_you_mean(u, allowed) for u in sorted(unknown)) if h]
        hint = f" ({'; '.join(hints)})" if hints else ""
        raise RobotDefinitionError(f"{where}: unknown field(s) {sorted(unknown)}{hint}; allowed: {sorted(allowed)}")


def _required(mapping: dict, key: str, where: str):
    if key not in mapping:
        raise RobotDefinitionError(f"{where}: missing field '{key}'")
    return mapping[key]


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RobotDefinitionError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _vector(value, n: int, where: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise RobotDefinitionError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return np.array([_number(v, where) for v in value])


def _limits(value, where: str) -> np.ndarray:
    lim = _vector(value, 2, f"{where}.limits")
    if not lim[0] < lim[1]:
        raise RobotDefinitionError(f"{where}.limits: lower must be < upper, got {value!r}")
    return lim


def _flange(spec, length: float, angle: float, where: str) -> tuple[str, np.ndarray]:
    """``{link: NAME, position: ..., rpy | rotation | quaternion: ...}`` -> (NAME, 4x4): the vendor's flange."""
    if not isinstance(spec, dict) or not isinstance(spec.get("link"), str) or not spec["link"]:
        raise RobotDefinitionError(f"{where}: expected a mapping with 'link' (the flange's name) and its frame")
    return spec["link"], _frame({k: v for k, v in spec.items() if k != "link"}, length, angle, where)


def _frame(spec, length: float, angle: float, where: str) -> np.ndarray | None:
    """``{position: [x, y, z], rpy: [r, p, y] | rotation: 3x3 | quaternion: [w, x, y, z]}`` -> 4x4, or None."""
    if spec is None:
        return None
    if not isinstance(spec, dict):
        raise RobotDefinitionError(
            f"{where}: expected a mapping with 'position' and optionally 'rpy', 'rotation' or 'quaternion'"
        )
    _no_unknown(spec, {"position", "rpy", "rotation", "quaternion"}, where)
    T = np.eye(4)
    T[:3, 3] = _vector(spec.get("position", [0, 0, 0]), 3, f"{where}.position") * length
    given = [key for key in ("rpy", "rotation", "quaternion") if key in spec]
    if len(given) > 1:
        raise RobotDefinitionError(f"{where}: give one of 'rpy', 'rotation', 'quaternion', not {' and '.join(given)}")
    if "quaternion" in spec:
        quat = _vector(spec["quaternion"], 4, f"{where}.quaternion")
        T[:3, :3] = as_frame(np.concatenate([np.zeros(3), quat]), name=f"{where}.quaternion")[:3, :3]
    elif "rpy" in spec:
        import torch

        rpy = torch.tensor(_vector(spec["rpy"], 3, f"{where}.rpy") * angle, dtype=torch.float64)
        T[:3, :3] = rpy_to_matrix(rpy).numpy()
    elif "rotation" in spec:
        rows = spec["rotation"]
        if not isinstance(rows, list) or len(rows) != 3:
            raise RobotDefinitionError(f"{where}.rotation: expected a 3x3 list of rows")
        R = np.stack([_vector(r, 3, f"{where}.rotation") for r in rows])
        err = np.abs(R.T @ R - np.eye(3)).max()
        if err > 1e-6 or abs(np.linalg.det(R) - 1) > 1e-6:
            raise RobotDefinitionError(f"{where}.rotation: not a rotation matrix (|R^T R - I| = {err:.3g})")
        T[:3, :3] = R
    return T
