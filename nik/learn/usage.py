"""How to get an installed network into a solver: the lines ``nik train --install`` and ``nik networks install`` print.

:class:`nik.IKSolver` finds an installed network by the arm's definition hash, never by its name
(:mod:`nik.nets.registry`), so the way to get it is to load the same arm: a built-in name, the YAML file, or the
URDF with the same tool link. :func:`robot_expression` writes that call and checks it (it loads the arm and
compares the hash) before saying it. On an arm with a closed form (:func:`nik.analytic.family`) the closed form
stays the default first guess and the auto-found network is not loaded; ``checkpoint=PATH`` makes the solver use
the network (for batches of :attr:`nik.IKSolver.network_min_batch` poses or more on the CPU; ``res.source`` says
which guess served each call).
"""

from __future__ import annotations

import json
from pathlib import Path

from nik.robots import Robot, builtin_robots, load_robot

__all__ = ["network_usage", "robot_expression"]


def _same_arm(expr_args: tuple, robot: Robot) -> bool:
    path, end_link = expr_args
    try:
        return load_robot(path, end_link=end_link).definition_hash == robot.definition_hash
    except (ValueError, OSError):
        return False


def robot_expression(robot: Robot, source: str | Path | Robot | None = None, end_link: str | None = None) -> str | None:
    """Python that loads ``robot`` again, as an argument of ``nik.IKSolver(...)``: ``"NAME"`` for a built-in,
    ``"/abs/arm.yaml"`` for a YAML file, ``nik.load_robot("/abs/arm.urdf", end_link="LINK")`` for a URDF (the
    tool link the arm really has). ``source``: how the arm was given (a name or path; a :class:`Robot` or None:
    a built-in of the same name is tried). None when no such call gives the same definition hash."""
    if source is None or isinstance(source, Robot):
        name = robot.name
        if name in builtin_robots() and _same_arm((name, None), robot):
            return json.dumps(name)
        return None
    path = Path(source)
    if not path.is_file():  # a built-in name
        return json.dumps(str(source)) if end_link is None and _same_arm((str(source), None), robot) else None
    path = path.resolve()
    is_urdf = path.suffix.lower() == ".urdf"
    link = robot.end_link if is_urdf else end_link
    if not _same_arm((path, link), robot):
        return None
    if link is None:
        return json.dumps(str(path))
    return f"nik.load_robot({json.dumps(str(path))}, end_link={json.dumps(link)})"


def network_usage(
    robot: Robot, installed: str | Path, *, source: str | Path | Robot | None = None, end_link: str | None = None
) -> list[str]:
    """What to call to solve with the network installed at ``installed`` for ``robot`` (module docstring): lines of
    text, each ending with the Python to run. ``source``, ``end_link``: how the arm was given
    (:func:`robot_expression`; a :class:`Robot` that is no built-in is called ``robot``)."""
    from nik.analytic import family
    from nik.ik import IKSolver

    h = robot.definition_hash
    expr = robot_expression(robot, source, end_link)
    if expr is not None:
        arm, which = expr, f"this arm (definition hash {h})"
    elif isinstance(source, Robot):
        arm, which = "robot", f"this Robot (definition hash {h}) or any arm of the same definition"
    else:
        link = f", end_link={json.dumps(robot.end_link)}" if robot.end_link else ""
        arm = f"nik.load_robot(ARM{link})"
        which = f"any arm of definition hash {h}, e.g. the file ARM that {robot.name} was trained from"
    fam = family(robot)
    if fam is None:
        return [f"nik.IKSolver finds it for {which}, by definition, not by name: nik.IKSolver({arm})"]
    few = IKSolver.network_min_batch
    when = f" (batches of {few} poses or more; a single CPU pose keeps the closed form)" if few > 1 else ""
    return [
        f"{robot.name} has a closed form ({fam}), which stays the default first guess for {which}: "
        f"nik.IKSolver({arm}) does not use the network",
        f"to solve with the network{when}: nik.IKSolver({arm}, checkpoint={json.dumps(str(Path(installed)))})",
    ]
