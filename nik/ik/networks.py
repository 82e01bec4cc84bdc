"""The network of an :class:`~nik.ik.solver.IKSolver`: the one shipped for its robot, or a checkpoint, loaded once
per process.

Loading a shipped network costs tens of milliseconds (building a 3 x 512 MLP, copying half a million weights),
more than solving a pose. So every solver of the same robot shares the network loaded first (a solver only
reads it, in eval mode): loaded networks are kept by file (path, size, modification time), robot definition
hash and device. A changed file is a new key, so it is loaded again.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import torch

__all__ = ["checkpoint_network", "clear", "shipped_network"]

_LOADED: dict[tuple, torch.nn.Module] = {}
_META: dict[tuple, dict] = {}


def _stamp(path: Path) -> tuple:
    st = os.stat(path)
    return str(path), st.st_size, st.st_mtime_ns


def _load_once(path: Path, robot, device, load: Callable[[], torch.nn.Module]) -> torch.nn.Module:
    key = (*_stamp(path), robot.definition_hash, str(device))
    net = _LOADED.get(key)
    if net is None:
        net = _LOADED[key] = load().to(device)
    return net


def shipped_network(robot, device) -> Callable[[], torch.nn.Module] | None:
    """A loader of the network shipped for ``robot`` (on ``device``) when one exists for its name and definition
    hash, else None. Checking reads the small ``.json`` once per file; the weights load when the loader is called,
    once per process."""
    from nik.nets.pretrained import PRETRAINED_DIR

    meta_path = PRETRAINED_DIR / f"{robot.name}.json"
    weights = meta_path.with_suffix(".safetensors")
    if not (meta_path.is_file() and weights.is_file()):
        return None
    key = _stamp(meta_path)
    meta = _META.get(key)
    if meta is None:
        from nik.nets.pretrained import read_meta

        meta = _META[key] = read_meta(robot.name)
    if meta.get("robot_hash") != robot.definition_hash:
        return None

    def load():
        from nik.nets.pretrained import load_pretrained

        return _load_once(weights, robot, device, lambda: load_pretrained(robot))

    return load


def checkpoint_network(path, robot, device) -> torch.nn.Module:
    """The network of the checkpoint ``path`` for ``robot`` on ``device`` (:func:`nik.nets.load_checkpoint`: one
    made for another robot is refused), loaded once per process."""
    from nik.nets import load_checkpoint

    path = Path(path)
    if not path.is_file():  # let load_checkpoint word the error
        return load_checkpoint(path, robot=robot).to(device)
    return _load_once(path.resolve(), robot, device, lambda: load_checkpoint(path, robot=robot))


def clear() -> None:
    """Forget every loaded network (the next solver loads its own)."""
    _LOADED.clear()
    _META.clear()
