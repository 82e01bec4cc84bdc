"""Arguments shared by the ``nik`` commands that take an arm: ``--robot``, for URDF arms ``--end-link``, and the
``--base`` / ``--tool`` frames, and ``--quat-order``: the order of the quaternions given on the command line."""

from __future__ import annotations

import contextlib
import sys
import warnings
from pathlib import Path

__all__ = [
    "add_robot_arguments",
    "add_root_link_argument",
    "notes_as_lines",
    "quat_wxyz",
    "robot_from_args",
    "tool_link_text",
]

_NIK_DIR = str(Path(__file__).resolve().parents[1])

_FRAME = ("X", "Y", "Z", "QW", "QX", "QY", "QZ")


def add_robot_arguments(parser) -> None:
    """``--robot`` (required), ``--end-link`` (the tool link of a URDF arm), ``--base``, ``--tool`` and
    ``--quat-order``."""
    parser.add_argument("--robot", required=True, help="built-in robot name or robot file (YAML/URDF)")
    parser.add_argument(
        "--end-link",
        default=None,
        metavar="LINK",
        help="tool link of a URDF arm (built-ins ur5 and panda included); default: a conventional tool link "
        "(*tcp*, *end_effector*, tool0, ee, flange, tool) at the end of the longest chain of revolute joints, "
        "gripper joints left out (docs/robots.md; the output names the one used)",
    )
    add_root_link_argument(parser)
    parser.add_argument(
        "--base",
        type=float,
        nargs=7,
        default=None,
        metavar=_FRAME,
        help="the robot's base in your world frame: position (the unit of --unit where the command has one, else "
        "metres) and unit quaternion; poses are then in the world frame",
    )
    parser.add_argument(
        "--tool",
        type=float,
        nargs=7,
        default=None,
        metavar=_FRAME,
        help="the tool centre point (TCP) in the flange's frame (the last link, or a built-in's flange: ur5's tool0, "
        "panda's panda_link8): position (the unit of --unit where the command has one, else metres) and unit "
        "quaternion; poses are then the TCP's",
    )
    parser.add_argument(
        "--quat-order",
        choices=["wxyz", "xyzw"],
        default="wxyz",
        help="order of the quaternions given as numbers (--pose, --base, --tool): wxyz (default: QW QX QY QZ) or "
        "xyzw (QX QY QZ QW, the order of ROS messages); a CSV's columns are read by their names (qw,qx,qy,qz)",
    )


def quat_wxyz(frame, args):
    """``X Y Z`` and a quaternion given on the command line, with the quaternion brought to w, x, y, z (nik's order)
    from ``--quat-order`` (``args.quat_order``; absent: wxyz); None stays None."""
    if frame is None or getattr(args, "quat_order", "wxyz") == "wxyz":
        return frame
    x, y, z, qx, qy, qz, qw = frame
    return [x, y, z, qw, qx, qy, qz]


def add_root_link_argument(parser) -> None:
    """``--root-link LINK``: the link a URDF arm's chain starts from (:func:`nik.load_robot`'s ``root_link``)."""
    parser.add_argument(
        "--root-link",
        default=None,
        metavar="LINK",
        help="URDF: the link the arm starts from (default the URDF's root); on a mobile manipulator, e.g. "
        "torso_lift_link for TIAGo or PR2, the arm without the torso lift, poses in that link's frame",
    )


def robot_from_args(args):
    """The robot of ``--robot`` with ``--end-link``, ``--root-link``, ``--base`` and ``--tool`` (positions in
    ``--unit`` where the command has one: ``--unit mm`` reads them in millimetres, as the poses).

    ``--end-link`` on an arm without links is a ValueError; a note on the default tool link (gripper joints
    left out, several candidates) goes to stderr as one line.
    """
    from nik.errors import RobotDefinitionWarning
    from nik.robots import load_robot

    scale = 1e-3 if getattr(args, "unit", "m") == "mm" else 1.0  # --base / --tool positions follow --unit
    base, tool = (_frame_si(quat_wxyz(getattr(args, key, None), args), scale) for key in ("base", "tool"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RobotDefinitionWarning)
        robot = load_robot(
            args.robot, end_link=args.end_link, base=base, tool=tool, root_link=getattr(args, "root_link", None)
        )
    for w in caught:
        if issubclass(w.category, RobotDefinitionWarning):
            print(f"nik: note: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if args.end_link is not None and robot.end_link is None:
        raise ValueError(
            f"--end-link applies to URDF arms; {robot.name} is defined by joint parameters (no links to choose from)"
        )
    return robot


def _frame_si(frame, scale: float):
    """``X Y Z QW QX QY QZ`` with the position times ``scale`` (to metres); None stays None."""
    if frame is None:
        return None
    return [v * scale for v in frame[:3]] + list(frame[3:])


@contextlib.contextmanager
def notes_as_lines():
    """While the block runs, nik's own warnings (:class:`nik.RobotDefinitionWarning`, and user warnings raised
    from nik's code) are printed to stderr as they come, each as one line ``nik: note: MESSAGE`` with no source
    line; other warnings are shown as Python shows them."""
    from nik.errors import RobotDefinitionWarning

    with warnings.catch_warnings():
        warnings.simplefilter("always", RobotDefinitionWarning)
        shown = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            ours = issubclass(category, RobotDefinitionWarning) or (
                issubclass(category, UserWarning) and str(filename).startswith(_NIK_DIR)
            )
            if ours:
                print(f"nik: note: {message}", file=sys.stderr, flush=True)
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        yield


def tool_link_text(robot) -> str:
    """``" (tool link NAME)"`` for a URDF arm (``" (flange tool0 on wrist_3_link)"`` where the robot file names
    the vendor's flange), with ``", tool frame at x, y, z mm"`` when a tool frame is set (past the flange);
    ``""`` for an arm without links or frames."""
    tool, flange = getattr(robot, "tool", None), getattr(robot, "flange", None)
    if flange is not None:
        on = f" on {robot.end_link}" if robot.end_link else ""
        parts = [f"flange {robot.flange_link}{on}"]
        import torch

        tool = torch.linalg.inv(flange) @ tool  # the part past the flange
        if torch.allclose(tool, torch.eye(4, dtype=tool.dtype), atol=1e-12, rtol=0):
            tool = None
    else:
        parts = [f"tool link {robot.end_link}"] if robot.end_link else []
    if tool is not None:
        parts.append("tool frame at " + ", ".join(f"{1e3 * float(v):.1f}" for v in tool[:3, 3]) + " mm")
    return f" ({', '.join(parts)})" if parts else ""
