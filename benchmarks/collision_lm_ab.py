"""The collision LM kernel of this checkout A/B against another checkout's (main's), in one process on the collision
speed scene: time, the first pass and the restarts pass, iterations, success target by target, false free.

    python benchmarks/collision_lm_ab.py --base PATH/collision_lm.py [--rounds 7] [--seeds 0 1 2]
        [--solver-seeds 0 1 2 3] [--cfg KEY=VALUE ...]

The built-in panda (its shipped spheres) among the scene of ``benchmarks/collision_speed.py`` (from
``benchmarks/collisions.py``, 1,000 targets from configurations the meshes call free, one thread). ``--base``: a copy of
another checkout's ``nik/kernels/collision_lm.py`` (e.g. ``git show main:nik/kernels/collision_lm.py >
/tmp/base_clm_1.py``; a new file name for each run: numba's cache of a module loaded from a file does not load in a
second process), loaded beside this checkout's and swapped in for variant A. Each variant is called with the
arguments its ``collision_lm`` takes, matched by name (a base from before a setting existed runs without it).
``--cfg``: fields of :class:`nik.ik.collide.CollideCfg` for the call (both variants get those their kernel takes).

Per scene seed: for each solver seed, the targets solved by one variant only (their indices) and the iterations of both
(first pass / all passes) and false free; then, per round, the solver without a world and the collision solver with A
and with B (their order alternating by round); CPU time per target (medians), the ratio to no world and B / A (medians
of the rounds), the CPU time per target of the first pass (the re-solve from the answer alone) and of the pass with
the uniform restarts, with their targets and iterations, success and answers called free that collide on the meshes.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import inspect
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import nik  # noqa: E402

PASSES = ("first", "restarts")


def _names(fn) -> list[str]:
    return list(inspect.signature(getattr(fn, "py_func", fn)).parameters)


#: the fields of this checkout's argument groups by the names of the flat signature a base before them takes
_FLAT = {
    "targets": ("Tt", "bounds", "modes"),
    "given": ("starts", "n_starts", "restarts"),
    "arm": ("spheres", "sphere_frame", "body_start", "pairs", "self_on"),
    "scene": ("w_spheres", "w_boxes", "w_capsules"),
    "out": ("q", "free", "done_out", "iterations", "pos", "rot"),
}


def _flat(names: list[str], a: tuple) -> dict:
    """The call's arguments ``a`` (of the signature ``names``) by the names of the flat signature: each group's
    fields spread (the settings by their own field names)."""
    kw = {}
    for name, v in zip(names, a, strict=True):
        if name in _FLAT:
            kw.update(zip(_FLAT[name], v, strict=True))
        elif name == "settings":
            kw.update(v._asdict())
        else:
            kw[name] = v
    return kw


def _cfg(pairs: list[str]):
    """``KEY=VALUE`` strings -> a CollideCfg (each value cast to its field's type)."""
    from nik.ik.collide import CollideCfg

    types = {f.name: type(getattr(CollideCfg(), f.name)) for f in dataclasses.fields(CollideCfg)}
    kw = {}
    for p in pairs:
        key, _, value = p.partition("=")
        if key not in types:
            raise SystemExit(f"collision_lm_ab: --cfg {key!r} is not a CollideCfg field ({', '.join(types)})")
        kw[key] = types[key](value)
    return CollideCfg(**kw)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="another checkout's nik/kernels/collision_lm.py (variant A)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--solver-seeds", type=int, nargs="+", default=[0, 1, 2, 3], help="the solver's seed= (counts)")
    ap.add_argument("--cfg", nargs="*", default=[], metavar="KEY=VALUE", help="CollideCfg fields of the call")
    args = ap.parse_args(argv)
    from collisions import panda_urdf, scene

    import nik.kernels.collision_lm as clm
    from nik.collision import collision_model
    from nik.collision.meshcheck import MeshCheck

    cfg = _cfg(args.cfg)
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
    ours_names = _names(ours)
    stats = {}

    def counted(fn):
        keep = set(_names(fn))
        grouped = "settings" in keep  # this checkout's signature: called as the pipeline calls it

        def call(*a):
            kw = _flat(ours_names, a)
            t = time.process_time()
            got = fn(*a) if grouped else fn(**{k: v for k, v in kw.items() if k in keep})
            dt, its = time.process_time() - t, int(np.asarray(kw["iterations"]).sum())
            restarts = np.asarray(kw["restarts"])
            first = restarts.sum() == 0 and kw["starts"].shape[1] == 1 and float(kw["margin"]) > 0.0
            p = "restarts" if restarts.sum() > 0 else "first" if first else None
            if p is not None:
                stats[p] = [x + y for x, y in zip(stats[p], (dt, len(restarts), its), strict=True)]
            stats["iters"] += its
            return got

        return call

    def reset():
        stats.update({p: [0.0, 0, 0] for p in PASSES} | {"iters": 0})

    variants = {"A (base)": counted(base.collision_lm), "B (this)": counted(ours)}
    print(f"call: {cfg}")
    print("| seed | variant | us/target CPU | ratio to no world | B / A | first pass us/target, targets, iterations "
          "| restarts pass us/target, targets, iterations | LM iterations | success | false free |")  # fmt: skip
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

            def run(name, safe=safe, T=T, world=world, **kw):  # this seed's solver, targets, scene
                clm.collision_lm = variants[name]
                reset()
                c = time.process_time()
                res = safe.solve(T, **kw)
                cpu = time.process_time() - c
                free = np.asarray(res.collision_free)
                return res, cpu, int(mesh.collides(np.asarray(res.q)[free], world).sum()), dict(stats)

            diffs = []
            for ss in args.solver_seeds:  # compiles / warms both; the counts of every solver seed
                got = {name: run(name, seed=ss) for name in variants}
                (ra, *_, fa, sa), (rb, *_, fb, sb) = got.values()
                a, b = np.asarray(ra.success), np.asarray(rb.success)
                diffs.append(
                    f"solver seed {ss}: {int(a.sum())} / {int(b.sum())} solved, only A {np.flatnonzero(a & ~b)}, "
                    f"only B {np.flatnonzero(b & ~a)}; iterations (first / all) A {sa['first'][2]} / {sa['iters']}, "
                    f"B {sb['first'][2]} / {sb['iters']}; false free A {fa}, B {fb}"
                )
            cpu = {k: [] for k in ["plain", *variants]}
            info = {}
            for r in range(args.rounds):
                c = time.process_time()
                plain.solve(T)
                cpu["plain"].append(time.process_time() - c)
                for name in list(variants)[:: 1 if r % 2 == 0 else -1]:
                    res, t, false_free, st = run(name)
                    cpu[name].append(t)
                    info.setdefault(name, []).append((np.mean(res.success), false_free, st))
            for name in variants:
                ratios = [s / p for s, p in zip(cpu[name], cpu["plain"], strict=True)]
                ab = [y / x for x, y in zip(cpu["A (base)"], cpu[name], strict=True)]
                ok, false_free, st = info[name][-1]
                passes = []
                for p in PASSES:
                    us = statistics.median(1e6 * i[2][p][0] / len(T) for i in info[name])
                    passes.append(f"{us:.1f}, {st[p][1]}, {st[p][2]}")
                print(f"| {seed} | {name} | {1e6 * statistics.median(cpu[name]) / len(T):.1f} (no world "
                      f"{1e6 * statistics.median(cpu['plain']) / len(T):.1f}) | {statistics.median(ratios):.2f} "
                      f"| {statistics.median(ab):.3f} | {passes[0]} | {passes[1]} | {st['iters']} | {ok:.1%} "
                      f"| {false_free} |", flush=True)  # fmt: skip
            for d in diffs:
                print(f"    seed {seed}, {d}", flush=True)
    finally:
        clm.collision_lm = ours


if __name__ == "__main__":
    main()
