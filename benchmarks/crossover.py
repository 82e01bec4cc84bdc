"""Where IKSolver.solve should stop taking the compiled path (``nik.ik.lean``) and batch in torch instead.

For each robot and batch size B, the default ``IKSolver(robot)`` solves the same B reachable targets (FK of
seeded random configurations) by both paths, interleaved (compiled, torch, compiled, torch, ...), with the
seed of the round; the table gives the median time per call and per target, the ratio torch / compiled
(> 1: the compiled path is faster) and the success counts. ``nik.ik.lean.LEAN_MAX_BATCH`` (LM arms: panda) and
``LEAN_MAX_BATCH_CLOSED_FORM`` (closed-form arms: kuka_kr, ur5) are set from it.

    python benchmarks/crossover.py                     # panda, ur5, kuka_kr; B = 1 ... 1024; 1 and 2 threads
    python benchmarks/crossover.py --quick             # B up to 64, fewer rounds
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import nik  # noqa: E402
from nik.ik import lean  # noqa: E402

TOL_POS, TOL_ROT = 1e-4, 1e-3


def timed(solver, T, seed: int, compiled: bool):
    lean.LEAN_MAX_BATCH = 10**9 if compiled else 0
    lean.LEAN_MAX_BATCH_CLOSED_FORM = 10**9
    t = time.perf_counter()
    res = solver.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=seed)
    return time.perf_counter() - t, int(res.success.sum()), res.source


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5", "kuka_kr"])
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 4, 16, 64, 256, 1024])
    parser.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    if args.quick:
        args.batches = [b for b in args.batches if b <= 64]
    warnings.simplefilter("ignore", UserWarning)
    print(f"torch {torch.__version__}; milliseconds per call (median), microseconds per target\n")
    print("| robot | threads | B | compiled ms | torch ms | compiled us/target | torch us/target | torch / compiled |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.robots:
        robot = nik.load_robot(name)
        solver = nik.IKSolver(robot)
        for threads in args.threads:
            nik.set_threads(threads)
            for B in args.batches:
                q = robot.sample(B, generator=torch.Generator().manual_seed(1_000_003 + B), dtype=torch.float64)
                T = robot.fk(q)
                rounds = max(3, min(30, 600 // B)) if not args.quick else 3
                timed(solver, T, 0, True), timed(solver, T, 0, False)  # warm-up
                fast, slow, ok_fast, ok_slow = [], [], 0, 0
                for r in range(rounds):
                    dt, ok, _ = timed(solver, T, r, True)
                    fast.append(dt)
                    ok_fast += ok
                    dt, ok, _ = timed(solver, T, r, False)
                    slow.append(dt)
                    ok_slow += ok
                mf, ms = statistics.median(fast), statistics.median(slow)
                print(
                    f"| {name} | {threads} | {B} | {mf * 1e3:.2f} | {ms * 1e3:.2f} | {mf / B * 1e6:.0f} | "
                    f"{ms / B * 1e6:.0f} | {ms / mf:.2f} |",
                    flush=True,
                )
                if ok_fast != rounds * B or ok_slow != rounds * B:
                    print(f"|  | success: compiled {ok_fast}/{rounds * B}, torch {ok_slow}/{rounds * B} | | | | | | |")
    nik.set_threads(None)


if __name__ == "__main__":
    main()
