"""Speed of ``solve_path``: the fixed cost of a call and the cost per waypoint, against Robotics Toolbox's ``ik_LM``
seeded by the previous waypoint (issue 29.5).

Paths: a straight line of 0.15 m from a configuration in the middle 60 % of the joint ranges, orientation fixed,
of 60 and 1,000 waypoints (the same line, finer), from ``q_start`` (the line's first configuration). nik:
``IKSolver(name).solve_path(T, q_start=q0)`` with its defaults (0.1 mm / 0.1 deg). rtb: ``ets.ik_LM(T[i],
q0=previous answer)`` with nik's tolerance (benchmarks/peers.py's RTB_TOL, RTB_MASK), joint limits on; the ETS is
benchmarks/paths.py's (nik's normal form, checked against nik's FK). One thread; the solvers interleaved, the order
alternating from repeat to repeat; medians, the ratio as the median of the interleaved pairs' ratios, and the
ratio of each solver's best time (the machine's load hits both alike; the best times are the quiet-machine figure).
The fixed cost: a 2-waypoint call (one step of the 1,000-waypoint
line), and the intercept of the line through the 60- and 1,000-waypoint times (printed below the table).

    OMP_NUM_THREADS=1 python benchmarks/path_speed.py --out benchmarks/results/path_speed.md
    OMP_NUM_THREADS=1 python benchmarks/path_speed.py --repeats 3   # a smoke run
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from paths import ets_of  # noqa: E402
from peers import RTB_MASK, RTB_TOL  # noqa: E402

import nik  # noqa: E402

LENGTH = 0.15  # m
SIZES = (2, 60, 1000)


def the_line(robot, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(T (n, 4, 4), q0 (dof,))``: a 0.15 m line from FK(q0) in a random direction, orientation fixed."""
    gen = torch.Generator().manual_seed(seed)
    lo, hi = robot.limits.double().T
    q0 = lo + (0.2 + 0.6 * torch.rand(robot.dof, generator=gen, dtype=torch.float64)) * (hi - lo)
    d = torch.randn(3, generator=gen, dtype=torch.float64)
    T0 = robot.fk(q0[None])[0]
    s = torch.linspace(0.0, 1.0, n, dtype=torch.float64)
    T = T0.expand(n, 4, 4).clone()
    length = LENGTH if n > 2 else LENGTH / 999  # 2 waypoints: one step of the 1,000-waypoint line
    T[:, :3, 3] = T0[:3, 3] + s[:, None] * length * d / d.norm()
    return T, q0


def time_nik(solver, T, q0) -> tuple[float, bool]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        res = solver.solve_path(T, q_start=q0)
        dt = time.perf_counter() - t
    return dt, bool(res.success.all())


def time_rtb(ets, T, q0) -> tuple[float, bool]:
    Tn = T.numpy()
    np.random.seed(0)
    prev = q0.numpy()
    ok = True
    t = time.perf_counter()
    for i in range(Tn.shape[0]):
        sol = ets.ik_LM(Tn[i], q0=prev, tol=RTB_TOL, mask=RTB_MASK, joint_limits=True)
        prev = sol.q
        ok &= bool(sol.success)
    return time.perf_counter() - t, ok


def bench(name: str, repeats: int) -> list[str]:
    solver = nik.IKSolver(name)
    robot = solver.robot
    ets = ets_of(robot)
    rows, whole = [], {}
    for n in SIZES:
        T, q0 = the_line(robot, n, seed=11)
        time_nik(solver, T, q0)  # compile / warm
        times = {"nik": [], "rtb": []}
        oks = {"nik": True, "rtb": True}
        reps = repeats if n < 1000 else max(3, repeats // 3)
        for r in range(reps):
            order = ("nik", "rtb") if r % 2 == 0 else ("rtb", "nik")
            for who in order:
                if who == "rtb" and ets is None:
                    continue
                dt, ok = time_nik(solver, T, q0) if who == "nik" else time_rtb(ets, T, q0)
                times[who].append(dt)
                oks[who] &= ok
        tn = statistics.median(times["nik"])
        tr = statistics.median(times["rtb"]) if times["rtb"] else math.nan
        paired = statistics.median(a / b for a, b in zip(times["rtb"], times["nik"], strict=True)) if tr == tr else tr
        best = min(times["rtb"]) / min(times["nik"]) if times["rtb"] else math.nan
        whole[n] = tn
        rows.append(
            f"| {name} | {n} | {tn * 1e3:.2f} | {tn / n * 1e6:.1f} | {oks['nik']} | {tr * 1e3:.2f} "
            f"| {tr / n * 1e6:.1f} | {oks['rtb']} | {paired:.1f}x | {best:.1f}x |"
        )
    slope = (whole[1000] - whole[60]) / 940
    fit = (
        f"- {name}: fixed cost {(whole[60] - 60 * slope) * 1e6:.0f} us (intercept), {slope * 1e6:.2f} us per waypoint "
        f"(slope), 2-waypoint call {whole[2] * 1e6:.0f} us"
    )
    return rows, fit + "; " + optimisation_cost(solver, repeats)


def optimisation_cost(solver, repeats: int) -> str:
    """The whole-trajectory optimisation's cost per waypoint (nik.paths.trajopt.optimise_path from solve_path's answer
    on the 60- and 1,000-waypoint lines, polished with every step capped at 1 deg: the shape terms active; run to its
    optimum, without the early stop of a feasible path that the polish uses)."""
    from nik.ik.model import model_of
    from nik.paths.trajopt import optimise_path

    model = model_of(solver.robot)
    out = []
    for n in SIZES[1:]:
        T, q0 = the_line(solver.robot, n, seed=11)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            Q = solver.solve_path(T, q_start=q0).q.numpy()
        Tn, qs = T.numpy(), q0.numpy()
        times, its = [], 0
        for _ in range(max(3, repeats // 3)):
            t = time.perf_counter()
            its = optimise_path(model, Tn, Q, q_start=qs, max_step=math.radians(1.0)).iterations
            times.append(time.perf_counter() - t)
        dt = statistics.median(times)
        each = dt / n / its * 1e6
        out.append(f"{n} waypoints {dt * 1e3:.1f} ms ({each:.2f} us per waypoint and factorisation, {its})")
    return "optimise_path: " + ", ".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    parser.add_argument("--out", type=Path, default=None, help="write the table (markdown) here")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    lines = [
        "| robot | waypoints | nik whole call ms | nik us / waypoint | nik all reached | rtb ik_LM ms | "
        "rtb us / waypoint | rtb all reached | rtb / nik (median of pairs) | rtb / nik (best of each) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for name in args.robots:
        rows, fit = bench(name, args.repeats)
        lines += rows
        notes.append(fit)
    lines += ["", *notes]
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        tmp = args.out.with_suffix(".tmp")
        tmp.write_text(f"`python benchmarks/path_speed.py --out {args.out}` (one thread)\n\n{text}\n")
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
