"""Tolerant goals and preferred postures in the solver, compiled backend, one thread (docs/bounds.md).

Rows: success and median us/target over 3 repeats, 1,000 random reachable targets (seed 0) per robot: full pose,
``bounds="position"``, ``bounds="axis_z"``, full pose with ``q_rest="mid"``; then, with a tool 0.25 m off the
flange and the targets turned about their tool z by a random angle, the share solved with a fixed orientation, with
z free, and solved only with z free. Run: ``OMP_NUM_THREADS=1 python benchmarks/goals.py`` (about a minute).

``--urdf PATH [--root-link A] --end-link B`` times a URDF arm instead (the speed rows only), with a row
``axis_z (turned)``: the targets turned about their tool z by a random angle (a closed-form arm then searches the free
angle), e.g. example-robot-data's Kinova Gen2:
``python benchmarks/goals.py --urdf .../kinova_description/robots/kinova.urdf --end-link j2s6s200_end_effector``.

``--rest`` measures ``q_rest="mid"`` on redundant arms (xarm7, panda; ``--n`` targets from FK of random configurations,
seed 0, default 200 with ``--rest``): success, the median ms/target of ``solve()`` and of ``solve(q_rest="mid")`` over 3
repeats, and the mean joint distance (Euclidean, rad) of the answers to the middle of the ranges against that of the
nearest solution ``solve_all`` finds (the first ``--n-all`` targets, default 60). Run:
``OMP_NUM_THREADS=1 python benchmarks/goals.py --rest`` (about a minute); result: ``benchmarks/results/goals_rest.md``.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import torch

import nik


def _median_time(solver, T, bounds, q_rest, reps: int = 3):
    times, res = [], None
    for _ in range(reps):
        t = time.perf_counter()
        res = solver.solve(T, bounds=bounds, q_rest=q_rest)
        times.append(time.perf_counter() - t)
    return res, sorted(times)[reps // 2]


def _turned(T: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    """``T: (n, 4, 4)`` turned about each tool z by a random angle."""
    n = T.shape[0]
    angle = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    R = torch.eye(4, dtype=torch.float64).repeat(n, 1, 1)
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = angle.cos(), -angle.sin(), angle.sin(), angle.cos()
    return T @ R


def speed(name, n: int = 1000, turned: bool = False) -> None:
    robot = nik.load_robot(name) if isinstance(name, str) else name
    g = torch.Generator().manual_seed(0)
    T = robot.fk(robot.sample(n, generator=g, dtype=torch.float64))
    solver = nik.IKSolver(robot, backend="compiled")
    cases = [(None, None, T), ("position", None, T), ("axis_z", None, T), (None, "mid", T)]
    if turned:
        cases.append(("axis_z", None, _turned(T, g)))
    cases = [(b, r, t.numpy()) for b, r, t in cases]
    for bounds, q_rest, Tc in cases:  # warm-up (compilation)
        solver.solve(Tc[:5], bounds=bounds, q_rest=q_rest)
    for i, (bounds, q_rest, Tc) in enumerate(cases):
        res, dt = _median_time(solver, Tc, bounds, q_rest)
        goal = (bounds or "pose") + (" + q_rest=mid" if q_rest else "") + (" (turned)" if i == 4 else "")
        print(f"| {robot.name} | {goal} | {res.success.mean() * 100:.2f} % | {dt / n * 1e6:.1f} |")


def free_axis(name: str, n: int = 1000) -> None:
    robot = nik.load_robot(name, tool=[0.25, 0, 0.1, 1, 0, 0, 0])
    g = torch.Generator().manual_seed(1)
    T = _turned(robot.fk(robot.sample(n, generator=g, dtype=torch.float64)), g).numpy()
    solver = nik.IKSolver(robot, backend="compiled")
    fixed, free = solver.solve(T).success, solver.solve(T, bounds="axis_z").success
    only = (free & ~fixed).mean() * 100
    print(f"| {name} | {fixed.mean() * 100:.1f} % | {free.mean() * 100:.1f} % | {only:.1f} % |")


def rest(name: str, n: int = 200, n_all: int = 60) -> None:
    """One row of ``--rest`` (module docstring)."""
    import numpy as np

    from nik.ik.goals import rest_target

    robot = nik.load_robot(name)
    g = torch.Generator().manual_seed(0)
    T = robot.fk(robot.sample(n, generator=g, dtype=torch.float64)).numpy()
    solver = nik.IKSolver(robot, backend="compiled")
    mid = rest_target(robot, "mid", 1)[0]
    solver.solve(T[:5]), solver.solve(T[:5], q_rest="mid")  # warm-up (compilation)
    plain, t_plain = _median_time(solver, T, None, None)
    res, t_rest = _median_time(solver, T, None, "mid")
    dist = np.linalg.norm(np.asarray(res.q) - mid, axis=1)
    nearest = np.array([np.linalg.norm(solver.solve_all(T[i : i + 1]).numpy() - mid, axis=1).min() for i in
                        range(n_all)])  # fmt: skip
    ratio = dist[:n_all].mean() / nearest.mean()
    print(
        f"| {name} | {plain.success.mean() * 100:.1f} % | {res.success.mean() * 100:.1f} % | {t_plain / n * 1e3:.3f} | "
        f"{t_rest / n * 1e3:.3f} | {dist.mean():.3f} | {nearest.mean():.3f} | {ratio:.3f} |"
    )


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urdf")
    ap.add_argument("--root-link")
    ap.add_argument("--end-link")
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--rest", action="store_true", help="q_rest='mid' on xarm7 and panda (module docstring)")
    ap.add_argument("--n-all", type=int, default=60)
    args = ap.parse_args()
    if args.rest:
        torch.set_num_threads(1)
        n = args.n if args.n != 1000 else 200
        print(
            f"{n} targets (FK of random q, seed 0), one thread; distances: mean over all targets, nearest of solve_all "
            f"and the ratio over the first {args.n_all}\n"
        )
        print(
            "| robot | success | success q_rest | ms/target solve() | ms/target q_rest='mid' | mean distance to mid "
            "(rad) | nearest of solve_all (rad) | ratio |\n|---|---|---|---|---|---|---|---|"
        )
        for robot_name in ("xarm7", "panda"):
            rest(robot_name, n, args.n_all)
        raise SystemExit
    print("| robot | goal | success | us/target |\n|---|---|---|---|")
    if args.urdf:
        speed(nik.load_robot(args.urdf, root_link=args.root_link, end_link=args.end_link), args.n, turned=True)
        raise SystemExit
    for robot_name in ("panda", "ur5"):
        speed(robot_name)
    print("\n| robot (tool 0.25 m off the flange) | fixed orientation | z free | only with z free |\n|---|---|---|---|")
    for robot_name in ("ur5", "kuka_kr"):
        free_axis(robot_name)
