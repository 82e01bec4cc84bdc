"""Feasible targets in scenes nobody tuned on: found % of the default collision solver and its time against the
same solver without a world (issue 47, item 7).

    python benchmarks/collision_feasible.py [--robots panda,xarm7,urdf-panda,baxter] [--seeds 0,1,2]
                                            [--targets 100] [--baxter-targets 50] [--repeats 3]
                                            [--out benchmarks/results/collision_feasible.md]

For each robot and seed: a scene drawn from the seed (a table just below the arm's base frame, 3 boxes and
3 spheres placed by the seed in the shell the arm reaches, sizes scaled by its reach), ``--targets`` poses of
random configurations that the robot's meshes call free of the scene and of the arm itself (coal,
:class:`nik.collision.meshcheck.MeshCheck` with the pairs the model leaves out by decision left out: each target
has a known free answer). Three solvers, one thread: ``IKSolver(robot, self_collision=False)`` (no world),
``IKSolver(robot, world=scene)`` (the default: the meshes judge where coal is installed, the spheres steer, the
meshes steer where the spheres refuse, :mod:`nik.ik.collide`) and the same without the mesh step
(``CollideCfg(mesh_steer=False)``). Reported: found % (success of the collision solver),
answers called free that collide on the meshes (must be 0), CPU time per target of each (after a warm-up call, the
median of ``--repeats`` calls on all the targets, the three solvers interleaved) and their ratio, and the default
solver's first call apart (it also pays what a process loads once for the mesh step); then per robot the median
and the spread (min - max) over the seeds.

Robots: the built-in ``panda`` and ``xarm7`` (shipped sphere models), ``urdf-panda`` (example-robot-data's panda
URDF, its fitted model), ``baxter`` (example-robot-data's Baxter, ``root_link="torso"``,
``end_link="right_hand_link"``; its first fit takes tens of seconds, then cached). Needs coal and
example-robot-data (``pip install -e ".[collision-check,urdf-tests]"``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik

ROBOTS = ("panda", "xarm7", "urdf-panda", "baxter")


def load(name: str):
    """``(robot, model)`` of a benchmark robot name (module docstring); SystemExit naming what is missing."""
    from nik.collision import collision_model
    from nik.collision.builtin import erd_path

    if name in ("panda", "xarm7"):
        robot = nik.load_robot(name)
        return robot, collision_model(robot)
    rel = {"urdf-panda": "panda_description/urdf/panda.urdf", "baxter": "baxter_description/urdf/baxter.urdf"}
    if name not in rel:
        raise SystemExit(f"collision_feasible: unknown robot {name!r} (one of {', '.join(ROBOTS)})")
    urdf = erd_path(rel[name])
    if urdf is None:
        raise SystemExit("collision_feasible: example-robot-data is not installed (pip install example-robot-data)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if name == "baxter":
            robot = nik.load_robot(urdf, root_link="torso", end_link="right_hand_link")
        else:
            robot = nik.load_robot(urdf, end_link="panda_hand")
        model = collision_model(robot)
    nik.collision.set_collision_model(robot, model)
    return robot, model


def reach_of(robot, seed: int = 0) -> tuple[np.ndarray, float]:
    """``(centre (3,), radius)``: the first moving joint's origin and the farthest tool position of 2,000 random
    configurations from it (metres)."""
    from nik.collision.urdf import frames_at

    q = robot.sample(2000, generator=torch.Generator().manual_seed(seed), dtype=torch.float64).numpy()
    p = np.asarray(robot.fk(q))[:, :3, 3]
    centre = frames_at(robot, q[0])[1][:3, 3]
    return centre, float(np.linalg.norm(p - centre, axis=1).max())


def scene(robot, seed: int) -> nik.World:
    """A table under the base frame (its top 1 cm below the base's origin; Baxter's half a reach below its torso),
    2 reaches wide, and 3 boxes and 3 spheres placed by ``seed`` between 0.4 and 0.9 reaches from the first joint,
    above the table."""
    centre, reach = reach_of(robot)
    rng = np.random.default_rng(seed)
    top = -0.01 if robot.name != "baxter" else -0.5 * reach  # under the base (Baxter's arm hangs below its torso)
    world = nik.World().add_box([centre[0] + 0.5 * reach, centre[1], top - 0.05], [2 * reach, 2 * reach, 0.1])
    for i in range(6):
        for _ in range(100):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            c = centre + d * rng.uniform(0.4, 0.9) * reach
            if c[2] > top + 0.05:
                break
        if i % 2 == 0:
            world.add_box(c, rng.uniform(0.05, 0.15, size=3) * reach)
        else:
            world.add_sphere(c, float(rng.uniform(0.04, 0.1) * reach))
    return world


def targets(robot, model, world, n: int, seed: int):
    """``(T (n', 4, 4), mesh)``: poses of random configurations the meshes call free (module docstring)."""
    from nik.collision.meshcheck import mesh_check

    mesh = mesh_check(robot, model, required=True)
    g = torch.Generator().manual_seed(1000 + seed)
    Q = np.ascontiguousarray(robot.sample(6 * n, generator=g, dtype=torch.float64).numpy())
    free = Q[~mesh.collides(Q, world)][:n]
    return np.ascontiguousarray(robot.fk(free)), mesh


class _Steered:
    """Counts the targets the collision stage hands to the mesh step (:mod:`nik.ik.collide.mesh_step`), those it
    finds, and the CPU seconds it takes, while installed (``with``)."""

    def __enter__(self):
        import nik.ik.collide.stage as stage

        self.stage, self.fn = stage, stage.mesh_step
        self.targets, self.found, self.cpu = 0, 0, 0.0

        def counted(robot, step, T, first, own):
            c = time.process_time()
            q, ok = self.fn(robot, step, T, first, own)
            self.cpu += time.process_time() - c
            self.targets, self.found = self.targets + len(T), self.found + int(ok.sum())
            return q, ok

        stage.mesh_step = counted
        return self

    def __exit__(self, *exc):
        self.stage.mesh_step = self.fn


def run(name: str, seeds: list[int], n: int, repeats: int = 3) -> list[dict]:
    """One row per seed: found % with and without a world, false free, us per target, the ratio, the mesh step.
    Each solver solves the ``n`` targets ``repeats`` times, the three solvers interleaved; the CPU time is the median
    call's. The first call of the default solver is given apart: it also pays what the process loads once (coal's
    hulls and distance objects on the mesh step's first use)."""
    from nik.ik.collide import CollideCfg

    robot, model = load(name)
    rows = []
    for seed in seeds:
        world = scene(robot, seed)
        T, mesh = targets(robot, model, world, n, seed)
        plain, safe = nik.IKSolver(robot, self_collision=False), nik.IKSolver(robot, world=world)
        spheres = nik.IKSolver(robot, world=world)
        spheres.collide_cfg = CollideCfg(mesh_steer=False)
        solvers = {"plain": plain, "spheres": spheres, "safe": safe}
        for solver in solvers.values():
            solver.solve(T[:8])  # kernels, networks, the mesh check loaded before timing
        out, times = {}, {key: [] for key in solvers}
        for _ in range(max(1, repeats)):
            for key, solver in solvers.items():
                with _Steered() as counted:
                    c = time.process_time()
                    out[key] = solver.solve(T)
                    times[key].append((time.process_time() - c) / len(T))
                if key == "safe" and len(times[key]) == 1:
                    steered = counted  # the mesh step's count and cost: the first call's
        cpu = {key: statistics.median(t) for key, t in times.items()}
        first = times["safe"][0]
        res = out["safe"]
        free = np.asarray(res.collision_free, dtype=bool)
        false_free = int(mesh.collides(np.asarray(res.q, dtype=np.float64)[free], world).sum())
        rows.append({"robot": name, "seed": seed, "targets": len(T), "found": float(np.mean(res.success)),
                     "plain": float(np.mean(out["plain"].success)), "false_free": false_free,
                     "us_plain": 1e6 * cpu["plain"], "us_world": 1e6 * cpu["safe"], "us_first": 1e6 * first,
                     "ratio": cpu["safe"] / cpu["plain"], "obstacles": sum(world.counts()),
                     "spheres": float(np.mean(out["spheres"].success)), "ratio_spheres": cpu["spheres"] / cpu["plain"],
                     "steered": steered.targets, "steer_found": steered.found, "steer_s": steered.cpu})  # fmt: skip
        r = rows[-1]
        print(f"{name} seed {seed}: {r['targets']} targets, found {r['found']:.1%} (no world {r['plain']:.1%}), "
              f"false free {false_free}, {r['us_world']:.0f} vs {r['us_plain']:.0f} us/target: {r['ratio']:.2f}x; "
              f"mesh step {r['steer_found']}/{r['steered']} in {r['steer_s']:.2f} s; without it found "
              f"{r['spheres']:.1%}, {r['ratio_spheres']:.2f}x",
              flush=True)  # fmt: skip
    return rows


def report(rows: list[dict], argv: list[str]) -> str:
    """The markdown of the results: one line per robot and seed, then per robot the median and spread."""
    cmd = "python benchmarks/collision_feasible.py " + " ".join(argv)
    lines = ["# Feasible targets in scenes drawn from seeds (collision-free IK)", "",
             f"Measured by `{cmd}` (one thread, CPU time per target of the median of the interleaved calls; a table, "
             "3 boxes and 3 spheres per seed; targets from configurations free on the meshes, so each has a free "
             "answer). Goal: >= 99.5 % found, <= 2x the time without a world. `first call`: the default solver's "
             "first call on the targets, which also pays what a process loads once for the mesh step.", "",
             "| robot | seed | targets | found | found, no world | called free, mesh colliding | us/target world "
             "| us/target no world | ratio | first call: us/target | mesh step (first call): found / targets, CPU s "
             "| without the mesh step: found, ratio |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        lines.append(
            f"| {r['robot']} | {r['seed']} | {r['targets']} | {r['found']:.1%} | {r['plain']:.1%} "
            f"| {r['false_free']} | {r['us_world']:.0f} | {r['us_plain']:.0f} | {r['ratio']:.2f}x "
            f"| {r['us_first']:.0f} | {r['steer_found']} / {r['steered']}, {r['steer_s']:.2f} "
            f"| {r['spheres']:.1%}, {r['ratio_spheres']:.2f}x |"
        )
    lines += ["", "| robot | found: median (min - max) | ratio: median (min - max) | called free, mesh colliding "
              "| without the mesh step: found, ratio (medians) |", "|---|---|---|---|---|"]  # fmt: skip
    for name in dict.fromkeys(r["robot"] for r in rows):
        rs = [r for r in rows if r["robot"] == name]
        f, x = [r["found"] for r in rs], [r["ratio"] for r in rs]
        lines.append(f"| {name} | {statistics.median(f):.1%} ({min(f):.1%} - {max(f):.1%}) "
                     f"| {statistics.median(x):.2f}x ({min(x):.2f} - {max(x):.2f}) "
                     f"| {sum(r['false_free'] for r in rs)} | {statistics.median(r['spheres'] for r in rs):.1%}, "
                     f"{statistics.median(r['ratio_spheres'] for r in rs):.2f}x |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default=",".join(ROBOTS))
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--targets", type=int, default=100)
    ap.add_argument("--baxter-targets", type=int, default=50, help="Baxter's targets per seed (its check is slower)")
    ap.add_argument("--repeats", type=int, default=3, help="timed calls per solver, interleaved (the median counts)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "collision_feasible.md"))
    args = ap.parse_args(argv)
    try:
        import coal  # noqa: F401
    except ImportError:
        raise SystemExit("collision_feasible: needs coal (pip install 'nik-ik[collision-check]')") from None
    nik.set_threads(1)
    torch.set_num_threads(1)
    seeds = [int(s) for s in args.seeds.split(",")]
    rows = []
    for name in args.robots.split(","):
        rows += run(name, seeds, args.baxter_targets if name == "baxter" else args.targets, args.repeats)
    text = report(rows, argv)
    print(text)
    out = Path(args.out)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, out)


if __name__ == "__main__":
    main()
