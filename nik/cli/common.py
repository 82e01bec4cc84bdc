"""Arguments shared by the ``nik`` commands that take an arm: ``--robot``, for URDF arms ``--end-link``, and the
``--base`` / ``--tool`` frames."""

from __future__ import annotations

import sys
import warnings

__all__ = ["add_robot_arguments", "robot_from_args", "tool_link_text"]

_FRAME = ("X", "Y", "Z", "QW", "QX", "QY", "QZ")


def add_robot_arguments(parser) -> None:
    """``--robot`` (required), ``--end-link`` (the tool link of a URDF arm), ``--base`` and ``--tool``."""
    parser.add_argument("--robot", required=True, help="built-in robot name or robot file (YAML/URDF)")
    parser.add_argument(
        "--end-link",
        default=None,
        metavar="LINK",
        help="tool link of a URDF arm (built-ins ur5 and panda included); default: a conventional tool link "
        "(*tcp*, *end_effector*, tool0, ee, flange, tool) at the end of the longest chain of revolute joints, "
        "gripper joints left out (docs/robots.md; the output names the one used)",
    )
    parser.add_argument(
        "--base",
        type=float,
        nargs=7,
        default=None,
        metavar=_FRAME,
        help="the robot's base in your world frame: position (metres, whatever --unit) and unit quaternion; "
        "poses are then in the world frame",
    )
    parser.add_argument(
        "--tool",
        type=float,
        nargs=7,
        default=None,
        metavar=_FRAME,
        help="the tool centre point (TCP) in the frame of the last link: position (metres, whatever --unit) and "
        "unit quaternion; poses are then the TCP's (a network trained without it is not used)",
    )


def robot_from_args(args):
    """The robot of ``--robot`` with ``--end-link``, ``--base`` and ``--tool``.

    ``--end-link`` on an arm without links is a ValueError; a note on the default tool link (gripper joints
    left out, several candidates) goes to stderr as one line.
    """
    from nik.errors import RobotDefinitionWarning
    from nik.robots import load_robot

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RobotDefinitionWarning)
        robot = load_robot(
            args.robot,
            end_link=args.end_link,
            base=getattr(args, "base", None),
            tool=getattr(args, "tool", None),
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


def tool_link_text(robot) -> str:
    """``" (tool link NAME)"`` for a URDF arm, with ``", tool frame at x, y, z mm"`` when a tool frame is set;
    ``""`` for an arm without links or frames."""
    parts = [f"tool link {robot.end_link}"] if robot.end_link else []
    tool = getattr(robot, "tool", None)
    if tool is not None:
        parts.append("tool frame at " + ", ".join(f"{1e3 * float(v):.1f}" for v in tool[:3, 3]) + " mm")
    return f" ({', '.join(parts)})" if parts else ""
