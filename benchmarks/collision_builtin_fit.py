"""Regenerate the built-in arms' collision models from their vendors' meshes, and measure them against the meshes.

    python benchmarks/collision_builtin_fit.py --tolerance 0.004 --max-spheres 48 --refine 10   # the shipped files
    python benchmarks/collision_builtin_fit.py --check           # measure the shipped files only (no fitting)
    python benchmarks/collision_builtin_fit.py --arms panda --tolerance 0.004 --max-spheres 48 --dry

What it does (choices): the collision meshes are example-robot-data's (``pip install -e ".[urdf-tests]"`` for the
URDFs and meshes, ``".[collision-check]"`` for trimesh and coal): the same arms as the built-ins (their links move
as the built-in's frames, checked by :func:`nik.collision.urdf.urdf_bodies`; the built-in is taken without its
flange/tool, whose frame does not move any link). Each link's surface is covered by spheres
(:func:`nik.collision.fit.fit_spheres`: greedy cover at ``--tolerance``, at most ``--max-spheres`` a link,
among random and medial-axis candidates; then ``--refine`` rounds of the continuous refinement against the mesh,
:mod:`nik.collision.fit`; seeded), the link pairs are those of nik's rules with the
vendor's MoveIt SRDF (:func:`nik.collision.collision_model`'s defaults: 1000 samples, 2 cm never-clearance, seed 0),
and the model is written to ``configs/robots/collision/NAME.collision.json`` for the bare arm's hash, its SHA-256
printed for :data:`nik.collision.builtin.CHECKSUMS`.

The measure (``--samples`` seeded configurations within the limits, and the scene of ``benchmarks/collisions.py``:
a table and 10 obstacles): by coal on the meshes (MoveIt's pairs) and by the model, how many the model calls
free that collide (must be 0) and the share of the mesh-free ones it calls colliding (the price of conservative
spheres): self only (the arm alone), world only (the scene, self-collision off on both sides) and both (the scene).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik
from nik.collision import collides, collision_model
from nik.collision.builtin import BUILTIN_MESHES, MODEL_DIR, erd_path, frames_key
from nik.collision.fit import fit_spheres
from nik.collision.meshcheck import MeshCheck
from nik.collision.model import CollisionModel, _find_pairs
from nik.collision.urdf import urdf_bodies

sys.path.insert(0, str(Path(__file__).resolve().parent))
from collisions import scene  # noqa: E402  (the same scene as benchmarks/collisions.py)


def fit(
    name: str, tolerance: float, max_spheres: int, medial: bool, seed: int, max_edge=None, refine: int = 0
) -> CollisionModel:
    """The model of the built-in ``name`` fitted to example-robot-data's meshes (module docstring)."""
    urdf_rel, srdf_rel = BUILTIN_MESHES[name]
    urdf, srdf = erd_path(urdf_rel), erd_path(srdf_rel)
    if urdf is None or srdf is None:
        raise SystemExit(f'{urdf_rel} not found: example-robot-data is not installed (pip install -e ".[urdf-tests]")')
    arm = nik.load_robot(name).arm
    bodies = urdf_bodies(arm, urdf)
    fits = []
    for b in bodies:
        t = time.perf_counter()
        f = fit_spheres(
            b.triangles,
            tolerance=tolerance,
            max_spheres=max_spheres,
            medial=medial,
            seed=seed,
            max_edge=max_edge,
            refine=refine,
        )
        fits.append(f)
        print(
            f"  {b.name}: {len(f.radii)} spheres, overreach {1000 * f.gap:.1f} mm, volume x{f.volume_ratio:.2f} "
            f"({time.perf_counter() - t:.1f} s)",
            flush=True,
        )
    counts = [len(f.radii) for f in fits]
    model = CollisionModel(
        robot_hash=arm.definition_hash,
        links=[b.name for b in bodies],
        frames=np.array([b.frame for b in bodies], dtype=np.int64),
        centers=np.round(np.concatenate([f.centers for f in fits]).reshape(-1, 3), 6),
        radii=np.zeros(sum(counts)),
        body_start=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        pairs=np.zeros((0, 2), dtype=np.int64),
        parents=[b.parent for b in bodies],
        gaps=np.asarray([f.gap for f in fits]),
        volume_ratios=np.asarray([f.volume_ratio for f in fits]),
        source=f"example-robot-data:{urdf_rel}",
    )
    # centres rounded to the micrometre (moved by at most 0.87 um): each radius grows by 1 um, rounded up, so
    # every ball still holds the fitted one
    model.radii = np.ceil((np.concatenate([f.radii for f in fits]) + 1e-6) * 1e6) / 1e6
    model.options = {
        "source": "builtin",
        "fit": {
            "tolerance": tolerance,
            "max_spheres": max_spheres,
            "medial": medial,
            "max_edge": max_edge,
            "refine": refine,
            "seed": seed,
        },
        "samples": 1000,
        "never_clearance": 0.02,
        "srdf": True,
        "seed": 0,
        "frames_key": frames_key(arm),
    }
    _find_pairs(arm, model, 1000, 0.02, 0, srdf)
    return model


def measure(name: str, model: CollisionModel, samples: int, seed: int) -> dict:
    """Model against meshes (module docstring) for the built-in ``name``."""
    urdf_rel, srdf_rel = BUILTIN_MESHES[name]
    robot = nik.load_robot(name)
    skip = [tuple(k.split("|")) for k, why in model.left_out.items() if why != "never"]
    mesh = MeshCheck(robot, erd_path(urdf_rel), skip=skip)
    g = torch.Generator().manual_seed(seed)
    Q = np.ascontiguousarray(robot.sample(samples, generator=g, dtype=torch.float64).numpy())
    out = {}
    w = scene(seed)
    for label, world, self_collision in (("self", None, True), ("world", w, False), ("scene", w, True)):
        ours = collides(robot, Q, world, model=model, self_collision=self_collision)
        theirs = mesh.collides(Q, world, self_collision=self_collision)
        free = ~theirs
        out[label] = (int((~ours & theirs).sum()), int((ours & free).sum()), int(free.sum()))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", nargs="*", default=sorted(BUILTIN_MESHES))
    ap.add_argument("--tolerance", type=float, default=0.004)
    ap.add_argument("--max-spheres", type=int, default=32)
    ap.add_argument("--max-edge", type=float, default=None, help="split triangles to this edge (m; default: fit's)")
    ap.add_argument("--refine", type=int, default=0, help="rounds of the continuous refinement (0: greedy only)")
    ap.add_argument("--no-medial", action="store_true", help="without the medial-axis candidates")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--check", action="store_true", help="measure the shipped models, fit nothing")
    ap.add_argument("--dry", action="store_true", help="fit and measure, write nothing")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for name in args.arms:
        if args.check:
            model = collision_model(nik.load_robot(name), source="builtin")
            print(f"{name}: shipped {model}")
        else:
            print(
                f"{name}: fitting (tolerance {args.tolerance} m, <= {args.max_spheres} spheres a link, "
                f"{'no ' if args.no_medial else ''}medial candidates, refine {args.refine}, seed {args.seed})",
                flush=True,
            )
            t = time.perf_counter()
            model = fit(
                name, args.tolerance, args.max_spheres, not args.no_medial, args.seed, args.max_edge, args.refine
            )
            print(f"  {model} in {time.perf_counter() - t:.0f} s; pairs {len(model.pairs)}")
            if not args.dry:
                path = model.save(MODEL_DIR / f"{name}.collision.json")
                digest = hashlib.sha256(path.read_bytes()).hexdigest()
                print(f"  wrote {path} ({path.stat().st_size // 1024} kB) sha256 {digest}")
        per_link = ", ".join(f"{n} {k}" for n, k in zip(model.links, np.diff(model.body_start), strict=True))
        print(
            f"  spheres {len(model.radii)} ({per_link}); overreach mm: max {1000 * np.max(model.gaps):.1f}, "
            f"median {1000 * np.median(model.gaps):.1f}"
        )
        for label, (missed, extra, free) in measure(name, model, args.samples, args.seed).items():
            print(
                f"  {label}: {args.samples} configurations, {free} free by the meshes; model free but mesh colliding "
                f"{missed}; free by the meshes but model colliding {extra} ({extra / max(free, 1):.1%})",
                flush=True,
            )


if __name__ == "__main__":
    main()
