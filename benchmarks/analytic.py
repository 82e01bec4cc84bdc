"""Closed-form IK: paper B's quaternion vs matrix wrist (``puma560_ik``), and ``nik.analytic.solve`` against its peers.

**Wrist variants** (default).
Paper B claims its quaternion wrist step is about 15 % faster than the pure D-H (matrix)
solution; the goal here is at least 2 million poses per second with all 8 solutions on
2 CPU cores. Both wrist variants run in the same process on the same poses, interleaved,
and the median of ``--repeats`` runs is reported. A reference elementwise multiply of the same
size is timed too: on a shared (busy) machine it shows how far from idle the numbers are.

    python benchmarks/analytic.py [--n 200000] [--threads 2] [--repeats 7] [--no-compile]

**Peers** (``--peers``, issue 18): ``nik.analytic.solve`` against IK-Geo (``ik-geo``, Rust, one pose per call)
and EAIK (``eaik``, C++, its batched call), all given the same arm: the joint axes and points of nik's normal
form at the zero configuration (the wrist axes' points moved to the wrist centre, or axes 5 and 6's to where
they meet, which IK-Geo needs), the tool orientation at zero folded into the target. Arms: ur5, a UR10 and a UR3
from example-robot-data (skipped with a note where it is not installed), kuka_kr, puma560, rebot_v_6r.

- Solution counts and residuals on ``--poses`` (1,000) FK poses of random configurations (seeded). The peers
  know no joint limits, so nik solves a copy of each arm with limits [-pi, pi] here; a peer's solutions are
  those it does not flag least-squares, counted once modulo 2 pi (1e-6 rad). Residuals are nik's float64 FK
  of the returned joints against the pose (metres, radians).
- Throughput on a batch of ``--batch`` (10,000) poses, one thread, interleaved rounds (nik with the FK check,
  nik without it, EAIK's ``IK_batched``), medians; IK-Geo one pose per call (its binding has no batch call),
  median of 3 passes over 200 poses, for information.

    python benchmarks/analytic.py --peers [--poses 1000] [--batch 10000] [--threads 1] [--repeats 7] [--compile]

Goals (issue 18): the same number of solutions as IK-Geo on >= 99.9 % of the poses of every arm; every nik
solution within 1e-9 m; throughput with the FK check >= 1x EAIK's batched call, without it >= 2x.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import statistics
import time
from pathlib import Path

import numpy as np
import torch

import nik
from nik.analytic import puma560_ik, solve
from nik.analytic.geometry import arm_geometry
from nik.kinematics import chain_joint_frames


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="puma560")
    ap.add_argument("--n", type=int, default=200_000, help="poses per batch")
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads (default 2; --peers: 1)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-compile", action="store_true", help="skip the torch.compile rows")
    ap.add_argument("--peers", action="store_true", help="nik.analytic.solve against IK-Geo and EAIK (issue 18)")
    ap.add_argument("--poses", type=int, default=1000, help="--peers: poses for solution counts and residuals")
    ap.add_argument("--batch", type=int, default=10_000, help="--peers: poses per throughput batch")
    ap.add_argument("--compile", action="store_true", help="--peers: add torch.compile'd nik rows")
    args = ap.parse_args(argv)
    if args.peers:
        torch.set_num_threads(args.threads or 1)
        peers_benchmark(args)
        return
    torch.set_num_threads(args.threads or 2)
    robot = nik.load_robot(args.robot)
    gen = torch.Generator().manual_seed(0)
    print(f"robot {robot.name}, {args.n} poses per batch, {torch.get_num_threads()} threads, torch {torch.__version__}")

    ref = torch.rand(args.n * 8, dtype=torch.float64)
    t_ref = _median_time(lambda: ref * ref, args.repeats)
    print(
        f"reference: one multiply of {args.n * 8} float64 takes {t_ref * 1e3:.2f} ms "
        f"({args.n * 8 * 16 / t_ref / 1e9:.1f} GB/s; an idle modern core does ~10 GB/s)\n"
    )

    rows = []
    compiled_modes = [False] if args.no_compile else [False, True]
    for dtype in (torch.float64, torch.float32):
        T = robot.fk(robot.sample(args.n, generator=gen, dtype=dtype))
        for compiled in compiled_modes:
            for check in (False, True):
                fns = {
                    w: (
                        lambda w=w, T=T, check=check, compiled=compiled: puma560_ik(
                            robot, T, wrist=w, check=check, compiled=compiled
                        )
                    )
                    for w in ("quaternion", "matrix")
                }
                for fn in fns.values():  # warm-up (and compilation)
                    fn()
                times = {w: [] for w in fns}
                for _ in range(args.repeats):  # interleaved, so both see the same machine load
                    for w, fn in fns.items():
                        t0 = time.perf_counter()
                        fn()
                        times[w].append(time.perf_counter() - t0)
                med = {w: statistics.median(v) for w, v in times.items()}
                rows.append((str(dtype).replace("torch.", ""), compiled, check, med["quaternion"], med["matrix"]))

    # single-query latency (Python overhead dominates)
    T1 = robot.fk(robot.sample(1, generator=gen, dtype=torch.float64))
    lat = {
        w: _median_time(lambda w=w: puma560_ik(robot, T1, wrist=w, check=False), 200) for w in ("quaternion", "matrix")
    }

    print(
        "| dtype | compiled | FK check | quaternion wrist (M poses/s) | matrix wrist (M poses/s) "
        "| quaternion speed-up |"
    )
    print("|---|---|---|---|---|---|")
    for dt, comp, check, tq, tm in rows:
        print(
            f"| {dt} | {comp} | {check} | {args.n / tq / 1e6:.3f} | {args.n / tm / 1e6:.3f} "
            f"| {100 * (tm / tq - 1):+.1f} % |"
        )
    print(
        f"\nsingle pose (B = 1, eager, no FK check): quaternion {lat['quaternion'] * 1e6:.0f} us, "
        f"matrix {lat['matrix'] * 1e6:.0f} us"
    )
    best = max(args.n / min(tq, tm) for _, _, check, tq, tm in rows if not check)
    print(f"best throughput with all 8 solutions: {best / 1e6:.2f} M poses/s (goal: 2 M poses/s on 2 cores)")


# ---------------------------------------------------------------------------
# --peers: nik.analytic.solve against IK-Geo and EAIK
# ---------------------------------------------------------------------------
ERD_ARMS = {"ur10": "ur_description/urdf/ur10_robot.urdf", "ur3": "ur_description/urdf/ur3_robot.urdf"}


def _erd_path(rel: str) -> Path | None:
    """A file of the example-robot-data package, or None when it is not installed."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        if str(f).endswith(rel):
            return Path(dist.locate_file(f))
    return None


def peer_model(robot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``H: (6, 3)`` joint axes, ``P: (7, 3)`` offsets between their points and ``M: (4, 4)`` the tool at zero.

    Product-of-exponentials form of nik's normal form at ``q = 0`` (base frame): the tool pose is
    ``exp(h_1 q_1) ... exp(h_6 q_6) M``, which the peers take with ``R_T M_R^T`` as the target rotation. The
    points of the wrist axes sit at the wrist centre (spherical) or axes 5 and 6's at their meeting point.
    """
    q0 = torch.zeros(1, 6, dtype=torch.float64)
    _, ax, pt = chain_joint_frames(q0, robot.G, robot.offsets)
    H = ax[0].T.numpy().copy()
    pts = pt[0].T.numpy().copy()
    g = arm_geometry(robot)
    if g.family == "spherical_wrist":
        pts[3] = pts[4] = pts[5] = g.point
    elif g.family == "three_parallel":
        pts[4] = pts[5] = g.point
    M = robot.fk(q0)[0].numpy()
    P = np.zeros((7, 3))
    P[0] = pts[0]
    P[1:6] = pts[1:] - pts[:-1]
    P[6] = M[:3, 3] - pts[5]
    return H, P, M


def _distinct(Q: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Rows of ``Q: (K, 6)`` counted once modulo 2 pi."""
    keep: list[np.ndarray] = []
    for row in Q:
        if all(np.abs(np.remainder(row - k + np.pi, 2 * np.pi) - np.pi).max() > tol for k in keep):
            keep.append(row)
    return np.array(keep).reshape(-1, 6)


def _residual(robot, T: torch.Tensor, Q: np.ndarray) -> tuple[float, float]:
    if len(Q) == 0:
        return 0.0, 0.0
    pe, re = nik.pose_error(T, robot.fk(torch.as_tensor(Q, dtype=torch.float64)))
    return float(pe.max()), float(re.max())


def _free_limits(robot):
    """The same arm with every joint in [-pi, pi] (the peers know no limits)."""
    lim = torch.tensor([[-math.pi, math.pi]] * 6, dtype=torch.float64)
    return nik.Robot(robot.name + "_free", robot.G, robot.offsets, lim, robot.joint_names)


def _arms() -> tuple[list, list[str]]:
    arms, notes = [], []
    for name in ("ur5", "ur10", "ur3", "kuka_kr", "puma560", "rebot_v_6r"):
        if name in ERD_ARMS:
            path = _erd_path(ERD_ARMS[name])
            if path is None:
                notes.append(f"{name}: skipped, example-robot-data is not installed (pip install example-robot-data)")
                continue
            arms.append((f"{name} (example-robot-data {Path(ERD_ARMS[name]).name})", nik.load_robot(path)))
        else:
            arms.append((name, nik.load_robot(name)))
    return arms, notes


def peers_benchmark(args) -> None:
    try:
        import ik_geo
    except ImportError:
        ik_geo = None
    try:
        from eaik.IK_HP import HPRobot
    except ImportError:
        HPRobot = None
    print(
        f"nik.analytic.solve vs IK-Geo (ik-geo) and EAIK (eaik); {args.poses} poses per arm for counts, "
        f"batch {args.batch} for throughput, {torch.get_num_threads()} thread(s), torch {torch.__version__}"
    )
    for mod, name in ((ik_geo, "ik-geo"), (HPRobot, "eaik")):
        if mod is None:
            print(f"note: {name} is not installed (pip install -e .[bench]); its columns are empty")
    arms, notes = _arms()
    for n in notes:
        print("note:", n)
    ref = torch.rand(args.batch * 8, dtype=torch.float64)
    t_ref = _median_time(lambda: ref * ref, args.repeats)
    print(f"reference: one multiply of {args.batch * 8} float64 takes {t_ref * 1e3:.3f} ms (machine load indicator)\n")

    count_rows, speed_rows, residual_rows = [], [], []
    for label, robot in arms:
        fam = nik.analytic.family(robot)
        H, P, M = peer_model(robot)
        ig = None
        if ik_geo is not None:
            make = (
                ik_geo.Robot.spherical_two_parallel
                if fam == "spherical_wrist"
                else ik_geo.Robot.three_parallel_two_intersecting
            )
            ig = make(H.tolist(), P.tolist())
        ea = HPRobot(H, P) if HPRobot is not None else None
        free = _free_limits(robot)
        gen = torch.Generator().manual_seed(0)
        T = robot.fk(robot.sample(args.poses, generator=gen, dtype=torch.float64))
        Tn = T.numpy()
        Tp = Tn.copy()
        Tp[:, :3, :3] = Tn[:, :3, :3] @ M[:3, :3].T
        # --- counts and residuals
        sols, valid = solve(free, T)
        n_nik = np.array([len(_distinct(sols[i][valid[i]].numpy())) for i in range(len(T))])
        res_nik = _residual(robot, T[:, None].expand(-1, 8, 4, 4)[valid], sols[valid].numpy())
        n_ig = np.full(len(T), -1)
        res_ig = (math.nan, math.nan)
        t_ig = math.nan
        if ig is not None:
            worst = [0.0, 0.0]
            raw = [ig.get_ik(Tp[i, :3, :3].T.copy(), Tp[i, :3, 3]) for i in range(len(T))]  # its binding takes R^T
            m = min(200, len(T))
            one_by_one = [(Tp[i, :3, :3].T.copy(), Tp[i, :3, 3].copy()) for i in range(m)]
            t_ig = _median_time(lambda g=ig, x=one_by_one: [g.get_ik(R, t) for R, t in x], 3) / m
            for i, out in enumerate(raw):
                Q = _distinct(np.array([q for q, ls in out if not ls]).reshape(-1, 6))
                n_ig[i] = len(Q)
                pe, re = _residual(robot, T[i], Q)
                worst = [max(worst[0], pe), max(worst[1], re)]
            res_ig = tuple(worst)
        n_ea = np.full(len(T), -1)
        res_ea = (math.nan, math.nan)
        if ea is not None:
            worst = [0.0, 0.0]
            for i, out in enumerate(ea.IK_batched(Tp, num_worker_threads=1)):
                Qa = np.array(out.Q).reshape(-1, 6)
                Q = _distinct(Qa[~np.array(out.is_LS, dtype=bool).reshape(-1)])
                n_ea[i] = len(Q)
                pe, re = _residual(robot, T[i], Q)
                worst = [max(worst[0], pe), max(worst[1], re)]
            res_ea = tuple(worst)
        count_rows.append(
            (
                label,
                fam,
                ea.getKinematicFamily() if ea is not None else "-",
                n_nik.mean(),
                n_ig.mean() if ig is not None else math.nan,
                n_ea.mean() if ea is not None else math.nan,
                100 * float((n_nik == n_ig).mean()) if ig is not None else math.nan,
                100 * float((n_nik == n_ea).mean()) if ea is not None else math.nan,
            )
        )
        residual_rows.append((label, res_nik, res_ig, res_ea))
        # --- throughput, interleaved
        Tb = robot.fk(robot.sample(args.batch, generator=gen, dtype=torch.float64))
        Tbp = Tb.numpy().copy()
        Tbp[:, :3, :3] = Tbp[:, :3, :3] @ M[:3, :3].T
        fns = {
            "nik, FK check": lambda r=robot, t=Tb: solve(r, t),
            "nik, no check": lambda r=robot, t=Tb: solve(r, t, check=False),
        }
        if args.compile:
            fns["nik compiled, FK check"] = lambda r=robot, t=Tb: solve(r, t, compiled=True)
            fns["nik compiled, no check"] = lambda r=robot, t=Tb: solve(r, t, check=False, compiled=True)
        if ea is not None:
            fns["EAIK IK_batched"] = lambda e=ea, t=Tbp: e.IK_batched(t, num_worker_threads=1)
        for fn in fns.values():  # warm-up (and compilation)
            fn()
        times = {k: [] for k in fns}
        for _ in range(args.repeats):
            for k, fn in fns.items():
                t0 = time.perf_counter()
                fn()
                times[k].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) / args.batch for k, v in times.items()}
        speed_rows.append((label, med, t_ig))

    print("## Solution counts (distinct, modulo 2 pi; nik with limits [-pi, pi]); same count as a peer: % of poses\n")
    print("| arm | nik family | EAIK family | nik | IK-Geo | EAIK | = IK-Geo | = EAIK |")
    print("|---|---|---|---|---|---|---|---|")
    for label, fam, efam, a, b, c, d, e in count_rows:
        print(f"| {label} | {fam} | {efam} | {a:.3f} | {b:.3f} | {c:.3f} | {d:.2f} % | {e:.2f} % |")
    print("\n## Largest residual of any returned solution (nik: the valid ones), position m / rotation rad\n")
    print("| arm | nik | IK-Geo | EAIK |")
    print("|---|---|---|---|")
    for label, a, b, c in residual_rows:
        print(f"| {label} | {a[0]:.1e} / {a[1]:.1e} | {b[0]:.1e} / {b[1]:.1e} | {c[0]:.1e} / {c[1]:.1e} |")
    keys = list(speed_rows[0][1])
    print(f"\n## Throughput: microseconds per pose (all solutions), batch {args.batch}, median of {args.repeats}\n")
    print(
        "| arm | "
        + " | ".join(keys)
        + " | IK-Geo, one pose per call |"
        + (" nik/EAIK speed, check | no check |" if "EAIK IK_batched" in keys else "")
    )
    print("|---" * (len(keys) + 2 + (2 if "EAIK IK_batched" in keys else 0)) + "|")
    for label, med, t_ig in speed_rows:
        cells = " | ".join(f"{med[k] * 1e6:.2f}" for k in keys)
        extra = ""
        if "EAIK IK_batched" in med:
            e = med["EAIK IK_batched"]
            extra = f" {e / med['nik, FK check']:.2f}x | {e / med['nik, no check']:.2f}x |"
        print(f"| {label} | {cells} | {t_ig * 1e6:.1f} |{extra}")
    if count_rows and not math.isnan(count_rows[0][6]):
        worst = min(r[6] for r in count_rows)
        print(f"\ngoal: same count as IK-Geo on >= 99.9 % of poses per arm: worst arm {worst:.2f} %")
    print(f"goal: every nik solution within 1e-9 m: largest {max(r[1][0] for r in residual_rows):.1e} m")
    if "EAIK IK_batched" in keys:
        chk = min(m["EAIK IK_batched"] / m["nik, FK check"] for _, m, _ in speed_rows)
        nochk = min(m["EAIK IK_batched"] / m["nik, no check"] for _, m, _ in speed_rows)
        print(f"goal: with the FK check >= 1x EAIK: worst arm {chk:.2f}x; without >= 2x: worst arm {nochk:.2f}x")


if __name__ == "__main__":
    main()
