"""Compare the training methods on one dataset and split under one budget, several seeds each, and name a winner.

    nik compare --data data/kuka_kr_100k --steps 300 --seeds 0 1 2 --nets paper
    (or python benchmarks/learners.py with the same arguments)

For each network (``paper``: paper C's 6-8-6 tanh net on xyz + RPY; ``default``: the realistic default of
:data:`nik.nets.DEFAULT`) and each method (``configs/train/<method>.yaml``), runs ``train.py``'s training in
this process, then evaluates the final network on the test split.

Budgets. ``--steps N`` stops every run after N trainer steps (an optimiser step on a batch, an L-BFGS step of up
to 20 iterations, a DE generation, a BP step of de_bp): two runs with the same seed give the same table, only
the times differ. ``--budget SECONDS`` stops every run on the wall clock, checked inside the steps
(:attr:`nik.learn.modules.IKModule.keep_budget`: a step is not started when the time left is shorter than the
last step took, a DE generation is abandoned between sample chunks, an L-BFGS step between loss evaluations
with the weights set back to the best point it evaluated), so a run ends within its budget; such runs differ
from one repetition to the next. With both, whichever ends first; with neither, 60 s. DE (``de``, ``de_bp``)
scores each generation on a random ``--de-samples`` subset of the training split (0: all of it) and runs
``--de-generations`` generations; a de_bp run that never reached its BP phase says so in the table.

Verdict. For every network and metric (test joint RMSE, position and rotation error, median and p95; lower is
better) the table names the best method by its mean over the seeds, the runner-up and the margin, against the
standard deviation over the seeds. The ranking counts as established only when every seed of the winner beats
every seed of the runner-up; with one seed it is never established.

Writes ``PREFIX.md`` (the table and the verdict), ``PREFIX.csv`` (one row per run), ``PREFIX_history.csv`` and
``PREFIX.png`` (validation joint MSE, paper C eq. 4, against wall-clock time), each to a temporary name then
renamed; ``PREFIX`` defaults to ``runs/compare/DATA/compare`` and the runs' checkpoints go to
``runs/compare/DATA/NET/METHOD/seedSEED/`` (``DATA``: the dataset folder's name).

Paper C's check is also reported: on 8 random test poses, the largest joint error, and over the whole test split
the fraction of poses whose every joint is within 0.003 degrees.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os
import statistics
import time
import warnings
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

import torch

from nik.learn.cli import METHODS, NET_NAMES, build_parser, cli_main, method_config
from nik.learn.losses import evaluate
from nik.nets import DEFAULT, PAPER_C

__all__ = [
    "NETS",
    "METRICS",
    "RunCfg",
    "check_args",
    "run_one",
    "table",
    "verdict",
    "MIN_SEEDS",
    "plot",
    "compare",
    "build_parser",
    "main",
]

NETS = dict(zip(NET_NAMES, (PAPER_C, DEFAULT), strict=True))
PAPER_TOL_DEG = 0.003
DEFAULT_BUDGET_S = 60.0
#: The metrics the verdict ranks (all lower-is-better): key in a result row, label, unit.
METRICS = (
    ("joint_rmse_deg", "test joint RMSE", "deg"),
    ("pos_mm_median", "position median", "mm"),
    ("pos_mm_p95", "position p95", "mm"),
    ("rot_deg_median", "rotation median", "deg"),
    ("rot_deg_p95", "rotation p95", "deg"),
)
#: Per-method validation cadence for the comparison (full-batch methods make one step an epoch).
EXTRA = {
    ("paper", "bp"): ["--trainer.check_val_every_n_epoch", "100"],
    ("paper", "lbfgs"): ["--trainer.check_val_every_n_epoch", "2"],
    ("paper", "de"): ["--trainer.check_val_every_n_epoch", "10"],
    ("paper", "de_bp"): ["--trainer.check_val_every_n_epoch", "20"],
    ("paper", "adam"): ["--data.batch_size", "256"],
    ("default", "bp"): ["--trainer.check_val_every_n_epoch", "20"],
    ("default", "lbfgs"): ["--trainer.check_val_every_n_epoch", "1"],
    ("default", "de"): ["--trainer.check_val_every_n_epoch", "5"],
    ("default", "de_bp"): ["--trainer.check_val_every_n_epoch", "5"],
}
#: Result columns that are measured times (they differ between two runs of the same seed; all others do not
#: under a step budget).
TIME_KEYS = ("train_s", "process_s")


@dataclass(frozen=True)
class RunCfg:
    """What every run of one comparison shares.

    ``budget_s``: wall-clock seconds of training (None: no clock); ``steps``: trainer steps (None: no limit);
    ``de_samples``: DE's fitness subset (0: the whole training split); ``de_generations``: DE generations."""

    data: Path
    runs_dir: Path
    budget_s: float | None = None
    steps: int | None = None
    de_samples: int = 1000
    de_generations: int = 500

    def budget_text(self) -> str:
        parts = []
        if self.budget_s is not None:
            parts.append(f"{self.budget_s:g} s of wall clock")
        if self.steps is not None:
            parts.append(f"{self.steps} steps")
        text = " or ".join(parts) + " per run" + (", whichever ends first" if len(parts) == 2 else "")
        if self.budget_s is None:
            return text + " (a step budget: the same seed gives the same numbers, only the times differ)"
        return text + " (a wall-clock budget: a repetition gives slightly other numbers)"


def check_args(args: argparse.Namespace) -> None:
    """Refuse bad values of ``nik compare``'s arguments before any work. Raises ``ValueError`` (one line) or
    :class:`nik.DatasetError` / ``FileNotFoundError`` for a folder that is no dataset."""
    if args.budget is not None and not (math.isfinite(args.budget) and args.budget > 0):
        raise ValueError(f"--budget must be a positive number of seconds, got {args.budget:g}")
    if args.steps is not None and args.steps < 1:
        raise ValueError(f"--steps must be a positive number of steps, got {args.steps}")
    bad = [s for s in args.seeds if not 0 <= s < 2**32]
    if bad:
        raise ValueError(f"--seeds must be whole numbers from 0 to 2**32 - 1, got {bad[0]}")
    if len(set(args.seeds)) != len(args.seeds):
        raise ValueError(f"--seeds lists a seed twice: {' '.join(map(str, args.seeds))}")
    if args.de_samples < 0:
        raise ValueError(f"--de-samples must be a positive number of samples (0: all), got {args.de_samples}")
    if args.de_generations < 1:
        raise ValueError(f"--de-generations must be a positive number of generations, got {args.de_generations}")
    if args.threads is not None and args.threads < 1:
        raise ValueError(f"--threads must be at least 1, got {args.threads}")
    if not Path(args.data).is_dir():
        raise FileNotFoundError(f"--data {args.data}: no such dataset folder (make one with nik generate)")
    from nik.data import load_dataset

    load_dataset(args.data, verify=False)  # a folder that is no dataset fails here, in one line


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


def _method_args(cfg: RunCfg, net_name: str, method: str, seed: int) -> list[str]:
    args = [
        "--config",
        str(method_config(method)),
        "--data.path",
        str(cfg.data),
        "--seed_everything",
        str(seed),
        "--trainer.max_epochs",
        "-1",
        "--trainer.max_steps",
        str(cfg.steps if cfg.steps is not None else -1),
        "--trainer.num_sanity_val_steps",
        "0",
        "--trainer.logger",
        "false",
        "--trainer.enable_progress_bar",
        "false",
        "--trainer.enable_model_summary",
        "false",
        "--trainer.default_root_dir",
        str(cfg.runs_dir / net_name / method / f"seed{seed}"),
        *_net_args(NETS[net_name]),
        *EXTRA.get((net_name, method), []),
    ]
    if method in ("de", "de_bp"):
        args += [
            "--model.fitness_samples",
            str(cfg.de_samples) if cfg.de_samples > 0 else "null",
            "--model.generations",
            str(cfg.de_generations),
        ]
    return args


def _phases(model, method: str, steps: int, batch: int) -> dict:
    """What ran: steps, DE generations and BP steps, the samples a step, whether every phase of the method ran."""
    if method not in ("de", "de_bp"):
        return {"de_generations": "", "bp_steps": "", "samples_a_step": batch, "all_phases": True}
    gens = model.de_state.generation if model.de_state is not None else 0
    # the first DE step evaluates the initial population (generation 0); BP steps are the steps after the DE ones
    de_steps = gens + 1 if model.de_state is not None else 0
    bp_steps = max(0, steps - de_steps) if method == "de_bp" else 0
    de_n = min(model.hparams.fitness_samples or batch, batch)
    return {
        "de_generations": gens,
        "bp_steps": bp_steps if method == "de_bp" else "",
        "samples_a_step": de_n,
        "all_phases": method == "de" or bp_steps > 0,
    }


def run_one(cfg: RunCfg, net_name: str, method: str, seed: int) -> tuple[dict, list]:
    """Train ``method`` on ``net_name`` with ``seed`` within ``cfg``'s budget; return (test metrics and what ran,
    validation history rows)."""
    from lightning.pytorch.callbacks import Checkpoint, Timer

    cli = cli_main(_method_args(cfg, net_name, method, seed), run=False)
    model, dm, trainer = cli.model, cli.datamodule, cli.trainer
    # no checkpoint writing inside the budget (a full-batch L-BFGS state takes seconds): one last.ckpt at the end
    trainer.callbacks[:] = [cb for cb in trainer.callbacks if not isinstance(cb, Checkpoint)]
    if cfg.budget_s is not None:
        trainer.callbacks.insert(0, Timer(duration=timedelta(seconds=cfg.budget_s), interval="step"))
    model.keep_budget = True
    t0 = time.perf_counter()
    trainer.fit(model, datamodule=dm)
    process_s = time.perf_counter() - t0
    ckpt = Path(trainer.default_root_dir) / "last.ckpt"
    ckpt.parent.mkdir(parents=True, exist_ok=True)
    tmp = ckpt.with_name(f".{ckpt.name}.tmp-{os.getpid()}")
    trainer.save_checkpoint(tmp, weights_only=False)
    os.replace(tmp, ckpt)
    net = model.net.eval()
    T, q = dm.test_data
    m = evaluate(net, T, q)
    g = torch.Generator().manual_seed(1000 + seed)
    pick = torch.randperm(T.shape[0], generator=g)[:8]
    with torch.no_grad():
        dq = (net.predict(T) - q).abs().rad2deg()
    steps = int(trainer.global_step)
    n_train = int(dm.train_data[0].shape[0])
    batch = min(dm.batch_size or n_train, n_train)
    ran = _phases(model, method, steps, batch)
    if cfg.steps is not None and steps >= cfg.steps:
        stopped = "steps"
    elif method == "de" and ran["de_generations"] >= cfg.de_generations:
        stopped = "generations"
    else:
        stopped = "clock"
    m.update(
        {
            "net": net_name,
            "method": method,
            "seed": seed,
            "params": net.n_params,
            "train_s": model.train_s if model.train_s is not None else model.wall_s,
            "process_s": process_s,
            "steps": steps,
            "stopped_by": stopped,
            "n_train": n_train,
            **ran,
            "loss_evals": model.loss_evals,
            "sample_evals": model.sample_evals,
            "paper8_max_joint_deg": float(dq[pick].max()),
            "within_0.003deg_frac": float((dq.amax(-1) <= PAPER_TOL_DEG).double().mean()),
        }
    )
    from nik.learn.callbacks import History

    hist = next(cb for cb in trainer.callbacks if isinstance(cb, History)).rows
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


def _span(values) -> str:
    """``5`` or ``5-7`` (the range over the seeds)."""
    lo, hi = min(values), max(values)
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


def _ran_text(rs: list[dict], de_generations: int) -> str:
    method = rs[0]["method"]
    if method not in ("de", "de_bp"):
        return f"{_span([int(r['steps']) for r in rs])} steps"
    gens = [int(r["de_generations"]) for r in rs]
    text = f"DE {_span(gens)} of {de_generations} gen"
    if method == "de_bp":
        bp = [int(r["bp_steps"]) for r in rs]
        if max(bp) == 0:
            return text + ", BP never ran"
        text += f" + BP {_span(bp)} steps"
        if min(bp) == 0:
            text += f" (BP never ran in {sum(b == 0 for b in bp)} of {len(bp)} seeds)"
    return text


def _samples_text(rs: list[dict]) -> str:
    r = rs[0]
    n, k = int(r["n_train"]), int(r["samples_a_step"])
    if r["method"] == "de":
        return f"{k} of {n}"
    if r["method"] == "de_bp":
        return f"DE {k} of {n}, BP {n}"
    return f"{k} (all)" if k == n else str(k)


def _groups(results: list[dict]):
    """``(net, method, rows)`` in the order of :data:`NETS` and :data:`METHODS`, for the pairs that ran."""
    for net_name in NETS:
        for method in METHODS:
            rs = [r for r in results if r["net"] == net_name and r["method"] == method]
            if rs:
                yield net_name, method, rs


def _num(v: float) -> str:
    """A figure for the verdict: 3 significant digits, no exponent (1234 -> 1234, 12.34 -> 12.3, 0.01234 -> 0.0123)."""
    v = float(v)
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    digits = max(0, 2 - int(math.floor(math.log10(abs(v)))))
    return f"{v:.{digits}f}"


#: Seeds a ranking needs before it can count as established.
MIN_SEEDS = 3


def verdict(results: list[dict]) -> list[str]:
    """One line per network and metric of :data:`METRICS`: the best method by its mean over the seeds, the
    runner-up, the margin and the standard deviations over the seeds. The ranking counts as established only
    with at least :data:`MIN_SEEDS` seeds each and every seed of the winner better than every seed of the
    runner-up (with 3 seeds each, a chance of 1 in 10 when the two methods are alike); with one seed there is no
    spread and it is never established."""
    lines = []
    for net_name in NETS:
        groups = {m: rs for n, m, rs in _groups(results) if n == net_name}
        if not groups:
            continue
        if len(groups) == 1:
            lines.append(f"- {net_name} net: one method ({next(iter(groups))}), nothing to rank.")
            continue
        n_seeds = min(len(rs) for rs in groups.values())
        for key, label, unit in METRICS:
            vals = {m: [float(r[key]) for r in rs] for m, rs in groups.items()}
            order = sorted(vals, key=lambda m: statistics.mean(vals[m]))
            w, r = order[0], order[1]
            mw, mr = statistics.mean(vals[w]), statistics.mean(vals[r])
            text = f"- {net_name} net, {label}: best {w} {_num(mw)} {unit}, then {r} {_num(mr)} {unit}"
            text += f", margin {_num(mr - mw)} {unit}"
            if n_seeds < 2:
                text += "; one seed: the ranking is not established (no spread over seeds)"
            else:
                sw, sr = statistics.stdev(vals[w]), statistics.stdev(vals[r])
                text += f" against sd {_num(sw)} and {_num(sr)} over {n_seeds} seeds: "
                if max(vals[w]) >= min(vals[r]):
                    text += "not established (the seeds overlap)"
                elif n_seeds < MIN_SEEDS:
                    text += (
                        f"not established (every seed of {w} beats every seed of {r}, but {n_seeds} seeds are too few)"
                    )
                else:
                    text += f"established (every seed of {w} beats every seed of {r})"
            if not all(x["all_phases"] in (True, "True") for x in groups[w]):
                text += f"; {w} did not run all its phases"
            lines.append(text + ".")
    return lines


def table(results: list[dict], cfg: RunCfg) -> str:
    """The Markdown table (one row per network and method, mean ± sd over the seeds), then the verdict."""
    seeds = sorted({int(r["seed"]) for r in results})
    dataset = f"`{cfg.data}`"
    lines = [
        f"Dataset {dataset}, test split of {results[0]['n']} poses. Budget: {cfg.budget_text()}. Mean ± sd over "
        f"seeds {seeds}; {torch.get_num_threads()} torch thread(s), CPU. DE (de, de_bp): NP 220, F 0.6, CR 0.5, "
        f"{cfg.de_generations} generations, each scored on "
        + (f"a random {cfg.de_samples}-sample subset of the training split" if cfg.de_samples else "the whole split")
        + " (`--de-samples`). Steps: optimiser steps, L-BFGS steps of up to 20 iterations, DE generations. "
        "Function evals = losses of one weight vector on one batch (every L-BFGS closure call and every DE "
        "individual counted). Train s = wall clock from the start of training to its end. Pose errors are of "
        "FK(predicted joints) against the test pose.",
        "",
        "| net | method | ran | stopped by | params | samples a step | train s | function evals "
        "| test joint RMSE (deg) | pos median (mm) | pos p95 (mm) | rot median (deg) | rot p95 (deg) "
        "| max joint error on 8 test poses (deg) |",
        "|---|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for net_name, method, rs in _groups(results):
        stopped = "/".join(sorted({str(r["stopped_by"]) for r in rs}))
        lines.append(
            f"| {net_name} | {method} | {_ran_text(rs, cfg.de_generations)} | {stopped} | {int(rs[0]['params'])} "
            f"| {_samples_text(rs)} | {_ms((r['train_s'] for r in rs), '.1f')} "
            f"| {_ms((r['loss_evals'] for r in rs), '.0f')} | {_ms((r['joint_rmse_deg'] for r in rs), '.1f')} "
            f"| {_ms((r['pos_mm_median'] for r in rs), '.0f')} | {_ms((r['pos_mm_p95'] for r in rs), '.0f')} "
            f"| {_ms((r['rot_deg_median'] for r in rs), '.1f')} | {_ms((r['rot_deg_p95'] for r in rs), '.1f')} "
            f"| {_ms((r['paper8_max_joint_deg'] for r in rs), '.0f')} |"
        )
    best = max(float(r["within_0.003deg_frac"]) for r in results)
    lines += [
        "",
        f"Verdict (lower is better; a ranking is established when at least {MIN_SEEDS} seeds ran and every seed "
        "of the best method beats every seed of the runner-up):",
        "",
        *verdict(results),
        "",
        f"Paper C's claim (every joint within {PAPER_TOL_DEG} deg on 8 test poses): best fraction of test "
        f"poses with every joint within {PAPER_TOL_DEG} deg over all runs = {best:.4f}.",
    ]
    return "\n".join(lines) + "\n"


def plot(history: list[dict], path: Path) -> None:
    """Validation joint MSE against wall-clock time, one panel per network (nothing when no validation ran)."""
    nets = [n for n in NETS if any(h["net"] == n for h in history)]
    if not nets:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(nets), figsize=(6 * len(nets), 4.5), squeeze=False)
    colors = dict(zip(METHODS, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    for ax, net_name in zip(axes[0], nets, strict=True):
        for method in METHODS:
            labelled = False
            for seed in sorted({h["seed"] for h in history}):
                pts = [
                    (h["wall_s"], h["val_joint_mse"])
                    for h in history
                    if h["net"] == net_name and h["method"] == method and h["seed"] == seed
                ]
                if pts:
                    xs, ys = zip(*pts, strict=True)
                    label = None if labelled else method
                    ax.plot(xs, ys, ".-", color=colors[method], alpha=0.8, markersize=3, label=label)
                    labelled = True
        ax.set_yscale("log")
        ax.set_xlabel("wall-clock time (s)")
        ax.set_ylabel("validation joint MSE (paper C eq. 4, normalised outputs)")
        ax.set_title(f"{net_name} net")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    os.replace(tmp, path)


def _cfg(args: argparse.Namespace) -> tuple[RunCfg, Path]:
    """The shared run settings and the output prefix, defaults filled in."""
    data = Path(args.data)
    home = Path("runs") / "compare" / (data.resolve().name or "data")
    budget = args.budget if args.budget is not None or args.steps is not None else DEFAULT_BUDGET_S
    cfg = RunCfg(
        data=data,
        runs_dir=Path(args.runs_dir) if args.runs_dir is not None else home,
        budget_s=budget,
        steps=args.steps,
        de_samples=args.de_samples,
        de_generations=args.de_generations,
    )
    return cfg, Path(args.out) if args.out is not None else home / "compare"


def _warm_up(data: Path) -> None:
    """Load the FK code the validations use (its first call imports and loads compiled kernels, seconds), so that
    no run's budget pays for it."""
    from nik.data import load_dataset

    ds = load_dataset(data, verify=False)
    q = torch.as_tensor(ds.split("val").q[:2]).clone()
    ds.robot.fk(q.double())
    ds.robot.fk(q.float())


def compare(args: argparse.Namespace) -> list[dict]:
    """Check ``args`` (:func:`check_args`), run every (net, method, seed) and write the table with its verdict,
    the CSVs and the plot (after each run, so an interrupted comparison keeps what it did); returns the result
    rows."""
    check_args(args)
    cfg, out = _cfg(args)
    torch.set_num_threads(args.threads)
    _warm_up(cfg.data)
    warnings.filterwarnings("ignore")
    results, history = [], []
    for net_name in args.nets:
        for method in args.methods:
            for seed in args.seeds:
                m, rows = run_one(cfg, net_name, method, seed)
                results.append(m)
                history += rows
                print(
                    f"{net_name:8s} {method:6s} seed {seed}: {_ran_text([m], cfg.de_generations)}, stopped by "
                    f"{m['stopped_by']}, {m['train_s']:6.1f} s, evals {m['loss_evals']:9d}, joint RMSE "
                    f"{m['joint_rmse_deg']:7.3f} deg, pos median {m['pos_mm_median']:8.2f} mm, rot median "
                    f"{m['rot_deg_median']:7.3f} deg",
                    flush=True,
                )
                _write(out, cfg, results, history)
    print(table(results, cfg))
    print(f"wrote {out}.md, {out}.csv, {out}_history.csv" + (f" and {out}.png" if history else ""))
    return results


def main(argv=None) -> int:
    """``benchmarks/learners.py``: :func:`compare`, a bad argument refused in one line with exit status 2."""
    import sys

    args = build_parser().parse_args(argv)
    try:
        compare(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"learners.py: error: {err}", file=sys.stderr)
        return 2
    return 0


def _replace_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def _csv_text(rows: list[dict], keys: list[str]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _write(out: Path, cfg: RunCfg, results: list[dict], history: list[dict]) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    _replace_text(out.with_name(out.name + ".csv"), _csv_text(results, list(results[0])))
    _replace_text(
        out.with_name(out.name + "_history.csv"),
        _csv_text(history, ["net", "method", "seed", "wall_s", "val_joint_mse"]),
    )
    _replace_text(out.with_name(out.name + ".md"), table(results, cfg))
    plot(history, out.with_name(out.name + ".png"))
