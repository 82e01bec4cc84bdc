"""Tolerant goals: success and time of the compiled LM with bounds against the full pose, and the free tool axis on
closed-form arms.

Part 1, per robot (one process, one thread): N reachable targets (FK of uniform configurations), no network, each
target from the best of 8 uniform configurations then LM with up to 274 uniform restarts (the compiled path's
budget, :mod:`nik.lm.compiled`). Goals, interleaved by repeats (median time per target):

- ``pose``: the classic error, 0.1 mm / 0.1 deg (``lm_solve``);
- ``position``: the ``"position"`` shorthand (``lm_solve_bounded``), the targets' orientations replaced by
  random ones (only the position is asked for);
- ``axis_z``: the ``"axis_z"`` shorthand, the targets turned about their tool z axis by a random angle.

Success is measured by torch FK of the answer: ``within_bounds`` (the pose goal: ``pose_error``).

Part 2 (``ur5``, ``kuka_kr`` with a tool 0.25 m off the flange): targets turned about their tool z axis by a
random angle: the share that no closed-form solution reaches at the given orientation, and the share of all
that :func:`nik.ik.free_axis.closed_form_free_axis` solves with the z rotation free.

    python benchmarks/bounds.py            # 1,000 targets, 3 repeats
    python benchmarks/bounds.py --quick    # 200 targets, 1 repeat
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
import torch

import nik
from nik.ik.bounds import parse_bounds
from nik.ik.free_axis import _about, closed_form_free_axis
from nik.kernels import lm
from nik.lm.batched import LMCfg
from nik.lm.compiled import restart_budget
from nik.poses import quaternion_to_matrix, within_bounds


def _goal_targets(robot, goal: str, n: int, seed: int):
    g = torch.Generator().manual_seed(seed)
    T = robot.fk(robot.sample(n, generator=g, dtype=torch.float64))
    if goal == "position":
        T[:, :3, :3] = quaternion_to_matrix(torch.randn(n, 4, generator=g, dtype=torch.float64))
    elif goal == "axis_z":
        T = T @ _about(2, (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * math.pi)
    return T


def part1(names, n: int, repeats: int) -> None:
    budget = restart_budget(LMCfg())
    print("| robot | goal | success | median us/target | ratio to pose |")
    print("|---|---|---|---|---|")
    for name in names:
        robot = nik.load_robot(name)
        G, joints = robot.chain_arrays()
        opts, iopts = lm.lm_options(first_starts=8, tail_after=LMCfg().restarts, tail_iters=100, tail_stall_iters=10)
        times = {g: [] for g in ("pose", "position", "axis_z")}
        success = {}
        targets = {g: _goal_targets(robot, g, n, seed=7) for g in times}
        for rep in range(-1, repeats):  # -1: a warm-up (compiles or loads the kernels), not timed
            for goal in times:
                T = targets[goal]
                Tn = np.ascontiguousarray(T.numpy())
                out = [np.empty((n, robot.dof)), np.empty(n, np.int64), np.empty(n, bool), np.empty(n), np.empty(n)]
                q0 = np.zeros((n, robot.dof))
                restarts = np.full(n, budget, dtype=np.int64)
                seed = lm.seed_state(max(rep, 0))
                if goal == "pose":
                    t = time.perf_counter()
                    lm.lm_solve(G, joints, Tn, q0, opts, iopts, restarts, seed, tuple(out))
                    times[goal].append((time.perf_counter() - t) / n)
                    pos, rot = nik.pose_error(T, robot.fk(torch.from_numpy(out[0])))
                    ok = (pos <= 1e-4) & (rot <= math.radians(0.1))
                else:
                    b = parse_bounds(goal, batch=n)
                    bounds, modes = b.expand(n), b.modes(n)
                    t = time.perf_counter()
                    lm.lm_solve_bounded(G, joints, Tn, q0, (bounds, modes), opts, iopts, restarts, seed, tuple(out))
                    times[goal].append((time.perf_counter() - t) / n)
                    ok = within_bounds(T, robot.fk(torch.from_numpy(out[0])), torch.from_numpy(bounds))
                success[goal] = float(ok.double().mean())
                if rep < 0:
                    times[goal].clear()
        base = statistics.median(times["pose"])
        for goal, ts in times.items():
            med = statistics.median(ts)
            print(f"| {name} | {goal} | {100 * success[goal]:.2f} % | {med * 1e6:.1f} | {med / base:.2f} |")


def part2(n: int) -> None:
    print("\n| robot (tool 0.25 m off the flange) | fixed orientation feasible | solved with z free | LM refined |")
    print("|---|---|---|---|")
    for name in ("ur5", "kuka_kr"):
        robot = nik.load_robot(name, tool=[0.25, 0, 0.1, 1, 0, 0, 0])
        g = torch.Generator().manual_seed(11)
        T = robot.fk(robot.sample(n, generator=g, dtype=torch.float64))
        T = T @ _about(2, (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * math.pi)
        _, valid = nik.analytic.solve(robot, T)
        res = closed_form_free_axis(robot, T)
        fixed = float(valid.any(-1).double().mean())
        print(f"| {name} | {100 * fixed:.1f} % | {100 * float(res.success.double().mean()):.1f} % "
              f"| {int(res.refined.sum())} |")  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", nargs="+", default=["panda", "ur5", "kuka_kr"])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--quick", action="store_true")
    a = p.parse_args()
    if a.quick:
        a.n, a.repeats = 200, 1
    torch.set_num_threads(1)
    part1(a.robots, a.n, a.repeats)
    part2(a.n)


if __name__ == "__main__":
    main()
