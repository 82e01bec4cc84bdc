"""Checkpoints of IK networks: a Lightning ``.ckpt`` (or :func:`save_checkpoint` file) read safely; and
:func:`load_network`, which reads any network file (an exported pair or a checkpoint).

A checkpoint holds ``state_dict`` (keys ``net.*``) and a ``checkpoint["nik"]`` block of plain data: the
robot's definition and hash and the network's architecture, so ``torch.load(weights_only=True)`` reads it
and the network is rebuilt without running code from the file.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch

from nik.errors import CheckpointError, CheckpointNotFoundError
from nik.nets.mlp import IKNet
from nik.nets.multi import build_net
from nik.nets.pair import architecture_mismatch, load_pair
from nik.robots import Robot, load_robot

__all__ = ["CHECKPOINT_FORMAT", "checkpoint_extra", "load_checkpoint", "load_network", "save_checkpoint"]

#: Version of the ``checkpoint["nik"]`` block.
CHECKPOINT_FORMAT = 1


def checkpoint_extra(net: IKNet) -> dict:
    """The ``checkpoint["nik"]`` block: plain data only, so ``torch.load(weights_only=True)`` reads it."""
    return {
        "format": CHECKPOINT_FORMAT,
        "robot": net.robot.to_definition(),
        "robot_hash": net.robot.definition_hash,
        "net": net.config(),
    }


def save_checkpoint(net: IKNet, path: str | Path) -> Path:
    """Save ``net`` alone in the same layout as a Lightning checkpoint (``state_dict`` keys ``net.*``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {f"net.{k}": v.detach().cpu().clone() for k, v in net.state_dict().items()}
    torch.save({"state_dict": state, "nik": checkpoint_extra(net)}, path)
    return path


def load_checkpoint(
    path: str | Path, *, robot: Robot | str | Path | None = None, map_location: str | torch.device = "cpu"
) -> IKNet:
    """Load an :class:`IKNet` (or a multi-solution network) from a Lightning ``.ckpt`` (or :func:`save_checkpoint`
    file), safely; an exported pair (``NAME.safetensors`` / ``NAME.json``) is read too (:func:`load_network`), so a
    network loads by path however it was trained and whether or not it was exported.

    The file is read with ``torch.load(..., weights_only=True)``: no code from it is run.

    Args:
        path: the checkpoint (or either file of an exported pair: float32, CPU, ``map_location`` applied after).
        robot: optional robot (object, built-in name or file) the network must belong to, matched by
            definition hash (not name); a checkpoint made for a different robot definition is refused.
            The network's ``robot`` is then this one.

    Returns:
        the network in eval mode; without ``robot``, ``net.robot`` is rebuilt from the stored definition.

    Raises:
        CheckpointError: a folder, an unreadable or damaged file, no nik block, a robot mismatch (both
            robots named) or weights that do not fit the stored architecture (the field named); one line.
        CheckpointNotFoundError: no such file (a CheckpointError and a FileNotFoundError).
    """
    path = Path(path)
    if path.suffix in (".safetensors", ".json"):
        return load_pair(path, robot=robot).to(map_location)
    if path.is_dir():
        raise CheckpointError(f"{path} is a folder, not a checkpoint file")
    if not path.is_file():
        raise CheckpointNotFoundError(f"checkpoint not found: {path}")
    try:
        with warnings.catch_warnings():  # torch warns about the pickle protocol of files it then refuses
            warnings.simplefilter("ignore")
            ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as err:  # torch's own text spans several lines and suggests weights_only=False: not ours
        raise CheckpointError(
            f"{path} is not a loadable nik checkpoint (torch.load(weights_only=True) refused it: "
            f"{type(err).__name__}; damaged, truncated or not a checkpoint)"
        ) from err
    if not isinstance(ckpt, dict) or "nik" not in ckpt or "state_dict" not in ckpt:
        raise CheckpointError(f"{path} is not a loadable nik checkpoint (no 'nik' block with the robot and network)")
    extra = ckpt["nik"]
    try:
        stored = Robot.from_definition(extra["robot"])
        cfg = dict(extra["net"])
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: malformed nik block: {str(err).splitlines()[0]}") from err
    if robot is not None:
        robot = load_robot(robot)
        if robot.definition_hash != stored.definition_hash:
            raise CheckpointError(
                f"checkpoint {path} was trained for robot {stored.name!r} (hash {stored.definition_hash}), "
                f"not for robot {robot.name!r} (hash {robot.definition_hash})"
            )
    owner = robot if robot is not None else stored
    try:
        net = build_net(owner, cfg) if "kind" in cfg else IKNet(owner, **cfg)
    except (TypeError, ValueError) as err:
        reason = str(err).splitlines()[0]
        raise CheckpointError(f"{path}: the stored architecture {cfg} is not valid: {reason}") from err
    state = {k[len("net.") :]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")}
    problem = architecture_mismatch(net, state, cfg)
    if problem is not None:
        raise CheckpointError(f"{path}: the weights do not fit the stored architecture: {problem}")
    net.load_state_dict(state)
    return net.to(torch.float32).eval() if "kind" in cfg else net.eval()


def load_network(path: str | Path, *, robot: Robot | str | Path | None = None):
    """Any network file: an exported pair (``NAME.safetensors`` or ``NAME.json``, :func:`nik.nets.pair.load_pair`,
    SHA-256 checked) or a Lightning / :func:`save_checkpoint` file (:func:`load_checkpoint`), matched to
    ``robot`` by definition hash. Raises ``CheckpointError`` (one line; a missing file too)."""
    p = Path(path)
    if p.suffix in (".safetensors", ".json"):
        return load_pair(p, robot=robot)
    return load_checkpoint(p, robot=robot)
