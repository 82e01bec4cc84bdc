"""Constraints compose (issue 34): success of each mix of {bounds, q_rest, world, self-collision} against the same
targets without the world, and the collision-free time against no world.

    python benchmarks/compose.py [--targets 500] [--time-targets 1000] [--seed 0] [--robots panda xarm7 ur5]

Per robot (nik's built-ins; their collision model: :func:`nik.collision.collision_model`), a clutter (:func:`scene`:
a table under the arm and 12 seeded obstacles 0.3-0.6 m from its base), and targets that are the poses of random
configurations the sphere check calls free of the scene and of the arm itself (the spheres are conservative: free by
them is free on the meshes, docs/collisions.md), so every target has a collision-free answer: its own configuration.
Each mix of ``bounds`` (none, ``"position"``, ``"axis_z"``) and ``q_rest`` (none, ``"mid"``) is solved without the
world (``self_collision=False``), with the world and self-collision (the default with a world) and with the world
alone (``self_collision=False``); success is re-checked here by FK (the pose within tolerance, or every axis inside
the bounds by :func:`nik.poses.tool_error`), the joint limits and the sphere check (:func:`nik.collision.collides`),
not read from ``res.success``; the last column is the mean distance of the successful answers from the middle of the
joint ranges (``q_rest="mid"``'s posture; also on the rows without it). Then the time per target of the panda with
the world against without (``--time-targets``, interleaved, median of 3, one process). Prints a table; saves it to
benchmarks/results/compose.txt.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik
from nik.collision import collides, collision_model, set_collision_model
from nik.ik.bounds import parse_bounds
from nik.poses import rotation_modes, tool_error

BOUNDS = (None, "position", "axis_z")
RESTS = (None, "mid")


def scene(seed: int) -> nik.World:
    """A table under the arm (top at z = 0) and 12 seeded boxes, spheres and capsules 0.3-0.6 m from its base, up to
    0.2 m across: a clutter in which 10-43 % of the plain answers collide (panda, xarm7, ur5)."""
    rng = np.random.default_rng(seed)
    world = nik.World().add_box([0.45, 0.0, -0.05], [0.9, 1.2, 0.1])
    for i in range(12):
        angle, r = rng.uniform(-np.pi, np.pi), rng.uniform(0.3, 0.6)
        c = np.array([r * np.cos(angle), r * np.sin(angle), rng.uniform(0.1, 0.8)])
        if i % 3 == 0:
            world.add_box(c, rng.uniform(0.05, 0.2, size=3))
        elif i % 3 == 1:
            world.add_sphere(c, rng.uniform(0.03, 0.1))
        else:
            world.add_capsule(c, c + rng.normal(size=3) * 0.1, rng.uniform(0.02, 0.2 / 3))
    return world


def targets(robot, n: int, world, seed: int) -> np.ndarray:
    """Poses of ``n`` random configurations free of ``world`` and of the arm itself (spheres)."""
    g = torch.Generator().manual_seed(seed)
    q = robot.sample(8 * n, generator=g, dtype=torch.float64).numpy()
    q = q[~collides(robot, q, world)][:n]
    return np.ascontiguousarray(robot.fk(torch.from_numpy(q)).numpy())


def honest(robot, T: np.ndarray, res, bounds, world, self_on: bool) -> np.ndarray:
    """``(B,)`` bool: the answer meets the goal by FK, inside the limits, and free (where a check is asked)."""
    q = torch.as_tensor(np.asarray(res.q), dtype=torch.float64)
    Tt = torch.from_numpy(T)
    Tq = robot.fk(q)
    goal = parse_bounds(bounds, tol_pos=1e-4, tol_rot=np.radians(0.1))
    if goal is None:
        pos, rot = nik.poses.pose_error(Tt, Tq)
        ok = (pos <= 1e-4) & (rot <= np.radians(0.1))
    else:
        half = torch.from_numpy(goal.expand(len(T)))
        d = tool_error(Tt, Tq, rotation_modes(half))
        ok = (d.abs() <= half).all(-1)
    lim = robot.limits.double()
    ok &= ((q >= lim[:, 0] - 1e-9) & (q <= lim[:, 1] + 1e-9)).all(-1)
    ok = ok.numpy()
    if world is not None or self_on:
        ok &= ~collides(robot, q.numpy(), world, self_collision=self_on)
    return ok


def success_table(names, n: int, seed: int, lines: list) -> None:
    world = scene(seed)
    lines.append(f"success (%), {n} targets per robot from configurations free of the scene (table + 12), seed {seed}")
    lines.append(
        "| robot | bounds | q_rest | no world | world + self | world only | world + self - no world "
        "| mean |q - q_rest| rad: no world / world + self |"
    )
    lines.append("|---|---|---|---|---|---|---|---|")
    for name in names:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            robot = nik.load_robot(name)
            set_collision_model(robot, collision_model(robot))
            T = targets(robot, n, world, seed)
            mid = robot.limits.double().mean(1).numpy()  # q_rest="mid"
            for bounds in BOUNDS:
                for rest in RESTS:
                    row, dist = [], []
                    for w, self_on in ((None, False), (world, True), (world, False)):
                        s = nik.IKSolver(robot, self_collision=self_on)
                        res = s.solve(T, bounds=bounds, q_rest=rest, world=w, seed=seed)
                        ok = honest(robot, T, res, bounds, w, self_on)
                        row.append(100.0 * ok.mean())
                        dist.append(np.linalg.norm(np.asarray(res.q)[ok] - mid, axis=1).mean())
                    lines.append(
                        f"| {name} | {bounds} | {rest} | {row[0]:.1f} | {row[1]:.1f} | {row[2]:.1f} "
                        f"| {row[1] - row[0]:+.1f} | {dist[0]:.3f} / {dist[1]:.3f} |"
                    )
                    print(lines[-1], flush=True)


def time_table(n: int, seed: int, lines: list) -> None:
    world = scene(seed)
    robot = nik.load_robot("panda")
    set_collision_model(robot, collision_model(robot))
    T = targets(robot, n, world, seed)
    plain, safe = nik.IKSolver(robot, self_collision=False), nik.IKSolver(robot, world=world)
    lines.append("")
    lines.append(f"time per target, panda, {len(T)} targets, interleaved, median of 3 (one process)")
    lines.append("| bounds | no world us | world + self us | ratio |")
    lines.append("|---|---|---|---|")
    for bounds in (None, "axis_z"):
        plain.solve(T[:4], bounds=bounds), safe.solve(T[:4], bounds=bounds)
        t = {"plain": [], "safe": []}
        for _ in range(3):
            for key, s in (("plain", plain), ("safe", safe)):
                t0 = time.process_time()
                s.solve(T, bounds=bounds, seed=seed)
                t[key].append((time.process_time() - t0) / len(T))
        a, b = float(np.median(t["plain"])), float(np.median(t["safe"]))
        lines.append(f"| {bounds} | {1e6 * a:.0f} | {1e6 * b:.0f} | {b / a:.2f}x |")
        print(lines[-1], flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=500)
    ap.add_argument("--time-targets", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--robots", nargs="+", default=["panda", "xarm7", "ur5"])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "compose.txt"))
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    lines: list = []
    success_table(args.robots, args.targets, args.seed, lines)
    if args.time_targets:
        time_table(args.time_targets, args.seed, lines)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
