"""Checkpoints of IK networks: a Lightning ``.ckpt`` (or :func:`save_checkpoint` file) read safely.

A checkpoint holds ``state_dict`` (keys ``net.*``) and a ``checkpoint["nik"]`` block of plain data: the
robot's definition and hash and the network's architecture, so ``torch.load(weights_only=True)`` reads it
and the network is rebuilt without running code from the file.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch

from nik.errors import CheckpointError
from nik.nets.mlp import IKNet
from nik.nets.multi import build_net
from nik.robots import Robot, load_robot

__all__ = ["CHECKPOINT_FORMAT", "checkpoint_extra", "load_checkpoint", "save_checkpoint"]

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
    """Load an :class:`IKNet` from a Lightning ``.ckpt`` (or :func:`save_checkpoint` file), safely.

    The file is read with ``torch.load(..., weights_only=True)``: no code from it is run.

    Args:
        path: the checkpoint.
        robot: optional robot (object, built-in name or file) the network must belong to; a
            checkpoint made for a different robot definition is refused.

    Returns:
        the network in eval mode; ``net.robot`` is rebuilt from the stored definition.

    Raises:
        CheckpointError: a folder, an unreadable file, no nik block, or a robot mismatch (both robots named).
        FileNotFoundError: no such file.
    """
    path = Path(path)
    if path.is_dir():
        raise CheckpointError(f"checkpoint {path} is a folder, not a checkpoint file (.ckpt)")
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    try:
        with warnings.catch_warnings():  # torch warns about the pickle protocol of files it then refuses
            warnings.simplefilter("ignore")
            ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as err:  # torch's own text spans several lines and suggests weights_only=False: not ours
        raise CheckpointError(
            f"{path} is not a loadable nik checkpoint (torch.load(weights_only=True) refused it: {type(err).__name__})"
        ) from err
    if not isinstance(ckpt, dict) or "nik" not in ckpt or "state_dict" not in ckpt:
        raise CheckpointError(f"{path} is not a loadable nik checkpoint (no 'nik' block with the robot and network)")
    extra = ckpt["nik"]
    try:
        stored = Robot.from_definition(extra["robot"])
        cfg = dict(extra["net"])
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: malformed nik block: {err}") from err
    if robot is not None:
        robot = load_robot(robot)
        if robot.definition_hash != stored.definition_hash:
            raise CheckpointError(
                f"checkpoint {path} was trained for robot {stored.name!r} (hash {stored.definition_hash}), "
                f"not for robot {robot.name!r} (hash {robot.definition_hash})"
            )
    if "kind" in cfg:  # a multi-solution network (nik.nets.multi), e.g. from configs/train/<robot>.yaml
        net = build_net(stored, cfg)
    else:
        net = IKNet(stored, **cfg)
    state = {k[len("net.") :]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")}
    try:
        net.load_state_dict(state)
    except RuntimeError as err:
        raise CheckpointError(f"{path}: weights do not fit the stored architecture {cfg}: {err}") from err
    return net.to(torch.float32).eval() if "kind" in cfg else net.eval()
