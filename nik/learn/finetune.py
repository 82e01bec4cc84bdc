"""Fine-tune a multi-hypothesis network on the pose error of every hypothesis, through the differentiable FK.

    python -m nik.learn.finetune panda --minutes 12 --threads 1 --out nik/nets/weights/panda.safetensors

``nik train`` trains a multi-head network with a relaxed winner-takes-all loss: the best head of a sample learns
it, the others only a little, so the best of the K heads is good (panda: 5 mm median) while a head taken on its own
is not (IKFlow's and PAIK's per-sample error counts every head). Fine-tuning minimises the mean over *all* heads and
samples of the root of the pose loss of the reached pose (:func:`nik.learn.multi.pose_loss_per_sample`:
``sqrt(|p - p*|^2 / L^2 + rot_weight |R - R*|_F^2 / 2)``, an L2 error like the measured one, so the few far-off
hypotheses do not dominate as they do under the squared loss), no joint term: every head is pulled onto a solution,
and since a redundant arm's pose has a continuum of solutions the heads stay where they were on it.
Adam with a cosine learning rate over the wall-clock budget (or ``max_steps``); fresh uniform joint samples every
step (seeded ``torch.Generator``, float64 FK, float32 network). The written pair keeps the original ``training`` block
(the command that made the network) and appends this run (command, settings, counters) to ``training.finetune``;
``network_use`` is measured again (:func:`nik.learn.report.record_use`).
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

__all__ = ["FinetuneCfg", "finetune", "main"]


@dataclass
class FinetuneCfg:
    """Settings of :func:`finetune`.

    Args:
        minutes: wall-clock budget (> 0).
        max_steps: stop after this many steps as well (None: the budget alone).
        lr: Adam's initial learning rate; the cosine schedule ends at ``lr * min_lr_ratio``.
        min_lr_ratio: see ``lr``.
        batch_size: fresh samples per step.
        rot_weight: rotation weight of the pose loss.
        seed: seeds the sample generator.
    """

    minutes: float = 12.0
    max_steps: int | None = None
    lr: float = 2e-5
    min_lr_ratio: float = 0.01
    batch_size: int = 1024
    rot_weight: float = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.minutes > 0:
            raise ValueError(f"minutes must be > 0, got {self.minutes}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if int(self.batch_size) < 1:
            raise ValueError(f"batch_size must be >= 1, got {self.batch_size}")


def hypotheses_pose_loss(net, T: torch.Tensor, rot_weight: float = 1.0) -> torch.Tensor:
    """Mean over samples and hypotheses of the root of the pose loss of each hypothesis of ``net`` (unclamped,
    differentiable; ``1e-10`` under the root keeps its gradient finite at zero) for targets ``T: (B, 4, 4)``; a
    scalar."""
    from nik.learn.multi import pose_loss_per_sample

    q = net(T)  # (B, K, dof)
    pl = pose_loss_per_sample(q.transpose(0, 1), T, net.robot, length_scale=net.length_scale, rot_weight=rot_weight)
    return (pl + 1e-10).sqrt().mean()


def finetune(net, cfg: FinetuneCfg, *, log=None) -> dict:
    """Train ``net`` (a multi-hypothesis network: ``forward(T) -> (B, K, dof)``) in place on
    :func:`hypotheses_pose_loss`, fresh uniform samples every step; returns the counters ``{"steps", "sample_evals",
    "wall_s"}``. ``log(step, seconds, loss)`` is called every 500 steps when given."""
    robot = net.robot
    dtype = next(net.parameters()).dtype
    g = torch.Generator().manual_seed(int(cfg.seed))
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    budget = 60.0 * float(cfg.minutes)
    net.train()
    t0, step = time.perf_counter(), 0
    while cfg.max_steps is None or step < cfg.max_steps:
        elapsed = time.perf_counter() - t0
        if elapsed >= budget:
            break
        frac = max(elapsed / budget, step / cfg.max_steps if cfg.max_steps else 0.0)
        r = cfg.min_lr_ratio
        for group in opt.param_groups:
            group["lr"] = cfg.lr * (r + (1 - r) * 0.5 * (1 + math.cos(math.pi * min(1.0, frac))))
        T = robot.fk(robot.sample(int(cfg.batch_size), generator=g, dtype=torch.float64)).to(dtype)
        loss = hypotheses_pose_loss(net, T, cfg.rot_weight)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        step += 1
        if log is not None and step % 500 == 0:
            log(step, time.perf_counter() - t0, float(loss.detach()))
    net.eval()
    return {"steps": step, "sample_evals": step * int(cfg.batch_size), "wall_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring). Bad input: one line on stderr, exit 2."""
    ap = argparse.ArgumentParser(prog="python -m nik.learn.finetune", description=__doc__.splitlines()[0])
    ap.add_argument("network", help="a robot name (its installed or shipped network) or a NAME.safetensors file")
    ap.add_argument("--out", required=True, type=Path, help="NAME.safetensors to write (the pair)")
    ap.add_argument("--minutes", type=float, default=12.0)
    ap.add_argument("--max-steps", type=int, default=None)
    ap.add_argument("--lr", type=float, default=2e-5)
    ap.add_argument("--batch-size", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    if a.out.suffix != ".safetensors":
        ap.error(f"--out must name a .safetensors file, got {a.out}")
    try:
        cfg = FinetuneCfg(minutes=a.minutes, max_steps=a.max_steps, lr=a.lr, batch_size=a.batch_size, seed=a.seed)
    except ValueError as e:
        ap.error(str(e))
    from nik.errors import CheckpointError
    from nik.learn.report import record_use
    from nik.nets.pair import load_pair, read_pair_meta
    from nik.nets.pretrained import load_pretrained, save
    from nik.nets.registry import find_network
    from nik.robots import load_robot

    torch.set_num_threads(int(a.threads))
    try:
        if a.network.endswith((".safetensors", ".json")):
            src = Path(a.network)
            net = load_pair(src)
        else:
            net = load_pretrained(a.network)
            src = find_network(load_robot(a.network))
        meta = read_pair_meta(src)
    except (CheckpointError, ValueError, OSError) as e:
        print(f"python -m nik.learn.finetune: error: {e}", file=sys.stderr)
        return 2
    if not hasattr(net, "n_hypotheses"):
        print("python -m nik.learn.finetune: error: a multi-hypothesis network is needed", file=sys.stderr)
        return 2
    net = net.float()
    counters = finetune(net, cfg, log=lambda s, t, v: print(f"step {s}  {t:.0f} s  loss {v:.5f}", flush=True))
    argv_used = sys.argv[1:] if argv is None else argv
    run = {
        "command": "python -m nik.learn.finetune " + " ".join(shlex.quote(x) for x in argv_used),
        **asdict(cfg),
        "threads": int(a.threads),
        "loss": "mean over heads and samples of the root of the pose loss (FK)",
        "counters": counters,
    }
    base = meta.get("training", {})
    training = {**base, "finetune": [*base.get("finetune", []), run]}  # how it was made, then each fine-tuning
    save(net, a.out, training=training, role=meta.get("role"))
    record_use(a.out, net.robot)
    print(f"wrote {a.out} ({counters['steps']} steps, {counters['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
