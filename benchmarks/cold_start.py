"""The first solve on a cold kernel cache (issue 37 item 2): time to the first answer and to the compiled backend.

Each run is a fresh process with ``NUMBA_CACHE_DIR`` set to a new empty folder (a machine that never compiled nik's
kernels), timing from the process start (before ``import torch, nik``) to the first answer of
``IKSolver(nik.load_robot(ARM)).solve(T)`` (one pose), then to the compiled backend being ready (a solve on it), wall
and CPU seconds of the process. ``before``: ``NIK_COMPILE=wait``, the compile on the caller's thread, as on main
before this change (the first answer waits for it); ``after``: the default, torch answers while the kernels compile
in a background thread (:mod:`nik.kernels.background`). ``--procs 2`` starts that many processes at once, each on its
own empty cache; ``--warm`` runs once more on the cache the first run filled (the warm first solve).

    python benchmarks/cold_start.py --modes before after --procs 1 --warm
    python benchmarks/cold_start.py --modes after --procs 2 --no-ready   # first answers only
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, os, sys, time
t0 = time.perf_counter()
import numpy as np
import torch, nik
arm, ready = sys.argv[1], sys.argv[2] == "1"
T = np.eye(4)[None].copy(); T[0, :3, 3] = [0.4, 0.1, 0.5]; T[0, :3, :3] = np.diag([1.0, -1.0, -1.0])
if arm != "panda":
    r = nik.load_robot(arm)
    T = r.fk(torch.full((1, r.dof), 0.3, dtype=torch.float64)).numpy()
solver = nik.IKSolver(nik.load_robot(arm))
res = solver.solve(T)
out = {"answer_wall": time.perf_counter() - t0, "answer_cpu": time.process_time(), "success": bool(res.success.all())}
from nik.kernels import background
out["torch_answer"] = background.BUSY
if ready:
    background.wait()
    solver.solve(T)
    out["ready_wall"], out["ready_cpu"] = time.perf_counter() - t0, time.process_time()
print(json.dumps(out), flush=True)
os._exit(0)
"""


def run(mode: str, arm: str, procs: int, ready: bool, cache=None) -> list[dict]:
    """``procs`` child processes started together (each on its own empty cache, or all on ``cache``)."""
    children = []
    for _ in range(procs):
        folder = cache or tempfile.mkdtemp(prefix="nik_cold_")
        env = dict(os.environ, NUMBA_CACHE_DIR=folder, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
        env.pop("NIK_COMPILE", None)
        if mode == "before":
            env["NIK_COMPILE"] = "wait"
        cmd = [sys.executable, "-c", CHILD, arm, "1" if ready else "0"]
        children.append(
            (folder, subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        )
    out = []
    for folder, p in children:
        so, se = p.communicate()
        row = json.loads(so.strip().splitlines()[-1]) if p.returncode == 0 else {"error": se[-500:]}
        row["cache"], row["line"] = folder, [s for s in se.splitlines() if s.startswith("nik: compiling")]
        out.append(row)
    return out


def fmt(row: dict) -> str:
    if "error" in row:
        return "error: " + row["error"]
    s = f"first answer {row['answer_wall']:6.1f} s wall {row['answer_cpu']:6.1f} s CPU (torch: {row['torch_answer']})"
    if "ready_wall" in row:
        s += f"; compiled ready {row['ready_wall']:6.1f} s wall {row['ready_cpu']:6.1f} s CPU"
    return s + f"; success {row['success']}; lines {len(row['line'])}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arm", default="panda")
    ap.add_argument("--modes", nargs="+", default=["before", "after"], choices=["before", "after"])
    ap.add_argument("--procs", type=int, default=1)
    ap.add_argument("--no-ready", action="store_true", help="time the first answers only (after: exit at once)")
    ap.add_argument("--warm", action="store_true", help="then once more on the filled cache (warm first solve)")
    ap.add_argument("--out", type=Path, default=None, help="append the lines printed to this file")
    args = ap.parse_args()
    lines = [f"# cold_start {time.strftime('%Y-%m-%d %H:%M')} arm={args.arm} procs={args.procs} cpus={os.cpu_count()}"]
    for mode in args.modes:
        rows = run(mode, args.arm, args.procs, not args.no_ready)
        for i, row in enumerate(rows):
            lines.append(f"{mode:6s} cold #{i}: {fmt(row)}")
        if args.warm and "error" not in rows[0]:
            for _ in range(2):  # the first warm run still loads numba's index files cold from disk
                row = run(mode, args.arm, 1, False, cache=rows[0]["cache"])[0]
            lines.append(f"{mode:6s} warm   : {fmt(row)}")
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        with open(args.out, "a") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
