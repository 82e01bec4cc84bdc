"""Time per target of collision-free IK on the built-in panda in the scene of benchmarks/collisions.py: its shipped
model (spheres fitted to the meshes) against 5 cm capsules and against no world; one thread, interleaved, median of 3.

    python benchmarks/collision_builtin_time.py [--targets 200] [--seed 0] [--models OLD.collision.json ...]

Targets: the poses of seeded random configurations free by every model timed. ``--models``: other panda model
files (an earlier fit, e.g. ``git show REV:configs/robots/collision/panda.collision.json``) timed alongside,
interleaved in the same process, for a before / after.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik
from nik.collision import CollisionModel, collides, collision_model, set_collision_model

sys.path.insert(0, str(Path(__file__).resolve().parent))
from collisions import scene  # noqa: E402  (the same scene as benchmarks/collisions.py)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--models", nargs="*", default=[], help="other panda model files timed alongside")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    nik.set_threads(1)
    world = scene(args.seed)
    robots = {}
    for kind in ("shipped", "capsules"):
        robot = nik.load_robot("panda")
        model = collision_model(robot) if kind == "shipped" else collision_model(robot, source="capsules")
        set_collision_model(robot, model)
        robots[kind] = (robot, model)
    for path in args.models:
        robot = nik.load_robot("panda")
        model = CollisionModel.load(path)
        model.robot_hash = robot.definition_hash  # a file of the bare arm (the shipped format)
        set_collision_model(robot, model)
        robots[Path(path).name] = (robot, model)
    r0 = robots["shipped"][0]
    q = r0.sample(3 * args.targets, generator=torch.Generator().manual_seed(args.seed), dtype=torch.float64).numpy()
    free = np.ones(len(q), dtype=bool)
    for _, model in robots.values():
        free &= ~collides(r0, q, world, model=model)
    T = np.ascontiguousarray(r0.fk(q[free][: args.targets]))
    solvers = {k: nik.IKSolver(r, world=world) for k, (r, _) in robots.items()}
    solvers["no world"] = nik.IKSolver(nik.load_robot("panda"))
    for s in solvers.values():
        s.solve(T[:5])  # compile / load the kernels
    times = {k: [] for k in solvers}
    success = {}
    for _ in range(3):
        for k, s in solvers.items():
            t = time.perf_counter()
            res = s.solve(T)
            times[k].append((time.perf_counter() - t) / len(T))
            success[k] = float(np.mean(np.asarray(res.success)))
    base = float(np.median(times["no world"]))
    for k in times:
        med = float(np.median(times[k]))
        n = len(robots[k][1].radii) if k in robots else 0
        print(
            f"{k}: {n} spheres, {len(T)} targets, {1e6 * med:.0f} us/target ({med / base:.2f}x no world), "
            f"ok {success[k]:.1%}"
        )


if __name__ == "__main__":
    main()
