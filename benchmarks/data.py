"""Dataset generation throughput and peak memory (issue 3's claim: >= 1M samples/s on 2 cores,
memory independent of N).

End to end, as ``nik generate`` does it: sampling + branch labels + FK + writing the ``.npy``
files with their SHA-256 checksums + fsync + the atomic rename. Each configuration runs in a
fresh subprocess so that its peak resident memory (``ru_maxrss``) is its own; the table shows
the resident memory before generation (Python + torch) and the peak during it, for two sizes
of N, to show that the increment does not grow with N.

    python benchmarks/data.py          # kuka_kr, 1M and 250k samples, 1 and 2 threads, eager/compiled, f64/f32
    python benchmarks/data.py --n 1000000 4000000 --threads 1 --dtype float64 --compiled 0

Numbers depend on the machine and on what else runs on it: report the load average with them.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB


def child(args) -> None:
    import torch

    torch.set_num_threads(args.threads)
    import nik
    from nik.data import Compute, generate_dataset

    robot = nik.load_robot(args.robot)
    out = Path(args.out)
    t0 = time.perf_counter()
    # warm-up (and compilation, for the compiled kernel) on a small dataset, not timed below
    generate_dataset(
        robot,
        70000,
        out / "warmup",
        dtype=args.dtype,
        progress=False,
        overwrite=True,
        compute=Compute(compiled=args.compiled, threads=args.threads),
    )
    warm = time.perf_counter() - t0
    shutil.rmtree(out / "warmup")
    rss_before = _maxrss_mb()
    t0 = time.perf_counter()
    generate_dataset(
        robot,
        args.n,
        out / "bench",
        dtype=args.dtype,
        progress=False,
        seed=0,
        overwrite=True,
        compute=Compute(compiled=args.compiled, threads=args.threads),
    )
    dt = time.perf_counter() - t0
    size = sum(f.stat().st_size for f in (out / "bench").iterdir())
    shutil.rmtree(out / "bench")
    print(
        json.dumps(
            {
                "n": args.n,
                "seconds": dt,
                "rate": args.n / dt,
                "rss_before_mb": rss_before,
                "rss_peak_mb": _maxrss_mb(),
                "warmup_s": warm,
                "bytes": size,
            }
        )
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", default="kuka_kr")
    p.add_argument("--n", type=int, nargs="+", default=[1_000_000, 250_000])
    p.add_argument(
        "--threads",
        type=int,
        nargs="+",
        default=[1, 2],
        help="torch threads for the maths; writing and hashing run in one more thread (default: 1 and 2)",
    )
    p.add_argument("--dtype", nargs="+", default=["float64", "float32"])
    p.add_argument("--compiled", nargs="+", default=["0", "1"], help="0 eager, 1 torch.compile'd FK")
    p.add_argument("--out", default=None, help="scratch folder (default: a temporary one)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        args.n, args.dtype, args.compiled = args.n[0], args.dtype[0], args.compiled[0] == "1"
        args.threads = args.threads[0]
        child(args)
        return

    scratch = Path(args.out or tempfile.mkdtemp(prefix="nik_bench_data_"))
    scratch.mkdir(parents=True, exist_ok=True)
    print(
        f"nik generate --robot {args.robot}: end to end (sample + labels + FK + write + sha256 + fsync), "
        f"cpus = {os.cpu_count()}, load average = "
        f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}"
    )
    print(
        f"{'threads':<8}{'dtype':<8}{'FK':<10}{'N':>10}{'time (s)':>10}{'samples/s':>14}{'MB/s':>8}"
        f"{'RSS before (MB)':>17}{'RSS peak (MB)':>15}{'peak-before':>13}{'warm-up (s)':>13}"
    )
    try:
        for threads, dtype, comp, n in itertools.product(args.threads, args.dtype, args.compiled, args.n):
            cmd = [
                sys.executable,
                __file__,
                "--child",
                "--robot",
                args.robot,
                "--n",
                str(n),
                "--dtype",
                dtype,
                "--compiled",
                comp,
                "--threads",
                str(threads),
                "--out",
                str(scratch),
            ]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            label = f"{threads:<8}{dtype:<8}{'compiled' if comp == '1' else 'eager':<10}{n:>10}"
            if proc.returncode != 0:
                print(f"{label}  failed: {proc.stderr.strip().splitlines()[-1:]}")
                continue
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            print(
                f"{label}{r['seconds']:>10.2f}{r['rate']:>14,.0f}{r['bytes'] / r['seconds'] / 1e6:>8.0f}"
                f"{r['rss_before_mb']:>17.0f}{r['rss_peak_mb']:>15.0f}{r['rss_peak_mb'] - r['rss_before_mb']:>13.0f}"
                f"{r['warmup_s']:>13.1f}",
                flush=True,
            )
    finally:
        if args.out is None:
            shutil.rmtree(scratch, ignore_errors=True)
    print(f"load average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
