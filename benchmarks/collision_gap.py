"""How tight the sphere models are: configurations the spheres call self-colliding that the meshes (coal) call free.

    python benchmarks/collision_gap.py [--samples 300] [--seed 0] [--robots panda,panda-urdf,baxter] [--no-cache]
        [--out benchmarks/results/collision_gap.md]

Per robot, on ``--samples`` configurations drawn within the joint limits (seeded), without a world: the share the
spheres call self-colliding and the meshes free (refused for nothing: the price of conservative spheres), the
share the meshes call colliding and the spheres free (must be 0: the spheres are conservative), and the link
pairs behind the first (each pair's share of all configurations, a configuration counted once per pair its
spheres say overlap). Both verdicts check the same pairs (those the model leaves out by decision, same frame,
adjacent, the SRDF's, always touching, are left out of both; the mesh check also tests the "never" pairs).

Robots: ``panda`` (nik's built-in, its shipped model fitted to the vendor's meshes), ``panda-urdf``
(example-robot-data's panda URDF, ``end_link="panda_hand"``: a model fitted by ``collision_model``), ``baxter``
(example-robot-data's Baxter, ``root_link="torso"``, ``end_link="right_hand_link"``, its SRDF found by search).
Also printed: each model's spheres, fit time (``--no-cache``: fitted now, else nik's cache may answer), and the
links whose spheres reach more than 2 cm past their meshes (the model's ``gaps``), and the static links checked on
a grid of signed distances (the model's ``grids``: pitch, size, bound). Extras ``collision-check``
(coal, trimesh, pycollada) and ``urdf-tests`` (example-robot-data).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

import torch

import nik
from nik.collision import collides, collision_model, collision_names
from nik.collision.builtin import erd_path
from nik.collision.meshcheck import mesh_check

ROBOTS = ("panda", "panda-urdf", "baxter")


def load(name: str):
    """The robot named (module docstring); SystemExit where its files are not installed."""
    if name == "panda":
        return nik.load_robot("panda")
    rel = {"panda-urdf": "panda_description/urdf/panda.urdf", "baxter": "baxter_description/urdf/baxter.urdf"}[name]
    urdf = erd_path(rel)
    if urdf is None:
        raise SystemExit("needs example-robot-data: pip install 'nik-ik[urdf-tests]'")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if name == "baxter":
            return nik.load_robot(urdf, root_link="torso", end_link="right_hand_link")
        return nik.load_robot(urdf, end_link="panda_hand")


def measure(name: str, samples: int, seed: int, cache: bool, max_spheres: int | None = None) -> dict:
    """The figures of one robot (module docstring) as a dict; ``max_spheres``: the fit's option (None: its default)."""
    robot = load(name)
    t, cpu = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        options = {} if max_spheres is None else {"max_spheres": int(max_spheres)}
        model = collision_model(robot, cache=cache, **options)
    fit_s, fit_cpu = time.perf_counter() - t, time.process_time() - cpu
    mesh = mesh_check(robot, model, required=True)
    q = robot.sample(samples, generator=torch.Generator().manual_seed(seed), dtype=torch.float64).numpy()
    collides(robot, q[:1], model=model)  # the kernels loaded
    cpu = time.process_time()
    spheres = collides(robot, q, model=model)
    sphere_us = 1e6 * (time.process_time() - cpu) / samples
    t = time.perf_counter()
    meshes = mesh.collides(q)
    mesh_s = (time.perf_counter() - t) / samples
    over = spheres & ~meshes
    pairs = Counter(p for names in collision_names(robot, q[over], model=model) for p in names or ())
    gaps = [] if model.gaps is None else [(float(g), n) for n, g in zip(model.links, model.gaps, strict=True)]
    return {
        "name": name,
        "model": model,
        "fit_s": fit_s,
        "fit_cpu": fit_cpu,
        "sphere_us": sphere_us,
        "mesh_us": 1e6 * mesh_s,
        "spheres": float(spheres.mean()),
        "meshes": float(meshes.mean()),
        "over": float(over.mean()),
        "false_free": int((meshes & ~spheres).sum()),
        "pairs": [(p, c / samples) for p, c in pairs.most_common(8)],
        "wide": sorted(((g, n) for g, n in gaps if g > 0.02), reverse=True),
    }


def _grid_note(model) -> str:
    """``" + grids on torso, pedestal"`` for a model with static links on grids, else empty."""
    return f" + grids on {', '.join(model.grids)}" if model.grids else ""


def report(rows: list[dict], command: str, samples: int) -> str:
    out = [
        "# Sphere models against the meshes: self-collision refused for nothing",
        "",
        f"`{command}` ({samples} seeded configurations a robot, no world; {os.cpu_count()} CPU cores, one process).",
        "",
        "| robot | spheres | called colliding: spheres / meshes | spheres only (refused, mesh-free) | "
        "meshes only (must be 0) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        m = r["model"]
        out.append(
            f"| {r['name']} | {len(m.radii)} on {len(m.links)} links{_grid_note(m)}, {len(m.pairs)} pairs | "
            f"{100 * r['spheres']:.1f} % / {100 * r['meshes']:.1f} % | {100 * r['over']:.1f} % | {r['false_free']} |"
        )
    out += ["", "Link pairs behind the configurations refused for nothing (share of all configurations):", ""]
    for r in rows:
        pairs = ", ".join(f"{p} {100 * s:.1f} %" for p, s in r["pairs"]) or "none"
        out.append(f"- {r['name']}: {pairs}")
    out += ["", "Links whose spheres reach more than 2 cm past their meshes (the model's `gaps`, mm):", ""]
    for r in rows:
        wide = ", ".join(f"{n} {1000 * g:.0f}" for g, n in r["wide"]) or "none"
        out.append(f"- {r['name']}: {wide}")
    out += [
        "",
        "Static links that also carry a grid of signed distances (the model's `grids`: a pair's row is the larger",
        "of the spheres' and the grid's; pitch, nodes, memory, and the most a value may fall short of the true",
        "distance, the link's gap):",
        "",
    ]
    for r in rows:
        grids = (r["model"].grids or {}).items()
        text = ", ".join(f"{n} ({1000 * g.pitch:.0f} mm, {g.values.size / 1e6:.2f} M nodes, "
                         f"{g.values.nbytes / 1e6:.1f} MB, {1000 * g.bound:.0f} mm)" for n, g in grids)  # fmt: skip
        out.append(f"- {r['name']}: {text or 'none'}")
    out += [
        "",
        "Time: the model (from nik's cache unless `--no-cache`; CPU time of the process, wall beside it), the spheres'",
        "check (`collides`, compiled, CPU time a configuration) and coal's (wall):",
        "",
    ]
    for r in rows:
        out.append(
            f"- {r['name']}: model {r['fit_cpu']:.1f} s CPU ({r['fit_s']:.1f} s wall), spheres' check "
            f"{r['sphere_us']:.1f} us, mesh check {r['mesh_us']:.0f} us a configuration"
        )
    return "\n".join(out) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--robots", default=",".join(ROBOTS), help=f"comma-separated, of {', '.join(ROBOTS)}")
    ap.add_argument("--no-cache", action="store_true", help="fit the models now (time the fit)")
    ap.add_argument("--max-spheres", type=int, default=None, help="the fit's max_spheres (default: its own)")
    ap.add_argument("--out", default=None, help="write the markdown table here (temporary name, then renamed)")
    args = ap.parse_args(argv)
    names = [n for n in args.robots.split(",") if n]
    unknown = [n for n in names if n not in ROBOTS]
    if unknown or args.samples < 1:
        print(f"collision_gap: unknown robot {unknown[0]!r} (of {', '.join(ROBOTS)})" if unknown
              else "collision_gap: --samples must be >= 1", file=sys.stderr)  # fmt: skip
        raise SystemExit(2)
    rows = []
    for name in names:
        rows.append(measure(name, args.samples, args.seed, not args.no_cache, args.max_spheres))
        r = rows[-1]
        print(
            f"{name}: spheres {100 * r['spheres']:.1f} %, meshes {100 * r['meshes']:.1f} %, spheres only "
            f"{100 * r['over']:.1f} %, meshes only {r['false_free']}; pairs: "
            + ", ".join(f"{p} {100 * s:.1f} %" for p, s in r["pairs"][:4]),
            flush=True,
        )
    command = "python benchmarks/collision_gap.py " + " ".join(argv if argv is not None else sys.argv[1:])
    text = report(rows, command.strip(), args.samples)
    print(text)
    if args.out:
        out = Path(args.out)
        tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        tmp.write_text(text)
        tmp.replace(out)


if __name__ == "__main__":
    main()
