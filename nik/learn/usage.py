"""How to get an installed network into a solver: the lines ``nik train --install`` and ``nik networks install`` print.

:class:`nik.IKSolver` finds an installed network by the arm's definition hash, never by its name
(:mod:`nik.nets.registry`), so the way to get it is to load the same arm: a built-in name, the YAML file, or the
URDF with the same tool link. :func:`robot_expression` writes that call and checks it (it loads the arm and
compares the hash) before saying it. On an arm with a closed form (:func:`nik.analytic.family`) the closed form
stays the default first guess and the auto-found network is not loaded; ``checkpoint=PATH`` makes the solver use
the network on every call (``res.source`` says which guess served each call).
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

from nik.robots import Robot, builtin_robots, load_robot

__all__ = ["network_usage", "recorded_source", "robot_expression"]


def _same_arm(expr_args: tuple, robot: Robot, root_link: str | None = None) -> bool:
    path, end_link = expr_args
    try:
        return load_robot(path, end_link=end_link, root_link=root_link).definition_hash == robot.definition_hash
    except (ValueError, OSError):
        return False


def robot_expression(
    robot: Robot,
    source: str | Path | Robot | None = None,
    end_link: str | None = None,
    *,
    root_link: str | None = None,
) -> str | None:
    """Python that loads ``robot`` again, as an argument of ``nik.IKSolver(...)``: ``"NAME"`` for a built-in,
    ``"/abs/arm.yaml"`` for a YAML file, ``nik.load_robot("/abs/arm.urdf", end_link="LINK")`` for a URDF (the
    tool link the arm really has; ``root_link="LINK"`` added where one was given). ``source``: how the arm was
    given (a name or path; a :class:`Robot` or None); where it does not give the same arm, a built-in of the
    robot's name is tried. None when no such call gives the same definition hash."""
    if source is not None and not isinstance(source, Robot):
        path = Path(source)
        if not path.is_file():  # a built-in name
            if end_link is None and _same_arm((str(source), None), robot, root_link):
                return _call(json.dumps(str(source)), None, root_link)
        else:
            path = path.resolve()
            link = robot.end_link if path.suffix.lower() == ".urdf" else end_link
            if _same_arm((path, link), robot, root_link):
                return _call(json.dumps(str(path)), link, root_link)
    if robot.name in builtin_robots() and _same_arm((robot.name, None), robot):
        return json.dumps(robot.name)
    return None


def _call(arm: str, end_link: str | None, root_link: str | None) -> str:
    """``arm`` (a quoted name or path) as the argument of ``nik.IKSolver``: itself, or a ``nik.load_robot`` call."""
    keywords = [f"{k}={json.dumps(v)}" for k, v in (("end_link", end_link), ("root_link", root_link)) if v]
    return f"nik.load_robot({', '.join([arm, *keywords])})" if keywords else arm


def recorded_source(meta: dict) -> tuple[str | None, str | None]:
    """``(ROBOT, END_LINK)`` of the ``nik train ROBOT [--end-link LINK]`` command recorded in a pair's JSON
    (``meta["training"]["command"]``), or ``(None, None)`` where it records none (a path is relative to where
    it ran: :func:`robot_expression` checks it before it is said)."""
    command = (meta.get("training") or {}).get("command")
    try:
        words = shlex.split(command) if isinstance(command, str) else []
    except ValueError:
        return None, None
    if len(words) < 3 or words[1] != "train" or words[2].startswith("-"):
        return None, None
    end_link = None
    for k, w in enumerate(words[:-1]):
        if w == "--end-link":
            end_link = words[k + 1]
    for w in words:
        if w.startswith("--end-link="):
            end_link = w.split("=", 1)[1]
    return words[2], end_link


def network_usage(
    robot: Robot,
    installed: str | Path,
    *,
    source: str | Path | Robot | None = None,
    end_link: str | None = None,
    root_link: str | None = None,
) -> list[str]:
    """What to call to solve with the network installed at ``installed`` for ``robot`` (module docstring): lines of
    text, each ending with the Python to run. ``source``, ``end_link``: how the arm was given
    (:func:`robot_expression`; a :class:`Robot` that is no built-in is called ``robot``)."""
    from nik.analytic import family

    h = robot.definition_hash
    expr = robot_expression(robot, source, end_link, root_link=root_link)
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
    return [
        f"{robot.name} has a closed form ({fam}), which stays the default first guess for {which}: "
        f"nik.IKSolver({arm}) does not use the network",
        f"to solve with the network: nik.IKSolver({arm}, checkpoint={json.dumps(str(Path(installed)))})",
    ]
