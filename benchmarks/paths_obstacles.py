"""Cartesian paths among obstacles (issue 36): ``solve_path(T, q_start=q0, world=w)`` on tool lines whose plain answer
sweeps the arm through a box, with CppFlow's criteria.

Problems (seeded): a 200-waypoint, 25 cm tool line (orientation fixed) from a configuration in the middle 60 % of the
ranges; the plain answer (no world) is solved; a box is placed off its elbow at the middle waypoint (``offset`` from
the elbow, away from the shoulder-wrist axis; half size ``size``), at least 20 cm from the tool's line, kept only
where the plain answer (which takes no step above 7 deg) collides with it and ``q0`` does not. Valid (CppFlow):
every waypoint within 0.1 mm / 0.1 deg by FK, no step (from q0 on) above 7 deg, no collision of the spheres at the
waypoints and at 7 samples inside every step (the sphere model: conservative, docs/collisions.md). Columns: valid
paths, the largest step (median over the problems, deg), the joint path length (median, sum of |dq|, rad), the
worst error (mm), the time per path (median, s). Rows: nik with the world (network on: the default checkpoint;
off: ``checkpoint=None``) and the plain answer (no world: what the straight motion does).

    OMP_NUM_THREADS=1 python benchmarks/paths_obstacles.py --n 8

Not measured here (issue 36, left to do): circles and letters among obstacles, xarm7 lines / circles and closed
loops from q_start, a chain of ``solve(q_near=previous, world=w)`` as the peer.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import nik  # noqa: E402
from nik.collision import collides, link_frames  # noqa: E402

N_WAYPOINTS, STEP = 200, math.radians(7.0)
BOXES = ((0.10, 0.02), (0.09, 0.03), (0.08, 0.04))  # (offset from the elbow, half size), metres


def problems(name: str, n: int, seed: int = 0):
    """``n`` problems ``(T (N, 4, 4), q0 (dof,), world)`` on ``name`` (module docstring)."""
    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot, checkpoint=None)
    rng = np.random.default_rng(seed)
    lim = robot.limits.numpy()
    mid = lim.mean(1)
    out = []
    while len(out) < n:
        q0 = mid + 0.6 * (rng.uniform(lim[:, 0], lim[:, 1]) - mid)
        d = rng.normal(size=3)
        T = np.repeat(robot.fk(q0)[None], N_WAYPOINTS, 0)
        T[:, :3, 3] += np.linspace(0, 1, N_WAYPOINTS)[:, None] * d * (0.25 / np.linalg.norm(d))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plain = solver.solve_path(T, q_start=q0)
        if not plain.success.all():
            continue
        q = plain.q.numpy()
        fr = link_frames(robot, torch.from_numpy(q[N_WAYPOINTS // 2 : N_WAYPOINTS // 2 + 1]))[0]
        elbow, sh, wr = (fr[k, :3, 3].numpy() for k in (4, 2, 6))
        if np.linalg.norm(T[:, :3, 3] - elbow, axis=1).min() < 0.2:
            continue
        ax = (wr - sh) / np.linalg.norm(wr - sh)
        away = elbow - sh - ((elbow - sh) @ ax) * ax
        offset, size = BOXES[len(out) % len(BOXES)]
        world = nik.World().add_box(elbow + offset * away / np.linalg.norm(away), [size] * 3)
        hit = collides(robot, np.concatenate([q0[None], q]), world, self_collision=False)
        if hit.any() and not hit[0] and np.abs(np.diff(q, axis=0)).max() <= STEP:  # q0 free, no jump of its own
            out.append((T, q0, world))
    return robot, out


def verdict(robot, T, q0, q, world) -> tuple[bool, float, float, float]:
    """``(valid, largest step rad, path length rad, worst error mm)`` of ``q: (N, dof)`` (module docstring)."""
    rows = np.concatenate([q0[None], q])
    d = np.diff(rows, axis=0)
    t = np.linspace(0.0, 1.0, 9)[None, :, None]
    motion = (rows[:-1, None] + t * d[:, None]).reshape(-1, robot.dof)
    pos, rot = (x.numpy() for x in nik.pose_error(torch.from_numpy(T), robot.fk(torch.from_numpy(q))))
    ok = pos.max() <= 1e-4 and rot.max() <= math.radians(0.1) and np.abs(d).max() <= STEP
    ok = ok and not collides(robot, motion, world, self_collision=False).any()
    return bool(ok), float(np.abs(d).max()), float(np.abs(d).sum()), float(pos.max() * 1e3)


def bench(name: str, n: int) -> list[str]:
    robot, probs = problems(name, n)
    solvers = {
        "nik, world, network on": nik.IKSolver(robot),
        "nik, world, network off": nik.IKSolver(robot, checkpoint=None),
    }
    rows = []
    for label, solver in [*solvers.items(), ("plain (no world)", solvers["nik, world, network off"])]:
        res = []
        for T, q0, world in probs:
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = solver.solve_path(T, q_start=q0, world=None if label.startswith("plain") else world)
            dt = time.perf_counter() - t
            res.append((*verdict(robot, T, q0, out.q.numpy(), world), dt))
        v, step, length, err, dt = (np.array(x) for x in zip(*res, strict=True))
        rows.append(
            f"| {name} | {label} | {int(v.sum())}/{len(v)} | {math.degrees(np.median(step)):.2f} | "
            f"{np.median(length):.2f} | {err.max():.4f} | {np.median(dt):.2f} |"
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=6, help="problems per robot")
    ap.add_argument("--robots", default="panda,xarm7")
    args = ap.parse_args()
    print("| robot | solver | valid | largest step (deg) | path length (rad) | worst error (mm) | s / path |")
    print("|---|---|---|---|---|---|---|")
    for name in args.robots.split(","):
        for row in bench(name, args.n):
            print(row, flush=True)


if __name__ == "__main__":
    main()
