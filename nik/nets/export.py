"""Export a trained network: ``python -m nik.nets.export CKPT [--robot NAME] [--out FILE]``.

Reads a Lightning checkpoint safely (``torch.load(weights_only=True)``): a multi-solution network
(:class:`nik.learn.multi.MultiSolutionIK`, ``nik train`` or ``configs/train/<robot>.yaml``) or a plain one
(:class:`nik.nets.IKNet`: ``train.py`` with ``bp``, ``adam``, ``lbfgs``, ``de``, ``de_bp``; recorded ``kind: plain``).
It rebuilds the network from the ``checkpoint["nik"]`` block and writes the pair ``NAME.safetensors`` + ``NAME.json``
(:func:`nik.nets.pretrained.save`) where ``--out`` says, recording the training command and data the checkpoint
carries (what really ran), this export's command, the config file's text when ``--config`` names one, the SHA-256
of the weights and the validation error. The pair then installs (``nik networks install``) and loads by path
(:func:`nik.nets.load_checkpoint`, ``IKSolver(robot, checkpoint=PATH)``) the same way whatever trained it.

Default ``--out``: a multi-solution network goes to ``runs/<robot>/<robot>.safetensors`` (``nik train``'s place); a
plain one beside its checkpoint, ``<checkpoint folder>/<robot>.safetensors`` (``runs/adam/kuka_kr.safetensors``), so
that exporting a baseline never replaces the arm's multi-solution network. The package's folder only when named,
``--out nik/nets/weights``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import torch

from nik.errors import CheckpointError
from nik.nets.pretrained import save

__all__ = ["cli", "command_line", "default_out", "load_training_checkpoint", "main"]


def load_training_checkpoint(path: str | Path, robot=None):
    """The network in a training checkpoint (multi-solution or plain), eval mode, float32, and its
    ``checkpoint["nik"]`` block; ``robot`` (optional) must match its definition hash. Raises ``CheckpointError``
    (one line), also for an exported pair (already exported: install or load it as it is)."""
    from nik.nets.checkpoint import load_checkpoint

    if Path(path).suffix in (".safetensors", ".json"):
        raise CheckpointError(f"{path} is an exported network already; export reads a training checkpoint (.ckpt)")
    net = load_checkpoint(path, robot=robot)
    ckpt = torch.load(Path(path), map_location="cpu", weights_only=True)
    return net.to(torch.float32).eval(), ckpt["nik"]


def default_out(name: str, checkpoint: str | Path | None = None) -> Path:
    """Where an export goes unless ``--out`` says otherwise: ``runs/<name>/<name>.safetensors``; for a plain network
    (``checkpoint`` given: its training checkpoint), ``<checkpoint folder>/<name>.safetensors``."""
    if checkpoint is not None:
        return Path(checkpoint).parent / f"{name}.safetensors"
    return Path("runs") / name / f"{name}.safetensors"


def command_line(argv: list[str] | None, prog: str) -> str:
    """The command as it ran: ``sys.argv`` (or ``prog`` + ``argv`` when called with a list), shell-quoted."""
    if argv is None:
        return shlex.join(["python", "-m", "nik.nets.export", *sys.argv[1:]])
    return " ".join([prog, shlex.join(argv)]).strip()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m nik.nets.export", description=__doc__.splitlines()[0])
    ap.add_argument(
        "checkpoint",
        help="a train.py checkpoint: runs/<robot>/last.ckpt (configs/train/<robot>.yaml) or runs/<method>/last.ckpt "
        "(bp, adam, lbfgs, de, de_bp)",
    )
    ap.add_argument("--robot", default=None, help="robot the checkpoint must belong to (default: its own)")
    ap.add_argument("--config", default=None, help="training config file to record with the network (its text)")
    ap.add_argument("--wall-min", type=float, default=None, help="training wall-clock minutes to record")
    ap.add_argument(
        "--out",
        default=None,
        help="NAME.safetensors to write (+ NAME.json beside it), or a folder for <robot>.safetensors; default "
        "runs/<robot>/<robot>.safetensors (a plain network: beside its checkpoint). The package's folder only when "
        "named: --out nik/nets/weights",
    )
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    net, extra = load_training_checkpoint(args.checkpoint, args.robot)
    name = net.robot.name
    run = extra.get("run", {})
    training = {
        "command": run.get("command", "not recorded (the checkpoint was written before nik recorded it)"),
        "data": run.get("data", "not recorded"),
        "export_command": command_line(argv, "python -m nik.nets.export"),
        "checkpoint": str(args.checkpoint),
        "counters": extra.get("counters", {}),
    }
    if args.config is not None:
        cfg = Path(args.config)
        if not cfg.is_file():
            raise FileNotFoundError(f"--config: no such file: {cfg}")
        training["config_file"] = str(cfg)
        training["config"] = cfg.read_text()
    if args.wall_min is not None:
        training["wall_min"] = args.wall_min
    plain = not hasattr(net, "hypotheses")
    out = Path(args.out) if args.out is not None else default_out(name, args.checkpoint if plain else None)
    path = save(net, out, training=training)
    print(f"wrote {path.with_suffix('.safetensors')} and {path}")
    val = json.loads(path.read_text())["validation"]
    print(
        f"validation ({val['n']} poses, seed {val['seed']}), {'the guess' if plain else 'best hypothesis'}: median "
        f"{val['best_pos_mm_median']:.2f} mm / {val['best_rot_deg_median']:.3f} deg, p95 "
        f"{val['best_pos_mm_p95']:.2f} mm / {val['best_rot_deg_p95']:.3f} deg"
    )
    return 0


def cli(argv: list[str] | None = None) -> int:
    """:func:`main` with nik's input errors as one line on stderr and exit status 2 (no traceback)."""
    try:
        return main(argv)
    except (ValueError, FileNotFoundError) as err:
        print(f"python -m nik.nets.export: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(cli())
