"""The blocked-pose proof's depth A/B on the collision speed scene: two depths of
:func:`nik.collision.compiled.blocked_targets` swapped between interleaved whole solves in one process.

    python benchmarks/collision_proof_ab.py [--rounds 15] [--seeds 0 1 2] [--a 0] [--b 4]

The set-up of ``benchmarks/collision_speed.py --builtin`` (nik's built-in panda and its shipped spheres, the scene of
``benchmarks/collisions.py``, 1,000 targets from configurations the meshes call free, one thread). Per seed and round:
the solver without a world, then the collision solver with depth ``--a`` and with depth ``--b`` (their order
alternating by round); CPU time per target (medians), the ratio to no world (median of the rounds), success, answers
called free that collide on the meshes, targets the proof ends, targets it was asked about, its CPU time, and the
collision LM's iterations (all passes); then the per-round ratio b / a. Depth 0 is the plain sweep (main before the
halving).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import nik  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--a", type=int, default=0, help="depth of variant A (0: the plain sweep)")
    ap.add_argument("--b", type=int, default=4, help="depth of variant B")
    args = ap.parse_args(argv)
    from collisions import panda_urdf, scene

    import nik.collision.compiled as compiled
    import nik.kernels.collision_lm as clm
    from nik.collision import collision_model
    from nik.collision.meshcheck import MeshCheck

    nik.set_threads(1)
    torch.set_num_threads(1)
    robot = nik.load_robot("panda")
    model = collision_model(robot, source="builtin")
    nik.collision.set_collision_model(robot, model)
    mesh = MeshCheck(robot, panda_urdf(), skip=[tuple(k.split("|")) for k, w in model.left_out.items() if w != "never"])
    proof, lm = compiled.blocked_targets, clm.collision_lm
    stats = {}

    def with_depth(depth):
        def call(*a, **k):
            t = time.process_time()
            got = proof(*a, depth=depth, **k)
            stats["proof"] += time.process_time() - t
            stats["proven"] += int(got.sum())
            stats["asked"] += len(got)
            return got

        return call

    def counted(*a, **k):
        got = lm(*a, **k)
        stats["iters"] += int(np.asarray(a[10].iterations).sum())  # the kernel's iterations (its `out` group)
        return got

    variants = {f"depth {args.a}": with_depth(args.a), f"depth {args.b}": with_depth(args.b)}
    print("| seed | variant | us/target CPU | ratio to no world | success | false free | proven | asked "
          "| proof us/target | LM iterations |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    clm.collision_lm = counted
    try:
        for seed in args.seeds:
            world = scene(seed)
            g = torch.Generator().manual_seed(seed)
            Q = np.ascontiguousarray(robot.sample(4000, generator=g, dtype=torch.float64).numpy())
            T = np.ascontiguousarray(robot.fk(Q[~mesh.collides(Q, world)][:1000]))
            plain, safe = nik.IKSolver(robot, self_collision=False), nik.IKSolver(robot, world=world)
            plain.solve(T)
            for f in variants.values():  # compile / warm both
                compiled.blocked_targets = f
                stats.update(proof=0.0, proven=0, asked=0, iters=0)
                safe.solve(T)
            cpu = {k: [] for k in ["plain", *variants]}
            info = {}
            for r in range(args.rounds):
                c = time.process_time()
                plain.solve(T)
                cpu["plain"].append(time.process_time() - c)
                for name, f in list(variants.items())[:: 1 if r % 2 == 0 else -1]:
                    compiled.blocked_targets = f
                    stats.update(proof=0.0, proven=0, asked=0, iters=0)
                    c = time.process_time()
                    res = safe.solve(T)
                    cpu[name].append(time.process_time() - c)
                    free = np.asarray(res.collision_free)
                    info[name] = (np.mean(res.success), int(mesh.collides(np.asarray(res.q)[free], world).sum()),
                                  dict(stats))  # fmt: skip
            for name in variants:
                ratios = [s / p for s, p in zip(cpu[name], cpu["plain"], strict=True)]
                ok, false_free, st = info[name]
                print(f"| {seed} | {name} | {1e6 * statistics.median(cpu[name]) / len(T):.1f} (no world "
                      f"{1e6 * statistics.median(cpu['plain']) / len(T):.1f}) | {statistics.median(ratios):.2f} "
                      f"| {ok:.1%} | {false_free} | {st['proven']} | {st['asked']} | "
                      f"{1e6 * st['proof'] / len(T):.2f} | {st['iters']} |")  # fmt: skip
            a, b = (cpu[name] for name in variants)
            ab = [y / x for x, y in zip(a, b, strict=True)]
            print(f"| {seed} | b / a per round | {statistics.median(ab):.3f} "
                  f"({', '.join(f'{x:.2f}' for x in ab)}) | | | | | | | |", flush=True)  # fmt: skip
    finally:
        compiled.blocked_targets, clm.collision_lm = proof, lm


if __name__ == "__main__":
    main()
