"""``IKSolver.solve_all`` on an arm without a closed form: LM from every start compiled (the CPU path) against the
batched torch LM (the GPU path, run here on the CPU), interleaved in one process, one thread; medians in ms and
how many distinct solutions each finds.

    python benchmarks/solve_all.py [--robots panda xarm7] [--poses 5] [--starts 256]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

import nik
from nik.ik import stages


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "xarm7"])
    ap.add_argument("--poses", type=int, default=5)
    ap.add_argument("--starts", type=int, default=256)
    args = ap.parse_args()
    torch.set_num_threads(1)
    compiled = stages._each_start_compiled
    print("robot   path      median ms   solutions (per pose)")
    for name in args.robots:
        robot = nik.load_robot(name)
        solver = nik.IKSolver(robot)
        g = torch.Generator().manual_seed(0)
        T = robot.fk(robot.sample(args.poses, generator=g, dtype=torch.float64))
        times = {"compiled": [], "torch": []}
        found = {"compiled": [], "torch": []}
        for i in range(args.poses):
            for path in ("compiled", "torch"):
                stages._each_start_compiled = compiled if path == "compiled" else stages._each_start_torch
                solver.solve_all(T[i : i + 1], n_starts=8)  # warm-up
                t0 = time.perf_counter()
                K = solver.solve_all(T[i : i + 1], n_starts=args.starts)
                times[path].append(time.perf_counter() - t0)
                found[path].append(int(K.shape[0]))
        stages._each_start_compiled = compiled
        for path in ("compiled", "torch"):
            print(f"{name:7s} {path:9s} {1e3 * statistics.median(times[path]):9.1f}   {found[path]}")


if __name__ == "__main__":
    main()
