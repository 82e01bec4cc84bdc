"""What the whole-trajectory optimisation adds to ``solve_path`` (issue 29.1): feasible paths followed with the polish
(nik.paths.trajopt.polish_path) and without it, on the redundant arms.

Paths: benchmarks/paths.py's stream (lines of 0.15 m and circles of radius 5 cm, 60 waypoints, orientation fixed,
from a configuration in the middle 60 % of the ranges). Feasible: the per-pose solver reaches every waypoint
(benchmarks/paths.py's rule). Followed: every waypoint within 0.1 mm / 0.1 deg by FK, inside the limits, every step
(the first from q0 included) <= 3 deg. ``solve_path(T, q_start=q0, max_step=3 deg)``: the polish runs where the
chain leaves a step above 3 deg or a waypoint unreached. "off" replaces the polish by the plain FK check. Time: the
whole solve_path calls, summed over the feasible paths.

    OMP_NUM_THREADS=1 python benchmarks/trajopt_paths.py --out benchmarks/results/trajopt_paths.md
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from paths import PATH_SEED, STEP_GOAL, circle, line, quality, start_configuration  # noqa: E402

import nik  # noqa: E402
import nik.paths.solve as P  # noqa: E402
from nik.paths.trajopt import polish_path  # noqa: E402


def _off(model, Tn, q, q0, **kw):
    """The polish switched off: the path as the chain left it, checked by FK."""
    return (q, *P._errors(model, Tn, q))


def bench(name: str, n_paths: int) -> str:
    solver = nik.IKSolver(name)
    robot = solver.robot
    gen = torch.Generator().manual_seed(PATH_SEED + sum(map(ord, name)))
    met = {"off": [0, 0], "on": [0, 0]}
    spent = {"off": 0.0, "on": 0.0}
    feasible = [0, 0]
    for k in range(2 * n_paths):
        kind = k % 2  # 0 line, 1 circle
        q0 = start_configuration(robot, gen, 0.6)
        T = line(robot, q0, gen, 0.15) if kind == 0 else circle(robot, q0, gen)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if not bool(solver.solve(T).success.all()):
                continue
            feasible[kind] += 1
            for mode in ("off", "on"):
                P.polish_path = _off if mode == "off" else polish_path
                t = time.perf_counter()
                res = solver.solve_path(T, q_start=q0, max_step=STEP_GOAL)
                spent[mode] += time.perf_counter() - t
                ok, step = quality(robot, T, res.q.numpy(), q0)
                met[mode][kind] += ok and step <= STEP_GOAL
    P.polish_path = polish_path
    return (
        f"| {name} | {met['off'][0]}/{feasible[0]} | {met['on'][0]}/{feasible[0]} | {met['off'][1]}/{feasible[1]} "
        f"| {met['on'][1]}/{feasible[1]} | {spent['off']:.2f} | {spent['on']:.2f} |"
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=40, help="lines and as many circles per arm (default 40)")
    parser.add_argument("--robots", nargs="+", default=["panda", "xarm7"])
    parser.add_argument("--out", type=Path, default=None, help="write the table (markdown) here")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    lines = [
        "| robot | lines, chain only | lines, with the polish | circles, chain only | circles, with the polish "
        "| time s, chain only | time s, with the polish |",
        "|---|---|---|---|---|---|---|",
        *(bench(name, args.paths) for name in args.robots),
    ]
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        tmp = args.out.with_suffix(".tmp")
        tmp.write_text(f"`python benchmarks/trajopt_paths.py --out {args.out}` (one thread)\n\n{text}\n")
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
