"""``--scene FILE``: obstacles for ``nik solve`` and ``nik path`` (a :class:`nik.World` from a YAML/JSON scene file).

The option and its reading live here so the commands each add one argument and one call; a bad file is a one-line
``ValueError`` (:meth:`nik.World.from_file`), which the CLI prints as ``nik solve: error: ...`` (exit 2).
"""

from __future__ import annotations

__all__ = ["add_scene_argument", "world_from_args"]


def add_scene_argument(parser) -> None:
    """Add ``--scene FILE.yaml|json`` to ``parser``."""
    parser.add_argument(
        "--scene",
        metavar="FILE.yaml",
        help="obstacles in the robot's base frame (YAML/JSON: spheres, boxes, capsules, points; metres, or "
        "millimetres with a key 'unit: mm'): answers that collide with them or with the arm itself are solved again "
        "or reported as failures (docs/collisions.md)",
    )


def world_from_args(args):
    """The :class:`nik.World` of ``--scene`` (None without it)."""
    path = getattr(args, "scene", None)
    if path is None:
        return None
    from nik.cli.common import notes_as_lines
    from nik.collision import World

    with notes_as_lines():  # a scene that looks written in millimetres: one line
        return World.from_file(path)
