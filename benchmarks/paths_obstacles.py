"""Cartesian paths among obstacles (issue 36): ``solve_path(T, q_start=q0, world=w)`` on tool lines whose plain answer
sweeps the arm through a box, with CppFlow's criteria.

Problems (seeded), 200 waypoints each, orientation fixed, from a configuration in the middle 60 % of the ranges
(:func:`shape`): a 25 cm tool line; a circle of radius 8 cm through the start in a random plane (closed); a letter,
"Z" (three strokes of 15 cm, 15 cm and 21 cm: corners where the tool turns on the spot), in a random plane. The plain
answer (no world) is solved; a box is placed off its elbow at the middle waypoint (``offset`` from the elbow, away
from the shoulder-wrist axis; half size ``size``), at least 20 cm from every waypoint of the tool's path, kept only
where the plain answer (which takes no step above 7 deg) collides with it and ``q0`` does not. Valid (CppFlow):
every waypoint within 0.1 mm / 0.1 deg by FK, no step (from q0 on) above 7 deg, no collision of the spheres at the
waypoints and at 7 samples inside every step (the sphere model: conservative, docs/collisions.md); a circle also
closed: its last row within 0.1 deg of its first (the loop repeats without a jump). Columns: valid paths, the largest
step (median over the problems, deg), the joint path length (median, sum of |dq|, rad), the worst error (mm), the worst
loop closure (circles, deg), the time per path (median, s). Rows: nik with the world (network on: the default
checkpoint; off: ``checkpoint=None``) and the plain answer (no world: what the straight motion does).

The second table (free space, from ``q_start``): benchmarks/paths.py's stream of paths on the redundant arms (60
waypoints; lines of 15 cm, circles of 5 cm radius, closed; from a configuration in the middle 60 % of the ranges);
feasible: the per-pose solver reaches every waypoint (benchmarks/paths.py's rule); followed: every waypoint within
0.1 mm / 0.1 deg, every step (the first from ``q_start``) <= 3 deg; closed: the last row within 0.1 deg of the first
(modulo whole turns on joints wider than a turn), over every circle; the worst first step from ``q_start``; the
median time per path. Rows: the search with the network, without it (``checkpoint=None``), and the plain chain alone
(the search switched off: what main did). Kinova Gen2 (example-robot-data, where installed): circles only.

    OMP_NUM_THREADS=1 python benchmarks/paths_obstacles.py --n 8 --free 40
    OMP_NUM_THREADS=1 python benchmarks/paths_obstacles.py --n 8 --shapes line,circle,letter   # obstacles only

Not measured here (issue 36, left to do): a chain of ``solve(q_near=previous, world=w)`` as the peer.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import nik  # noqa: E402
from nik.collision import collides, link_frames  # noqa: E402

N_WAYPOINTS, STEP = 200, math.radians(7.0)
BOXES = ((0.10, 0.02), (0.09, 0.03), (0.08, 0.04))  # (offset from the elbow, half size), metres


SHAPES = ("line", "circle", "letter")


def shape(robot, q0: np.ndarray, rng: np.random.Generator, kind: str) -> np.ndarray:
    """``(N, 4, 4)``: the tool path ``kind`` (:data:`SHAPES`, module docstring) from FK(``q0``), orientation fixed."""
    T = np.repeat(robot.fk(q0)[None], N_WAYPOINTS, 0)
    s = np.linspace(0, 1, N_WAYPOINTS)[:, None]
    if kind == "line":
        d = rng.normal(size=3)
        T[:, :3, 3] += s * d * (0.25 / np.linalg.norm(d))
        return T
    u, v = np.linalg.qr(rng.normal(size=(3, 2)))[0].T
    if kind == "circle":
        a = 2 * math.pi * s
        T[:, :3, 3] += 0.08 * (u - np.cos(a) * u - np.sin(a) * v)
        return T
    if kind != "letter":
        raise ValueError(f"shape: expected one of {SHAPES}, got {kind!r}")
    corners = 0.15 * np.array([[0.0, 1.0], [1.0, 1.0], [0.0, 0.0], [1.0, 0.0]]) - [0.0, 0.15]  # "Z" from its top left
    seg = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    at = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()  # arc length of each corner, 0 ... 1
    xy = np.stack([np.interp(s[:, 0], at, corners[:, k]) for k in range(2)], axis=1)
    T[:, :3, 3] += xy[:, :1] * u + xy[:, 1:] * v
    return T


def problems(name: str, n: int, seed: int = 0, kind: str = "line"):
    """``n`` problems ``(T (N, 4, 4), q0 (dof,), world)`` on ``name`` along paths of ``kind`` (module docstring)."""
    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot, checkpoint=None)
    rng = np.random.default_rng(seed)
    lim = robot.limits.numpy()
    mid = lim.mean(1)
    out = []
    while len(out) < n:
        q0 = mid + 0.6 * (rng.uniform(lim[:, 0], lim[:, 1]) - mid)
        T = shape(robot, q0, rng, kind)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plain = solver.solve_path(T, q_start=q0)
        if not plain.success.all():
            continue
        q = plain.q.numpy()
        fr = link_frames(robot, torch.from_numpy(q[N_WAYPOINTS // 2 : N_WAYPOINTS // 2 + 1]))[0]
        elbow, sh, wr = (fr[k, :3, 3].numpy() for k in (4, 2, 6))
        if np.linalg.norm(T[:, :3, 3] - elbow, axis=1).min() < 0.2:
            continue
        ax = (wr - sh) / np.linalg.norm(wr - sh)
        away = elbow - sh - ((elbow - sh) @ ax) * ax
        offset, size = BOXES[len(out) % len(BOXES)]
        world = nik.World().add_box(elbow + offset * away / np.linalg.norm(away), [size] * 3)
        hit = collides(robot, np.concatenate([q0[None], q]), world, self_collision=False)
        if hit.any() and not hit[0] and np.abs(np.diff(q, axis=0)).max() <= STEP:  # q0 free, no jump of its own
            out.append((T, q0, world))
    return robot, out


def verdict(robot, T, q0, q, world, closed: bool = False) -> tuple[bool, float, float, float, float]:
    """``(valid, largest step rad, path length rad, worst error mm, closure deg)`` of ``q: (N, dof)`` (module
    docstring; ``closed``: a loop, valid only where its last row is within 0.1 deg of its first)."""
    rows = np.concatenate([q0[None], q])
    d = np.diff(rows, axis=0)
    t = np.linspace(0.0, 1.0, 9)[None, :, None]
    motion = (rows[:-1, None] + t * d[:, None]).reshape(-1, robot.dof)
    pos, rot = (x.numpy() for x in nik.pose_error(torch.from_numpy(T), robot.fk(torch.from_numpy(q))))
    ok = pos.max() <= 1e-4 and rot.max() <= math.radians(0.1) and np.abs(d).max() <= STEP
    ok = ok and not collides(robot, motion, world, self_collision=False).any()
    closure = _closure_deg(robot, q) if closed else 0.0
    ok = ok and closure <= 0.1
    return bool(ok), float(np.abs(d).max()), float(np.abs(d).sum()), float(pos.max() * 1e3), closure


def bench(name: str, n: int, kind: str = "line") -> list[str]:
    robot, probs = problems(name, n, kind=kind)
    solvers = {
        "nik, world, network on": nik.IKSolver(robot),
        "nik, world, network off": nik.IKSolver(robot, checkpoint=None),
    }
    rows = []
    for label, solver in [*solvers.items(), ("plain (no world)", solvers["nik, world, network off"])]:
        res = []
        for T, q0, world in probs:
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = solver.solve_path(T, q_start=q0, world=None if label.startswith("plain") else world)
            dt = time.perf_counter() - t
            res.append((*verdict(robot, T, q0, out.q.numpy(), world, closed=kind == "circle"), dt))
        v, step, length, err, closure, dt = (np.array(x) for x in zip(*res, strict=True))
        shut = f"{closure.max():.3g}" if kind == "circle" else "-"
        rows.append(
            f"| {name} | {kind} | {label} | {int(v.sum())}/{len(v)} | {math.degrees(np.median(step)):.2f} | "
            f"{np.median(length):.2f} | {err.max():.4f} | {shut} | {np.median(dt):.2f} |"
        )
    return rows


def _closure_deg(robot, q: np.ndarray) -> float:
    """Last row vs first, degrees (modulo whole turns on joints whose range exceeds a turn)."""
    d = np.abs(q[-1] - q[0])
    lim = robot.limits.numpy()
    w = lim[:, 1] - lim[:, 0] > 2 * math.pi
    d[w] = np.abs(np.remainder(d[w] + math.pi, 2 * math.pi) - math.pi)
    return math.degrees(float(d.max()))


def _kinova():
    """example-robot-data's Kinova Gen2, or None."""
    import importlib.metadata

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/kinova_description/robots/kinova.urdf"))
    return nik.load_robot(path, end_link="j2s6s200_end_effector") if path.is_file() else None


def free_paths(name: str, n: int):
    """``(robot, [(kind, T, q0, feasible)])``: benchmarks/paths.py's stream (module docstring); Kinova: circles."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from paths import PATH_SEED, circle, line, start_configuration

    robot = _kinova() if name == "kinova" else nik.load_robot(name)
    if robot is None:
        return None, []
    solver = nik.IKSolver(robot, checkpoint=None)
    gen = torch.Generator().manual_seed(PATH_SEED + sum(map(ord, name)))
    out = []
    for k in range(2 * n):
        kind = "circle" if (k % 2 or name == "kinova") else "line"
        q0 = start_configuration(robot, gen, 0.6)
        T = line(robot, q0, gen, 0.15) if kind == "line" else circle(robot, q0, gen)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            feasible = bool(solver.solve(T).success.all())
        out.append((kind, T, q0, feasible))
    return robot, out


def bench_free(name: str, n: int) -> list[str]:
    import nik.paths.solve as P

    robot, probs = free_paths(name, n)
    if robot is None:
        return [f"| {name} | (not installed) | | | | | |"]
    smooth = P._smooth
    runs = {
        "search, network on": (nik.IKSolver(robot), smooth),
        "search, network off": (nik.IKSolver(robot, checkpoint=None), smooth),
        "chain alone (main)": (nik.IKSolver(robot), lambda *a, **k: True),
    }
    rows = []
    for label, (solver, sm) in runs.items():
        P._smooth = sm
        met = {"line": [0, 0], "circle": [0, 0]}
        closed, first, dts = [], [], []
        for kind, T, q0, feasible in probs:
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = solver.solve_path(T, q_start=q0)
            dts.append(time.perf_counter() - t)
            q = res.q.numpy()
            pos, rot = nik.pose_error(T, robot.fk(res.q))
            steps = np.abs(np.diff(np.concatenate([q0.numpy()[None], q]), axis=0)).max()
            ok = bool(pos.max() <= 1e-4 and rot.max() <= math.radians(0.1) and steps <= math.radians(3.0))
            if feasible:
                met[kind][0] += 1
                met[kind][1] += ok
            if kind == "circle":
                closed.append(_closure_deg(robot, q))
            first.append(math.degrees(float(np.abs(q[0] - q0.numpy()).max())))
        P._smooth = smooth
        c = np.array(closed)
        rows.append(
            f"| {name} | {label} | {met['line'][1]}/{met['line'][0]} | {met['circle'][1]}/{met['circle'][0]} | "
            f"{int((c <= 0.1).sum())}/{len(c)} | {c.max():.3g} | {max(first):.3g} | {1e3 * np.median(dts):.1f} |"
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=6, help="problems among obstacles per robot (0: none)")
    ap.add_argument("--robots", default="panda,xarm7")
    ap.add_argument("--shapes", default=",".join(SHAPES), help="tool paths among obstacles: line, circle, letter")
    ap.add_argument("--free", type=int, default=0, help="free-space lines + circles per arm from q_start (0: none)")
    ap.add_argument("--free-robots", default="xarm7,panda,kinova")
    args = ap.parse_args()
    if args.n:
        print(
            "| robot | path | solver | valid | largest step (deg) | path length (rad) | worst error (mm) | "
            "worst closure (deg) | s / path |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for name in args.robots.split(","):
            for kind in args.shapes.split(","):
                for row in bench(name, args.n, kind):
                    print(row, flush=True)
    if args.free:
        print()
        print(
            "| robot | solver | lines followed (<= 3 deg) | circles followed | loops closed (0.1 deg) | "
            "worst closure (deg) | worst first step (deg) | ms / path |"
        )
        print("|---|---|---|---|---|---|---|---|")
        for name in args.free_robots.split(","):
            for row in bench_free(name, args.free):
                print(row, flush=True)


if __name__ == "__main__":
    main()
