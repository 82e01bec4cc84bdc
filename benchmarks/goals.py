"""Tolerant goals and preferred postures in the solver, compiled backend, one thread (docs/bounds.md).

Rows: success and median us/target over 3 repeats, 1,000 random reachable targets (seed 0) per robot: full pose,
``bounds="position"``, ``bounds="axis_z"``, full pose with ``q_rest="mid"``; then, with a tool 0.25 m off the
flange and the targets turned about their tool z by a random angle, the share solved with a fixed orientation, with
z free, and solved only with z free. Run: ``OMP_NUM_THREADS=1 python benchmarks/goals.py`` (about a minute).
"""

from __future__ import annotations

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


def speed(name: str, n: int = 1000) -> None:
    robot = nik.load_robot(name)
    g = torch.Generator().manual_seed(0)
    T = robot.fk(robot.sample(n, generator=g, dtype=torch.float64)).numpy()
    solver = nik.IKSolver(robot, backend="compiled")
    cases = [(None, None), ("position", None), ("axis_z", None), (None, "mid")]
    for bounds, q_rest in cases:  # warm-up (compilation)
        solver.solve(T[:5], bounds=bounds, q_rest=q_rest)
    for bounds, q_rest in cases:
        res, dt = _median_time(solver, T, bounds, q_rest)
        goal = (bounds or "pose") + (" + q_rest=mid" if q_rest else "")
        print(f"| {name} | {goal} | {res.success.mean() * 100:.2f} % | {dt / n * 1e6:.1f} |")


def free_axis(name: str, n: int = 1000) -> None:
    robot = nik.load_robot(name, tool=[0.25, 0, 0.1, 1, 0, 0, 0])
    g = torch.Generator().manual_seed(1)
    T = robot.fk(robot.sample(n, generator=g, dtype=torch.float64))
    angle = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    R = torch.eye(4, dtype=torch.float64).repeat(n, 1, 1)
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = angle.cos(), -angle.sin(), angle.sin(), angle.cos()
    T = (T @ R).numpy()
    solver = nik.IKSolver(robot, backend="compiled")
    fixed, free = solver.solve(T).success, solver.solve(T, bounds="axis_z").success
    only = (free & ~fixed).mean() * 100
    print(f"| {name} | {fixed.mean() * 100:.1f} % | {free.mean() * 100:.1f} % | {only:.1f} % |")


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    print("| robot | goal | success | us/target |\n|---|---|---|---|")
    for robot_name in ("panda", "ur5"):
        speed(robot_name)
    print("\n| robot (tool 0.25 m off the flange) | fixed orientation | z free | only with z free |\n|---|---|---|---|")
    for robot_name in ("ur5", "kuka_kr"):
        free_axis(robot_name)
