"""The network of an :class:`~nik.solver.IKSolver`: the one known for its robot (installed or shipped), or a
file it was given, loaded once per process.

Loading a shipped network costs tens of milliseconds (building a 4 x 256 MLP, copying a quarter of a million
weights), more than solving a pose. So every solver of the same robot shares the network loaded first (a solver only
reads it, in eval mode): loaded networks are kept by file (path, size, modification time), robot definition
hash and name, and device. A changed file is a new key, so it is loaded again.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import torch

__all__ = ["checkpoint_network", "clear", "known_network"]

_LOADED: dict[tuple, torch.nn.Module] = {}


def _stamp(path: Path) -> tuple:
    st = os.stat(path)
    return str(path), st.st_size, st.st_mtime_ns


def _load_once(path: Path, robot, device, load: Callable[[], torch.nn.Module]) -> torch.nn.Module:
    key = (*_stamp(path), robot.definition_hash, robot.name, str(device))  # the net's robot is this one
    net = _LOADED.get(key)
    if net is None:
        net = _LOADED[key] = load().to(device)
    return net


def known_network(robot, device, *, single_pose: bool = False) -> tuple[torch.nn.Module | None, bool]:
    """``(network, installed)``: the network known for ``robot`` (its definition hash, else its bare arm's
    :attr:`nik.Robot.arm_hash`: base and tool frames left out, so a framed arm keeps it; whatever its name), one
    installed in the user folder, else the one shipped (:func:`nik.nets.registry.find_network`), loaded on ``device``
    once per process (SHA-256 checked), and whether it is the user's (installed) rather than shipped; ``(None,
    False)`` when there is none. ``single_pose=True``: the small network for single poses instead
    (:func:`nik.nets.registry.find_single_pose_network`).
    """
    from nik.nets.pair import load_pair
    from nik.nets.registry import SHIPPED_DIR, find_network, find_single_pose_network

    path = (find_single_pose_network if single_pose else find_network)(robot)
    if path is None and robot.base is None and robot.tool is None:
        path = _same_arm(robot, single_pose)
    if path is None:
        return None, False
    net = _load_once(path, robot, device, lambda: load_pair(path, robot=robot))
    return net, not path.resolve().is_relative_to(SHIPPED_DIR.resolve())


def checkpoint_network(path, robot, device) -> torch.nn.Module:
    """The network of the file ``path`` for ``robot`` on ``device``: an exported pair or a Lightning checkpoint
    (:func:`nik.nets.load_network`: one made for another robot definition, or a damaged file, is refused), loaded
    once per process. A robot with base/tool frames also takes a network made for its bare arm
    (:attr:`nik.Robot.arm`)."""
    from nik.errors import CheckpointError
    from nik.nets import load_network

    path = Path(path)
    if not path.is_file():  # let load_network word the error
        return load_network(path, robot=robot).to(device)
    try:
        return _load_once(path.resolve(), robot, device, lambda: load_network(path, robot=robot))
    except CheckpointError:
        arm = robot.arm
        if arm is robot:
            raise
        try:
            return _load_once(path.resolve(), arm, device, lambda: load_network(path, robot=arm))
        except CheckpointError:
            pass
        raise


def solver_networks(checkpoint, robot, device, closed_form: bool) -> tuple:
    """``(net, single_pose_net, given)`` of an :class:`nik.IKSolver` built with ``checkpoint``: ``"auto"`` the
    arm's installed or shipped networks where it has no closed form (loaded once per process, SHA-256 checked: a
    damaged file is refused here; an installed main network takes an installed single-pose one only), a path that
    network alone (``given``), None none. ``single_pose_net``, where there is one, guesses on the CPU
    (:func:`nik.ik.plan.choose_network`)."""
    if isinstance(checkpoint, str) and checkpoint == "auto":
        if closed_form:
            return None, None, False
        net, given = known_network(robot, device)
        one, one_installed = known_network(robot, device, single_pose=True) if net is not None else (None, False)
        if given and not one_installed:  # the user's own network is not served by a shipped single-pose one
            one = None
        return net, one, given
    if checkpoint is not None:
        return checkpoint_network(checkpoint, robot, device), None, True
    return None, None, False


def _same_arm(robot, single_pose: bool) -> Path | None:
    """The network of the same arm under another definition (:func:`nik.nets.registry.find_same_arm`: another file
    of the same robot, or another end link a fixed transform past the network's), or None. Found, ``robot`` records
    that arm and the tool frame between (:func:`nik.robots.frames.adopt_arm`), so the network guesses in the arm's
    frame, ``T @ tool^-1``, as for any robot with a tool."""
    from nik.ik.model import forget_model
    from nik.nets.registry import SINGLE_POSE, find_same_arm
    from nik.robots.frames import adopt_arm

    found = find_same_arm(robot, role=SINGLE_POSE if single_pose else None)
    if found is None:
        return None
    path, arm, tool = found
    adopt_arm(robot, arm, tool)
    forget_model(robot)  # a model built before holds no tool frame
    return path


def clear() -> None:
    """Forget every loaded network (the next solver loads its own)."""
    _LOADED.clear()
