"""FK throughput: nik (eager and compiled) vs pytorch-kinematics on the same URDF arms.

Both run in this process, on the same joint samples; the table gives configurations per
second and the ratio nik / pytorch-kinematics.

    python benchmarks/fk.py            # panda (7-DOF) and ur5 (6-DOF), batch 1 / 1,000 / 100,000, float32 / float64
    python benchmarks/fk.py --quick    # smaller batches, fewer repeats
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

import nik
from nik.robots.urdf import build_pk_chain


def throughput(fn, batch: int, min_time: float, repeats: int) -> float:
    """Configurations per second: the median over ``repeats`` timings of at least ``min_time`` s each."""
    fn()
    fn()
    rates = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while True:
            fn()
            calls += 1
            elapsed = time.perf_counter() - start
            if elapsed >= min_time:
                break
        rates.append(calls * batch / elapsed)
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 1_000, 100_000])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="batches 1 and 1,000 only, short timings")
    args = parser.parse_args()
    if args.quick:
        args.batches = [b for b in args.batches if b <= 1_000]
    min_time, repeats = (0.05, 3) if args.quick else (0.3, 5)
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; configurations per second (M = 1e6)\n")
    header = "| robot | dtype | batch | nik eager | nik compiled | pytorch-kinematics | eager / pk | compiled / pk |"
    print(header)
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name in args.robots:
        robot = nik.load_robot(name)
        chain = build_pk_chain(open(robot.source).read(), robot.end_link)
        for dtype in (torch.float32, torch.float64):
            pk_chain = chain.to(dtype=dtype)
            for batch in args.batches:
                q = robot.sample(batch, generator=torch.Generator().manual_seed(0), dtype=dtype)
                with torch.no_grad():
                    eager = throughput(lambda r=robot, q=q: r.fk(q), batch, min_time, repeats)
                    compiled = throughput(lambda r=robot, q=q: r.fk(q, compiled=True), batch, min_time, repeats)
                    peer = throughput(
                        lambda c=pk_chain, q=q: c.forward_kinematics(q).get_matrix(), batch, min_time, repeats
                    )
                print(
                    f"| {name} | {str(dtype)[6:]} | {batch:,} | {eager / 1e6:.3f} M | {compiled / 1e6:.3f} M "
                    f"| {peer / 1e6:.3f} M | {eager / peer:.1f}x | {compiled / peer:.1f}x |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
