"""The network of an :class:`~nik.ik.solver.IKSolver`: the one known for its robot (installed or shipped), or a
file it was given, loaded once per process.

Loading a shipped network costs tens of milliseconds (building a 3 x 512 MLP, copying half a million weights),
more than solving a pose. So every solver of the same robot shares the network loaded first (a solver only
reads it, in eval mode): loaded networks are kept by file (path, size, modification time), robot definition
hash and name, and device. A changed file is a new key, so it is loaded again.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import torch

__all__ = ["checkpoint_network", "clear", "shipped_network", "single_pose_network"]

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


def shipped_network(robot, device, *, single_pose: bool = False) -> Callable[[], torch.nn.Module] | None:
    """A loader of the network known for ``robot``'s definition hash, whatever its name (one installed in the
    user folder, else the one shipped: :func:`nik.nets.registry.find_network`), on ``device``; None when there is
    none. Finding reads the small ``.json`` files once per file; the weights load (SHA-256 checked) when the
    loader is called, once per process. ``single_pose=True``: the small network for single poses instead
    (:func:`nik.nets.registry.find_single_pose_network`)."""
    from nik.nets.registry import find_network, find_single_pose_network

    path = (find_single_pose_network if single_pose else find_network)(robot)
    if path is None:
        return None

    def load():
        from nik.nets.pair import load_pair

        return _load_once(path, robot, device, lambda: load_pair(path, robot=robot))

    return load


def single_pose_network(robot, device) -> Callable[[], torch.nn.Module] | None:
    """A loader of ``robot``'s single-pose network (see :func:`shipped_network`), or None."""
    return shipped_network(robot, device, single_pose=True)


def checkpoint_network(path, robot, device) -> torch.nn.Module:
    """The network of the file ``path`` for ``robot`` on ``device``: an exported pair or a Lightning checkpoint
    (:func:`nik.nets.load_network`: one made for another robot definition, or a damaged file, is refused), loaded
    once per process."""
    from nik.nets import load_network

    path = Path(path)
    if not path.is_file():  # let load_network word the error
        return load_network(path, robot=robot).to(device)
    return _load_once(path.resolve(), robot, device, lambda: load_network(path, robot=robot))


def clear() -> None:
    """Forget every loaded network (the next solver loads its own)."""
    _LOADED.clear()
