"""Is there a CPU batch size where the torch backend beats the compiled one (``nik.ik.backends.choose``)?

For each robot and batch size B, ``IKSolver(robot, backend="compiled")`` and ``IKSolver(robot, backend="torch")``
solve the same B reachable targets (FK of seeded random configurations), interleaved (compiled, torch, compiled,
torch, ...), with the seed of the round; the table gives the median time per call and per target, the ratio torch /
compiled (> 1: the compiled backend is faster), the guess each reports and the success counts.

    python benchmarks/crossover.py                     # panda, ur5, kuka_kr; B = 1 ... 10,000; 1 and 2 threads
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

TOL_POS, TOL_ROT = 1e-4, 1e-3


def timed(solver, T, seed: int):
    t = time.perf_counter()
    res = solver.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=seed)
    return time.perf_counter() - t, int(res.success.sum()), res.source


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5", "kuka_kr"])
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 4, 16, 64, 256, 1024, 4096, 10000])
    parser.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    if args.quick:
        args.batches = [b for b in args.batches if b <= 64]
    warnings.simplefilter("ignore", UserWarning)
    print(f"torch {torch.__version__}; milliseconds per call (median), microseconds per target\n")
    print(
        "| robot | threads | B | compiled ms | torch ms | compiled us/target | torch us/target | torch / compiled "
        "| guess (compiled, torch) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for name in args.robots:
        robot = nik.load_robot(name)
        fast_solver, slow_solver = nik.IKSolver(robot, backend="compiled"), nik.IKSolver(robot, backend="torch")
        for threads in args.threads:
            nik.set_threads(threads)
            for B in args.batches:
                q = robot.sample(B, generator=torch.Generator().manual_seed(1_000_003 + B), dtype=torch.float64)
                T = robot.fk(q)
                rounds = max(3, min(30, 600 // B)) if not args.quick else 1
                timed(fast_solver, T, 0), timed(slow_solver, T, 0)  # warm-up
                fast, slow, ok_fast, ok_slow = [], [], 0, 0
                for r in range(rounds):
                    dt, ok, src_fast = timed(fast_solver, T, r)
                    fast.append(dt)
                    ok_fast += ok
                    dt, ok, src_slow = timed(slow_solver, T, r)
                    slow.append(dt)
                    ok_slow += ok
                mf, ms = statistics.median(fast), statistics.median(slow)
                print(
                    f"| {name} | {threads} | {B} | {mf * 1e3:.2f} | {ms * 1e3:.2f} | {mf / B * 1e6:.0f} | "
                    f"{ms / B * 1e6:.0f} | {ms / mf:.2f} | {src_fast}, {src_slow} |",
                    flush=True,
                )
                if ok_fast != rounds * B or ok_slow != rounds * B:
                    print(f"|  | success: compiled {ok_fast}/{rounds * B}, torch {ok_slow}/{rounds * B} | | | | | | |")
    nik.set_threads(None)


if __name__ == "__main__":
    main()
