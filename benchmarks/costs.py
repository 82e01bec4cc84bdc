"""What ``costs=`` adds to a solve: a user's term (the elbow above a plane) on a redundant arm, against the same
solve without it, interleaved in one process, one thread; medians in ms per call and the ratio.

Three calls on the same targets (poses of random configurations): ``plain``; ``met``: a term the plain answer
already meets (a plane 1 m below the elbow: the problem's first pass stops at once); ``binding``: the plane halfway
between the plain answer's elbow and the target configuration's own elbow where that one sits 1 cm or more higher
(the term moves every answer; it can be met).

    python benchmarks/costs.py [--robots panda xarm7] [--targets 20] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import torch

import nik
from nik.collision import link_frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "xarm7"])
    ap.add_argument("--targets", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    print("robot   targets  plain ms  met ms (x plain)  binding ms (x plain)  binding success")
    for name in args.robots:
        robot = nik.load_robot(name)
        solver = nik.IKSolver(robot)

        def elbow(q, robot=robot):
            return link_frames(robot, torch.as_tensor(q, dtype=torch.float64))[:, 4, 2, 3]

        q_own = robot.sample(8 * args.targets, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
        T = robot.fk(q_own)
        plain = solver.solve(T)
        keep = (elbow(q_own) > elbow(plain.q) + 0.01).nonzero()[:, 0][: args.targets]
        T = T[keep]
        h_bind = 0.5 * (elbow(q_own) + elbow(plain.q))[keep]
        h_low = elbow(plain.q)[keep] - 1.0
        met = nik.costs.custom(lambda q, h=h_low, f=elbow: (h - f(q)).clamp(min=0)[:, None], name="met")
        bind = nik.costs.custom(lambda q, h=h_bind, f=elbow: (h - f(q)).clamp(min=0)[:, None], name="binding")
        times = {"plain": [], "met": [], "binding": []}
        ok = None
        for _ in range(args.repeats):
            for key, costs in (("plain", None), ("met", [met]), ("binding", [bind])):
                t0 = time.perf_counter()
                res = solver.solve(T, costs=costs)
                times[key].append((time.perf_counter() - t0) * 1e3)
                if key == "binding":
                    ok = float(res.success.double().mean())
        m = {k: statistics.median(v) for k, v in times.items()}
        print(f"{name:7} {len(T):7d}  {m['plain']:8.1f}  {m['met']:6.1f} ({m['met'] / m['plain']:4.1f}x)  "
              f"{m['binding']:10.1f} ({m['binding'] / m['plain']:5.1f}x)  {ok:.0%}")  # fmt: skip


if __name__ == "__main__":
    main()
