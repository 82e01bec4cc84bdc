"""A useless network's cost: untrained, scrambled and randomised networks against no network and the shipped one
(issue 37 item 4).

    python benchmarks/bad_network.py --out benchmarks/results/bad_network.md
    PYTHONPATH=/path/to/old/checkout python benchmarks/bad_network.py     # the figures before (no nik.ik.judge)
    python benchmarks/bad_network.py --networks shipped "shipped, by path"  # the shipped ones only (old vs new)

Per robot (panda, ur5; ``analytic=False``, so that ur5's closed form does not serve), the networks, all of the
shipped architecture (``nik.models.load_pretrained``):

- ``none``: ``IKSolver(robot, checkpoint=None, analytic=False)``, the reference of every ratio;
- ``shipped``: ``IKSolver(robot, analytic=False)`` (``checkpoint="auto"``: on the CPU the small single-pose network);
- ``shipped, by path``: the shipped main network saved (:func:`nik.nets.checkpoint.save_checkpoint`) and given by
  path (``checkpoint=PATH``: judged, as any given network);
- ``untrained``: fresh weights (``nik.nets.multi.build_net`` of the shipped config, ``torch.manual_seed(0)``) with
  the shipped input normalisation; ``untrained, raw``: the same without it (mean 0, deviation 1);
  ``scrambled``: the shipped network with the units of its last layer permuted (seeded); ``randomised``: every
  weight of the shipped network drawn again, normal at its tensor's standard deviation (seeded); each given by path;
- ``randomised, solver.net``: that network set on a solver (``solver.net = net``; panda only, as in the issue).

Measured, one torch thread, one process, solvers interleaved (A B C ... A B C ...), medians: the wall time of a batch
of ``--n`` (2,000) FK targets of uniform joints (seeded; ``--reps`` rounds; ``solver.net`` also on 1,000 poses),
and of single poses (``--n-one`` poses, one call each, interleaved pose by pose); the ratio to ``none``; the success
rate (0.1 mm / 0.1 deg) and the guess each result reports; ``judged: wins``, the share of probe poses where the
network's best hypothesis is the better start (:func:`nik.ik.judge.verdict`, printed for every network, the shipped
ones included, which the solver does not judge). Every solver is called once before timing (the verdict, a one-time
cost per network, is timed on its own: ``judge once``). The rows whose source is ``multistart`` run the very plan
of ``none``: their spread around 1.00x is this machine's noise.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik
from nik.nets.checkpoint import save_checkpoint
from nik.nets.multi import build_net


def useless(robot, kind: str, seed: int = 0):
    """A useless network of the shipped architecture (module docstring), ``kind`` one of its names."""
    shipped = nik.models.load_pretrained(robot)
    g = torch.Generator().manual_seed(seed)
    if kind.startswith("untrained"):
        torch.manual_seed(seed)
        net = build_net(robot, shipped.config())
        if kind == "untrained":
            net.in_mean.copy_(shipped.in_mean)
            net.in_std.copy_(shipped.in_std)
        return net.eval()
    net = copy.deepcopy(shipped)
    with torch.no_grad():
        if kind == "scrambled":
            last = [m for m in net.modules() if isinstance(m, torch.nn.Linear)][-1]
            perm = torch.randperm(last.out_features, generator=g)
            last.weight.copy_(last.weight[perm])
            last.bias.copy_(last.bias[perm])
        else:
            for p in net.parameters():
                p.copy_(torch.randn(p.shape, generator=g) * p.std().clamp_min(1e-3))
    return net.eval()


def solvers(robot, folder: Path, only=None) -> dict:
    """The solvers of the module docstring (``only``: those names and ``none``)."""
    out = {
        "none": nik.IKSolver(robot, checkpoint=None, analytic=False),
        "shipped": nik.IKSolver(robot, analytic=False),
    }
    shipped = save_checkpoint(nik.models.load_pretrained(robot), folder / f"{robot.name}_shipped.ckpt")
    out["shipped, by path"] = nik.IKSolver(robot, checkpoint=str(shipped), analytic=False)
    for kind in ("untrained", "untrained, raw", "scrambled", "randomised"):
        path = save_checkpoint(useless(robot, kind), folder / f"{robot.name}_{kind.replace(', ', '_')}.ckpt")
        out[kind] = nik.IKSolver(robot, checkpoint=str(path), analytic=False)
    if robot.name == "panda":
        s = nik.IKSolver(robot, analytic=False)
        s.net = useless(robot, "randomised", seed=1)
        out["randomised, solver.net"] = s
    return {k: s for k, s in out.items() if only is None or k == "none" or k in only}


def _time(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def judge_once(robot) -> str:
    """The verdict's one-time cost on two fresh networks (the first one in the process pays torch's warm-up)."""
    try:
        from nik.ik import judge
    except ImportError:
        return "no judge (nik.ik.judge absent)"
    nets = [useless(robot, "untrained", seed=s) for s in (98, 99)]
    first, warm = (_time(lambda net=net: judge.verdict(net, robot)) for net in nets)
    return f"judge once: {warm * 1e3:.1f} ms ({first * 1e3:.1f} ms the first time in this process)"


def _wins(net, robot) -> str:
    """The share of probe poses where the network's best hypothesis is the better start (:mod:`nik.ik.judge`)."""
    try:
        from nik.ik import judge
    except ImportError:
        return "-"
    return "-" if net is None else f"{judge.verdict(net, robot).wins:.0%}"


def run(name: str, n: int, reps: int, n_one: int, only=None) -> list[str]:
    robot = nik.load_robot(name)
    q = robot.sample(n, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    T = robot.fk(q).numpy()
    lines = [f"### {name} (analytic=False); {judge_once(robot)}", ""]
    with tempfile.TemporaryDirectory() as tmp:
        S = solvers(robot, Path(tmp), only)
        rows = {}
        for k, s in S.items():  # warm: kernels compiled, networks loaded and judged
            r = s.solve(T)
            s.solve(T[:1])
            rows[k] = (float(np.mean(r.success)), r.source)
        sizes = [n] + ([1000] if "randomised, solver.net" in S else [])
        batch = {(k, m): [] for k in S for m in sizes}
        for _ in range(reps):
            for m in sizes:
                for k, s in S.items():
                    batch[k, m].append(_time(lambda s=s, m=m: s.solve(T[:m])))
        one = {k: [] for k in S}
        for i in range(n_one):
            Ti = T[i : i + 1]
            for k, s in S.items():
                one[k].append(_time(lambda s=s, Ti=Ti: s.solve(Ti)))
    wins = {k: _wins(s.net, robot) for k, s in S.items()}
    med = {key: statistics.median(v) for key, v in batch.items()}
    med1 = {k: statistics.median(v) for k, v in one.items()}
    head = f"| network | judged: wins | source | success | batch {n} ms | ratio |"
    if len(sizes) > 1:
        head += " batch 1000 ms | ratio |"
    lines += [head + " one pose us | ratio |", "|" + "---|" * (head.count("|") + 1)]
    for k in S:
        row = f"| {k} | {wins[k]} | {rows[k][1]} | {rows[k][0]:.4f} |"
        row += f" {med[k, n] * 1e3:.1f} | {med[k, n] / med['none', n]:.2f}x |"
        if len(sizes) > 1:
            row += f" {med[k, 1000] * 1e3:.1f} | {med[k, 1000] / med['none', 1000]:.2f}x |"
        lines.append(row + f" {med1[k] * 1e6:.0f} | {med1[k] / med1['none']:.2f}x |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--n-one", type=int, default=300)
    ap.add_argument("--networks", nargs="+", default=None, help="only these rows (and none), e.g. shipped")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.ones(8, 8) @ torch.ones(8, 8)  # torch's own first-use cost, out of every figure
    warnings.simplefilter("ignore")  # the judge's one warning per useless network
    lines = [f"# A useless network's cost ({nik.__file__})", ""]
    lines += [f"`python benchmarks/bad_network.py --n {args.n} --reps {args.reps} --n-one {args.n_one}`", ""]
    for name in args.robots:
        lines += run(name, args.n, args.reps, args.n_one, args.networks)
        print("\n".join(lines[-12:]), flush=True)
    if args.out is not None:
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
