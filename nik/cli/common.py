"""Arguments shared by the ``nik`` commands that take an arm: ``--robot`` and, for URDF arms, ``--end-link``."""

from __future__ import annotations

__all__ = ["add_robot_arguments", "robot_from_args", "tool_link_text"]


def add_robot_arguments(parser) -> None:
    """``--robot`` (required) and ``--end-link`` (the tool link of a URDF arm)."""
    parser.add_argument("--robot", required=True, help="built-in robot name or robot file (YAML/URDF)")
    parser.add_argument(
        "--end-link",
        default=None,
        metavar="LINK",
        help="tool link of a URDF arm (built-ins ur5 and panda included); default: the last link of the longest "
        "chain of revolute joints (the output names the one used)",
    )


def robot_from_args(args):
    """The robot of ``--robot`` with ``--end-link``; ``--end-link`` on an arm without links is a ValueError."""
    from nik.robots import load_robot

    robot = load_robot(args.robot, end_link=args.end_link)
    if args.end_link is not None and robot.end_link is None:
        raise ValueError(
            f"--end-link applies to URDF arms; {robot.name} is defined by joint parameters (no links to choose from)"
        )
    return robot


def tool_link_text(robot) -> str:
    """``" (tool link NAME)"`` for a URDF arm, ``""`` for one without links."""
    return f" (tool link {robot.end_link})" if robot.end_link else ""
