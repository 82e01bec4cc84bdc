"""A URDF arm's sphere fit: its time, peak memory, overreach, and how tight it is against the meshes (coal).

    python benchmarks/collision_fit.py [--max-spheres 16] [--samples 300] [--seed 0] [--no-rates]

Baxter's right arm of example-robot-data (``root_link="torso"``, ``end_link="right_hand_link"``; its SRDF found
beside the URDF); extras ``urdf-tests`` (example-robot-data) and ``collision-check`` (trimesh, pycollada, coal).
Prints the time of ``collision_model(robot, max_spheres=N, cache=False)``, the process's peak memory
(``ru_maxrss``), the links whose spheres reach more than 2 cm past their meshes, and, on ``--samples`` seeded
configurations within the limits, how many the spheres and the meshes call self-colliding (the pairs the model
leaves out by decision left out of both) and how many each alone calls so. Run it under ``/usr/bin/time -v`` for
the peak memory the system measures.
"""

from __future__ import annotations

import argparse
import resource
import time
import warnings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-spheres", type=int, default=16)
    ap.add_argument("--samples", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-rates", action="store_true", help="the fit only (no coal)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import torch

    import nik
    from nik.collision import collides, collision_model
    from nik.collision.builtin import erd_path
    from nik.collision.meshcheck import mesh_check

    urdf = erd_path("baxter_description/urdf/baxter.urdf")
    if urdf is None:
        raise SystemExit("needs example-robot-data: pip install 'nik-ik[urdf-tests]'")
    robot = nik.load_robot(urdf, root_link="torso", end_link="right_hand_link")
    t = time.perf_counter()
    model = collision_model(robot, max_spheres=args.max_spheres, cache=False)
    took = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{model}: fitted in {took:.1f} s, peak memory {peak:.0f} MB, SRDF {model.options.get('srdf_file')}")
    over = [f"{name} {1000 * g:.0f}" for name, g in zip(model.links, model.gaps, strict=True) if g > 0.02]
    print(f"links over 2 cm (mm): {', '.join(over) or 'none'}")
    if args.no_rates:
        return
    q = robot.sample(args.samples, generator=torch.Generator().manual_seed(args.seed), dtype=torch.float64).numpy()
    spheres = collides(robot, q)
    meshes = mesh_check(robot, model, required=True).collides(q)
    print(
        f"{args.samples} configurations called self-colliding: spheres {100 * spheres.mean():.1f} %, meshes "
        f"{100 * meshes.mean():.1f} %; spheres only {100 * (spheres & ~meshes).mean():.1f} %, meshes only "
        f"{100 * (meshes & ~spheres).mean():.1f} %"
    )


if __name__ == "__main__":
    main()
