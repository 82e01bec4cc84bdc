"""Export a trained multi-solution network to the package: ``python -m nik.nets.export CKPT --robot NAME``.

Reads the Lightning checkpoint of :class:`nik.learn.multi.MultiSolutionIK` safely
(``torch.load(weights_only=True)``), rebuilds the network from its ``checkpoint["nik"]`` block and writes
``<robot>.safetensors`` + ``<robot>.json`` (:func:`nik.nets.pretrained.save`) with the training command,
the config file's text and the recorded validation error.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from nik.errors import CheckpointError
from nik.nets.multi import build_net
from nik.nets.pretrained import PRETRAINED_DIR, save
from nik.robots import Robot, load_robot

__all__ = ["load_training_checkpoint", "main"]


def load_training_checkpoint(path: str | Path, robot=None):
    """The network in a ``MultiSolutionIK`` checkpoint, eval mode; ``robot`` (optional) must match its hash."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    extra = ckpt.get("nik") if isinstance(ckpt, dict) else None
    if not extra or "kind" not in extra.get("net", {}):
        raise CheckpointError(f"{path} is not a checkpoint of a multi-solution network (nik.learn.multi)")
    stored = Robot.from_definition(extra["robot"])
    if robot is not None:
        robot = load_robot(robot) if not isinstance(robot, Robot) else robot
        if robot.definition_hash != stored.definition_hash:
            raise CheckpointError(f"{path} was trained for another definition of {stored.name!r}")
    net = build_net(stored, extra["net"])
    net.load_state_dict({k[4:]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")})
    return net.to(torch.float32).eval(), extra


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m nik.nets.export", description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint", help="runs/<robot>/last.ckpt of train.py with configs/train/<robot>.yaml")
    ap.add_argument("--robot", default=None, help="robot the checkpoint must belong to (default: its own)")
    ap.add_argument("--config", default=None, help="training config to record (default configs/train/<robot>.yaml)")
    ap.add_argument("--wall-min", type=float, default=None, help="training wall-clock minutes to record")
    ap.add_argument("--out", default=str(PRETRAINED_DIR), help="output folder (default: the package's)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    net, extra = load_training_checkpoint(args.checkpoint, args.robot)
    name = net.robot.name
    cfg = Path(args.config) if args.config else Path("configs/train") / f"{name}.yaml"
    training = {
        "command": f"python train.py fit --config configs/train/{name}.yaml",
        "config_file": str(cfg),
        "config": cfg.read_text() if cfg.is_file() else None,
        "counters": extra.get("counters", {}),
    }
    if args.wall_min is not None:
        training["wall_min"] = args.wall_min
    path = save(net, args.out, training=training)
    print(f"wrote {path} and {path.with_suffix('.safetensors')}")
    val = json.loads(path.read_text())["validation"]
    print(
        f"validation ({val['n']} poses, seed {val['seed']}), best hypothesis: median "
        f"{val['best_pos_mm_median']:.2f} mm / {val['best_rot_deg_median']:.3f} deg, p95 "
        f"{val['best_pos_mm_p95']:.2f} mm / {val['best_rot_deg_p95']:.3f} deg"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
