"""The learned networks, measured (issues 9 and 17): one run, printed tables, results in a file.

    python benchmarks/learned.py --out benchmarks/results/learned.md              # every section
    python benchmarks/learned.py --sections cost pays --robots panda xarm7 ur5    # some of them

Arms: every robot with a network (``nik/nets/weights``, found by definition hash), or ``--robots``. Targets
are FK poses of uniform joints inside the full limits (seeded), so every one is reachable. One torch thread
unless ``--threads``; CPU. Times are medians of interleaved runs (A B A B ...) in this process: wall clock,
and CPU time of this thread (``time.thread_time``, less sensitive to other processes on a shared machine).

Sections (``--sections``):

- ``raw``: on ``--n`` (2,000) targets, median / mean / p95 of the position (mm) and rotation (deg) error
  of a single shot (branch nets: the head of the reference joints' branch label; multi-head nets: one
  head drawn at random per target, seeded) and of the best hypothesis by FK;
- ``lm``: on the same targets, LM from the network's best hypothesis alone (one pass, no restarts), the
  solver ``IKSolver(robot, refine="lm", fallback="none", analytic=False)`` (+ LM from the other hypotheses
  where needed) and that solver without a network: success within 0.1 mm / 0.1 deg, ms per target;
- ``cost``: per target on a batch of ``--n-cost`` (10,000): the network's forward pass (all hypotheses,
  decoded and clamped: ``net.hypotheses``), ranking them by FK, and the whole solver that uses the network
  (``IKSolver(robot, analytic=False)``); the forward pass's share of the solver's time (goal: <= 20 %);
- ``pays``: the default ``IKSolver(robot)`` against ``IKSolver(robot, checkpoint=None)`` on batches of
  ``--pays-sizes`` (100, 1,000, 10,000) targets and on ``--n-one`` single poses (one call each, interleaved pose by
  pose; with and without ``q_near``; median and p99 per call), plus the same with ``analytic=False`` for arms with a
  closed form (their network matters only there): success (0.1 mm / 0.1 deg), ms per target, LM iterations, the
  guess each result reports; goals: >= 2x at every batch size, single poses p99 >= 2x lower, median no slower;
- ``stream``: training data per step of ``nik train`` (batch 1,024): drawing fresh FK samples (and branch
  labels), taking a batch from a tensor in memory (a fixed file's data after loading), and one training step
  of the default 4 x 256 network (pose loss, Adam);
- ``all``: PUMA-like arms, ``IKSolver(robot, analytic=False).solve_all`` against the closed form's solutions;
- ``paper``: paper C's 6-8-6 tanh net given the branch label (needs ``--paper-data``; 0 budget skips).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import warnings
from pathlib import Path

import torch

import nik
from nik.nets import load_pretrained
from nik.nets.multi import BranchHeadsIKNet, BranchIKNet, hypothesis_pose_error
from nik.nets.registry import SHIPPED_DIR, index, role_of
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT, score

TOL_POS, TOL_ROT = DEFAULT_TOL_POS, DEFAULT_TOL_ROT  # m, rad: 0.1 mm / 0.1 deg, nik's one tolerance
SECTIONS = ("raw", "lm", "cost", "pays", "stream", "all", "paper")


def _targets(robot, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    q = robot.sample(int(n), generator=torch.Generator().manual_seed(int(seed)), dtype=torch.float64)
    return q, robot.fk(q)


def _stats(pos: torch.Tensor, rot: torch.Tensor) -> dict:
    p, r = pos * 1e3, torch.rad2deg(rot)
    return {
        "pos_median": float(p.median()),
        "pos_mean": float(p.mean()),
        "pos_p95": float(torch.quantile(p, 0.95)),
        "rot_median": float(r.median()),
        "rot_mean": float(r.mean()),
        "rot_p95": float(torch.quantile(r, 0.95)),
    }


def _fmt(s: dict, key: str, digits: int) -> str:
    return f"{s[key + '_median']:.{digits}f} / {s[key + '_mean']:.{digits}f} / {s[key + '_p95']:.{digits}f}"


def timed(runs: dict, repeats: int) -> dict:
    """``{name: fn}`` -> ``{name: (last result, wall median s, cpu median s)}``, run interleaved ``repeats`` times
    after one untimed warm-up call each (caches, first-call set-up)."""
    for fn in runs.values():
        fn()
    wall = {k: [] for k in runs}
    cpu = {k: [] for k in runs}
    out = {}
    for _ in range(repeats):
        for k, fn in runs.items():
            c0, t0 = time.thread_time(), time.perf_counter()
            out[k] = fn()
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.thread_time() - c0)
    return {k: (out[k], statistics.median(wall[k]), statistics.median(cpu[k])) for k in runs}


# -- raw and lm ----------------------------------------------------------------------------
def raw_network(robot, net, q: torch.Tensor, T: torch.Tensor) -> dict:
    hyp = net.hypotheses(T).to(T.dtype)
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = score(pos, rot).argmin(-1, keepdim=True)
    if isinstance(net, BranchIKNet | BranchHeadsIKNet):
        pick, single_name = net.labels(q)[:, None], "given branch"
    else:
        g = torch.Generator().manual_seed(7)
        pick, single_name = torch.randint(0, hyp.shape[1], (T.shape[0], 1), generator=g), "random head"
    return {
        "single_name": single_name,
        "single": _stats(pos.gather(1, pick)[:, 0], rot.gather(1, pick)[:, 0]),
        "best": _stats(pos.gather(1, best)[:, 0], rot.gather(1, best)[:, 0]),
        "K": hyp.shape[1],
    }


def lm_passes(robot, net, T: torch.Tensor, repeats: int) -> dict:
    """Success and (wall, cpu) seconds per target: ``best`` (LM from the best hypothesis only, forward pass
    included), ``solver`` (IKSolver with the network, fallback none), ``none`` (the same without a network)."""
    from nik.swarm import refine as swarm_refine

    with_net = nik.IKSolver(robot, checkpoint="auto", refine="lm", fallback="none", analytic=False)
    without = nik.IKSolver(robot, checkpoint=None, refine="lm", fallback="none", analytic=False)
    runs = {
        "best": lambda: (
            swarm_refine(robot, T, method="lm", q_init=net.predict(T), tol_pos=TOL_POS, tol_rot=TOL_ROT).success
        ),
        "solver": lambda: with_net.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=0).success,
        "none": lambda: without.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=0).success,
    }
    res = timed(runs, repeats)
    n = T.shape[0]
    return {k: (float(v[0].double().mean()), v[1] / n, v[2] / n) for k, v in res.items()}


def section_raw_lm(robots, args, sections) -> list[str]:
    lines = []
    raw_rows, lm_rows = [], []
    for name in robots:
        robot = nik.load_robot(name)
        net = load_pretrained(robot)
        q, T = _targets(robot, args.n, args.seed)
        if "raw" in sections:
            r = raw_network(robot, net, q, T)
            s, b = r["single"], r["best"]
            row = (
                f"| {name} | {net.config()['kind']} | {r['K']} | {r['single_name']} | {_fmt(s, 'pos', 1)} | "
                f"{_fmt(s, 'rot', 2)} | {_fmt(b, 'pos', 1)} | {_fmt(b, 'rot', 2)} |"
            )
            print(row, flush=True)
            raw_rows.append(row)
        if "lm" in sections:
            m = lm_passes(robot, net, T, args.repeats)
            row = (
                f"| {name} | "
                + " | ".join(
                    f"{100 * m[k][0]:.2f} % | {1e3 * m[k][1]:.3f} | {1e3 * m[k][2]:.3f}"
                    for k in ("best", "solver", "none")
                )
                + " |"
            )
            print(row, flush=True)
            lm_rows.append(row)
    if raw_rows:
        lines += [
            f"Raw networks, {args.n} random targets per arm (seed {args.seed}). Position mm, rotation deg, each as "
            "median / mean / p95.",
            "",
            "| arm | network | K | single shot | single pos | single rot | best-of-K pos | best-of-K rot |",
            "|---|---|---:|---|---:|---:|---:|---:|",
            *raw_rows,
            "",
        ]
    if lm_rows:
        lines += [
            f"One LM pass, no restarts, same targets; success within 0.1 mm and 0.1 deg; ms per target, wall / CPU "
            f"(median of {args.repeats}, interleaved).",
            "",
            "| arm | best hypothesis + LM: success | wall ms | CPU ms | solver (+ other hypotheses): success | wall ms "
            "| CPU ms | no network (LM from uniform starts): success | wall ms | CPU ms |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
            *lm_rows,
            "",
        ]
    return lines


# -- cost ----------------------------------------------------------------------------------
def cost_row(name: str, args) -> str:
    robot = nik.load_robot(name)
    net = load_pretrained(robot)
    _, T = _targets(robot, args.n_cost, args.seed + 10)
    solver = nik.IKSolver(robot, analytic=False)
    assert solver.plan(backend="torch").source == "network"
    hyp = net.hypotheses(T)
    with torch.no_grad():
        runs = {
            "forward": lambda: net.hypotheses(T),
            "rank": lambda: hypothesis_pose_error(robot, T, hyp),
            "solver": lambda: solver.solve(T, seed=0),
        }
        res = timed(runs, args.repeats)
    n = T.shape[0]
    f, r, s = (res[k] for k in ("forward", "rank", "solver"))
    return (
        f"| {name} | {net.config()['kind']} | {'x'.join(map(str, net.hidden))} | {net.n_params} | "
        f"{1e3 * f[1] / n:.4f} / {1e3 * f[2] / n:.4f} | {1e3 * r[1] / n:.4f} / {1e3 * r[2] / n:.4f} | "
        f"{1e3 * s[1] / n:.4f} / {1e3 * s[2] / n:.4f} | {100 * f[1] / s[1]:.0f} % / {100 * f[2] / s[2]:.0f} % | "
        f"{100 * float(s[0].success.double().mean()):.2f} % |"
    )


def section_cost(robots, args) -> list[str]:
    rows = []
    for name in robots:
        rows.append(cost_row(name, args))
        print(rows[-1], flush=True)
    return [
        f"Inference cost per target on a batch of {args.n_cost} (seed {args.seed + 10}), ms, wall / CPU (median of "
        f"{args.repeats}, interleaved). Forward: every hypothesis, decoded and clamped (`net.hypotheses`); rank: "
        "their FK pose errors; solver: `IKSolver(robot, analytic=False).solve` (network guess, LM, the other "
        "hypotheses where needed, restarts). Goal: forward <= 20 % of the solver.",
        "",
        "| arm | network | trunk | parameters | forward | rank by FK | solver | forward / solver | solver success |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
        *rows,
        "",
    ]


# -- pays ----------------------------------------------------------------------------------
def _pose_by_pose(solvers: dict, T: torch.Tensor, q_near=None) -> dict:
    """Single poses, one call each, the solvers interleaved pose by pose (A B A B ...), after one warm-up call
    each: ``{name: (success share, sources, wall us per call (n,), cpu us per call (n,))}``."""
    for s in solvers.values():
        s.solve(T[:1], seed=0)
    out = {k: [0, set(), [], []] for k in solvers}
    for i in range(T.shape[0]):
        kw = {} if q_near is None else {"q_near": q_near[i]}
        for k, s in solvers.items():
            c0, t0 = time.thread_time(), time.perf_counter()
            res = s.solve(T[i], seed=0, **kw)
            out[k][2].append(1e6 * (time.perf_counter() - t0))
            out[k][3].append(1e6 * (time.thread_time() - c0))
            out[k][0] += int(res.success[0])
            out[k][1].add(res.source)
    return {k: (v[0] / T.shape[0], v[1], torch.tensor(v[2]), torch.tensor(v[3])) for k, v in out.items()}


def pays_rows(name: str, label: str, kw: dict, args) -> list[str]:
    """Rows of one arm and solver variant: batches of each ``--pays-sizes``, single poses (with and without
    ``q_near``); the guess column is the ``source`` of the results (the guess that served)."""
    robot = nik.load_robot(name)
    a = nik.IKSolver(robot, **kw)
    b = nik.IKSolver(robot, checkpoint=None, **kw)
    rows = []
    for n in args.pays_sizes:
        _, Tb = _targets(robot, n, args.seed + 20 + n)
        holder = {}

        def run(s, key, Tb=Tb, holder=holder):
            holder[key] = s.solve(Tb, seed=0)
            return float(holder[key].success.double().mean())

        res = timed({"a": lambda: run(a, "a"), "b": lambda: run(b, "b")}, args.repeats)
        wa, wb = 1e3 * res["a"][1] / n, 1e3 * res["b"][1] / n
        ca, cb = 1e3 * res["a"][2] / n, 1e3 * res["b"][2] / n
        ita, itb = (float(holder[k].iterations.double().mean()) for k in "ab")
        rows.append(
            f"| {name} | {label} | batch of {n:,} | {holder['a'].source} | {100 * res['a'][0]:.2f} % | "
            f"{wa:.4f} / {ca:.4f} | {ita:.1f} | {holder['b'].source} | {100 * res['b'][0]:.2f} % | "
            f"{wb:.4f} / {cb:.4f} | {itb:.1f} | {wb / wa:.2f}x / {cb / ca:.2f}x |"
        )
        print(rows[-1], flush=True)
    _, To = _targets(robot, args.n_one, args.seed + 21)
    q_near = robot.sample(args.n_one, generator=torch.Generator().manual_seed(args.seed + 22), dtype=torch.float64)
    for case, near in ((f"one pose ({args.n_one} calls)", None), (f"one pose + q_near ({args.n_one} calls)", q_near)):
        res = _pose_by_pose({"a": a, "b": b}, To, near)
        (sa, srca, wa, ca), (sb, srcb, wb, cb) = res["a"], res["b"]

        def q(x, p):
            return float(torch.quantile(x.double(), p))

        rows.append(
            f"| {name} | {label} | {case} | {'/'.join(sorted(srca))} | {100 * sa:.2f} % | "
            f"median {q(wa, 0.5) / 1e3:.4f} / {q(ca, 0.5) / 1e3:.4f}, p99 {q(wa, 0.99) / 1e3:.4f} / "
            f"{q(ca, 0.99) / 1e3:.4f} | | {'/'.join(sorted(srcb))} | "
            f"{100 * sb:.2f} % | median {q(wb, 0.5) / 1e3:.4f} / {q(cb, 0.5) / 1e3:.4f}, p99 {q(wb, 0.99) / 1e3:.4f} / "
            f"{q(cb, 0.99) / 1e3:.4f} | | median {q(wb, 0.5) / q(wa, 0.5):.2f}x / {q(cb, 0.5) / q(ca, 0.5):.2f}x, p99 "
            f"{q(wb, 0.99) / q(wa, 0.99):.2f}x / {q(cb, 0.99) / q(ca, 0.99):.2f}x |"
        )
        print(rows[-1], flush=True)
    return rows


def section_pays(robots, args) -> list[str]:
    rows = []
    for name in robots:
        rows += pays_rows(name, "default", {}, args)
        if nik.IKSolver(name, checkpoint=None).closed_form:
            rows += pays_rows(name, "analytic=False", {"analytic": False}, args)
    return [
        "Does the network pay for itself? `IKSolver(robot, **kw)` (its network where it has one: on the CPU the "
        "compiled backend and the arm's single-pose network) against "
        f"`IKSolver(robot, checkpoint=None, **kw)`, on batches of {', '.join(f'{n:,}' for n in args.pays_sizes)} "
        f"targets (median of {args.repeats} interleaved runs) and on {args.n_one} single poses (one call each, the "
        "two solvers interleaved pose by pose; q_near: a random configuration per pose). 'guess' is the `source` "
        "the results report. Success within 0.1 mm / 0.1 deg; ms per target, wall / CPU of this thread; 'it': LM "
        "iterations per target. Speed-up > 1: the default is faster.",
        "",
        "| arm | solver | case | guess | success | ms | it | guess without network | success | ms | it | speed-up |",
        "|---|---|---|---|---:|---:|---:|---|---:|---:|---:|---:|",
        *rows,
        "",
    ]


# -- stream --------------------------------------------------------------------------------
def section_stream(args) -> list[str]:
    from nik.data.branches import ik_branch_classifier
    from nik.learn.multi import pose_loss_per_sample
    from nik.learn.recipe import DEFAULT_HIDDEN, choose_kind
    from nik.learn.stream import fk_samples
    from nik.nets.multi import KINDS

    rows = []
    for name in ("panda", "ur5"):
        robot = nik.load_robot(name)
        g = torch.Generator().manual_seed(0)
        clf = ik_branch_classifier(robot)
        pool_T, pool_q = fk_samples(robot, 200_000, g, torch.float32)
        kind = choose_kind(robot)[0]
        net = KINDS[kind](robot, hidden=DEFAULT_HIDDEN).fit_normalisation(pool_T[:20000])
        opt = torch.optim.Adam(net.parameters(), lr=1e-4)
        T0, q0 = pool_T[:1024], pool_q[:1024]

        def step(net=net, opt=opt, T0=T0, q0=q0, robot=robot, kind=kind):
            if kind == "branch_heads":
                qh = net.decode(net.raw_branch(T0, net.labels(q0)))
                loss = pose_loss_per_sample(qh, T0, robot, length_scale=net.length_scale).mean()
            else:
                qh = net.decode(net.raw_hypotheses(T0)).transpose(0, 1)
                loss = pose_loss_per_sample(qh, T0, robot, length_scale=net.length_scale).amin(0).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()

        def stream(robot=robot, g=g, clf=clf):
            T, q = fk_samples(robot, 1024, g, torch.float32)
            return clf(q.double()) if clf is not None else T

        def from_memory(g=g, pool_T=pool_T, pool_q=pool_q):
            idx = torch.randint(0, pool_T.shape[0], (1024,), generator=g)
            return pool_T.index_select(0, idx), pool_q.index_select(0, idx)

        res = timed({"stream": stream, "memory": from_memory, "step": step}, max(5, args.repeats * 3))
        s, m, st = (res[k] for k in ("stream", "memory", "step"))
        row = (
            f"| {name} | {kind} | {'FK + branch labels' if clf is not None else 'FK'} | {1e3 * s[1]:.2f} / "
            f"{1e3 * s[2]:.2f} | {1e3 * m[1]:.3f} / {1e3 * m[2]:.3f} | {1e3 * st[1]:.1f} / {1e3 * st[2]:.1f} | "
            f"{100 * s[2] / st[2]:.1f} % |"
        )
        print(row, flush=True)
        rows.append(row)
    return [
        "Training data per step of `nik train` (batch 1,024, float32, one thread), ms, wall / CPU: fresh FK samples "
        "(float64 FK) against a batch taken from tensors in memory (a loaded dataset file), and one training step "
        "of the default 4 x 256 network (pose loss, Adam). Streaming costs the share in the last column and gives "
        "every step new samples; `nik train` streams by default (`--data DIR` takes a dataset).",
        "",
        "| arm | network | fresh samples | stream | from memory | training step | stream / step (CPU) |",
        "|---|---|---|---:|---:|---:|---:|",
        *rows,
        "",
    ]


# -- all solutions and paper C (issue 9, unchanged) ------------------------------------------
def all_solutions(robot, T: torch.Tensor, n_starts: int) -> tuple[float, float, float, float]:
    """Median found, median closed-form count, median fraction found, share of targets with all found."""
    from nik.analytic import puma560_ik

    solver = nik.IKSolver(robot, analytic=False)
    found, total = [], []
    for i in range(T.shape[0]):
        sols, valid = puma560_ik(robot, T[i])
        ref = sols[valid]
        got = solver.solve_all(T[i : i + 1], n_starts=n_starts, tol_pos=TOL_POS, tol_rot=TOL_ROT)
        if ref.shape[0] == 0:
            continue
        if got.shape[0] == 0:
            n = 0
        else:
            d = torch.remainder(ref[:, None] - got[None] + math.pi, 2 * math.pi) - math.pi
            n = int((d.abs().amax(-1) < 1e-2).any(-1).sum())
        found.append(n)
        total.append(ref.shape[0])
    all_found = sum(f == t for f, t in zip(found, total, strict=True)) / len(found)
    frac = statistics.median(f / t for f, t in zip(found, total, strict=True))
    return statistics.median(found), statistics.median(total), frac, all_found


def section_all(robots, args) -> list[str]:
    from nik.analytic import puma560_ik

    rows = []
    for name in [r for r in robots if r in ("kuka_kr", "puma560")]:
        robot = nik.load_robot(name)
        _, pool = _targets(robot, max(args.n, args.n_all), args.seed + 1)
        eight = pool[puma560_ik(robot, pool)[1].sum(-1) == 8][: args.n_all]
        for subset, T in ((f"random, first {args.n_all}", pool[: args.n_all]), (f"all 8 valid, {len(eight)}", eight)):
            for n_starts in (0, 32):
                med, med_total, frac, share = all_solutions(robot, T, n_starts)
                row = f"| {name} | {subset} | {n_starts} | {med:g} | {med_total:g} | {100 * frac:.0f} % "
                row += f"| {100 * share:.0f} % |"
                print(row, flush=True)
                rows.append(row)
    if not rows:
        return []
    return [
        "All solutions, `IKSolver(robot, analytic=False).solve_all(T, n_starts=...)` (LM from the 8 branch "
        "hypotheses, then n_starts uniform starts) against the closed form's valid solutions (a match: every joint "
        "within 0.01 rad, modulo 2 pi).",
        "",
        "| arm | targets | uniform starts | found (median) | valid closed-form solutions (median) "
        "| found / closed form (median) | targets with all found |",
        "|---|---|---:|---:|---:|---:|---:|",
        *rows,
        "",
    ]


def paper_c_given_branch(data: Path, branch: int, budget: float) -> list[dict]:
    from nik.learn.cli import cli_main, method_config
    from nik.learn.losses import evaluate

    out = []
    for method in ("bp", "de_bp"):
        extra = ["--model.fitness_samples", "1000"] if method == "de_bp" else []
        b = int(math.ceil(budget))
        args = ["fit", "--config", str(method_config(method)), "--data.path", str(data), "--data.branch", str(branch)]
        args += [
            "--data.verify",
            "false",
            "--seed_everything",
            "0",
            "--trainer.max_time",
            f"00:00:{b // 60:02d}:{b % 60:02d}",
        ]
        args += ["--trainer.max_epochs", "-1", "--trainer.logger", "false", "--trainer.enable_progress_bar", "false"]
        args += ["--trainer.enable_model_summary", "false", "--trainer.check_val_every_n_epoch", "100"]
        args += ["--trainer.default_root_dir", f"runs/learned_bench/paper_{method}", *extra]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cli = cli_main(args)
        net = cli.model.net.eval()
        T, q = cli.datamodule.test_data
        m = evaluate(net, T, q)
        pick = torch.randperm(T.shape[0], generator=torch.Generator().manual_seed(1000))[:8]
        dq = (torch.remainder(net.predict(T) - q + math.pi, 2 * math.pi) - math.pi).abs().rad2deg().amax(-1)
        m.update(method=method, n_test=int(T.shape[0]), max8=float(dq[pick].max()))
        m.update(within=float((dq <= 0.003).double().mean()), wall=cli.model.wall_s)
        out.append(m)
    return out


def section_paper(args) -> list[str]:
    if args.paper_budget <= 0 or not args.paper_data.is_dir():
        print(f"paper section skipped (budget {args.paper_budget}, data {args.paper_data})")
        return []
    res = paper_c_given_branch(args.paper_data, args.paper_branch, args.paper_budget)
    lines = [
        f"Paper C's 6-8-6 tanh net given the branch label (branch {args.paper_branch} of `{args.paper_data}`), "
        f"{args.paper_budget:g} s per method, seed 0; test split of {res[0]['n_test']} poses:",
        "",
        "| method | wall s | pos median / p95 (mm) | rot median / p95 (deg) | joint RMSE (deg) | max joint error "
        "on 8 test poses (deg, mod 2 pi) | test poses with every joint within 0.003 deg |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for m in res:
        row = (
            f"| {m['method']} | {m['wall']:.0f} | {m['pos_mm_median']:.0f} / {m['pos_mm_p95']:.0f} | "
            f"{m['rot_deg_median']:.1f} / {m['rot_deg_p95']:.1f} | {m['joint_rmse_deg']:.1f} | {m['max8']:.1f} | "
            f"{100 * m['within']:.2f} % |"
        )
        print(row, flush=True)
        lines.append(row)
    return [*lines, ""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS), help="default: all")
    ap.add_argument("--robots", nargs="+", default=None, help="default: every robot with a shipped network")
    ap.add_argument("--n", type=int, default=2000, help="random targets per arm (raw, lm)")
    ap.add_argument("--n-cost", type=int, default=10000, help="batch size of the cost section")
    ap.add_argument("--n-one", type=int, default=300, help="single poses of the pays section")
    ap.add_argument(
        "--pays-sizes", type=int, nargs="+", default=[100, 1000, 10000], help="batch sizes of the pays section"
    )
    ap.add_argument("--n-all", type=int, default=100, help="targets for the all-solutions count")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--repeats", type=int, default=3, help="interleaved timed repeats")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--paper-data", type=Path, default=Path("data/kuka_kr_1m"), help="kuka_kr dataset with labels")
    ap.add_argument("--paper-branch", type=int, default=0)
    ap.add_argument("--paper-budget", type=float, default=60.0, help="seconds per paper C run (0: skip)")
    ap.add_argument("--out", type=Path, default=None, help="markdown file for the results")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    nik.set_threads(args.threads)
    robots = args.robots or sorted({st.stem for st, _ in index([SHIPPED_DIR]) if role_of(st) is None})
    lines = [
        f"`python benchmarks/learned.py {' '.join(argv) if argv is not None else ''}`".replace(" `", "`"),
        "",
        f"Networks: {', '.join(robots)}; CPU, {torch.get_num_threads()} torch thread(s). Targets: FK poses of uniform "
        "joints inside the full limits. Position mm, rotation degrees.",
        "",
    ]
    sections = set(args.sections)
    if sections & {"raw", "lm"}:
        lines += section_raw_lm(robots, args, sections)
    if "cost" in sections:
        lines += section_cost(robots, args)
    if "pays" in sections:
        lines += section_pays(robots, args)
    if "stream" in sections:
        lines += section_stream(args)
    if "all" in sections:
        lines += section_all(robots, args)
    if "paper" in sections:
        lines += section_paper(args)
    text = "\n".join(lines) + "\n"
    print()
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_name(args.out.name + ".tmp")
        tmp.write_text(text)
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    import sys

    raise SystemExit(main(sys.argv[1:]))
