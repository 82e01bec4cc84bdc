"""Closed-form PUMA 560 IK: quaternion vs rotation-matrix wrist, and batch throughput.

Paper B claims its quaternion wrist step is about 15 % faster than the pure D-H (matrix)
solution; the goal here is at least 2 million poses per second with all 8 solutions on
2 CPU cores. Both wrist variants run in the same process on the same poses, interleaved,
and the median of ``--repeats`` runs is reported. A reference elementwise multiply of the same
size is timed too: on a shared (busy) machine it shows how far from idle the numbers are.

    python benchmarks/analytic.py [--n 200000] [--threads 2] [--repeats 7] [--no-compile]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

import nik
from nik.analytic import puma560_ik


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="puma560")
    ap.add_argument("--n", type=int, default=200_000, help="poses per batch")
    ap.add_argument("--threads", type=int, default=2, help="torch CPU threads (the goal is stated for 2)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-compile", action="store_true", help="skip the torch.compile rows")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    robot = nik.load_robot(args.robot)
    gen = torch.Generator().manual_seed(0)
    print(f"robot {robot.name}, {args.n} poses per batch, {torch.get_num_threads()} threads, torch {torch.__version__}")

    ref = torch.rand(args.n * 8, dtype=torch.float64)
    t_ref = _median_time(lambda: ref * ref, args.repeats)
    print(
        f"reference: one multiply of {args.n * 8} float64 takes {t_ref * 1e3:.2f} ms "
        f"({args.n * 8 * 16 / t_ref / 1e9:.1f} GB/s; an idle modern core does ~10 GB/s)\n"
    )

    rows = []
    compiled_modes = [False] if args.no_compile else [False, True]
    for dtype in (torch.float64, torch.float32):
        T = robot.fk(robot.sample(args.n, generator=gen, dtype=dtype))
        for compiled in compiled_modes:
            for check in (False, True):
                fns = {
                    w: (
                        lambda w=w, T=T, check=check, compiled=compiled: puma560_ik(
                            robot, T, wrist=w, check=check, compiled=compiled
                        )
                    )
                    for w in ("quaternion", "matrix")
                }
                for fn in fns.values():  # warm-up (and compilation)
                    fn()
                times = {w: [] for w in fns}
                for _ in range(args.repeats):  # interleaved, so both see the same machine load
                    for w, fn in fns.items():
                        t0 = time.perf_counter()
                        fn()
                        times[w].append(time.perf_counter() - t0)
                med = {w: statistics.median(v) for w, v in times.items()}
                rows.append((str(dtype).replace("torch.", ""), compiled, check, med["quaternion"], med["matrix"]))

    # single-query latency (Python overhead dominates)
    T1 = robot.fk(robot.sample(1, generator=gen, dtype=torch.float64))
    lat = {
        w: _median_time(lambda w=w: puma560_ik(robot, T1, wrist=w, check=False), 200) for w in ("quaternion", "matrix")
    }

    print(
        "| dtype | compiled | FK check | quaternion wrist (M poses/s) | matrix wrist (M poses/s) "
        "| quaternion speed-up |"
    )
    print("|---|---|---|---|---|---|")
    for dt, comp, check, tq, tm in rows:
        print(
            f"| {dt} | {comp} | {check} | {args.n / tq / 1e6:.3f} | {args.n / tm / 1e6:.3f} "
            f"| {100 * (tm / tq - 1):+.1f} % |"
        )
    print(
        f"\nsingle pose (B = 1, eager, no FK check): quaternion {lat['quaternion'] * 1e6:.0f} us, "
        f"matrix {lat['matrix'] * 1e6:.0f} us"
    )
    best = max(args.n / min(tq, tm) for _, _, check, tq, tm in rows if not check)
    print(f"best throughput with all 8 solutions: {best / 1e6:.2f} M poses/s (goal: 2 M poses/s on 2 cores)")


if __name__ == "__main__":
    main()
