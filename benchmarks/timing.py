"""Timing of IK paths by toppra (nik.paths.timing.time_path): limits kept at 1 ms, duration against toppra's own
defaults, the check's stretch and the time per call.

For each arm, Cartesian lines and circles (radius 5-15 cm, seeded) are solved by ``IKSolver.solve_path``; the
paths it follows (every waypoint reached, no reconfiguration) are timed with the arm's limits (``robot.vel_limits``
/ ``acc_limits``; ur5 and xarm7: accelerations assumed, 10 x the speed limits) and again with a tool speed of
0.25 m/s. Columns: paths followed and timed, the largest joint speed and acceleration over their limits when
sampled every 1 ms (<= 1 is kept), the largest stretch of the check, the largest relative difference of the
duration from toppra called with its own grid (``propose_gridpoints``) and output spline on the same joint path
and the largest acceleration over its limit of that answer sampled every 1 ms (toppra's defaults check the limits
at their gridpoints only), the median duration and the median milliseconds per ``time_path`` call.

    python benchmarks/timing.py                 # ur5, panda, xarm7; 8 paths each of 60 and 1,000 waypoints
    python benchmarks/timing.py --quick         # 3 paths each
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import warnings

import numpy as np
import torch

import nik
from nik.paths.timing import time_path


def _paths(robot, n_paths: int, n_points: int, seed: int):
    """Seeded Cartesian lines and circles starting at the pose of a random configuration: ``(n_points, 4, 4)``."""
    g = torch.Generator().manual_seed(seed)
    for k in range(n_paths):
        q0 = robot.sample(1, generator=g, dtype=torch.float64)[0]
        T0 = robot.fk(q0)
        r = 0.05 + 0.1 * float(torch.rand(1, generator=g, dtype=torch.float64))
        w = torch.linspace(0, 1, n_points, dtype=torch.float64)
        T = T0.expand(n_points, 4, 4).clone()
        if k % 2 == 0:
            d = torch.nn.functional.normalize(torch.randn(3, generator=g, dtype=torch.float64), dim=0)
            T[:, :3, 3] += 2 * r * w[:, None] * d
        else:
            a = 2 * math.pi * w
            T[:, 0, 3] += r * (torch.cos(a) - 1)
            T[:, 1, 3] += r * torch.sin(a)
        yield T


def run(names, n_paths: int, sizes) -> None:
    import toppra
    import toppra.algorithm
    import toppra.constraint

    print("| arm | waypoints | tool m/s | paths | max qd/limit | max qdd/limit | stretch | vs toppra defaults | "
          "toppra defaults: max qdd/limit | duration s (median) | ms per call (median) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        robot = nik.load_robot(name)
        solver = nik.IKSolver(robot)
        for n in sizes:
            joint_paths = []
            for T in _paths(robot, n_paths, n, seed=n):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = solver.solve_path(T, seed=0)
                if bool(res.success.all()) and int(res.path.reconfigurations.sum()) == 0:  # followed paths only
                    joint_paths.append(res.q.double().numpy())
            if not joint_paths:
                print(f"| {name} | {n} | - | 0 | | | | | | | |")
                continue
            for tool in (None, 0.25):
                vr, ar, stretch, diff, own_ar, dur, ms = [], [], [], [], [], [], []
                for q in joint_paths:
                    t0 = time.perf_counter()
                    tim = time_path(q, robot=robot, tool_speed=tool)
                    ms.append((time.perf_counter() - t0) * 1e3)
                    _, _, qd, qdd = tim.sample(1e-3)
                    vr.append(float(np.max(np.abs(qd) / tim.vel_limits)))
                    ar.append(float(np.max(np.abs(qdd) / tim.acc_limits)))
                    stretch.append(tim.stretch)
                    dur.append(tim.duration)
                    if tool is None:
                        cons = [
                            toppra.constraint.JointVelocityConstraint(tim.vel_limits),
                            toppra.constraint.JointAccelerationConstraint(tim.acc_limits),
                        ]
                        keep = np.concatenate([[True], np.diff(tim.s) > 0])
                        path = (
                            toppra.SplineInterpolator(tim.s[keep], q[keep])
                            if tim.interpolation == "cubic"
                            else tim.path
                        )
                        own = toppra.algorithm.TOPPRA(cons, path, solver_wrapper="seidel").compute_trajectory()
                        diff.append(abs(tim.duration / own.duration - 1))
                        t = np.append(np.arange(0.0, own.duration, 1e-3), own.duration)
                        own_ar.append(float(np.max(np.abs(own(t, 2)) / tim.acc_limits)))
                print(
                    f"| {name} | {n} | {tool or '-'} | {len(joint_paths)} | {max(vr):.9f} | {max(ar):.9f} | "
                    f"{max(stretch):.4f} | {f'{max(diff):.1e}' if diff else '-'} | "
                    f"{f'{max(own_ar):.3f}' if own_ar else '-'} | {statistics.median(dur):.3f} | "
                    f"{statistics.median(ms):.1f} |"
                )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", nargs="+", default=["ur5", "panda", "xarm7"])
    p.add_argument("--quick", action="store_true", help="3 paths per size")
    a = p.parse_args()
    torch.set_num_threads(1)
    run(a.robots, 3 if a.quick else 8, (60, 1000))


if __name__ == "__main__":
    main()
