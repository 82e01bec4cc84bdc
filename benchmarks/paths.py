"""Cartesian paths: ``IKSolver.solve_path`` against the hand-made chain and Robotics Toolbox, on the same paths.

Paths (seeded): straight lines (60 waypoints, fixed orientation) and circles (60 waypoints, radius 0.05 m, fixed
orientation, a random plane) that start at the FK pose of a random configuration inside the limits, so the first
waypoint is reachable. On the redundant arms the lines are 0.15 m long and start from configurations inside the
central 60 % of each joint range (the issue's goal); on the closed-form arms they are 0.2 m long.

Per path, in one process, the solvers interleaved (the order rotates from path to path):

- ``solve_path``: ``IKSolver(robot).solve_path(T)`` (the start chosen by the solver) and, for the speed column,
  ``solve_path(T, q_start=q0)`` from the configuration the path was made from;
- ``chain``: the hand-made chain ``solve(T[0])`` (or ``q_near=q0``), then ``solve(T[i], q_near=q[i-1])``;
- ``rtb``: Robotics Toolbox ``ik_LM`` seeded with the previous waypoint's answer (from ``q0``), joint limits on,
  nik's tolerance as in ``benchmarks/peers.py`` (``RTB_TOL``, ``RTB_MASK``); its model is built from nik's own normal
  form (the same FK).

Closed-form arms (ur5, kuka_kr): the exhaustive check takes all 8 branches of every waypoint (the torch closed
form, ``nik.analytic.solve``, not the compiled one solve_path uses) and finds the smallest largest step any branch
sequence achieves (a threshold search over the layered graph, independent of solve_path's dynamic programming; real
joint motion: a joint whose range exceeds a full turn enters at each of its values inside the limits). "Feasible"
paths: every waypoint has a valid branch and that best is <= 3 deg. A solver "meets" a feasible path when every
waypoint is reached (0.1 mm / 0.1 deg by nik's FK, inside the limits) and its largest step, measured on its own
joints, is <= best + 0.5 deg. Redundant arms (panda, xarm7), from q0: "feasible" paths are those whose every
waypoint the per-pose solver (``solve(T)``, no continuity asked) reaches; the goal is every waypoint within 0.1 mm
/ 0.1 deg and every step (the first from q0 included) <= 3 deg.

"Certified" (redundant arms): the feasible paths for which a witness is known, a joint path from q0 that meets the
goal (every waypoint at 0.1 mm / 0.1 deg by nik's FK, inside the limits, every step from q0 on <= 3 deg): the answer
of any solver in the table that meets it, else the slow oracle :func:`witness_path` (a beam of up to 160
configurations per waypoint, each stepped to the next waypoint by Cartesian continuation, the damped pseudo-inverse
through 3 interpolated poses, with 9 offsets of up to +-2.4 deg along the self-motion, then Newton to 0.05 mm /
0.05 deg; every step <= 3 deg). Where no witness is found the path is not counted as feasible in the goal's sense:
the oracle is a search, not a proof, but on the xarm7 stream every such path it was run on starts next to a
singularity (the smallest singular value of the Jacobian at q0 about 0.01) or meets one on the way, where a
linearised step to the next waypoint already needs more than 3 deg on some joint whatever the self-motion. The
goal column "certified" counts solve_path's met paths over the certified ones.

Speed: median time per waypoint over the paths (each path timed once per solver); ratios are the peer's median
over solve_path's (from q0).

The second table reports ``solve_path(T)`` (no ``q_start``) as CppFlow (ICRA 2024) does, over all paths: valid
(every waypoint at 0.1 mm / 0.1 deg, inside the limits, every step <= 7 deg revolute / 2 cm prismatic), the largest
step, the total joint motion, the time per path; on the circles (closed) the last row vs the first; on the valid
paths, the trajectory timed by ``nik.paths.timing.time_path`` (the robot's limits) sampled every millisecond: samples
over a limit, and the duration over toppra's answer. ``ur10`` is example-robot-data's URDF (a robot nik does not
ship; skipped when the package is missing).

    python benchmarks/paths.py                 # 40 lines + 40 circles per arm (a few minutes)
    python benchmarks/paths.py --out benchmarks/results/paths   # also writes the table to paths.md
    python benchmarks/paths.py --paths 5       # a smoke run
    python benchmarks/paths.py --paths 10 --out benchmarks/results/paths_10   # the stored short run
"""

from __future__ import annotations

import argparse
import io
import itertools
import math
import os
import statistics
import sys
import time
import warnings
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import nik  # noqa: E402
from nik.analytic import solve as closed_form_solutions  # noqa: E402
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from peers import RTB_MASK, RTB_TOL  # noqa: E402  (ik_LM given nik's tolerance)

ARMS = ("ur5", "kuka_kr", "panda", "xarm7", "ur10")
#: Arms from URDFs nik does not ship: name -> (pip distribution, file inside its cmeel prefix).
EXTERNAL = {
    "ur10": ("example-robot-data", "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur10_robot.urdf")
}
#: CppFlow's (ICRA 2024) validity of a path: every waypoint at 0.1 mm / 0.1 deg and every step at most this.
CPPFLOW_STEP = math.radians(7.0)  # rad, revolute joints
CPPFLOW_SLIDE = 0.02  # m, prismatic joints
#: Relative excess over a speed or acceleration limit counted as a violation of the timed trajectory (1 ms samples).
RATE_SLACK = 1e-6
N_WAYPOINTS = 60
STEP_GOAL = math.radians(3.0)  # rad
SLACK_GOAL = math.radians(0.5)  # rad
PATH_SEED = 7_000_003  # the paths' own random stream (not the solvers' seed 0)


# ---------------------------------------------------------------------------
# paths
# ---------------------------------------------------------------------------
def start_configuration(robot, gen: torch.Generator, central: float | None) -> torch.Tensor:
    """A random configuration inside the limits (inside the central fraction ``central`` of each range if given)."""
    lo, hi = robot.limits.double().T
    u = torch.rand(robot.dof, generator=gen, dtype=torch.float64)
    if central is not None:
        u = 0.5 - central / 2 + central * u
    return lo + u * (hi - lo)


def line(robot, q0, gen, length: float) -> torch.Tensor:
    """``(N, 4, 4)``: a straight line of ``length`` m from FK(q0) in a random direction, orientation fixed."""
    T0 = robot.fk(q0[None])[0]
    d = torch.randn(3, generator=gen, dtype=torch.float64)
    s = torch.linspace(0.0, 1.0, N_WAYPOINTS, dtype=torch.float64)
    T = T0.expand(N_WAYPOINTS, 4, 4).clone()
    T[:, :3, 3] = T0[:3, 3] + s[:, None] * length * d / d.norm()
    return T


def circle(robot, q0, gen, radius: float = 0.05) -> torch.Tensor:
    """``(N, 4, 4)``: a full circle through FK(q0) in a random plane, orientation fixed."""
    T0 = robot.fk(q0[None])[0]
    u, v = torch.linalg.qr(torch.randn(3, 2, generator=gen, dtype=torch.float64))[0].T
    a = torch.linspace(0.0, 2 * math.pi, N_WAYPOINTS, dtype=torch.float64)
    centre = T0[:3, 3] + radius * u
    T = T0.expand(N_WAYPOINTS, 4, 4).clone()
    T[:, :3, 3] = centre - radius * (torch.cos(a)[:, None] * u + torch.sin(a)[:, None] * v)
    return T


# ---------------------------------------------------------------------------
# the exhaustive check (closed-form arms)
# ---------------------------------------------------------------------------
def with_turns(robot, q: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every branch with each joint whose range exceeds a full turn at each of its values inside the limits
    (``+-2 pi`` copies): ``(N, 8 x 3^w, dof)`` and the validity ``(N, 8 x 3^w)``."""
    lo, hi = robot.limits.double().numpy().T
    w = (hi - lo) > 2 * math.pi + 1e-6
    turns = np.zeros((3 ** int(w.sum()), robot.dof))
    turns[:, w] = 2 * math.pi * np.array(list(itertools.product((0.0, -1.0, 1.0), repeat=int(w.sum()))))
    big = (q[:, :, None, :] + turns[None, None]).reshape(q.shape[0], -1, robot.dof)
    ok = np.repeat(valid, turns.shape[0], axis=1) & ((big >= lo) & (big <= hi)).all(axis=-1)
    return big, ok


def best_largest_step(robot, T: torch.Tensor) -> float:
    """The smallest largest step (rad) over all branch sequences if it is <= STEP_GOAL, else inf (also when some
    waypoint has no valid branch). Real joint motion: a joint that turns past +-pi is taken at each of its values
    inside the limits, so a sequence that would leave a limit is not counted."""
    q, valid = closed_form_solutions(robot, T, tol_pos=DEFAULT_TOL_POS, tol_rot=DEFAULT_TOL_ROT)
    q, valid = with_turns(robot, q.numpy(), valid.numpy())
    if not valid.any(axis=1).all():
        return math.inf
    D = np.stack([np.abs(q[i + 1][:, None] - q[i][None]).max(axis=-1) for i in range(q.shape[0] - 1)])
    D[~np.broadcast_to(valid[1:, :, None] & valid[:-1, None, :], D.shape)] = math.inf  # (N-1, next, previous)

    def feasible(theta: float) -> bool:
        reach = valid[0].copy()
        for i in range(D.shape[0]):
            reach = ((D[i] <= theta) & reach[None, :]).any(axis=1)
            if not reach.any():
                return False
        return True

    if not feasible(STEP_GOAL):
        return math.inf
    values = np.unique(D[D <= STEP_GOAL])
    lo_i, hi_i = 0, len(values) - 1
    while lo_i < hi_i:  # the smallest edge value that still connects the first layer to the last
        mid = (lo_i + hi_i) // 2
        if feasible(values[mid]):
            hi_i = mid
        else:
            lo_i = mid + 1
    return float(values[lo_i])


# ---------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------
def ets_of(robot):
    """A Robotics Toolbox ETS with nik's normal form (G_0 Rz(q_1 + o_1) G_1 ...), None without rtb."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return None
    with redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        G, off, lim = robot.G.double().numpy(), robot.offsets.double().numpy(), robot.limits.double().numpy()
        e = rtb.ET.SE3(G[0])
        for i in range(robot.dof):
            if off[i] != 0.0:
                e = e * rtb.ET.Rz(off[i])
            e = e * rtb.ET.Rz(qlim=lim[i]) * rtb.ET.SE3(G[i + 1])
    q = robot.sample(16, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    gap = max(float(np.abs(e.eval(a) - b).max()) for a, b in zip(q.numpy(), robot.fk(q).numpy(), strict=True))
    if gap > 1e-9:
        raise RuntimeError(f"rtb model of {robot.name} disagrees with nik's FK by {gap:.2e} m")
    return e


def _pose_gap(robot, q: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(e (B, 6), J (B, 6, dof))``: the pose error of ``q: (B, dof)`` towards ``T: (B, 4, 4)`` (position, then the
    rotation vector of ``R_T R_q^T``, both in the base frame) and the geometric Jacobian at ``q``."""
    from scipy.spatial.transform import Rotation

    Tq, J = robot.fk_and_jacobian(torch.from_numpy(np.ascontiguousarray(q)))
    Tq, J = Tq.numpy(), J.numpy()
    e = np.empty((q.shape[0], 6))
    e[:, :3] = T[:, :3, 3] - Tq[:, :3, 3]
    e[:, 3:] = Rotation.from_matrix(T[:, :3, :3] @ np.swapaxes(Tq[:, :3, :3], 1, 2)).as_rotvec()
    return e, J


def witness_path(robot, T: torch.Tensor, q0: torch.Tensor, beam: int = 160, sub: int = 3) -> np.ndarray | None:
    """The slow oracle of the "certified" column (module docstring): a joint path ``(N, dof)`` from ``q0`` through
    the waypoints ``T: (N, 4, 4)`` with every step <= STEP_GOAL and every waypoint within half the tolerances, or
    None where the beam dies out. Each configuration of the beam is moved to the next waypoint by ``sub``
    interpolated poses (damped pseudo-inverse steps) with an offset along the self-motion (the Jacobian's null
    vector, scaled to a largest component of 1), then 4 Newton steps at the waypoint; distinct answers (a 0.5 deg
    grid) are thinned to ``beam`` by farthest-point sampling (largest joint difference)."""
    Tn, q0n = T.numpy(), q0.numpy()
    lo, hi = robot.limits.double().numpy().T
    offsets = np.radians(np.linspace(-2.4, 2.4, 9))
    frontier, layers, parents, prev = q0n[None], [], [], Tn[0]

    def newton(q, Tb):
        e, J = _pose_gap(robot, q, Tb)
        y = np.linalg.solve(J @ np.swapaxes(J, 1, 2) + 1e-9 * np.eye(6), e[..., None])[..., 0]
        dq = np.einsum("bji,bj->bi", J, y)
        return dq, J

    for i in range(Tn.shape[0]):
        q = np.repeat(frontier, offsets.size, axis=0)
        par = np.repeat(np.arange(frontier.shape[0]), offsets.size)
        t = np.tile(offsets, frontier.shape[0])
        ref = None
        for s in range(1, sub + 1):
            Tb = np.repeat(Tn[i][None], q.shape[0], axis=0)
            Tb[:, :3, 3] = (1 - s / sub) * prev[:3, 3] + (s / sub) * Tn[i][:3, 3]
            dq, J = newton(q, Tb)
            null = np.linalg.svd(J)[2][:, -1]
            null /= np.abs(null).max(axis=1, keepdims=True)
            if ref is not None:  # the same sense as the substep before
                null *= np.sign((null * ref).sum(axis=1, keepdims=True) + 1e-30)
            ref = null
            q = np.clip(q + dq + (t / sub)[:, None] * null, lo, hi)
        Tb = np.repeat(Tn[i][None], q.shape[0], axis=0)
        for _ in range(4):
            q = np.clip(q + newton(q, Tb)[0], lo, hi)
        e, _ = _pose_gap(robot, q, Tb)
        ok = (np.linalg.norm(e[:, :3], axis=1) <= 0.5 * DEFAULT_TOL_POS) & (
            np.linalg.norm(e[:, 3:], axis=1) <= 0.5 * DEFAULT_TOL_ROT
        )
        ok &= np.abs(q - frontier[par]).max(axis=1) <= STEP_GOAL
        q, par = q[ok], par[ok]
        if not q.shape[0]:
            return None
        order = np.random.default_rng(i).permutation(q.shape[0])
        _, first = np.unique(np.floor(q[order] / math.radians(0.5)).astype(np.int64), axis=0, return_index=True)
        keep = order[np.sort(first)]
        if keep.size > beam:  # farthest-point thinning
            sel, dist = [keep[0]], np.abs(q[keep] - q[keep[0]]).max(axis=1)
            for _ in range(beam - 1):
                j = int(np.argmax(dist))
                sel.append(keep[j])
                dist = np.minimum(dist, np.abs(q[keep] - q[keep[j]]).max(axis=1))
            keep = np.array(sel)
        frontier, prev = q[keep], Tn[i]
        layers.append(frontier)
        parents.append(par[keep])
    path, k = [layers[-1][0]], parents[-1][0]
    for i in range(len(layers) - 2, -1, -1):
        path.append(layers[i][k])
        k = parents[i][k]
    return np.array(path[::-1])


def run_solve_path(solver, T, q0):
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = solver.solve_path(T, q_start=q0)
    return res.q.numpy(), time.perf_counter() - t


def run_chain(solver, T, q0):
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        q = [solver.solve(T[0], q_near=q0).q[0]]
        for i in range(1, T.shape[0]):
            q.append(solver.solve(T[i], q_near=q[-1]).q[0])
    return torch.stack(q).numpy(), time.perf_counter() - t


def run_rtb(ets, T, q0):
    Tn = T.numpy()
    np.random.seed(0)  # ik_LM draws its restarts from numpy's global generator
    q = np.empty((Tn.shape[0], ets.n))
    prev = q0.numpy()
    t = time.perf_counter()
    for i in range(Tn.shape[0]):
        prev = q[i] = ets.ik_LM(Tn[i], q0=prev, tol=RTB_TOL, mask=RTB_MASK, joint_limits=True).q
    return q, time.perf_counter() - t


def quality(robot, T, q, q0=None) -> tuple[bool, float]:
    """``(every waypoint reached within 0.1 mm / 0.1 deg and inside the limits, largest step rad)``."""
    qt = torch.from_numpy(np.ascontiguousarray(q))
    pe, re = nik.pose_error(T, robot.fk(qt))
    lo, hi = robot.limits.double().T
    inside = ((qt >= lo - 1e-9) & (qt <= hi + 1e-9)).all()
    ok = bool(((pe <= DEFAULT_TOL_POS) & (re <= DEFAULT_TOL_ROT)).all() and inside)
    full = q if q0 is None else np.concatenate([q0.numpy()[None], q])
    return ok, float(np.abs(np.diff(full, axis=0)).max())


# ---------------------------------------------------------------------------
# the table
# ---------------------------------------------------------------------------
def load_arm(name: str):
    """The robot ``name``: built in, or from :data:`EXTERNAL` (None when its package is not installed)."""
    if name not in EXTERNAL:
        return nik.load_robot(name)
    import importlib.metadata

    dist, rel = EXTERNAL[name]
    try:
        path = Path(importlib.metadata.distribution(dist).locate_file(rel))
    except importlib.metadata.PackageNotFoundError:
        return None
    return nik.load_robot(str(path)) if path.exists() else None


def cppflow(robot, T, q: np.ndarray, seconds: float, closed: bool) -> dict:
    """CppFlow's report of one ``solve_path`` answer: valid (every waypoint reached within 0.1 mm / 0.1 deg by FK,
    inside the limits; every step <= 7 deg revolute / 2 cm prismatic), the largest step (deg, revolute; mm,
    prismatic), the total joint motion (deg, revolute joints), seconds, and on a closed path the last row vs the
    first (deg)."""
    reached, _ = quality(robot, T, q)
    dq = np.abs(np.diff(q, axis=0))
    slide = robot.prismatic.numpy()
    step_rev = float(dq[:, ~slide].max()) if (~slide).any() else 0.0
    step_pri = float(dq[:, slide].max()) if slide.any() else 0.0
    out = {
        "valid": reached and step_rev <= CPPFLOW_STEP and step_pri <= CPPFLOW_SLIDE,
        "step": math.degrees(step_rev),
        "motion": math.degrees(float(dq[:, ~slide].sum())),
        "seconds": seconds,
        "closure": math.degrees(float(np.abs(q[-1] - q[0]).max())) if closed else None,
    }
    return out


def timed(robot, q: np.ndarray) -> tuple[int, int, float]:
    """``(samples above a limit, samples, duration / toppra's)`` of ``q``'s time-optimal trajectory
    (:func:`nik.paths.timing.time_path`, the robot's limits), sampled every millisecond."""
    from nik.paths.timing import time_path

    tm = time_path(q, robot=robot)
    _, _, qd, qdd = tm.sample(1e-3)
    bad = (np.abs(qd) > tm.vel_limits * (1 + RATE_SLACK)).any(axis=1) | (
        np.abs(qdd) > tm.acc_limits * (1 + RATE_SLACK)
    ).any(axis=1)
    ratio = tm.duration / tm.toppra_duration if tm.toppra_duration > 0 else 1.0
    return int(bad.sum()), int(bad.size), ratio


def bench_arm(name: str, n_paths: int) -> dict | None:
    """Per kind of path (``line``, ``circle``): paths, feasible ones, goals met per solver, times per waypoint, and
    CppFlow's report of ``solve_path`` without ``q_start`` (``"cppflow"``: one entry per path; ``"timing"``: the
    timed trajectory of each valid one)."""
    robot = load_arm(name)
    if robot is None:
        return None
    solver = nik.IKSolver(robot)
    ets = ets_of(robot)
    redundant = not solver.closed_form
    gen = torch.Generator().manual_seed(PATH_SEED + sum(map(ord, name)))
    rows = {
        kind: {"feasible": 0, "paths": 0, "meets": {}, "times": {}, "cppflow": [], "timing": []}
        for kind in ("line", "circle")
    }
    for k in range(2 * n_paths):
        kind = "line" if k % 2 == 0 else "circle"
        row = rows[kind]
        q0 = start_configuration(robot, gen, 0.6 if redundant else None)
        T = line(robot, q0, gen, 0.15 if redundant else 0.2) if kind == "line" else circle(robot, q0, gen)
        row["paths"] += 1
        runs = {
            "solve_path (q_start)": lambda T=T, q0=q0: run_solve_path(solver, T, q0),
            "chain (q_near)": lambda T=T, q0=q0: run_chain(solver, T, q0),
        }
        runs["solve_path"] = lambda T=T: run_solve_path(solver, T, None)
        if not redundant:
            runs["chain"] = lambda T=T: run_chain(solver, T, None)
        if ets is not None:
            runs["rtb"] = lambda T=T, q0=q0: run_rtb(ets, T, q0)
        labels = list(runs)
        shift = k % len(labels)
        out = {}
        for label in labels[shift:] + labels[:shift]:  # interleaved: the order rotates from path to path
            q, dt = runs[label]()
            out[label] = q
            row["times"].setdefault(label, []).append(dt / T.shape[0])
        q = out["solve_path"]  # CppFlow's report reads solve_path without q_start
        report = cppflow(robot, T, q, row["times"]["solve_path"][-1] * T.shape[0], kind == "circle")
        row["cppflow"].append(report)
        if report["valid"] and robot.vel_limits is not None:
            row["timing"].append(timed(robot, q))
        if redundant:  # feasible: the per-pose solver reaches every waypoint (continuity aside)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if not bool(solver.solve(T).success.all()):
                    continue
            row["feasible"] += 1
            met = {}
            for label in ("solve_path (q_start)", "chain (q_near)", "rtb"):
                if label in out:
                    ok, step = quality(robot, T, out[label], q0)
                    met[label] = ok and step <= STEP_GOAL
                    row["meets"][label] = row["meets"].get(label, 0) + met[label]
            if not any(met.values()):  # no solver's answer is a witness: the oracle's
                w = witness_path(robot, T, q0)
                certified = w is not None and quality(robot, T, w, q0)[1] <= STEP_GOAL and quality(robot, T, w)[0]
            else:
                certified = True
            row["certified"] = row.get("certified", 0) + certified
            row["certified_met"] = row.get("certified_met", 0) + (certified and met["solve_path (q_start)"])
        else:
            best = best_largest_step(robot, T)
            if best > STEP_GOAL:
                continue
            row["feasible"] += 1
            for label in ("solve_path", "chain"):
                ok, step = quality(robot, T, out[label])
                row["meets"][label] = row["meets"].get(label, 0) + (ok and step <= best + SLACK_GOAL)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=40, help="lines and as many circles per arm (default 40)")
    parser.add_argument("--arms", default=",".join(ARMS), help="comma-separated arms")
    parser.add_argument("--out", default=None, help="also write the table to OUT.md, with the command that made it")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    lines = []

    def say(line: str) -> None:
        print(line, flush=True)
        lines.append(line)

    say(
        "| arm | paths | feasible | goal met: solve_path | hand-made chain | rtb ik_LM | "
        "certified (a witness from q_start) | goal met on the certified: solve_path | "
        "us/waypoint: solve_path from q_start (no q_start) | chain | rtb | rtb / solve_path | chain / solve_path |"
    )
    say("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    cpp_rows = []
    for name in args.arms.split(","):
        kinds = bench_arm(name, args.paths)
        if kinds is None:
            say(f"| {name} | (not installed: pip install {EXTERNAL[name][0]}) |")
            continue
        cpp_rows.append((name, kinds))
        for kind, row in kinds.items():
            med = {k: statistics.median(v) * 1e6 for k, v in row["times"].items()}
            m, f = row["meets"], row["feasible"]
            sp, chain = med["solve_path (q_start)"], med["chain (q_near)"]
            rtb = med.get("rtb", float("nan"))
            free = f" ({med['solve_path']:.1f})"
            if "chain" in med:  # closed-form arms: the goal against the exhaustive check's best
                met = (m.get("solve_path", 0), m.get("chain", 0), "n/a")
            else:
                met = (m.get("solve_path (q_start)", 0), m.get("chain (q_near)", 0), m.get("rtb", "n/a"))
            met = [f"{v} / {f}" if isinstance(v, int) else v for v in met]
            cert = (
                (f"{row.get('certified', 0)} / {f}", f"{row.get('certified_met', 0)} / {row.get('certified', 0)}")
                if "chain" not in med
                else ("n/a (exhaustive)", "n/a")
            )
            say(
                f"| {name} {kind}s | {row['paths']} | {f} | {met[0]} | {met[1]} | {met[2]} | {cert[0]} | {cert[1]} | "
                f"{sp:.1f}{free} | "
                f"{chain:.1f} | {rtb:.1f} | {rtb / sp:.1f}x | {chain / sp:.1f}x |"
            )
    say("")
    say(
        "| arm | paths | valid (CppFlow: 0.1 mm / 0.1 deg, steps <= 7 deg) | largest step, deg: median (max) | "
        "total joint motion, deg: median | ms per path: median | closed loops: last vs first, deg: max | "
        "timed: samples over a limit at 1 ms | timed: duration / toppra's, max |"
    )
    say("|---|---|---|---|---|---|---|---|---|")
    for name, kinds in cpp_rows:
        for kind, row in kinds.items():
            c = row["cppflow"]
            valid = sum(r["valid"] for r in c)
            steps = [r["step"] for r in c]
            closure = [r["closure"] for r in c if r["valid"] and r["closure"] is not None]
            tm = row["timing"]
            over = f"{sum(t[0] for t in tm)} / {sum(t[1] for t in tm)}" if tm else "n/a"
            ratio = f"{max(t[2] for t in tm):.4f}" if tm else "n/a"
            say(
                f"| {name} {kind}s | {len(c)} | {valid} / {len(c)} | "
                f"{statistics.median(steps):.2f} ({max(steps):.1f}) | "
                f"{statistics.median(r['motion'] for r in c):.1f} | "
                f"{statistics.median(r['seconds'] for r in c) * 1e3:.2f} | "
                f"{f'{max(closure):.2g}' if closure else 'n/a'} | {over} | {ratio} |"
            )
    if args.out:
        command = "python benchmarks/paths.py " + " ".join(sys.argv[1:] if argv is None else argv)
        text = (
            f"`{command.strip()}` (one process, one thread; see the script's docstring)\n\n" + "\n".join(lines) + "\n"
        )
        path = Path(args.out).with_suffix(".md")
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)  # written whole, then renamed
    return 0


if __name__ == "__main__":
    sys.exit(main())
