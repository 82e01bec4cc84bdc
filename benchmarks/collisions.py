"""nik's sphere verdicts against the real collision meshes (coal) on sampled panda configurations.

    python benchmarks/collisions.py [--samples 2000] [--seed 0]

The panda of example-robot-data (its URDF with collision meshes, arm + hand + fingers; extra ``collision-check``
for coal and ``bench``/``urdf-tests`` for the URDF). Prints, for random configurations within the joint limits
(each one reachable by definition), without a world and in a scene (a table and 10 seeded boxes / spheres /
capsules near the arm): how many the meshes call colliding, how many nik calls colliding, how many nik calls
free that collide (must be 0) and how many nik calls colliding that are free (the price of conservative
spheres); and the time per configuration of each check (one core, one process).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik
from nik.collision.meshcheck import MeshCheck


def panda_urdf() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("cmeel")
    roots = [Path(p) for p in (spec.submodule_search_locations or [])] if spec else []
    for root in [*roots, *Path(nik.__file__).resolve().parents]:
        for cand in root.glob("**/example-robot-data/robots/panda_description/urdf/panda.urdf"):
            return cand
    import site

    for sp in site.getsitepackages():
        cand = Path(sp) / "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
        if cand.is_file():
            return cand
    raise SystemExit("example-robot-data's panda not found: pip install example-robot-data")


def scene(seed: int) -> nik.World:
    """A table under the arm's reach (top at z = 0, the base stands on it) and 10 obstacles around it."""
    rng = np.random.default_rng(seed)
    world = nik.World().add_box([0.45, 0.0, -0.05], [0.9, 1.2, 0.1])
    for i in range(10):
        angle = rng.uniform(-np.pi, np.pi)
        r = rng.uniform(0.45, 0.75)
        c = np.array([r * np.cos(angle), r * np.sin(angle), rng.uniform(0.1, 0.8)])
        kind = i % 3
        if kind == 0:
            world.add_box(c, rng.uniform(0.05, 0.15, size=3))
        elif kind == 1:
            world.add_sphere(c, rng.uniform(0.03, 0.08))
        else:
            world.add_capsule(c, c + rng.normal(size=3) * 0.1, rng.uniform(0.02, 0.05))
    return world


def verdicts(robot, mesh, Q, world):
    t = time.perf_counter()
    ours = nik.collision.collides(robot, Q, world)
    t_nik = (time.perf_counter() - t) / len(Q)
    t = time.perf_counter()
    theirs = mesh.collides(Q, world)
    t_mesh = (time.perf_counter() - t) / len(Q)
    return ours, theirs, t_nik, t_mesh


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    urdf = panda_urdf()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    t = time.perf_counter()
    model = robot.collision_spheres()
    print(f"model: {model} ({time.perf_counter() - t:.1f} s, cached after the first run)")
    print(f"  overreach per link (mm): {dict(zip(model.links, (1000 * model.gaps).round(0).astype(int)))}")
    mesh = MeshCheck(robot, urdf)
    g = torch.Generator().manual_seed(args.seed)
    dropped = mesh.drop_always(robot.sample(200, generator=g, dtype=torch.float64).numpy())
    print(f"mesh pairs checked: {len(mesh.pairs)} (always in contact, left out: {dropped})")
    Q = np.ascontiguousarray(robot.sample(args.samples, generator=g, dtype=torch.float64).numpy())
    # the kernels compile (or load) before timing
    nik.collision.collides(robot, Q[:2], scene(args.seed))
    print(f"\n{args.samples} random configurations, seed {args.seed}")
    print(
        "| world | mesh: colliding | nik: colliding | nik free, mesh colliding | nik colliding, mesh free "
        "| nik us/config | coal us/config |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, world in (("none (self only)", None), ("table + 10 obstacles", scene(args.seed))):
        ours, theirs, t_nik, t_mesh = verdicts(robot, mesh, Q, world)
        missed = int((~ours & theirs).sum())
        extra = int((ours & ~theirs).sum())
        print(
            f"| {name} | {theirs.mean():.1%} | {ours.mean():.1%} | {missed} | {extra} ({extra / len(Q):.1%}) "
            f"| {1e6 * t_nik:.1f} | {1e6 * t_mesh:.0f} |"
        )


if __name__ == "__main__":
    main()
