"""nik's sphere verdicts against the real collision meshes (coal) on sampled panda configurations; collision-free IK.

    python benchmarks/collisions.py [--samples 2000] [--seed 0] [--tolerance 0.01] [--max-spheres 16]
    python benchmarks/collisions.py --ik [--targets 1000] [--seed 0] [--tolerance 0.01] [--max-spheres 16]

``--ik`` (issue 28's goals for collision-free IK, :mod:`nik.ik.collide`): the same panda and scene; targets are
the poses of random configurations that the meshes call free (MoveIt's pairs, and the scene); the solver with
the scene and self-collision on against the same solver without a collision model (``self_collision=False``),
interleaved, median of 3 runs: collision-free success, answers called free that collide with the meshes (must be
0), time per target; then random reachable targets without a world: self-colliding answers (meshes) with the
model off and on.

The panda of example-robot-data (its URDF with collision meshes, arm + hand + fingers; extra ``collision-check``
for coal and ``bench``/``urdf-tests`` for the URDF). Prints, for random configurations within the joint limits
(each one reachable by definition), without a world and in a scene (a table and 10 seeded boxes / spheres /
capsules near the arm): how many the meshes call colliding, how many nik calls colliding, how many nik calls
free that collide (must be 0) and how many nik calls colliding that are free (the price of conservative
spheres); and the time per configuration of each check (one core, one process). Two scopes of link pairs: every
pair but adjacent links, and MoveIt's (the pairs the panda's SRDF disables left out, by nik and by the mesh check
alike).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik
from nik.collision import collides, collision_model
from nik.collision.meshcheck import MeshCheck
from nik.collision.model import srdf_disabled, srdf_of


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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tolerance", type=float, default=0.01, help="sphere fitting tolerance, metres")
    ap.add_argument("--max-spheres", type=int, default=16, help="at most this many spheres per link")
    args = ap.parse_args(argv)
    urdf = panda_urdf()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    srdf = srdf_of(urdf)
    g = torch.Generator().manual_seed(args.seed)
    Q = np.ascontiguousarray(robot.sample(args.samples, generator=g, dtype=torch.float64).numpy())
    world = scene(args.seed)
    print(f"{args.samples} random configurations of the panda (arm, hand, fingers), seed {args.seed}")
    print(
        "| pairs | world | mesh: colliding | nik: colliding | nik free, mesh colliding | nik colliding, mesh free "
        "| nik us/config | coal us/config |"
    )
    print("|---|---|---|---|---|---|---|---|")
    notes = []
    for use_srdf in (False, True):
        t = time.perf_counter()
        model = collision_model(robot, srdf=use_srdf, tolerance=args.tolerance, max_spheres=args.max_spheres)
        built = time.perf_counter() - t
        skip = list(srdf_disabled(srdf)) if use_srdf and srdf is not None else []
        mesh = MeshCheck(robot, urdf, skip=skip)
        label = "all but adjacent" if not use_srdf else "MoveIt SRDF's off"
        notes.append(
            f"{label}: {model} ({built:.1f} s, cached); sphere overreach per link (mm): "
            + ", ".join(f"{n} {1000 * x:.0f}" for n, x in zip(model.links, model.gaps, strict=True))
            + f"; left out by sampling: {sorted(k for k, v in model.left_out.items() if v in ('always', 'never'))}"
        )
        collides(robot, Q[:2], world, model=model)  # compile / load the kernels before timing
        for name, w in (("none (self only)", None), ("table + 10 obstacles", world)):
            t = time.perf_counter()
            ours = collides(robot, Q, w, model=model)
            t_nik = (time.perf_counter() - t) / len(Q)
            t = time.perf_counter()
            theirs = mesh.collides(Q, w)
            t_mesh = (time.perf_counter() - t) / len(Q)
            missed = int((~ours & theirs).sum())
            extra = int((ours & ~theirs).sum())
            print(
                f"| {label} | {name} | {theirs.mean():.1%} | {ours.mean():.1%} | {missed} "
                f"| {extra} ({extra / len(Q):.1%}) | {1e6 * t_nik:.1f} | {1e6 * t_mesh:.0f} |"
            )
    print()
    for note in notes:
        print(note)
    # one LM residual evaluation (rows and Jacobian) for one configuration, what the pipeline will call
    from nik.collision.compiled import kernel_arguments
    from nik.kernels.collision import collision_residual

    (G, joints), rest = kernel_arguments(robot, model, world)
    R = len(model.pairs) + len(model.links)
    r, J = np.empty(R), np.empty((R, robot.dof))
    collision_residual(G, joints, Q[0], *rest, 0.01, r, J)
    times = []
    for _ in range(5):
        t = time.perf_counter()
        for q in Q[:500]:
            collision_residual(G, joints, q, *rest, 0.01, r, J)
        times.append((time.perf_counter() - t) / 500)
    print(
        f"LM residual rows + Jacobian ({R} rows: {len(model.pairs)} pairs + {len(model.links)} links; "
        f"{len(model.radii)} spheres, scene of {sum(world.counts())} obstacles), one configuration: "
        f"median {1e6 * float(np.median(times)):.1f} us"
    )


def ik_main(args) -> None:
    """Collision-free IK on the panda in the scene (module docstring, ``--ik``)."""
    urdf = panda_urdf()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    srdf = srdf_of(urdf)
    mesh = MeshCheck(robot, urdf, skip=list(srdf_disabled(srdf)) if srdf is not None else [])
    world = scene(args.seed)
    model = collision_model(robot, tolerance=args.tolerance, max_spheres=args.max_spheres)
    nik.collision.set_collision_model(robot, model)  # the model every check below uses
    g = torch.Generator().manual_seed(args.seed)
    Q = np.ascontiguousarray(robot.sample(4 * args.targets, generator=g, dtype=torch.float64).numpy())
    free = ~mesh.collides(Q, world)
    T = np.ascontiguousarray(robot.fk(Q[free][: args.targets]))
    plain = nik.IKSolver(robot, self_collision=False)
    safe = nik.IKSolver(robot, world=world, self_collision=True)
    judged = nik.IKSolver(robot, world=world, mesh_verdict=urdf)  # the spheres steer, the meshes judge
    print(f"panda (example-robot-data, arm + hand + fingers), {len(T)} targets from configurations the meshes call")
    print(f"free in a scene of {sum(world.counts())} obstacles (table + 10), seed {args.seed}; model: {model}")
    plain.solve(T[:4]), safe.solve(T[:4]), judged.solve(T[:4])  # compile / load the kernels before timing
    times = {"plain": [], "safe": [], "judged": []}
    cpu = {"plain": [], "safe": [], "judged": []}  # CPU time of this process: fair on a machine shared with others
    out = {}
    for _ in range(3):
        for name, solver in (("plain", plain), ("safe", safe), ("judged", judged)):
            t, c = time.perf_counter(), time.process_time()
            out[name] = solver.solve(T)
            times[name].append((time.perf_counter() - t) / len(T))
            cpu[name].append((time.process_time() - c) / len(T))
    r0, r1, r2 = out["plain"], out["safe"], out["judged"]
    called_free = np.asarray(r1.collision_free)
    mesh_hit = mesh.collides(np.asarray(r1.q)[called_free], world)
    plain_hit = mesh.collides(np.asarray(r0.q), world)
    t0, t1 = (float(np.median(times[k])) for k in ("plain", "safe"))
    c0, c1 = (float(np.median(cpu[k])) for k in ("plain", "safe"))
    print(
        "| solver | success | collision-free (spheres) | called free, mesh colliding | mesh colliding "
        "| us/target (wall) | us/target (CPU) |"
    )
    print("|---|---|---|---|---|---|---|")
    print(
        f"| no collision model | {np.mean(r0.success):.1%} | - | - | {plain_hit.mean():.1%} | {1e6 * t0:.0f} "
        f"| {1e6 * c0:.0f} |"
    )
    print(
        f"| scene + self (spheres) | {np.mean(r1.success):.1%} | {called_free.mean():.1%} | {int(mesh_hit.sum())} "
        f"| {mesh.collides(np.asarray(r1.q), world).mean():.1%} | {1e6 * t1:.0f} | {1e6 * c1:.0f} |"
    )
    t2, c2 = float(np.median(times["judged"])), float(np.median(cpu["judged"]))
    q2, free2 = np.asarray(r2.q), np.asarray(r2.collision_free)
    print(
        f"| scene + self, mesh verdict | {np.mean(r2.success):.1%} | - | "
        f"{int(mesh.collides(q2[free2], world).sum())} | {mesh.collides(q2, world).mean():.1%} "
        f"| {1e6 * t2:.0f} | {1e6 * c2:.0f} |"
    )
    print(
        f"time ratio collision-free / plain: {t1 / t0:.2f}x wall, {c1 / c0:.2f}x CPU (mesh verdict {c2 / c0:.2f}x CPU)"
    )
    own = ~collides(robot, Q[free][: args.targets], world, model=model)
    ok = np.asarray(r1.success)
    print(
        f"targets whose configuration the spheres also call free: {own.mean():.1%}; success on those "
        f"{ok[own].mean():.1%}, on the others (the spheres' false alarms) {ok[~own].mean():.1%}"
    )
    # self-collision, no world: random reachable targets (poses of random configurations, colliding or not)
    T2 = np.ascontiguousarray(robot.fk(Q[: args.targets]))
    off = plain.solve(T2)
    on = nik.IKSolver(robot, self_collision=True)
    on.solve(T2[:4])
    c = time.process_time()
    r_on = on.solve(T2)
    t_on = (time.process_time() - c) / len(T2)
    hit_off = mesh.collides(np.asarray(off.q))
    hit_on = mesh.collides(np.asarray(r_on.q))
    print(f"\n{len(T2)} random reachable targets, no world (MoveIt's pairs):")
    print("| self-collision model | success | self-colliding (meshes) | called free, mesh colliding | us/target, CPU |")
    print("|---|---|---|---|---|")
    print(f"| off | {np.mean(off.success):.1%} | {hit_off.mean():.1%} | - | - |")
    miss = int((np.asarray(r_on.collision_free) & hit_on).sum())
    print(f"| on | {np.mean(r_on.success):.1%} | {hit_on.mean():.1%} | {miss} | {1e6 * t_on:.0f} |")


if __name__ == "__main__":
    import sys

    if "--ik" in sys.argv:
        ap = argparse.ArgumentParser(description="collision-free IK on the panda in a scene")
        ap.add_argument("--ik", action="store_true")
        ap.add_argument("--targets", type=int, default=1000)
        ap.add_argument("--seed", type=int, default=0)
        ap.add_argument("--tolerance", type=float, default=0.01, help="sphere fitting tolerance, metres")
        ap.add_argument("--max-spheres", type=int, default=16, help="at most this many spheres per link")
        ik_main(ap.parse_args())
    else:
        main()
