"""From a fresh process to the first one-pose solve, against ``python -c "import torch"``.

Each round starts, in turn, a process that only imports torch and one that runs the whole first solve (``import
nik``, ``load_robot``, ``IKSolver``, ``solve`` of one pose), the two interleaved; each is timed from its start to
the moment it is done (torch imported; the pose solved), not to its exit, by the wall clock and by the CPU time the
process used (the column to read on a machine shared with other work: waiting for a core does not count). The table
gives medians over the rounds and the difference. The solve process also reports where its time went, and the cost
of a second ``IKSolver`` of the same robot; numba's import and the import of the kernel modules are timed apart (the
first solve would do both), and ``second solve`` is a warm call for comparison. Caches are warm (the compiled
kernels and the parsed URDF from an earlier run: the first round after a change is left out), and so is Python's
bytecode: the processes run without ``PYTHONDONTWRITEBYTECODE`` (with it, each one compiles nik's sources again,
0.1-0.2 s, which no installed copy does).

With ``--baseline PATH`` (another checkout of nik, e.g. ``git archive`` of an earlier commit, its kernel cache warm)
each round also runs the same first solve with that checkout's code, interleaved with this one's, so that the two are
compared in the same machine state (a shared machine's load drifts between runs made apart).

    python benchmarks/startup.py                 # panda, 7 rounds
    python benchmarks/startup.py --robot ur5 --rounds 11
    python benchmarks/startup.py --rounds 5 --baseline /tmp/nik_main
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_TORCH = "import time\nimport torch\nprint(time.process_time())\nprint(time.time())"

_SOLVE = """
import json, time
t0 = time.perf_counter()
import torch
t1 = time.perf_counter()
import nik
t2 = time.perf_counter()
robot = nik.load_robot({robot!r})
t3 = time.perf_counter()
solver = nik.IKSolver(robot)
t4 = time.perf_counter()
import numba
t5 = time.perf_counter()
import nik.kernels.chain, nik.kernels.closed, nik.kernels.lm, nik.kernels.poses
t6 = time.perf_counter()
T = torch.tensor({pose!r}, dtype=torch.float64)
res = solver.solve(T)
t7 = time.perf_counter()
done, cpu = time.time(), time.process_time()
solver.solve(T, seed=1)
t8 = time.perf_counter()
nik.IKSolver(robot)
t9 = time.perf_counter()
print(json.dumps({{"import torch": t1 - t0, "import nik": t2 - t1, "load_robot": t3 - t2, "IKSolver": t4 - t3,
                  "import numba": t5 - t4, "kernel modules": t6 - t5, "first solve": t7 - t6,
                  "second solve": t8 - t7, "second IKSolver": t9 - t8, "success": bool(res.success.all()),
                  "source": res.source, "done": done, "cpu": cpu}}))
"""


def run(code: str, root: Path = ROOT) -> tuple[float, str]:
    """Seconds from starting the process to the moment it reports (its last line: a wall-clock time, or JSON
    with ``done``), so that the process's exit is not counted; and its output (whose line before a wall-clock time,
    or whose JSON's ``cpu``, is the CPU time the process had used by then)."""
    start = time.time()
    env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(root)  # the checkout whose nik is timed
    done = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, check=True)
    last = done.stdout.strip().splitlines()[-1]
    end = json.loads(last)["done"] if last.startswith("{") else float(last)
    return end - start, done.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="panda")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--baseline", type=Path, default=None, help="another checkout of nik, timed in the same rounds")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    import torch

    import nik

    robot = nik.load_robot(args.robot)
    pose = robot.fk(robot.sample(1, generator=torch.Generator().manual_seed(5), dtype=torch.float64))[0].tolist()
    code = _SOLVE.format(robot=args.robot, pose=pose)
    run(code)  # warms the caches (kernels, URDF) if a change left them cold
    if args.baseline is not None:
        run(code, args.baseline)
    base, full, parts, base_cpu, old, old_parts = [], [], [], [], [], []
    for _ in range(args.rounds):
        dt, out = run(_TORCH)
        base.append(dt)
        base_cpu.append(float(out.strip().splitlines()[-2]))
        dt, out = run(code)
        full.append(dt)
        parts.append(json.loads(out.strip().splitlines()[-1]))
        if args.baseline is not None:
            dt, out = run(code, args.baseline)
            old.append(dt)
            old_parts.append(json.loads(out.strip().splitlines()[-1]))
    b, f = statistics.median(base), statistics.median(full)
    bc, fc = statistics.median(base_cpu), statistics.median(p["cpu"] for p in parts)
    print(f"{args.robot}, {args.rounds} rounds, medians (s):      wall    CPU")
    print(f"  start to torch imported             {b:.3f}  {bc:.3f}")
    print(f"  fresh process to first solve        {f:.3f}  {fc:.3f}")
    print(f"  difference                          {f - b:.3f}  {fc - bc:.3f}")
    if args.baseline is not None:
        o, oc = statistics.median(old), statistics.median(p["cpu"] for p in old_parts)
        print(f"  baseline {args.baseline}: fresh process to first solve {o:.3f}  {oc:.3f}")
        print(f"  baseline difference                 {o - b:.3f}  {oc - bc:.3f}")
    print("  inside the solve process:")
    keys = ("import torch", "import nik", "load_robot", "IKSolver", "import numba", "kernel modules", "first solve")
    for key in keys + ("second solve", "second IKSolver"):
        print(f"    {key:20s} {statistics.median(p[key] for p in parts) * 1e3:8.1f} ms")
    print(f"  success {all(p['success'] for p in parts)}, source {parts[-1]['source']}")


if __name__ == "__main__":
    main()
