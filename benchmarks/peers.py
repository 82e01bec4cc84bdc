"""nik against its peers on the same random targets: Robotics Toolbox ``ik_LM`` (C++, one target per
call, its own random restarts) and pytorch-kinematics ``PseudoInverseIK`` (batched, 10 random retries).

Targets are the FK poses of random configurations inside the limits (seeded), so every one is reachable.
Success: within 0.1 mm and 0.1 deg by nik's float64 FK of the returned joints, with no joint outside its
limits (the "outside" column counts joints beyond a limit by more than 1e-9 rad). Each peer is timed on the
same targets in interleaved rounds (nik, rtb, pk, nik, rtb, pk, ...); the table gives the median per target.
nik runs its default pipeline, ``IKSolver(robot).solve(T)`` (shipped network when one exists, else a
multi-start; then Levenberg-Marquardt with restarts for the leftovers).

Also measured: the 10 %-unreachable scenario (1,000 targets of which 100 at 3 x the reach bound: total
time against the 900 reachable ones alone) and the single-pose latency (one pose per call, median).

Robotics Toolbox models are built from the same URDF files nik ships (``rtb.Robot.URDF(path).ets(end=...)``)
and their FK is checked against nik's before timing. Install the peers with ``pip install -e .[bench]``.

    python benchmarks/peers.py                       # the full run (about 5 minutes on an idle machine)
    python benchmarks/peers.py --quick               # a smoke run (seconds)
    python benchmarks/peers.py --out benchmarks/results/peers   # also writes peers.md and peers.txt
"""

from __future__ import annotations

import argparse
import io
import math
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
from nik.robots.reach import reach_center, reach_radius  # noqa: E402
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT, describe  # noqa: E402

TOL_POS, TOL_ROT = DEFAULT_TOL_POS, DEFAULT_TOL_ROT  # m, rad: 0.1 mm / 0.1 deg, nik's one tolerance

#: ``ik_LM`` given nik's tolerance. It stops when ``E = 0.5 e^T W e < tol``, ``e`` the position error (m) and the
#: angle-axis rotation error (rad) stacked, ``W = diag(mask)`` (roboticstoolbox/core/ik.cpp, ``_IK_LM_Chan``). With
#: ``mask = (1, 1, 1, w, w, w)``, ``w = (TOL_POS / TOL_ROT)^2`` and ``tol = TOL_POS^2 / 2``, ``E < tol`` reads
#: ``|e_pos|^2 / TOL_POS^2 + |e_rot|^2 / TOL_ROT^2 < 1``: the ellipse inscribed in nik's box ``|e_pos| <= 0.1 mm``,
#: ``|e_rot| <= 0.1 deg`` (as strict on each axis alone, at most sqrt(2) stricter where both errors are large). The
#: former ``tol=1e-10`` with no mask asked ``|e| < 1.4e-5`` of both: 7x tighter in position, 120x in rotation.
RTB_TOL = 0.5 * TOL_POS**2
RTB_MASK = np.array([1.0, 1.0, 1.0, *[(TOL_POS / TOL_ROT) ** 2] * 3])
URDF = {name: ROOT / f"configs/robots/urdf/{name}.urdf" for name in ("panda", "ur5", "xarm7")}


#: Targets come from their own random stream: were it the solvers' (nik's seed 0), a multistart would
#: draw the very configurations the targets were made from.
TARGET_SEED_BASE = 1_000_003


def target_joints(robot, n: int, seed: int) -> torch.Tensor:
    return robot.sample(n, generator=torch.Generator().manual_seed(TARGET_SEED_BASE + seed), dtype=torch.float64)


def targets(robot, n: int, seed: int) -> torch.Tensor:
    return robot.fk(target_joints(robot, n, seed))


def score(robot, T, q) -> tuple[float, int]:
    """(success %, joints outside the limits) of answers ``q: (B, dof)`` for ``T: (B, 4, 4)``."""
    q = torch.as_tensor(np.asarray(q), dtype=torch.float64)
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    outside = (q < lo - 1e-9) | (q > hi + 1e-9)
    pos, rot = nik.pose_error(T, robot.fk(q))
    ok = (pos <= TOL_POS) & (rot <= TOL_ROT) & ~outside.any(-1)
    return float(ok.double().mean()) * 100, int(outside.sum())


# ---------------------------------------------------------------------------
# The solvers: each (robot, T) -> (q (B, dof), seconds)
# ---------------------------------------------------------------------------
def run_nik(robot, T, *, solver=None):
    solver = solver or nik.IKSolver(robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the unreachable scenario warns, by design
        t = time.perf_counter()
        res = solver.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=0)
        dt = time.perf_counter() - t
    return res.q, dt, res.source  # the guess that served: the row's label


def available(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def run_nik_from_guess(robot, T, q_guess):
    """nik's LM (with its restarts) from given guesses: what the pipeline does after a network."""
    from nik.ik import lm_refine

    t = time.perf_counter()
    res = lm_refine(robot, T, q_guess, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=0)
    return res.q, time.perf_counter() - t


def rtb_model(robot):
    if not available("roboticstoolbox"):
        return None, float("nan")
    import roboticstoolbox as rtb

    with redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # Robot.URDF: still the documented way in 1.x
        ets = rtb.Robot.URDF(str(URDF[robot.name].resolve())).ets(end=robot.flange_link or robot.end_link)
    q = robot.sample(32, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    gap = max(float(np.abs(ets.eval(qi) - Ti).max()) for qi, Ti in zip(q.numpy(), robot.fk(q).numpy(), strict=True))
    if gap > 1e-6:
        raise RuntimeError(f"rtb model of {robot.name} disagrees with nik's FK by {gap:.2e} m")
    return ets, gap


def run_rtb(ets, T):
    Tn = T.numpy()
    np.random.seed(0)  # ik_LM draws its restarts from numpy's global generator
    q = np.zeros((Tn.shape[0], ets.n))
    t = time.perf_counter()
    for i in range(Tn.shape[0]):
        q[i] = ets.ik_LM(Tn[i], tol=RTB_TOL, mask=RTB_MASK, joint_limits=True).q  # nik's tolerance: RTB_TOL
    return torch.from_numpy(q), time.perf_counter() - t


def pk_solver(robot):
    import pytorch_kinematics as pk

    from nik.evaluate import robot_to_urdf
    from nik.robots.urdf import build_pk_chain

    text, end = robot_to_urdf(robot)
    chain = build_pk_chain(text, end).to(dtype=torch.float64)
    return pk, chain


def run_pk(robot, pkc, T, *, retries: int = 10, max_iterations: int = 50):
    pk, chain = pkc
    torch.manual_seed(0)  # pk draws its retries from the global generator
    ik = pk.PseudoInverseIK(
        chain,
        pos_tolerance=TOL_POS,
        rot_tolerance=TOL_ROT,
        num_retries=retries,
        max_iterations=max_iterations,
        joint_limits=robot.limits,
        early_stopping_any_converged=True,
    )
    t = time.perf_counter()
    sol = ik.solve(pk.Transform3d(matrix=T))
    dt = time.perf_counter() - t
    err = sol.err_pos + sol.err_rot + (~sol.converged) * 1e6
    best = err.argmin(dim=1)
    return sol.solutions[torch.arange(T.shape[0]), best], dt


# ---------------------------------------------------------------------------
# Scenarios
# ---------------------------------------------------------------------------
def compare(
    robot_name: str, n: int, threads: int, rounds: int, *, with_pk: bool, seed: int, proxy: float
) -> list[dict]:
    robot = nik.load_robot(robot_name)
    T = targets(robot, n, seed)
    q_true = target_joints(robot, n, seed)
    noise = torch.randn(q_true.shape, generator=torch.Generator().manual_seed(seed + 1), dtype=torch.float64)
    q_proxy = robot.clamp(q_true + proxy * noise)  # a network-quality guess (stand-in until one ships)
    ets, gap = rtb_model(robot)
    pkc = pk_solver(robot) if with_pk and available("pytorch_kinematics") else None
    solver = nik.IKSolver(robot)
    torch.set_num_threads(threads)
    nik.set_threads(threads)
    proxy_name = f"nik LM from truth + N(0, {proxy:g} rad) (network stand-in)"
    runs = {"nik": [], proxy_name: [], "rtb ik_LM": [], "pk PseudoInverseIK": []}
    last = {}
    for _ in range(rounds):
        last["nik"] = run_nik(robot, T, solver=solver)
        runs["nik"].append(last["nik"][1])
        if proxy > 0:
            last[proxy_name] = run_nik_from_guess(robot, T, q_proxy)
            runs[proxy_name].append(last[proxy_name][1])
        if ets is not None:
            last["rtb ik_LM"] = run_rtb(ets, T)
            runs["rtb ik_LM"].append(last["rtb ik_LM"][1])
        if pkc is not None:
            last["pk PseudoInverseIK"] = run_pk(robot, pkc, T)
            runs["pk PseudoInverseIK"].append(last["pk PseudoInverseIK"][1])
    nik.set_threads(None)
    rows = []
    ref = statistics.median(runs["rtb ik_LM"]) if runs["rtb ik_LM"] else float("nan")
    for name, times in runs.items():
        if not times:
            continue
        succ, outside = score(robot, T, last[name][0])
        med = statistics.median(times)
        rows.append(
            {
                "robot": robot_name,
                "n": n,
                "threads": threads,
                "solver": name + (f" (guess: {last['nik'][2]})" if name == "nik" else ""),
                "ms": med / n * 1e3,
                "success": succ,
                "outside": outside,
                "vs_rtb": ref / med,
            }
        )
    if ets is not None:
        print(f"  ({robot_name}: rtb FK agrees with nik within {gap:.1e} m)", flush=True)
    return rows


def times_rtb(x: float) -> str:
    """A speed ratio against Robotics Toolbox as printed: ``2.50x``, or ``n/a`` without an rtb row."""
    return "n/a" if math.isnan(x) else f"{x:.2f}x"


def ms_or_na(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{x:.3f}"


def unreachable_scenario(robot_name: str, rounds: int, seed: int) -> dict:
    """1,000 targets of which 100 at 3 x the reach bound; nik's time against the 900 reachable ones alone."""
    robot = nik.load_robot(robot_name)
    T = targets(robot, 1000, seed)
    c = reach_center(robot)
    far = T[:100].clone()
    u = far[:, :3, 3] - c
    far[:, :3, 3] = c + 3.0 * reach_radius(robot) * u / torch.linalg.vector_norm(u, dim=-1, keepdim=True)
    mixed = torch.cat([T[100:], far])
    solver = nik.IKSolver(robot)
    t_reach, t_mixed = [], []
    for _ in range(rounds):
        t_reach.append(run_nik(robot, T[100:], solver=solver)[1])
        q, dt, _ = run_nik(robot, mixed, solver=solver)
        t_mixed.append(dt)
    succ, _ = score(robot, mixed[:900], q[:900])
    a, b = statistics.median(t_reach), statistics.median(t_mixed)
    return {"robot": robot_name, "reachable_s": a, "mixed_s": b, "ratio": b / a, "success_900": succ}


# ---------------------------------------------------------------------------
# One pose per call: nik, Robotics Toolbox ik_LM, TRAC-IK
# ---------------------------------------------------------------------------
#: A 7-DOF arm from example-robot-data (``pip install example-robot-data``); the same definition as the built-in xarm7.
EXAMPLE_ROBOTS = {"xarm7": "xarm_description/urdf/xarm7.urdf"}
TRACIK_TIMEOUT = 0.005  # s, TRAC-IK's usual default
TRACIK_EPS = 1e-5  # its convergence threshold on the Cartesian error
LATENCY_BLOCK = 1  # poses a solver solves in a row before the next solver takes the same poses (1: pose by pose)


def example_robot_file(name: str) -> Path | None:
    """The URDF of ``name`` in the installed example-robot-data (its files live under ``cmeel.prefix``), or None."""
    for entry in sys.path:
        path = Path(entry) / "cmeel.prefix" / "share" / "example-robot-data" / "robots" / EXAMPLE_ROBOTS[name]
        if path.is_file():
            return path
    return None


def latency_robot(name: str):
    """``(robot, urdf_path, tool_link)``: nik's model and a URDF file with the same FK (the shipped or
    example-robot-data file, else one written from nik's normal form), or Nones when the arm is not available."""
    path = example_robot_file(name) if name in EXAMPLE_ROBOTS else URDF.get(name)
    if name in EXAMPLE_ROBOTS and path is None:
        return None, None, None
    robot = nik.load_robot(path if name in EXAMPLE_ROBOTS else name)
    end = robot.flange_link or robot.end_link  # the link a pose means (a built-in's flange, tool0)
    if path is not None:
        path = kinematics_only(Path(path))
    else:  # an arm defined by a table: a URDF written from nik's normal form
        import tempfile

        from nik.evaluate import robot_to_urdf

        text, end = robot_to_urdf(robot)
        path = Path(tempfile.mkdtemp()) / f"{name}.urdf"
        path.write_text(text)
    return robot, Path(path), end


def kinematics_only(path: Path) -> Path:
    """A copy of the URDF without visual, collision and inertial elements and without the joints' safety
    controllers: none is needed for kinematics; Robotics Toolbox's xacro step would look for the mesh packages,
    KDL (under TRAC-IK) mishandles a root link with an inertia, and pytracik reads a joint with a safety
    controller as limits [0, 0] (it then solved none of the panda poses)."""
    import tempfile
    import xml.etree.ElementTree as ET

    tree = ET.parse(path)
    for link in tree.getroot().findall("link"):
        for tag in ("visual", "collision", "inertial"):
            for element in link.findall(tag):
                link.remove(element)
    for joint in tree.getroot().findall("joint"):
        for element in joint.findall("safety_controller"):
            joint.remove(element)
    out = Path(tempfile.mkdtemp()) / path.name
    tree.write(out)
    return out


def urdf_root(path: Path) -> str:
    """The root link of a URDF: the link that is no joint's child."""
    import xml.etree.ElementTree as ET

    tree = ET.parse(path).getroot()
    children = {e.find("child").get("link") for e in tree.findall("joint")}
    return next(e.get("name") for e in tree.findall("link") if e.get("name") not in children)


def tracik_solver(robot, path: Path, end: str):
    """A TRAC-IK solver of the same chain, or None when pytracik is not installed."""
    if not available("pytracik"):
        return None
    import pytracik

    root = urdf_root(path)
    text = path.read_text()
    with redirect_stdout(io.StringIO()):
        solver = pytracik.TRAC_IK(root, end, text, TRACIK_TIMEOUT, TRACIK_EPS, pytracik.SolveType.Speed)
    q = robot.sample(16, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    gap = max(
        float(np.abs(pytracik.fk(solver, qi) - Ti).max()) for qi, Ti in zip(q.numpy(), robot.fk(q).numpy(), strict=True)
    )
    if gap > 1e-6:
        raise RuntimeError(f"TRAC-IK model of {robot.name} disagrees with nik's FK by {gap:.2e} m")
    return solver


def rtb_from_file(robot, path: Path, end: str):
    if not available("roboticstoolbox"):
        return None
    import roboticstoolbox as rtb

    with redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ets = rtb.Robot.URDF(str(path.resolve())).ets(end=end)
    q = robot.sample(16, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    gap = max(float(np.abs(ets.eval(qi) - Ti).max()) for qi, Ti in zip(q.numpy(), robot.fk(q).numpy(), strict=True))
    if gap > 1e-6:
        raise RuntimeError(f"rtb model of {robot.name} disagrees with nik's FK by {gap:.2e} m")
    return ets


def latency_table(names: list[str], n: int, seed: int, block: int = LATENCY_BLOCK) -> tuple[list[str], list[str]]:
    """One pose per call, ``n`` reachable poses per arm, the solvers interleaved by blocks of ``block`` poses (1: pose
    by pose, each call after the other libraries' calls, as in a control loop that does other work between calls);
    then nik alone in a tight loop over the same poses. Per solver: median / p95 / p99 / max microseconds per call,
    calls over 2 ms, success, joints outside the limits; nik's rows name the guess its results report
    (``res.source``). Returns the table's lines and notes (peers left out, and why)."""
    from scipy.spatial.transform import Rotation

    torch.set_num_threads(1)
    nik.set_threads(1)
    lines = [
        "| robot | solver | median us | p95 us | p99 us | max us | calls > 2 ms | success % | joints outside limits | "
        "ik_LM median / this median |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    if not available("pytracik"):
        notes.append("TRAC-IK left out: pytracik is not installed (pip install -e .[bench])")
    for name in names:  # (a missing Robotics Toolbox is said once, at the top of the run)
        robot, path, end = latency_robot(name)
        if robot is None:
            notes.append(f"{name} left out: example-robot-data is not installed (pip install example-robot-data)")
            continue
        T = targets(robot, n, seed)
        Tn = T.numpy()
        quats = Rotation.from_matrix(Tn[:, :3, :3]).as_quat()  # x, y, z, w for TRAC-IK (outside the timing)
        solver = nik.IKSolver(robot)
        ets = rtb_from_file(robot, path, end)
        tracik = tracik_solver(robot, path, end)
        mid = ((robot.limits[:, 0] + robot.limits[:, 1]) / 2).numpy()
        calls = {"nik": []}
        sources = set()
        if ets is not None:
            calls["rtb ik_LM"] = []
        if tracik is not None:
            calls["TRAC-IK (pytracik)"] = []
        answers = {k: [] for k in calls}
        solver.solve(T[:64], tol_pos=TOL_POS, tol_rot=TOL_ROT)  # warm-up: loads every compiled kernel it uses
        solver.solve(T[0], tol_pos=TOL_POS, tol_rot=TOL_ROT)
        for start in range(0, n, block):
            for label in calls:
                for i in range(start, min(start + block, n)):
                    if label == "nik":
                        t = time.perf_counter_ns()
                        res = solver.solve(T[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)
                        dt = time.perf_counter_ns() - t
                        q = res.q[0]
                        sources.add(res.source)
                    elif label.startswith("rtb"):
                        np.random.seed(i)
                        t = time.perf_counter_ns()
                        q = ets.ik_LM(Tn[i], tol=RTB_TOL, mask=RTB_MASK, joint_limits=True).q
                        dt = time.perf_counter_ns() - t
                    else:
                        import pytracik

                        x, y, z = Tn[i, :3, 3]
                        qx, qy, qz, qw = quats[i]
                        t = time.perf_counter_ns()
                        r = pytracik.ik(tracik, mid, x, y, z, qx, qy, qz, qw)
                        dt = time.perf_counter_ns() - t
                        q = r[1:] if r[0] >= 0 else mid  # no solution: counts as a failure
                    calls[label].append(dt / 1e3)
                    answers[label].append(torch.as_tensor(np.asarray(q, dtype=np.float64)))
        tight, tight_answers = [], []
        for i in range(n):  # nik alone, call after call (warm caches)
            t = time.perf_counter_ns()
            res = solver.solve(T[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)
            tight.append((time.perf_counter_ns() - t) / 1e3)
            tight_answers.append(res.q[0])
        label_of = {"nik": f"nik (guess: {'/'.join(sorted(sources))}), interleaved"}
        calls["nik, tight loop"] = tight
        answers["nik, tight loop"] = tight_answers
        rtb_median = float(np.median(calls["rtb ik_LM"])) if "rtb ik_LM" in calls else math.nan
        for label, times in calls.items():
            ts = np.asarray(times)
            succ, outside = score(robot, T, torch.stack(answers[label]))
            lines.append(
                f"| {name} | {label_of.get(label, label)} | {np.median(ts):.0f} | {np.percentile(ts, 95):.0f} | "
                f"{np.percentile(ts, 99):.0f} | {ts.max():.0f} | {int((ts > 2000).sum())} | {succ:.1f} | {outside} | "
                f"{times_rtb(rtb_median / np.median(ts))} |"
            )
        print(f"  ({name}: latency rows done)", flush=True)
    nik.set_threads(None)
    return lines, notes


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--robots", default="panda,ur5", help="comma-separated (panda, ur5, xarm7: the arms with shipped URDFs)"
    )
    p.add_argument("--sizes", default="1000,10000", help="comma-separated numbers of targets")
    p.add_argument("--threads", default="1,2", help="comma-separated torch thread counts")
    p.add_argument("--rounds", type=int, default=2, help="interleaved rounds per row (median)")
    p.add_argument("--pk-max-n", type=int, default=10000, help="leave pytorch-kinematics out above this size")
    p.add_argument("--latency-n", type=int, default=300, help="poses per arm of the one-pose latency table")
    p.add_argument("--latency-robots", default="panda,ur5,kuka_kr,xarm7", help="arms of the one-pose latency table")
    p.add_argument("--latency-only", action="store_true", help="only the one-pose latency table")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--proxy-noise",
        type=float,
        default=0.1,
        help="also time nik's LM from the true joints plus this much noise (rad), a stand-in for a network "
        "guess (0: leave the row out)",
    )
    p.add_argument("--quick", action="store_true", help="smoke run: 200 targets, 1 thread, 1 round")
    p.add_argument("--out", default=None, help="write OUT.md (tables) and OUT.txt (raw output)")
    args = p.parse_args(argv)
    if args.quick:
        args.sizes, args.threads, args.rounds, args.latency_n = "200", "1", 1, 20
        args.latency_robots = "panda,ur5"
    robots = [r.strip() for r in args.robots.split(",") if r.strip()]
    sizes = [int(s) for s in args.sizes.split(",")]
    thread_list = [int(s) for s in args.threads.split(",")]
    log = io.StringIO()

    def say(line: str = "") -> None:
        print(line, flush=True)
        log.write(line + "\n")

    say(f"nik {nik.__version__}, torch {torch.__version__}, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}")
    say(f"success: within {describe(TOL_POS, TOL_ROT)} by float64 FK, inside the limits")
    if not available("roboticstoolbox"):
        say("(roboticstoolbox-python is not installed: pip install -e .[bench]; its rows and ratios are n/a)")
    rows = []
    if args.latency_only:
        thread_list = []
    for th in thread_list:
        for n in sizes:
            for rb in robots:
                rows += compare(
                    rb, n, th, args.rounds, with_pk=n <= args.pk_max_n, seed=args.seed, proxy=args.proxy_noise
                )
    torch.set_num_threads(1)
    md = [
        "| robot | targets | threads | solver | ms / target | success % | joints outside limits | speed vs rtb |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        md.append(
            f"| {r['robot']} | {r['n']:,} | {r['threads']} | {r['solver']} | {r['ms']:.4f} | {r['success']:.2f} | "
            f"{r['outside']} | {times_rtb(r['vs_rtb'])} |"
        )
    unreach = (
        []
        if args.latency_only
        else [unreachable_scenario(rb, max(args.rounds, 2), args.seed) for rb in ["kuka_kr", "panda"]]
    )
    md += [
        "",
        "10 % unreachable (1,000 targets, 100 at 3 x the reach; nik, one thread):",
        "",
        "| robot | 900 reachable alone (s) | 1,000 with 100 unreachable (s) | ratio | success on the 900 % |",
        "|---|---|---|---|---|",
    ]
    for u in unreach:
        md.append(
            f"| {u['robot']} | {u['reachable_s']:.3f} | {u['mixed_s']:.3f} | {u['ratio']:.2f} "
            f"| {u['success_900']:.2f} |"
        )
    lat, notes = latency_table(
        [r.strip() for r in args.latency_robots.split(",") if r.strip()], args.latency_n, args.seed
    )
    md += [
        "",
        f"One pose per call ({args.latency_n} reachable poses per arm, the solvers interleaved pose by pose "
        "(each call after the other libraries' calls, caches cold as in a control loop), then nik alone in a tight "
        "loop over the same poses; one "
        f"thread; TRAC-IK: Speed, timeout {TRACIK_TIMEOUT * 1e3:g} ms, eps {TRACIK_EPS:g}, seeded at the middle of "
        "the limits; rtb: ik_LM with nik's tolerance (RTB_TOL, RTB_MASK), joint limits on):",
        "",
        *lat,
        *(["", *(f"- {note}" for note in notes)] if notes else []),
    ]
    say()
    for line in md:
        say(line)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        cmd = "python benchmarks/peers.py " + " ".join(argv if argv is not None else sys.argv[1:])
        text = f"# nik vs Robotics Toolbox vs pytorch-kinematics\n\nCommand: `{cmd.strip()}`\n\n" + "\n".join(md) + "\n"
        for path, body in ((out.with_suffix(".md"), text), (out.with_suffix(".txt"), log.getvalue())):
            tmp = path.with_suffix(path.suffix + ".tmp")
            tmp.write_text(body)
            tmp.replace(path)
        print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.txt')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
