"""What ``costs=`` adds to a solve: a user's term (the elbow above a plane) on a redundant arm, against the same
solve without it, interleaved in one process, one thread; medians in ms per call and the ratio.

Three calls on the same targets (poses of random configurations): ``plain``; ``met``: a term the plain answer
already meets (a plane 1 m below the elbow: the problem's first pass stops at once); ``binding``: the plane halfway
between the plain answer's elbow and the target configuration's own elbow where that one sits 1 cm or more higher
(the term moves every answer; it can be met).

    python benchmarks/costs.py [--robots panda xarm7] [--targets 20] [--repeats 5]

``--builtin``: the built-in terms given via ``costs=`` against the keyword they equal (``posture`` vs ``q_rest="mid"``,
``bounded_pose`` vs ``bounds=``) and ``manipulability`` against a plain solve, interleaved call by call in one
process, one thread, medians in us per target; with the mean manipulability of the answers and the success rate:

    python benchmarks/costs.py --builtin [--robots panda] [--targets 300] [--repeats 7]
"""

from __future__ import annotations

import argparse
import math
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
    ap.add_argument("--builtin", action="store_true", help="built-in terms via costs= against their keywords")
    args = ap.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    if args.builtin:
        return builtin(args)
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


def builtin(args) -> None:
    """The ``--builtin`` table (module docstring)."""
    from nik.costs.manipulability import measure

    print("robot   targets  call                          us/target  x base  mean w   success")
    for name in args.robots:
        robot = nik.load_robot(name)
        solver = nik.IKSolver(robot)
        T = robot.fk(robot.sample(args.targets, generator=torch.Generator().manual_seed(0), dtype=torch.float64))
        box = (1e-3, 1e-3, 1e-3, math.inf, math.inf, math.inf)
        calls = {
            "plain": {},
            'q_rest="mid"': {"q_rest": "mid"},
            "costs=[posture mid]": {"costs": [nik.costs.posture(robot, "mid")]},
            "bounds=": {"bounds": box},
            "costs=[bounded_pose]": {"costs": [nik.costs.bounded_pose(robot, T, box)]},
            "costs=[manipulability 0.1]": {"costs": [nik.costs.manipulability(robot, weight=0.1)]},
        }
        base = {'q_rest="mid"': "plain", "costs=[posture mid]": 'q_rest="mid"', "bounds=": "plain",
                "costs=[bounded_pose]": "bounds=", "costs=[manipulability 0.1]": "plain"}  # fmt: skip
        times = {k: [] for k in calls}
        out = {}
        for k, kw in calls.items():  # warm: compiled kernels loaded
            out[k] = solver.solve(T, **kw)
        for _ in range(args.repeats):
            for k, kw in calls.items():
                t0 = time.perf_counter()
                solver.solve(T, **kw)
                times[k].append((time.perf_counter() - t0) * 1e6 / len(T))
        med = {k: statistics.median(v) for k, v in times.items()}
        for k in calls:
            ratio = f"{med[k] / med[base[k]]:5.2f}x" if k in base else "     -"
            w = float(measure(robot, torch.as_tensor(out[k].q)).mean())
            ok = float(out[k].success.double().mean())
            print(f"{name:7} {len(T):7d}  {k:28} {med[k]:9.1f}  {ratio}  {w:.4f}  {ok:.1%}")


if __name__ == "__main__":
    main()
