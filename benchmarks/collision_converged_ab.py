"""The collision LM's converged stop (``CollideCfg.converged``), A/B against the kernel of another checkout (main's),
in one process on the collision speed scene.

    python benchmarks/collision_converged_ab.py --base PATH/collision_lm.py [--rounds 7] [--seeds 0 1 2]
        [--solver-seeds 0 1 2 3] [--converged X]

The set-up of ``benchmarks/collision_speed.py --builtin`` (nik's built-in panda and its shipped spheres, the scene of
``benchmarks/collisions.py``, 1,000 targets from configurations the meshes call free, one thread). ``--base``: a
copy of another checkout's ``nik/kernels/collision_lm.py`` (e.g. ``git show main:nik/kernels/collision_lm.py >
/tmp/base_clm.py``), loaded beside this checkout's and swapped in for variant A (its ``collision_lm`` takes no
``converged``). Per scene seed and round: the solver without a world, then the collision solver with A and with B
(their order alternating by round); CPU time per target (medians), the ratio to no world and B / A (medians of the
rounds), the CPU time of the first pass (the re-solve from the answer alone), its targets and iterations, the
collision LM's iterations (all passes), success, answers called free that collide on the meshes; then, per solver
seed, the targets solved by one variant only (their indices) and the iterations of both (first pass / all).
"""

from __future__ import annotations

import argparse
import importlib.util
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
    ap.add_argument("--base", required=True, help="another checkout's nik/kernels/collision_lm.py (variant A)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument(
        "--solver-seeds", type=int, nargs="+", default=[0, 1, 2, 3], help="the solver's seed= (counts only)"
    )
    ap.add_argument("--converged", type=float, default=None, help="CollideCfg.converged of B (default: the default)")
    args = ap.parse_args(argv)
    from collisions import panda_urdf, scene

    import nik.kernels.collision_lm as clm
    from nik.collision import collision_model
    from nik.collision.meshcheck import MeshCheck
    from nik.ik.collide import CollideCfg

    spec = importlib.util.spec_from_file_location("base_collision_lm", args.base)
    base = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(base)
    nik.set_threads(1)
    torch.set_num_threads(1)
    robot = nik.load_robot("panda")
    model = collision_model(robot, source="builtin")
    nik.collision.set_collision_model(robot, model)
    mesh = MeshCheck(robot, panda_urdf(), skip=[tuple(k.split("|")) for k, w in model.left_out.items() if w != "never"])
    ours = clm.collision_lm
    stats = {}

    def counted(fn, drop):
        def call(*a):
            a = a[:25] + a[26:] if drop else a
            t = time.process_time()
            got = fn(*a)
            restarts, its = np.asarray(a[9]), int(np.asarray(a[-3]).sum())  # the kernel's iterations (B,)
            if restarts.sum() == 0 and a[3].shape[1] == 1 and float(a[21]) > 0.0:  # from the answer alone
                stats["pass"] += time.process_time() - t
                stats["targets"] += len(restarts)
                stats["first"] += its
            stats["iters"] += its
            return got

        return call

    variants = {"A (base)": counted(base.collision_lm, True), "B (this)": counted(ours, False)}
    cfg = CollideCfg() if args.converged is None else CollideCfg(converged=args.converged)
    print(f"B: {cfg}")
    print("| seed | variant | us/target CPU | ratio to no world | B / A | first pass us/target | its targets, "
          "iterations | LM iterations | success | false free |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    try:
        for seed in args.seeds:
            world = scene(seed)
            g = torch.Generator().manual_seed(seed)
            Q = np.ascontiguousarray(robot.sample(4000, generator=g, dtype=torch.float64).numpy())
            T = np.ascontiguousarray(robot.fk(Q[~mesh.collides(Q, world)][:1000]))
            plain, safe = nik.IKSolver(robot, self_collision=False), nik.IKSolver(robot, world=world)
            safe.collide_cfg = cfg
            plain.solve(T)
            diffs = []
            for ss in args.solver_seeds:
                got = {}
                for name, f in variants.items():  # compile / warm both; the counts of every solver seed
                    clm.collision_lm = f
                    stats.update({"pass": 0.0, "targets": 0, "iters": 0, "first": 0})
                    res = safe.solve(T, seed=ss)
                    free = np.asarray(res.collision_free)
                    ff = int(mesh.collides(np.asarray(res.q)[free], world).sum())
                    got[name] = (np.asarray(res.success), f"{stats['first']} / {stats['iters']} its, {ff} false free")
                (a, ia), (b, ib) = got.values()
                diffs.append(f"solver seed {ss}: {int(a.sum())} / {int(b.sum())} solved, only A "
                             f"{np.flatnonzero(a & ~b)}, only B {np.flatnonzero(b & ~a)}; A {ia}, B {ib}")  # fmt: skip
            cpu = {k: [] for k in ["plain", *variants]}
            info = {}
            for r in range(args.rounds):
                c = time.process_time()
                plain.solve(T)
                cpu["plain"].append(time.process_time() - c)
                for name, f in list(variants.items())[:: 1 if r % 2 == 0 else -1]:
                    clm.collision_lm = f
                    stats.update({"pass": 0.0, "targets": 0, "iters": 0, "first": 0})
                    c = time.process_time()
                    res = safe.solve(T)
                    cpu[name].append(time.process_time() - c)
                    free = np.asarray(res.collision_free)
                    info.setdefault(name, []).append(
                        (np.mean(res.success), int(mesh.collides(np.asarray(res.q)[free], world).sum()), dict(stats))
                    )
            for name in variants:
                ratios = [s / p for s, p in zip(cpu[name], cpu["plain"], strict=True)]
                ab = [y / x for x, y in zip(cpu["A (base)"], cpu[name], strict=True)]
                ok, false_free, st = info[name][-1]
                pass_us = statistics.median(1e6 * i[2]["pass"] / len(T) for i in info[name])
                print(f"| {seed} | {name} | {1e6 * statistics.median(cpu[name]) / len(T):.1f} (no world "
                      f"{1e6 * statistics.median(cpu['plain']) / len(T):.1f}) | {statistics.median(ratios):.2f} "
                      f"| {statistics.median(ab):.3f} | {pass_us:.1f} | {st['targets']}, {st['first']} | {st['iters']} "
                      f"| {ok:.1%} "
                      f"| {false_free} |", flush=True)  # fmt: skip
            for d in diffs:
                print(f"    seed {seed}, {d}", flush=True)
    finally:
        clm.collision_lm = ours


if __name__ == "__main__":
    main()
