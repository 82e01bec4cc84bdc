"""Paper D protocol: classic PSO vs improved PSO vs GA on REBot-V-6R.

Two targets T(Q1), T(Q2); 100 independent runs of each algorithm with the paper's settings
(classic PSO: 30 particles like the improved PSO, otherwise paper A's settings),
batched as the B dimension (each run has its own random stream). As in the paper, the arm
problem f1 = ||p* - p|| is solved over joints 1-3 (the tool frame sits at the wrist centre, so
joints 4-6 do not move it), then the wrist problem f2 = ||x* - x|| over joints 4-6 with joints
1-3 fixed at that run's f1 solution (x: the nine rotation entries, see nik.swarm.objectives).
Every run does the full 100 generations (no tolerance stop).

    python benchmarks/paper_d.py [--runs 100] [--out runs/paper_d] [--threads 1]

Prints the max / min / mean table (f1 in mm, f2 dimensionless), writes the convergence plot
``convergence.png`` and ``table.md`` under ``--out``, and says whether the paper's ordering
(improved PSO < classic PSO << GA) held.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import torch

import nik
from nik.swarm import GACfg, IPSOCfg, PSOCfg, make_objective, make_problem, run_swarm

Q1 = [1.0, -1.5, 2.0, 1.0, 2.0, 3.0]
Q2 = [-1.0, 1.0, 2.1, 1.5, -2.0, 3.0]
ALGOS = {"classic PSO": ("pso", lambda: PSOCfg(particles=30)), "improved PSO": ("ipso", IPSOCfg), "GA": ("ga", GACfg)}


def solve_split(robot, T, method, cfg, *, seed):
    """f1 over joints 1-3, then f2 over joints 4-6; returns final f1 (B,), f2 (B,), histories."""
    g = torch.Generator(device=T.device).manual_seed(seed)
    B = T.shape[0]
    arm = make_problem(robot, T, make_objective("paper_d_position"), free=[0, 1, 2])
    c1 = replace(cfg, objective="paper_d_position")
    r1 = run_swarm(arm, method, c1, None, generator=g, tol_pos=-1, tol_rot=-1, history=True)
    q_fixed = torch.zeros(B, robot.dof, dtype=T.dtype, device=T.device)
    q_fixed[:, :3] = r1.x
    wrist = make_problem(robot, T, make_objective("paper_d_orientation"), free=[3, 4, 5], q_fixed=q_fixed)
    c2 = replace(cfg, objective="paper_d_orientation")
    r2 = run_swarm(wrist, method, c2, None, generator=g, tol_pos=-1, tol_rot=-1, history=True)
    return r1.f, r2.f, r1.history, r2.history


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--out", default="runs/paper_d")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--dtype", choices=["float64", "float32"], default="float64")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    dtype = getattr(torch, args.dtype)
    robot = nik.load_robot("rebot_v_6r")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, curves, verdicts = [], {}, []
    for tname, Q in (("Q1", Q1), ("Q2", Q2)):
        T = robot.fk(torch.tensor(Q, dtype=dtype)).expand(args.runs, 4, 4).contiguous()
        stats = {}
        for aname, (method, cfg_cls) in ALGOS.items():
            t0 = time.perf_counter()
            f1, f2, h1, h2 = solve_split(robot, T, method, cfg_cls(), seed=args.seed)
            dt = time.perf_counter() - t0
            f1mm = f1.double() * 1000
            stats[aname] = (f1mm.mean().item(), f2.double().mean().item())
            rows.append(
                (
                    tname,
                    aname,
                    f1mm.max().item(),
                    f1mm.min().item(),
                    f1mm.mean().item(),
                    f2.max().item(),
                    f2.min().item(),
                    f2.mean().item(),
                    dt,
                )
            )
            curves[(tname, aname)] = (h1.double().mean(1) * 1000, h2.double().mean(1))
        for k, label in ((0, "f1"), (1, "f2")):
            i, c, g = stats["improved PSO"][k], stats["classic PSO"][k], stats["GA"][k]
            verdicts.append(
                f"{tname} {label} (mean): improved PSO {i:.3g} < classic PSO {c:.3g}: "
                f"{'held' if i < c else 'did NOT hold'}; classic PSO << GA {g:.3g}: "
                f"{'held' if c * 10 < g else 'did NOT hold'}"
            )
    header = (
        "| target | algorithm | f1 max (mm) | f1 min (mm) | f1 mean (mm) | f2 max | f2 min | f2 mean "
        "| time (s) |\n|---|---|---|---|---|---|---|---|---|"
    )
    lines = [header]
    lines += [f"| {r[0]} | {r[1]} | " + " | ".join(f"{v:.3g}" for v in r[2:8]) + f" | {r[8]:.1f} |" for r in rows]
    text = "\n".join(lines) + "\n\n" + "\n".join(verdicts) + "\n"
    print(
        f"paper D protocol: rebot_v_6r, {args.runs} runs per algorithm and target, {args.dtype}, "
        f"{args.threads} thread(s)\n"
    )
    print(text)
    n_ic = sum(v.split(";")[0].endswith("held") for v in verdicts)
    n_cg = sum(v.endswith("held") for v in verdicts)
    overall = n_ic == n_cg == len(verdicts)
    print(
        f"paper D ordering improved PSO < classic PSO << GA: {'HELD' if overall else 'DID NOT HOLD'} "
        f"(improved < classic on {n_ic}/{len(verdicts)} rows, classic << GA (10x) on {n_cg}/{len(verdicts)} rows)"
    )
    (out / "table.md").write_text(text)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(2, 2, figsize=(10, 7))
        for r, tname in enumerate(("Q1", "Q2")):
            for c, (label, unit) in enumerate((("f1", " (mm)"), ("f2", ""))):
                ax = axes[r, c]
                for aname in ALGOS:
                    ax.semilogy(curves[(tname, aname)][c].clamp_min(1e-16).numpy(), label=aname)
                ax.set_title(f"{tname}: {label}, mean best over {args.runs} runs")
                ax.set_xlabel("generation")
                ax.set_ylabel(label + unit)
                ax.legend()
        fig.tight_layout()
        fig.savefig(out / "convergence.png", dpi=110)
        print(f"wrote {out / 'convergence.png'} and {out / 'table.md'}")
    except ImportError:  # pragma: no cover
        print("matplotlib missing: no plot")


if __name__ == "__main__":
    main()
