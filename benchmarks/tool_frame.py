"""What a tool (TCP) and base frame cost the default solver: nothing is expected, as both are folded into the arm's
normal form (``nik.robots.frames``).

For each robot and batch size B the default ``IKSolver`` of the arm without frames and of the same arm with a base
and a tool frame solve B reachable targets (FK of the same seeded configurations, with the frames for the second),
interleaved (plain, framed, plain, framed, ...) after one warm-up call each; the table gives the median time per
call, the ratio framed / plain and the success counts.

    python benchmarks/tool_frame.py                   # ur5 (closed form), panda (LM); B = 1 and 1000; 15 rounds
    python benchmarks/tool_frame.py --rounds 5
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import nik  # noqa: E402

TOOL = [0.012, -0.025, 0.16, math.cos(0.35), 0.6 * math.sin(0.35), 0.0, 0.8 * math.sin(0.35)]
BASE = [0.5, -0.2, 0.1, math.cos(0.45), 0.0, 0.0, math.sin(0.45)]


def timed(solver, T, seed):
    t = time.perf_counter()
    res = solver.solve(T, seed=seed)
    return time.perf_counter() - t, int(res.success.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["ur5", "panda"])
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 1000])
    parser.add_argument("--rounds", type=int, default=15)
    args = parser.parse_args()
    print(f"default IKSolver, plain arm vs the same arm with base and tool frames; {args.rounds} interleaved rounds")
    print(f"{'robot':8s} {'B':>6s} {'plain ms':>10s} {'framed ms':>10s} {'framed/plain':>13s} {'success':>15s}")
    for name in args.robots:
        plain = nik.load_robot(name)
        framed = nik.load_robot(name, base=BASE, tool=TOOL)
        for b in args.batches:
            q = plain.sample(b, generator=torch.Generator().manual_seed(b), dtype=torch.float64)
            Tp, Tf = plain.fk(q), framed.fk(q)
            sp, sf = nik.IKSolver(plain, checkpoint=None), nik.IKSolver(framed, checkpoint=None)
            timed(sp, Tp, 0), timed(sf, Tf, 0)  # warm-up: compiled kernels, closed-form constants
            tp, tf, okp, okf = [], [], 0, 0
            for r in range(args.rounds):
                dt, ok = timed(sp, Tp, r)
                tp.append(dt)
                okp += ok
                dt, ok = timed(sf, Tf, r)
                tf.append(dt)
                okf += ok
            mp, mf = statistics.median(tp) * 1e3, statistics.median(tf) * 1e3
            total = b * args.rounds
            print(f"{name:8s} {b:6d} {mp:10.3f} {mf:10.3f} {mf / mp:13.2f} {okp:>7d}/{okf:<7d} of {total}")


if __name__ == "__main__":
    main()
