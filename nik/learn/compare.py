"""Compare the training methods on one dataset, split and wall-clock budget, several seeds each.

    nik compare --data data/kuka_kr_100k --budget 60 --seeds 0 1 2 --out benchmarks/results/learners_kuka_kr
    (or python benchmarks/learners.py with the same arguments)

For each network (``paper``: paper C's 6-8-6 tanh net on xyz + RPY; ``default``: the realistic default
of :data:`nik.nets.DEFAULT`) and each method (``configs/train/<method>.yaml``), runs
``train.py fit`` in this process with ``--trainer.max_time`` = budget (DE also stops at its 500
generations), then evaluates the final network on the test split. Writes ``<out>.md`` (the table),
``<out>.csv`` (one row per run), ``<out>_history.csv`` and ``<out>.png`` (validation joint MSE, paper C
eq. 4, against wall-clock time).

Paper C's check is also reported: on 8 random test poses, the largest joint error, and over the whole
test split the fraction of poses whose every joint is within 0.003 degrees.
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import time
import warnings
from pathlib import Path

import torch

from nik.learn.cli import METHODS, NET_NAMES, build_parser, cli_main, method_config
from nik.learn.losses import evaluate
from nik.nets import DEFAULT, PAPER_C

__all__ = ["NETS", "run_one", "table", "plot", "compare", "build_parser", "main"]

NETS = dict(zip(NET_NAMES, (PAPER_C, DEFAULT), strict=True))
PAPER_TOL_DEG = 0.003

#: Per-method settings for the comparison beyond the config file (validation cadence; DE on the big net).
EXTRA = {
    ("paper", "bp"): ["--trainer.check_val_every_n_epoch", "100"],
    ("paper", "lbfgs"): ["--trainer.check_val_every_n_epoch", "2"],
    # full-batch DE on 80k samples costs ~2 s a generation on this CPU (500 generations: ~17 min), so
    # within the budget DE scores each generation on a random 1,000-sample subset (same for all individuals)
    ("paper", "de"): ["--trainer.check_val_every_n_epoch", "10", "--model.fitness_samples", "1000"],
    ("paper", "de_bp"): ["--trainer.check_val_every_n_epoch", "20", "--model.fitness_samples", "1000"],
    ("paper", "adam"): ["--data.batch_size", "256"],
    ("default", "bp"): ["--trainer.check_val_every_n_epoch", "20"],
    ("default", "lbfgs"): ["--trainer.check_val_every_n_epoch", "1"],
    # a 140k-weight net cannot be scored 220 times on 80k samples per generation: DE uses a random
    # subset of 1024 samples per generation (the same for every individual)
    ("default", "de"): ["--trainer.check_val_every_n_epoch", "5", "--model.fitness_samples", "1024"],
    ("default", "de_bp"): ["--trainer.check_val_every_n_epoch", "5", "--model.fitness_samples", "1024"],
}


def _net_args(cfg: dict) -> list[str]:
    return [
        "--model.hidden",
        str(list(cfg["hidden"])),
        "--model.activation",
        cfg["activation"],
        "--model.representation",
        cfg["representation"],
        "--model.output",
        cfg["output"],
    ]


def run_one(data: Path, net_name: str, method: str, seed: int, budget: float, root: Path) -> tuple[dict, list]:
    budget_s = int(math.ceil(budget))
    """Train ``method`` on ``net_name`` for ``budget`` seconds; return (test metrics, validation history rows)."""
    args = [
        "fit",
        "--config",
        str(method_config(method)),
        "--data.path",
        str(data),
        "--seed_everything",
        str(seed),
        "--trainer.max_time",
        f"00:00:{budget_s // 60:02d}:{budget_s % 60:02d}",
        "--trainer.max_epochs",
        "-1",
        "--trainer.logger",
        "false",
        "--trainer.enable_progress_bar",
        "false",
        "--trainer.enable_model_summary",
        "false",
        "--trainer.default_root_dir",
        str(root / net_name / method / f"seed{seed}"),
        *_net_args(NETS[net_name]),
        *EXTRA.get((net_name, method), []),
    ]
    t0 = time.perf_counter()
    cli = cli_main(args)
    wall = time.perf_counter() - t0
    model, dm = cli.model, cli.datamodule
    net = model.net.eval()
    T, q = dm.test_data
    m = evaluate(net, T, q)
    g = torch.Generator().manual_seed(1000 + seed)
    pick = torch.randperm(T.shape[0], generator=g)[:8]
    dq = (net.predict(T) - q).abs().rad2deg()
    m.update(
        {
            "net": net_name,
            "method": method,
            "seed": seed,
            "params": net.n_params,
            "wall_s": model.wall_s,
            "process_s": wall,
            "loss_evals": model.loss_evals,
            "sample_evals": model.sample_evals,
            "paper8_max_joint_deg": float(dq[pick].max()),
            "within_0.003deg_frac": float((dq.amax(-1) <= PAPER_TOL_DEG).double().mean()),
            "de_generations": getattr(getattr(model, "de_state", None), "generation", ""),
        }
    )
    from nik.learn.callbacks import History

    hist = next(cb for cb in cli.trainer.callbacks if isinstance(cb, History)).rows
    rows = [
        {
            "net": net_name,
            "method": method,
            "seed": seed,
            "wall_s": r.get("wall_s", float("nan")),
            "val_joint_mse": r.get("val_joint_mse", float("nan")),
        }
        for r in hist
    ]
    return m, rows


def _ms(values, fmt: str = ".3g") -> str:
    values = [float(v) for v in values]
    if len(values) == 1:
        return format(values[0], fmt)
    return f"{format(statistics.mean(values), fmt)} ± {format(statistics.stdev(values), fmt)}"


def table(results: list[dict], budget: float, data: Path) -> str:
    """The Markdown table: one row per (net, method), mean ± sd over the seeds."""
    lines = [
        f"Dataset `{data}`, test split of {results[0]['n']} poses; wall-clock budget {budget:g} s per run; "
        f"mean ± sd over seeds {sorted({int(r['seed']) for r in results})}; {torch.get_num_threads()} torch "
        "thread(s), CPU. Function evaluations = losses of one weight vector on one batch (every L-BFGS closure "
        "call and every DE individual counted). Pose errors are of FK(predicted joints) against the test pose.",
        "",
        "| net | method | params | wall s | function evals | test joint RMSE (deg) | pos median (mm) | pos p95 (mm) "
        "| rot median (deg) | rot p95 (deg) | max joint error on 8 test poses (deg) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for net_name in NETS:
        for method in METHODS:
            rs = [r for r in results if r["net"] == net_name and r["method"] == method]
            if not rs:
                continue
            lines.append(
                f"| {net_name} | {method} | {int(rs[0]['params'])} | {_ms((r['wall_s'] for r in rs), '.1f')} | "
                f"{_ms((r['loss_evals'] for r in rs), '.0f')} | {_ms((r['joint_rmse_deg'] for r in rs), '.1f')} | "
                f"{_ms((r['pos_mm_median'] for r in rs), '.0f')} | {_ms((r['pos_mm_p95'] for r in rs), '.0f')} | "
                f"{_ms((r['rot_deg_median'] for r in rs), '.1f')} | {_ms((r['rot_deg_p95'] for r in rs), '.1f')} | "
                f"{_ms((r['paper8_max_joint_deg'] for r in rs), '.0f')} |"
            )
    best = max(float(r["within_0.003deg_frac"]) for r in results)
    lines += [
        "",
        f"Paper C's claim (every joint within {PAPER_TOL_DEG} deg on 8 test poses): best fraction of test "
        f"poses with every joint within {PAPER_TOL_DEG} deg over all runs = {best:.4f}.",
    ]
    return "\n".join(lines) + "\n"


def plot(history: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nets = [n for n in NETS if any(h["net"] == n for h in history)]
    fig, axes = plt.subplots(1, len(nets), figsize=(6 * len(nets), 4.5), squeeze=False)
    colors = dict(zip(METHODS, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    for ax, net_name in zip(axes[0], nets, strict=True):
        for method in METHODS:
            for seed in sorted({h["seed"] for h in history}):
                pts = [
                    (h["wall_s"], h["val_joint_mse"])
                    for h in history
                    if h["net"] == net_name and h["method"] == method and h["seed"] == seed
                ]
                if pts:
                    xs, ys = zip(*pts, strict=True)
                    ax.plot(
                        xs, ys, ".-", color=colors[method], alpha=0.8, markersize=3, label=method if seed == 0 else None
                    )
        ax.set_yscale("log")
        ax.set_xlabel("wall-clock time (s)")
        ax.set_ylabel("validation joint MSE (paper C eq. 4, normalised outputs)")
        ax.set_title(f"{net_name} net")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def compare(args: argparse.Namespace) -> list[dict]:
    """Run every (net, method, seed) of ``args`` and write the table, CSVs and plot; returns the result rows."""
    torch.set_num_threads(args.threads)
    warnings.filterwarnings("ignore")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    results, history = [], []
    for net_name in args.nets:
        for method in args.methods:
            for seed in args.seeds:
                m, rows = run_one(args.data, net_name, method, seed, args.budget, args.runs_dir)
                results.append(m)
                history += rows
                print(
                    f"{net_name:8s} {method:6s} seed {seed}: wall {m['wall_s']:6.1f} s, evals {m['loss_evals']:9d}, "
                    f"joint RMSE {m['joint_rmse_deg']:7.3f} deg, pos median {m['pos_mm_median']:8.2f} mm, "
                    f"rot median {m['rot_deg_median']:7.3f} deg",
                    flush=True,
                )
                _write(args, results, history)
    print(table(results, args.budget, args.data))
    return results


def main(argv=None) -> int:
    compare(build_parser().parse_args(argv))
    return 0


def _write(args, results, history) -> None:
    keys = list(results[0])
    with open(args.out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(results)
    with open(args.out.parent / f"{args.out.name}_history.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["net", "method", "seed", "wall_s", "val_joint_mse"])
        w.writeheader()
        w.writerows(history)
    args.out.with_suffix(".md").write_text(table(results, args.budget, args.data))
    plot(history, args.out.with_suffix(".png"))
