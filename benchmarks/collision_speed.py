"""Collision-free IK speed on the panda in a scene (issue 35 item 4): time per target against the same solver
without a world, per stage, and the collision-free success.

    python benchmarks/collision_speed.py [--targets 1000] [--seed 0] [--rounds 5] [--builtin] [--mesh-verdict]

The panda of example-robot-data (its URDF with collision meshes: arm, hand, fingers), its sphere model fitted to
the meshes (:func:`nik.collision.collision_model`, cached), the scene of ``benchmarks/collisions.py`` (a table and
10 boxes, spheres and capsules), ``--targets`` poses of random configurations that the meshes call free (coal,
MoveIt's pairs). Two solvers in one process, one thread (``nik.set_threads(1)``, torch one thread), interleaved
``--rounds`` times: ``IKSolver(robot, self_collision=False)`` (no world) and ``IKSolver(robot, world=scene)`` (the
world and the arm itself); medians of the CPU time of the process per target (fair on a machine shared with
other jobs; the wall time beside it) and the median of the per-round ratios. Then one more call of the collision
solver with each stage of :func:`nik.ik.collide.resolve` timed (the pipeline without a world, the first check, the
blocked-pose proof where the code has it, the re-solve, the check of the new answers, the names), and the
outcome: success, answers called free that collide on the meshes (must be 0), targets re-solved, blocked.

``--builtin``: nik's built-in ``panda`` with its shipped model (spheres fitted to the same meshes, tighter:
:mod:`nik.collision.builtin`) instead, the targets and the mesh check as above (coal on example-robot-data's meshes,
the model's pairs), what a user of ``nik.load_robot("panda")`` gets.

``--mesh-verdict``: a third solver in the rotation, ``IKSolver(robot, world=scene, mesh_verdict="auto")`` (the meshes
judge ``collision_free``, coal; :mod:`nik.ik.collide`): its success, answers it calls free that collide on the meshes
(must be 0), time per target and ratio to no world, and its stages (with the configurations coal was asked about:
where the spheres cover the meshes, only those the spheres call colliding). The code measured is the one on
``sys.path`` (``PYTHONPATH``), so the same file measures an older checkout's verdict.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import nik  # noqa: E402


class _Timer:
    """CPU seconds spent in wrapped functions, by stage name."""

    def __init__(self):
        self.spent: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.items: dict[str, int] = {}  # targets re-solved, targets blocked
        self.iters: dict[str, list] = {}  # the re-solve's iterations per target, by pass

    def wrap(self, owner, attr: str, name: str):
        fn = getattr(owner, attr)

        def timed(*a, **k):
            t = time.process_time()
            label = _pass(name, a)
            try:
                got = fn(*a, **k)
                if name.startswith("blocked"):
                    self.items[label] = self.items.get(label, 0) + int(np.sum(got))
                return got
            finally:
                if name.startswith("re-solve"):
                    self.items[label] = self.items.get(label, 0) + len(a[2])
                    its = np.asarray(a[29])  # the kernel's iterations (its 30th argument)
                    self.iters[label] = self.iters.get(label, []) + its.tolist()
                self.spent[label] = self.spent.get(label, 0.0) + time.process_time() - t
                self.calls[label] = self.calls.get(label, 0) + 1

        setattr(owner, attr, timed)
        return fn


def _pass(name: str, a) -> str:
    """The re-solve's pass of a :func:`nik.kernels.collision_lm.collision_lm` call by its arguments (given starts,
    uniform restarts, margin): from the answer alone (1 start, no restarts, margin > 0), the hypotheses and the
    restarts, or margin 0 (one start, none); other stages keep their name."""
    if not name.startswith("re-solve"):
        return name
    starts, restarts, margin = a[3].q, np.asarray(a[3].restarts), float(a[8].margin)  # Starts, CollideOpts
    if margin == 0.0:
        return "re-solve: margin 0, from the last answer"
    if restarts.sum() == 0 and starts.shape[1] == 1:
        return "re-solve: from the answer alone"
    return "re-solve: hypotheses, then uniform restarts"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=5, help="timed rounds per solver, interleaved")
    ap.add_argument("--builtin", action="store_true", help="the built-in panda and its shipped model")
    ap.add_argument("--mesh-verdict", action="store_true", help="a third solver: the meshes judge (coal)")
    args = ap.parse_args(argv)
    from collisions import panda_urdf, scene

    from nik.collision import collision_model
    from nik.collision.meshcheck import MeshCheck
    from nik.collision.model import srdf_disabled, srdf_of

    nik.set_threads(1)
    torch.set_num_threads(1)
    urdf = panda_urdf()
    if args.builtin:
        robot = nik.load_robot("panda")
        model = collision_model(robot, source="builtin")
        skip = [tuple(k.split("|")) for k, why in model.left_out.items() if why != "never"]
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            robot = nik.load_robot(urdf, end_link="panda_hand")
        model = collision_model(robot)
        srdf = srdf_of(urdf)
        skip = list(srdf_disabled(srdf)) if srdf is not None else []
    nik.collision.set_collision_model(robot, model)
    mesh = MeshCheck(robot, urdf, skip=skip)
    world = scene(args.seed)
    g = torch.Generator().manual_seed(args.seed)
    Q = np.ascontiguousarray(robot.sample(4 * args.targets, generator=g, dtype=torch.float64).numpy())
    T = np.ascontiguousarray(robot.fk(Q[~mesh.collides(Q, world)][: args.targets]))
    plain = nik.IKSolver(robot, self_collision=False)
    safe = nik.IKSolver(robot, world=world)
    solvers = [("plain", plain), ("safe", safe)]
    if args.mesh_verdict:
        solvers.append(("judged", nik.IKSolver(robot, world=world, mesh_verdict="auto")))
    print(f"nik at {Path(nik.__file__).resolve().parent.parent}")
    which = "built-in, shipped spheres" if args.builtin else "example-robot-data, arm + hand + fingers"
    print(f"panda ({which}), {len(T)} targets from configurations the meshes call free")
    print(f"in a scene of {sum(world.counts())} obstacles (table + 10), seed {args.seed}; model: {model}; one thread")
    for _, solver in solvers:  # compile / load the kernels, and one full call each, before timing
        solver.solve(T)
    cpu = {name: [] for name, _ in solvers}
    wall = {name: [] for name, _ in solvers}
    out = {}
    for _ in range(args.rounds):
        for name, solver in solvers:
            t, c = time.perf_counter(), time.process_time()
            out[name] = solver.solve(T)
            wall[name].append((time.perf_counter() - t) / len(T))
            cpu[name].append((time.process_time() - c) / len(T))
    labels = {"plain": "no world", "safe": "scene + self", "judged": "scene + self, meshes judge"}
    print("\n| solver | success | collision-free | called free, mesh colliding | us/target CPU | us/target wall |")
    print("|---|---|---|---|---|---|")
    for key, _ in solvers:
        r = out[key]
        cf = ff = "-"
        if r.collision_free is not None:
            free = np.asarray(r.collision_free)
            cf, ff = f"{np.mean(free):.1%}", str(int(mesh.collides(np.asarray(r.q)[free], world).sum()))
        print(
            f"| {labels[key]} | {np.mean(r.success):.1%} | {cf} | {ff} | {1e6 * statistics.median(cpu[key]):.0f} "
            f"| {1e6 * statistics.median(wall[key]):.0f} |"
        )
    for key, _ in solvers[1:]:
        ratios = [s / p for s, p in zip(cpu[key], cpu["plain"], strict=True)]
        print(
            f"ratio {labels[key]} / no world (CPU, median of {args.rounds} interleaved rounds): "
            f"{statistics.median(ratios):.2f}x (rounds: {', '.join(f'{x:.2f}' for x in ratios)})"
        )
    if args.mesh_verdict:
        judged = np.asarray(out["judged"].success)
        spheres = np.asarray(out["safe"].success)
        print(f"meshes judge vs spheres, same targets: {int((judged & ~spheres).sum())} won, "
              f"{int((spheres & ~judged).sum())} lost")  # fmt: skip
    for key, solver in solvers[1:]:
        print(f"\n{labels[key]}:")
        _stages(robot, solver, T, len(T))


def _stages(robot, safe, T, B: int) -> None:
    """One more call of the collision solver with each stage of :func:`nik.ik.collide.resolve` timed."""
    import nik.collision.compiled as compiled
    import nik.ik.collide as collide
    import nik.kernels.collision_lm as clm
    from nik.collision.meshcheck import MeshCheck

    timer = _Timer()
    checks = ["steering", "judge"] if hasattr(collide.Setup, "judge") else ["colliding"]
    originals = [(collide.Setup, c, timer.wrap(collide.Setup, c, f"check ({c})")) for c in checks]
    asked = []  # configurations coal was asked about (the verdict and the names)
    for attr in ("collides", "collision_names"):
        fn = getattr(MeshCheck, attr)
        originals.append((MeshCheck, attr, fn))
        setattr(MeshCheck, attr, _counted(fn, asked))
    originals += [
        (collide.Setup, "names", timer.wrap(collide.Setup, "names", "names")),
        (collide.stage, "_starts", timer.wrap(collide.stage, "_starts", "starts (hypotheses)")),
        (clm, "collision_lm", timer.wrap(clm, "collision_lm", "re-solve (LM with collision rows)")),
    ]
    if hasattr(compiled, "blocked_targets"):
        originals.append((compiled, "blocked_targets", timer.wrap(compiled, "blocked_targets", "blocked-pose proof")))
    c = time.process_time()
    try:
        res = safe.solve(T)
    finally:
        for owner, attr, fn in originals:
            setattr(owner, attr, fn)
    total = time.process_time() - c
    inner = sum(timer.spent.values())
    print(f"\nstages of one call ({B} targets), CPU us per target (of all targets):")
    print("| stage | us/target | calls | targets | iterations (largest 3 targets) |")
    print("|---|---|---|---|---|")
    print(f"| pipeline without a world (backend) and Python between the stages | {1e6 * (total - inner) / B:.1f} | 1 "
          f"| {B} | |")  # fmt: skip
    for name, spent in timer.spent.items():
        its = sorted(timer.iters.get(name, []), reverse=True)
        it = f"{sum(its)} ({', '.join(map(str, its[:3]))})" if its else ""
        print(f"| {name} | {1e6 * spent / B:.1f} | {timer.calls[name]} | {timer.items.get(name, '')} | {it} |")
    print(f"| total | {1e6 * total / B:.1f} | | |")
    print(f"success {np.mean(res.success):.1%}, collision-free {np.mean(res.collision_free):.1%}; coal asked about "
          f"{sum(asked)} configurations in {len(asked)} calls")  # fmt: skip


def _counted(fn, asked: list):
    """``fn`` (a :class:`nik.collision.meshcheck.MeshCheck` method taking ``Q``), counting the configurations."""

    def counted(self, Q, *a, **k):
        asked.append(len(np.asarray(Q).reshape(-1, self.robot.dof)))
        return fn(self, Q, *a, **k)

    return counted


if __name__ == "__main__":
    main()
