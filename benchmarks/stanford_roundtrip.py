"""Round trip of the default ``nik.IKSolver`` on the Stanford arm (one prismatic joint).

Issue 11's acceptance: at least 99.9 % of 1,000 random configurations (uniform within the
limits) solved within 0.1 mm / 0.1 deg, errors measured by FK on the returned joints, limits
always held. One line per seed: the configurations are drawn with generator seed ``s`` and
the solver runs with ``seed=s``.

    python benchmarks/stanford_roundtrip.py                  # seeds 0..9, 1,000 configurations each
    python benchmarks/stanford_roundtrip.py --seeds 3 --n 200
"""

from __future__ import annotations

import argparse
import math
import time

import torch

import nik
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=1000, help="configurations per seed (default 1000)")
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..S-1 (default 10)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    robot = nik.load_robot("stanford")
    solver = nik.IKSolver(robot)
    print(f"{solver}; torch {torch.__version__}, {torch.get_num_threads()} thread(s), float64")
    print("seed  within 0.1 mm / 0.1 deg   success   limits held   max pos (mm)   max rot (deg)   solve s")
    total_ok = total = 0
    for seed in range(args.seeds):
        q = robot.sample(args.n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
        T = robot.fk(q)
        start = time.perf_counter()
        res = solver.solve(T, seed=seed)
        seconds = time.perf_counter() - start
        pos, rot = nik.pose_error(T, robot.fk(res.q))
        ok = (pos <= DEFAULT_TOL_POS) & (rot <= DEFAULT_TOL_ROT)
        total_ok, total = total_ok + int(ok.sum()), total + args.n
        print(
            f"{seed:>4}  {int(ok.sum()):>6} / {args.n} = {100 * ok.double().mean():6.2f} %"
            f"  {int(res.success.sum()):>8}   {bool(robot.within_limits(res.q).all())!s:>11}"
            f"   {float(pos.max()) * 1e3:>12.4f}   {math.degrees(float(rot.max())):>13.4f}   {seconds:>7.2f}"
        )
    print(f"all   {total_ok} / {total} = {100 * total_ok / total:.2f} %")


if __name__ == "__main__":
    main()
