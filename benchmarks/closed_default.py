"""Is the default solver ever slower than ``analytic=False``? Every 6R arm of example-robot-data (issue 22, item 1).

For each URDF of the package that loads as a 6-joint revolute arm with its default tool link, the default
``IKSolver(robot)`` (the closed form where ``nik.analytic.family`` finds one, approximate fits included: the ideal
arm's closed form polished by LM on the compiled backend) against ``IKSolver(robot, analytic=False)`` (LM from
uniform starts: these arms have no network), on the same reachable targets (FK of seeded uniform joints):

- one pose per call, ``--n-one`` poses, the two solvers interleaved pose by pose (median and p95 per call);
- batches of ``--n-batch`` poses, median of ``--rounds`` interleaved runs.

Times are CPU time of this thread (``time.thread_time``), one torch thread. The ratio is ``analytic=False`` over the
default: >= 0.9 meets the goal (the default never more than 10 % slower). Needs example-robot-data (the bench extra).

    python benchmarks/closed_default.py --out benchmarks/results/closed_default.md
"""

from __future__ import annotations

import argparse
import importlib.metadata
import statistics
import time
import warnings
from pathlib import Path

import torch

import nik


def erd_root() -> Path | None:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        if str(f).endswith("ur_description/urdf/ur5_robot.urdf"):
            return Path(dist.locate_file(f)).parents[2]
    return None


def six_r_arms(root: Path) -> list[tuple[str, nik.Robot]]:
    out = []
    for path in sorted(root.rglob("*.urdf")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                robot = nik.load_robot(path)
            except ValueError:
                continue
        if robot.dof == 6 and not robot.has_prismatic:
            out.append((path.relative_to(root).as_posix(), robot))
    return out


def row(rel: str, robot, args) -> str:
    default, lm = nik.IKSolver(robot), nik.IKSolver(robot, analytic=False)
    family = nik.analytic.family(robot) or "none"
    q = robot.sample(args.n_one + args.n_batch, generator=torch.Generator().manual_seed(args.seed), dtype=torch.float64)
    T = robot.fk(q)
    To, Tb = T[: args.n_one], T[args.n_one :]
    for s in (default, lm):
        s.solve(Tb[:64])
    times = {"d": [], "l": []}
    ok = {"d": 0, "l": 0}
    src = set()
    for i in range(args.n_one):
        for k, s in (("d", default), ("l", lm)):
            c0 = time.thread_time()
            res = s.solve(To[i])
            times[k].append(time.thread_time() - c0)
            ok[k] += int(res.success[0])
            if k == "d":
                src.add(res.source)
    batch = {"d": [], "l": []}
    bok = {}
    for _ in range(args.rounds):
        for k, s in (("d", default), ("l", lm)):
            c0 = time.thread_time()
            res = s.solve(Tb)
            batch[k].append(time.thread_time() - c0)
            bok[k] = float(res.success.double().mean())
    med = {k: 1e6 * statistics.median(v) for k, v in times.items()}
    p95 = {k: 1e6 * sorted(v)[int(0.95 * len(v))] for k, v in times.items()}
    bt = {k: 1e6 * statistics.median(v) / args.n_batch for k, v in batch.items()}
    return (
        f"| {rel} | {robot.end_link} | {family} | {'/'.join(sorted(src))} | {med['d']:.1f} / {p95['d']:.1f} | "
        f"{med['l']:.1f} / {p95['l']:.1f} | {med['l'] / med['d']:.2f}x | {100 * ok['d'] / args.n_one:.1f} / "
        f"{100 * ok['l'] / args.n_one:.1f} % | {bt['d']:.1f} | {bt['l']:.1f} | {bt['l'] / bt['d']:.2f}x | "
        f"{100 * bok['d']:.1f} / {100 * bok['l']:.1f} % |"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-one", type=int, default=300)
    ap.add_argument("--n-batch", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    nik.set_threads(1)
    root = erd_root()
    if root is None:
        print("example-robot-data is not installed (pip install -e .[bench]): nothing to measure")
        return 0
    lines = [
        f"`python benchmarks/closed_default.py {' '.join(argv or [])}`".replace(" `", "`"),
        "",
        f"Every 6R arm of example-robot-data; one pose: {args.n_one} calls interleaved pose by pose, us median / p95 "
        f"(CPU time of this thread); batch: {args.n_batch} poses, us per pose, median of {args.rounds} interleaved "
        "runs. "
        "Success within 0.1 mm / 0.1 deg (default / analytic=False). Ratio: analytic=False over the default "
        "(>= 0.90: the default is at most 10 % slower).",
        "",
        "| URDF | tool link | family | default's guess | default one pose | analytic=False one pose | ratio | success "
        "| default batch | analytic=False batch | ratio | success |",
        "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    print("\n".join(lines), flush=True)
    for rel, robot in six_r_arms(root):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lines.append(row(rel, robot, args))
        print(lines[-1], flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_name(args.out.name + ".tmp")
        tmp.write_text("\n".join(lines) + "\n")
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
