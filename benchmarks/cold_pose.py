"""One pose per call, warm and cold: nik with a numpy pose, nik with a torch pose, Robotics Toolbox ``ik_LM``.

A pose should cross Python once, whether it comes as numpy or torch. For each arm, ``--n`` reachable poses
(FK of seeded configurations inside the limits); the solvers take each pose in turn (the order rotated pose by
pose), interleaved in one process, in three settings:

- ``tight``: call after call;
- ``idle``: 0.5 ms asleep before each call (``time.sleep``; a control loop waiting for its next tick);
- ``busy``: 0.5 ms of other work before each call (numpy passes over a 4 MB buffer: the caches hold someone
  else's data when the call starts);

and with 1 and 2 threads (``nik.set_threads``, torch's too). A numpy pose's call is timed with what a control loop
reads, ``res = solver.solve(T); res.q; res.success``; a torch pose's twice, as two solvers in the rotation: the call
alone (``solver.solve(T)``) and with the same reads (a torch pose's result makes its tensors when first read).
``ik_LM`` is given nik's tolerance as in ``benchmarks/peers.py`` (``RTB_TOL``, ``RTB_MASK``: the ellipse inscribed
in nik's 0.1 mm / 0.1 deg box), joint limits on, its restarts seeded per pose. Medians (microseconds,
``perf_counter_ns``), success by nik's float64 FK, and the ratios: ``ik_LM / nik`` and ``torch - numpy`` (us).

``--fresh-cache`` also runs the arms once more in a child process on an empty ``NUMBA_CACHE_DIR`` (every kernel
compiled first: the first call's seconds reported, then the same table).

    python benchmarks/cold_pose.py                                 # panda, ur5, kuka_kr, xarm7; 300 poses
    python benchmarks/cold_pose.py --out benchmarks/results/cold_pose --fresh-cache
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from peers import RTB_MASK, RTB_TOL, TOL_POS, TOL_ROT, latency_robot, rtb_from_file, score, targets  # noqa: E402

import nik  # noqa: E402

GAP_S = 0.0005  # the pause before each call in the idle and busy settings
_BUF = np.zeros(512 * 1024)  # 4 MB: the busy setting's other work


def gap(mode: str) -> None:
    if mode == "idle":
        time.sleep(GAP_S)
    elif mode == "busy":
        end = time.perf_counter() + GAP_S
        while time.perf_counter() < end:
            np.add(_BUF, 1.0, out=_BUF)


def measure(name: str, n: int, seed: int, modes: list[str], threads: list[int]) -> list[dict]:
    """Rows ``{robot, threads, mode, solver, median_us, success}`` of one arm."""
    robot, path, end = latency_robot(name)
    if robot is None:
        print(f"  {name} left out (example-robot-data is not installed)")
        return []
    T = targets(robot, n, seed)
    Tn = T.numpy()
    poses_np = [Tn[i].copy() for i in range(n)]  # (4, 4) float64 numpy, each its own array
    poses_t = [T[i] for i in range(n)]  # (4, 4) float64 tensors (views of one batch, as a loop over a batch has)
    solver = nik.IKSolver(robot)
    ets = rtb_from_file(robot, path, end)
    solver.solve(T[:64], tol_pos=TOL_POS, tol_rot=TOL_ROT)  # warm-up: every kernel loaded
    for i in range(min(n, 20)):
        solver.solve(poses_np[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)
        solver.solve(poses_t[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)

    def nik_np(i):
        res = solver.solve(poses_np[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)
        return res.q, res.success

    def nik_t(i):
        return solver.solve(poses_t[i], tol_pos=TOL_POS, tol_rot=TOL_ROT), None

    def nik_t_read(i):
        res = solver.solve(poses_t[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)
        return res.q, res.success

    def rtb(i):
        return ets.ik_LM(Tn[i], tol=RTB_TOL, mask=RTB_MASK, joint_limits=True).q, None

    calls = {"nik numpy": nik_np, "nik torch": nik_t, "nik torch read": nik_t_read}
    if ets is not None:
        calls["rtb ik_LM"] = rtb
    labels = list(calls)
    rows = []
    for th in threads:
        nik.set_threads(th)
        for mode in modes:
            times = {k: [] for k in labels}
            answers = {k: [None] * n for k in labels}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                for i in range(n):
                    for j in range(len(labels)):
                        label = labels[(i + j) % len(labels)]
                        np.random.seed(i)  # ik_LM's restarts (numpy's global generator), outside the timing
                        gap(mode)
                        t = time.perf_counter_ns()
                        q, _ = calls[label](i)
                        times[label].append((time.perf_counter_ns() - t) / 1e3)
                        q = q.q if label == "nik torch" else q  # the result, read after the timing
                        answers[label][i] = np.asarray(q, dtype=np.float64).reshape(-1).copy()  # not kept: a
                        q = None  # torch pose's output slot is taken again only when nothing refers to it
            for label in labels:
                succ, outside = score(robot, T, np.stack(answers[label]))
                rows.append(
                    dict(robot=name, threads=th, mode=mode, solver=label, median_us=statistics.median(times[label]),
                         success=succ, outside=outside)
                )  # fmt: skip
        print(f"  ({name}, {th} thread(s) done)", flush=True)
    nik.set_threads(None)
    return rows


def table(rows: list[dict]) -> list[str]:
    """One line per arm, threads and setting: the medians, ``ik_LM / nik`` (numpy pose; torch pose with its result
    read) and the torch pose's extra microseconds over the numpy pose (solve only; solve and read)."""
    out = [
        "| robot | threads | setting | nik numpy us | nik torch us (solve / + read) | rtb ik_LM us | "
        "ik_LM / nik numpy | ik_LM / nik torch + read | torch - numpy us (solve / + read) | "
        "success % numpy / torch / ik_LM |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    keyed = {(r["robot"], r["threads"], r["mode"], r["solver"]): r for r in rows}
    for robot, th, mode in dict.fromkeys((r["robot"], r["threads"], r["mode"]) for r in rows):
        a, b = keyed[(robot, th, mode, "nik numpy")], keyed[(robot, th, mode, "nik torch")]
        br, c = keyed[(robot, th, mode, "nik torch read")], keyed.get((robot, th, mode, "rtb ik_LM"))
        rtb_us = c["median_us"] if c else float("nan")
        succ = f"{a['success']:.1f} / {b['success']:.1f} / {c['success']:.1f}" if c else "-"
        out.append(
            f"| {robot} | {th} | {mode} | {a['median_us']:.1f} | {b['median_us']:.1f} / {br['median_us']:.1f} | "
            f"{rtb_us:.1f} | {rtb_us / a['median_us']:.2f}x | {rtb_us / br['median_us']:.2f}x | "
            f"{b['median_us'] - a['median_us']:+.1f} / {br['median_us'] - a['median_us']:+.1f} | {succ} |"
        )
    return out


def fresh_cache(argv: list[str]) -> list[str]:
    """The same run in a child process on an empty ``NUMBA_CACHE_DIR``: its first-call times and its table."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        code = (
            "import sys, time, torch; sys.argv = ['cold_pose'] + sys.argv[1:]; "
            f"sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); sys.path.insert(0, {str(ROOT)!r}); "
            "import nik; from peers import targets; "
            "r = nik.load_robot(sys.argv[2].split(',')[0]); T = targets(r, 2, 0); s = nik.IKSolver(r); "
            "t = time.perf_counter(); s.solve(T[0].numpy().copy()); a = time.perf_counter() - t; "
            "t = time.perf_counter(); s.solve(T[1]); b = time.perf_counter() - t; "
            "print(f'first call on an empty cache ({r.name}): numpy pose {a:.1f} s, '"
            "f'then torch pose {b * 1e3:.1f} ms'); "
            "import cold_pose; cold_pose.main(sys.argv[1:], child=True)"
        )  # fmt: skip
        done = subprocess.run([sys.executable, "-c", code, *argv], env=env, capture_output=True, text=True)
        if done.returncode != 0:
            return ["(fresh-cache run failed)", done.stderr[-2000:]]
        return done.stdout.splitlines()


def main(argv=None, child: bool = False) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default="panda,ur5,kuka_kr,xarm7")
    p.add_argument("--n", type=int, default=300, help="poses per arm")
    p.add_argument("--modes", default="tight,idle,busy")
    p.add_argument("--threads", default="1,2")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fresh-cache", action="store_true", help="also a run on an empty NUMBA_CACHE_DIR (child)")
    p.add_argument("--out", default=None, help="write OUT.md")
    args = p.parse_args(argv)
    log = io.StringIO()

    def say(line: str = "") -> None:
        print(line, flush=True)
        log.write(line + "\n")

    import platform

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    say(
        f"nik {nik.__version__}, torch {torch.__version__}, "
        f"numba cache {os.environ.get('NUMBA_CACHE_DIR', 'default')}, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {load:.1f}, "
        f"{time.strftime('%Y-%m-%d %H:%M:%S %Z')}"
    )
    rows = []
    for name in args.robots.split(","):
        rows += measure(
            name.strip(), args.n, args.seed, args.modes.split(","), [int(t) for t in args.threads.split(",")]
        )
    for line in table(rows):
        say(line)
    if args.fresh_cache and not child:
        say("")
        say("On an empty NUMBA_CACHE_DIR (a child process; every kernel compiled first):")
        sub = ["--robots", args.robots, "--n", str(args.n), "--modes", args.modes, "--threads", args.threads]
        for line in fresh_cache(sub):
            say(line)
    if args.out:
        Path(args.out + ".md").write_text(log.getvalue())
    return 0


if __name__ == "__main__":
    sys.exit(main())
