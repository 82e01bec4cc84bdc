"""The collision rows call A/B: the collision kernels of a git revision (``--base``) and of this checkout, one
rows call at a time on the configurations a solve visits, then whole solves swapped between interleaved rounds.

    python benchmarks/collision_rows_ab.py [--rounds 9] [--seeds 0 1 2] [--base main] [--no-rows] [--no-solve]

The set-up of ``benchmarks/collision_speed.py --builtin`` (nik's built-in panda and its shipped spheres, the scene of
``benchmarks/collisions.py``, 1,000 targets from configurations the meshes call free, one thread). The base's
``nik/kernels/collision.py`` and ``nik/kernels/collision_lm.py`` are read with ``git show`` into a temporary folder and
imported beside nik's (compiled there once).

Rows: one solve per seed records the configurations the collision LM passes to ``residual_in`` (a rows call with its
Jacobian, reach 5 mm) and ``collides_in`` (its check of a draw), by running the LM's driver functions as Python
(their ``py_func``) around the compiled rows; then each variant's ``residual_in`` (5 mm) on those, and its
``collides_in`` (cutoff 0) on the solve's answers, in a compiled loop; CPU time per call (medians of interleaved
rounds, the ratio B / A the median of the per-round ratios). The two variants' rows, Jacobians and verdicts are
compared on the way (bit for bit).

Solve: per seed and round, the solver without a world, then A and B (their order alternating by round): variant A
swaps in the base's ``collides_batch``, ``overlaps_batch`` and ``collision_lm``; CPU time per target (medians),
success, answers called free that collide on the meshes, the collision LM's iterations, and the per-round B / A.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import nik  # noqa: E402


def _base_kernels(rev: str, folder: Path):
    """The modules ``base_collision`` and ``base_collision_lm``: revision ``rev``'s kernels, imported from
    ``folder``."""
    for name in ("collision", "collision_lm"):
        text = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:nik/kernels/{name}.py"], check=True,
                              capture_output=True, text=True).stdout  # fmt: skip
        text = text.replace("from nik.kernels.collision import", "from base_collision import")
        (folder / f"base_{name}.py").write_text(text)
    sys.path.insert(0, str(folder))
    return importlib.import_module("base_collision"), importlib.import_module("base_collision_lm")


def _visited(clm, safe, T):
    """``(rows, checks, answers)``: the configurations one solve passes to the collision LM's ``residual_in`` and
    ``collides_in`` ``(k, n)``, and its answers ``(B, n)`` (the LM's drivers run as Python, the rows compiled)."""
    names = ("collision_lm", "_descend", "_rank_starts", "_finish", "residual_in", "collides_in")
    orig = {k: getattr(clm, k) for k in names}
    rows, checks = [], []

    def residual_in(*a):
        rows.append(np.array(a[2]))
        return orig["residual_in"](*a)

    def collides_in(*a):
        checks.append(np.array(a[2]))
        return orig["collides_in"](*a)

    try:
        for k in names[:4]:
            setattr(clm, k, orig[k].py_func)
        clm.residual_in, clm.collides_in = residual_in, collides_in
        with np.errstate(over="ignore"):  # the LM's stream seeds wrap around in uint64, as compiled
            res = safe.solve(T)
    finally:
        for k, v in orig.items():
            setattr(clm, k, v)
    return np.array(rows), np.array(checks), np.ascontiguousarray(res.q)


def _loops(mod):
    """Compiled loops over configurations of ``mod``'s ``residual_in`` (with Jacobian) and ``collides_in``."""
    residual_in, collides_in, rows_work, link_bounds = mod.residual_in, mod.collides_in, mod.rows_work, mod.link_bounds

    @numba.njit
    def rows(G, joints, Q, arm, scene, margin, reps, out, Jout):
        spheres, bs, pairs = arm[0], arm[2], arm[3]
        n, R = Q.shape[1], pairs.shape[0] + bs.shape[0] - 1
        bounds = np.empty((bs.shape[0] - 1, 4))
        link_bounds(spheres, bs, bounds)
        work = rows_work(n, arm, scene)
        r, Jr = np.empty(R), np.empty((R, n))
        for _ in range(reps):
            for b in range(Q.shape[0]):
                residual_in(G, joints, Q[b], arm, scene, margin, r, Jr, bounds, work)
                out[b] = r
                Jout[b] = Jr

    @numba.njit
    def check(G, joints, Q, arm, scene, margin, reps, out):
        spheres, bs, pairs = arm[0], arm[2], arm[3]
        n, R = Q.shape[1], pairs.shape[0] + bs.shape[0] - 1
        bounds = np.empty((bs.shape[0] - 1, 4))
        link_bounds(spheres, bs, bounds)
        work = rows_work(n, arm, scene)
        d = np.empty(R)
        for _ in range(reps):
            for b in range(Q.shape[0]):
                out[b] = collides_in(G, joints, Q[b], arm, scene, margin, d, bounds, work)

    return rows, check


def _rows_ab(seed, robot, model, world, visited, loops, rounds):
    """Print the rows-call and check rows of the table for one seed; assert the variants agree bit for bit."""
    from nik.collision.compiled import kernel_arguments

    (G, joints), rest = kernel_arguments(robot, model, world)
    R, n = len(model.pairs) + len(model.links), robot.dof
    rows_q, _, answers = visited
    for what, Q, margin in (("rows + Jacobian, 5 mm", rows_q, 0.005), ("check, cutoff 0", answers, 0.0)):
        outs, cpu = {}, {k: [] for k in loops}
        for r in range(rounds + 1):
            for name, (rows, check) in list(loops.items())[:: 1 if r % 2 == 0 else -1]:
                if what.startswith("rows"):
                    out, Jout = np.empty((len(Q), R)), np.empty((len(Q), R, n))
                    args = (G, joints, Q, *rest, margin, 5, out, Jout)
                    fn, outs[name] = rows, (out, Jout)
                else:
                    out = np.empty(len(Q), dtype=np.bool_)
                    args = (G, joints, Q, *rest, margin, 5, out)
                    fn, outs[name] = check, (out,)
                c = time.process_time()
                fn(*args)
                if r > 0:  # round 0 compiles
                    cpu[name].append((time.process_time() - c) / 5 / len(Q))
        a, b = (outs[k] for k in loops)
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)), f"{what}: the variants differ"
        ta, tb = (cpu[k] for k in loops)
        ratio = statistics.median(y / x for x, y in zip(ta, tb, strict=True))
        print(f"| {seed} | {what} ({len(Q)} configurations) | {1e6 * statistics.median(ta):.2f} "
              f"| {1e6 * statistics.median(tb):.2f} | {ratio:.3f} |", flush=True)  # fmt: skip


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--base", default="main", help="the git revision of variant A")
    ap.add_argument("--no-rows", action="store_true", help="skip the rows-call A/B")
    ap.add_argument("--no-solve", action="store_true", help="skip the whole-solve A/B")
    args = ap.parse_args(argv)
    from collisions import panda_urdf, scene

    import nik.kernels.collision as kc
    import nik.kernels.collision_lm as clm
    from nik.collision import collision_model
    from nik.collision.meshcheck import MeshCheck

    nik.set_threads(1)
    torch.set_num_threads(1)
    robot = nik.load_robot("panda")
    model = collision_model(robot, source="builtin")
    nik.collision.set_collision_model(robot, model)
    mesh = MeshCheck(robot, panda_urdf(), skip=[tuple(k.split("|")) for k, w in model.left_out.items() if w != "never"])
    folder = Path(tempfile.mkdtemp(prefix="nik_rows_ab_"))
    base, base_lm = _base_kernels(args.base, folder)
    print(f"base {args.base} kernels from {folder}")
    problems = {}
    for seed in args.seeds:
        world = scene(seed)
        g = torch.Generator().manual_seed(seed)
        Q = np.ascontiguousarray(robot.sample(4000, generator=g, dtype=torch.float64).numpy())
        problems[seed] = world, np.ascontiguousarray(robot.fk(Q[~mesh.collides(Q, world)][:1000]))
    if not args.no_rows:
        loops = {f"A ({args.base})": _loops(base), "B (this checkout)": _loops(kc)}
        print("\n| seed | call | A us/call CPU | B us/call CPU | B / A |\n|---|---|---|---|---|")
        for seed, (world, T) in problems.items():
            visited = _visited(clm, nik.IKSolver(robot, world=world), T)
            _rows_ab(seed, robot, model, world, visited, loops, args.rounds)
    if args.no_solve:
        return
    stats = {"iters": 0}

    def counting(lm):
        def call(*a, **k):
            got = lm(*a, **k)
            stats["iters"] += int(np.asarray(a[29]).sum())  # the kernel's iterations (its 30th argument)
            return got

        return call

    ours = (kc.collides_batch, kc.overlaps_batch, counting(clm.collision_lm))
    variants = {
        f"A ({args.base})": (base.collides_batch, base.overlaps_batch, counting(base_lm.collision_lm)),
        "B (this checkout)": ours,
    }

    def use(v):
        kc.collides_batch, kc.overlaps_batch, clm.collision_lm = v

    print("\n| seed | variant | us/target CPU | ratio to no world | success | false free | LM iterations |")
    print("|---|---|---|---|---|---|---|")
    try:
        for seed, (world, T) in problems.items():
            plain, safe = nik.IKSolver(robot, self_collision=False), nik.IKSolver(robot, world=world)
            plain.solve(T)
            for v in variants.values():  # compile / warm both
                use(v)
                safe.solve(T)
            cpu = {k: [] for k in ["plain", *variants]}
            info = {}
            for r in range(args.rounds):
                c = time.process_time()
                plain.solve(T)
                cpu["plain"].append(time.process_time() - c)
                for name, v in list(variants.items())[:: 1 if r % 2 == 0 else -1]:
                    use(v)
                    stats["iters"] = 0
                    c = time.process_time()
                    res = safe.solve(T)
                    cpu[name].append(time.process_time() - c)
                    free = np.asarray(res.collision_free)
                    false_free = int(mesh.collides(np.asarray(res.q)[free], world).sum())
                    info[name] = (np.mean(res.success), false_free, stats["iters"])
            for name in variants:
                ratios = [s / p for s, p in zip(cpu[name], cpu["plain"], strict=True)]
                ok, false_free, iters = info[name]
                print(f"| {seed} | {name} | {1e6 * statistics.median(cpu[name]) / len(T):.1f} (no world "
                      f"{1e6 * statistics.median(cpu['plain']) / len(T):.1f}) | {statistics.median(ratios):.2f} "
                      f"| {ok:.1%} | {false_free} | {iters} |")  # fmt: skip
            a, b = (cpu[name] for name in variants)
            ab = [y / x for x, y in zip(a, b, strict=True)]
            print(f"| {seed} | B / A per round | {statistics.median(ab):.3f} "
                  f"({', '.join(f'{x:.2f}' for x in ab)}) | | | | |", flush=True)  # fmt: skip
    finally:
        use(ours)


if __name__ == "__main__":
    main()
