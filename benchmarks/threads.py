"""Threads sharing one solver: throughput of two threads against one, batches of 100 poses.

The compiled kernels release the GIL, so threads that share one ``nik.IKSolver`` run their solves side by
side. Each round solves the same batches twice, interleaved: once on one thread, then split between two
threads (each its half); the table gives poses per second (medians over the rounds), the ratio, and the
process's CPU seconds per wall-clock second in the two-thread runs (up to 2 when both threads compute at
once; at most 1 when a lock, the GIL, serialises them, or when other processes hold the cores). torch
runs one intra-op thread (``nik.set_threads(1)``), so that threads do not oversubscribe the cores. The
answers of both runs are compared (they must be the same).

    python benchmarks/threads.py                         # panda (LM) and kuka_kr (closed form), 7 rounds
    python benchmarks/threads.py --robots panda --rounds 11 --batches 16
"""

from __future__ import annotations

import argparse
import os
import statistics
import threading
import time

import torch

import nik

BATCH = 100


def solve_all(solver, batches, threads: int) -> tuple[float, float, list]:
    """Wall-clock and process CPU seconds to solve every batch with ``threads`` threads (batch ``i`` on thread
    ``i % threads``), and the answers in the order of ``batches``."""
    answers = [None] * len(batches)
    barrier = threading.Barrier(threads + 1)

    def work(k: int) -> None:
        barrier.wait()
        for i in range(k, len(batches), threads):
            answers[i] = solver.solve(batches[i], seed=i)

    pool = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
    for t in pool:
        t.start()
    barrier.wait()
    start, cpu = time.perf_counter(), time.process_time()
    for t in pool:
        t.join()
    return time.perf_counter() - start, time.process_time() - cpu, answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["panda", "kuka_kr"])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--batches", type=int, default=8, help="batches of 100 poses per round (even)")
    args = parser.parse_args()
    nik.set_threads(1)
    print(
        f"{os.cpu_count()} CPUs, torch intra-op threads {torch.get_num_threads()}; batches of {BATCH} poses, "
        f"{args.batches} per round, {args.rounds} rounds (1 thread, 2 threads interleaved)\n"
    )
    print("| robot | source | 1 thread (poses/s) | 2 threads (poses/s) | 2 / 1 | CPU / wall (2) | same answers |")
    print("|---|---|---:|---:|---:|---:|---|")
    for name in args.robots:
        robot = nik.load_robot(name)
        solver = nik.IKSolver(robot)
        batches = [
            robot.fk(robot.sample(BATCH, generator=torch.Generator().manual_seed(100 + i), dtype=torch.float64))
            for i in range(args.batches)
        ]
        *_, reference = solve_all(solver, batches, 1)  # warm-up: kernels loaded, per-robot facts built
        rates, busy = {1: [], 2: []}, []
        same = True
        for _ in range(args.rounds):
            for threads in (1, 2):
                seconds, cpu, answers = solve_all(solver, batches, threads)
                rates[threads].append(len(batches) * BATCH / seconds)
                if threads == 2:
                    busy.append(cpu / seconds)
                same = same and all(torch.equal(a.q, r.q) for a, r in zip(answers, reference, strict=True))
        one, two = statistics.median(rates[1]), statistics.median(rates[2])
        print(
            f"| {name} | {reference[0].source} | {one:,.0f} | {two:,.0f} | {two / one:.2f}x "
            f"| {statistics.median(busy):.2f} | {same} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
