"""The shipped multi-solution networks, measured (issue 9): one run, a printed table, results in a file.

    python benchmarks/learned.py --out benchmarks/results/learned.md

Per arm with a shipped network (``nik/pretrained``), on ``--n`` (2,000) random targets from uniform joints
inside the full limits (seed 2026), one torch thread, CPU:

1. **raw network**: median and p95 of the position (mm) and rotation (deg) error of a single shot (branch
   net: the hypothesis of the reference joints' branch label, i.e. the label given; multi-head net: one
   head drawn at random per target, seeded) and of the best hypothesis by FK;
2. **network + one LM pass, no restarts** (:func:`lm_passes`): LM from the network's best hypothesis alone;
   ``IKSolver(robot, refine="lm", fallback="none", analytic=False)`` (the same, then LM from the other
   hypotheses for the targets still outside tolerance); and that solver without a network (LM from
   ``LMCfg.starts`` uniform starts): success within 0.1 mm / 0.1 deg and time per target (the batch's wall
   time / n, median of ``--repeats``, the three interleaved);
3. **all solutions** (PUMA-like arms: ``kuka_kr``, ``puma560``): on ``--n-all`` targets,
   ``IKSolver(robot, analytic=False).solve_all(T, n_starts=0)`` (LM from the 8 branch hypotheses only) and with
   ``n_starts=32``; how many of the closed form's valid solutions it finds (median, and the share of targets
   where it finds all of them);
4. **paper C given the branch label**: paper C's 6-8-6 tanh net trained on one IK branch of kuka_kr
   (``--data.branch``), by BP and DE-BP (``configs/train/bp.yaml``, ``de_bp.yaml``) for ``--paper-budget``
   seconds each; test-split pose errors and paper C's check (every joint within 0.003 deg on 8 test poses;
   joint errors taken modulo 2 pi).
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
from nik.nets import load_pretrained, pretrained_robots
from nik.nets.multi import BranchIKNet, hypothesis_pose_error
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

TOL_POS, TOL_ROT = DEFAULT_TOL_POS, DEFAULT_TOL_ROT  # m, rad: 0.1 mm / 0.1 deg, nik's one tolerance


def _stats(pos: torch.Tensor, rot: torch.Tensor) -> tuple[float, float, float, float]:
    p, r = pos * 1e3, torch.rad2deg(rot)
    return float(p.median()), float(torch.quantile(p, 0.95)), float(r.median()), float(torch.quantile(r, 0.95))


def raw_network(robot, net, q: torch.Tensor, T: torch.Tensor) -> dict:
    hyp = net.hypotheses(T).to(T.dtype)
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = (pos + 0.1 * rot).argmin(-1, keepdim=True)
    if isinstance(net, BranchIKNet):
        pick = net.labels(q)[:, None]
        single_name = "given branch"
    else:
        g = torch.Generator().manual_seed(7)
        pick = torch.randint(0, hyp.shape[1], (T.shape[0], 1), generator=g)
        single_name = "random head"
    return {
        "single_name": single_name,
        "single": _stats(pos.gather(1, pick)[:, 0], rot.gather(1, pick)[:, 0]),
        "best": _stats(pos.gather(1, best)[:, 0], rot.gather(1, best)[:, 0]),
        "K": hyp.shape[1],
    }


def lm_passes(robot, net, T: torch.Tensor, repeats: int) -> dict[str, tuple[float, float]]:
    """Success and seconds per target of three ways to one LM pass, timed interleaved (A, B, C, A, B, C, ...):

    ``best``: LM from the network's best hypothesis only (``nik.swarm.refine(method="lm", q_init=...)``, the
    network's forward pass included in the time); ``solver``: ``IKSolver(refine="lm", fallback="none")``, i.e.
    the same, then LM from the other hypotheses for the targets still outside tolerance; ``none``: the same
    solver without a network (LM from ``LMCfg.starts`` uniform starts)."""
    from nik.swarm import refine as swarm_refine

    with_net = nik.IKSolver(robot, checkpoint="auto", refine="lm", fallback="none", analytic=False)
    without = nik.IKSolver(robot, checkpoint=None, refine="lm", fallback="none", analytic=False)

    def best():
        res = swarm_refine(robot, T, method="lm", q_init=net.predict(T), tol_pos=TOL_POS, tol_rot=TOL_ROT)
        return res.success

    runs = {
        "best": best,
        "solver": lambda: with_net.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=0).success,
        "none": lambda: without.solve(T, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=0).success,
    }
    times = {k: [] for k in runs}
    ok = {}
    for _ in range(repeats):
        for k, fn in runs.items():
            t0 = time.perf_counter()
            ok[k] = float(fn().double().mean())
            times[k].append(time.perf_counter() - t0)
    return {k: (ok[k], statistics.median(times[k]) / T.shape[0]) for k in runs}


def all_solutions(robot, T: torch.Tensor, n_starts: int) -> tuple[float, float, float, float]:
    """Median found, median closed-form count, median fraction found, share of targets with all found
    (targets whose closed form has no valid solution are left out)."""
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


def paper_c_given_branch(data: Path, branch: int, budget: float) -> list[dict]:
    from nik.learn.cli import cli_main, method_config
    from nik.learn.losses import evaluate

    out = []
    for method in ("bp", "de_bp"):
        extra = ["--model.fitness_samples", "1000"] if method == "de_bp" else []
        b = int(math.ceil(budget))
        args = [
            "fit",
            "--config",
            str(method_config(method)),
            "--data.path",
            str(data),
            "--data.branch",
            str(branch),
            "--data.verify",
            "false",
            "--seed_everything",
            "0",
            "--trainer.max_time",
            f"00:00:{b // 60:02d}:{b % 60:02d}",
            "--trainer.max_epochs",
            "-1",
            "--trainer.logger",
            "false",
            "--trainer.enable_progress_bar",
            "false",
            "--trainer.enable_model_summary",
            "false",
            "--trainer.check_val_every_n_epoch",
            "100",
            "--trainer.default_root_dir",
            f"runs/learned_bench/paper_{method}",
            *extra,
        ]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cli = cli_main(args)
        net = cli.model.net.eval()
        T, q = cli.datamodule.test_data
        m = evaluate(net, T, q)
        g = torch.Generator().manual_seed(1000)
        pick = torch.randperm(T.shape[0], generator=g)[:8]
        # modulo 2 pi: kuka_kr's joints 4 and 6 span more than a turn, so even a branch leaves q and q +- 2 pi
        dq = (torch.remainder(net.predict(T) - q + math.pi, 2 * math.pi) - math.pi).abs().rad2deg().amax(-1)
        m.update(
            method=method,
            n_test=int(T.shape[0]),
            max8=float(dq[pick].max()),
            within=float((dq <= 0.003).double().mean()),
            wall=cli.model.wall_s,
        )
        out.append(m)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="random targets per arm")
    ap.add_argument("--n-all", type=int, default=100, help="targets for the all-solutions count")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--repeats", type=int, default=3, help="timed repeats of the LM pass")
    ap.add_argument("--robots", nargs="+", default=None, help="default: every robot with a shipped network")
    ap.add_argument("--paper-data", type=Path, default=Path("data/kuka_kr_1m"), help="kuka_kr dataset with labels")
    ap.add_argument("--paper-branch", type=int, default=0)
    ap.add_argument("--paper-budget", type=float, default=60.0, help="seconds per paper C run (0: skip)")
    ap.add_argument("--out", type=Path, default=None, help="markdown file for the results")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    robots = args.robots or pretrained_robots()
    lines = [
        f"Shipped networks (nik/pretrained), {args.n} random targets per arm from uniform joints inside the full "
        f"limits (seed {args.seed}); CPU, {torch.get_num_threads()} torch thread. Errors: position mm, rotation "
        "degrees. Success: within 0.1 mm and 0.1 deg.",
        "",
        "| arm | network | K | single shot | single pos median / p95 | single rot median / p95 | best-of-K pos median "
        "/ p95 | best-of-K rot median / p95 | best hypothesis + 1 LM pass: success | ms / target | solver: + LM from "
        "the other hypotheses where needed: success | ms / target | LM from 32 uniform starts, no net: success "
        "| ms / target |",
        "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name in robots:
        robot = nik.load_robot(name)
        net = load_pretrained(robot)
        g = torch.Generator().manual_seed(args.seed)
        q = robot.sample(args.n, generator=g, dtype=torch.float64)
        T = robot.fk(q)
        raw = raw_network(robot, net, q, T)
        lm = lm_passes(robot, net, T, args.repeats)
        s, b = raw["single"], raw["best"]
        row = (
            f"| {name} | {net.config()['kind']} | {raw['K']} | {raw['single_name']} | {s[0]:.1f} / {s[1]:.1f} | "
            f"{s[2]:.2f} / {s[3]:.2f} | {b[0]:.1f} / {b[1]:.1f} | {b[2]:.2f} / {b[3]:.2f} | "
            + " | ".join(f"{100 * lm[k][0]:.2f} % | {1e3 * lm[k][1]:.2f}" for k in ("best", "solver", "none"))
            + " |"
        )
        print(row, flush=True)
        lines.append(row)
    sol_lines = []
    for name in [r for r in robots if r in ("kuka_kr", "puma560")]:
        robot = nik.load_robot(name)
        from nik.analytic import puma560_ik

        g = torch.Generator().manual_seed(args.seed + 1)
        pool = robot.fk(robot.sample(max(args.n, args.n_all), generator=g, dtype=torch.float64))
        n_valid = puma560_ik(robot, pool)[1].sum(-1)
        eight = pool[n_valid == 8][: args.n_all]  # poses the closed form reaches in all 8 ways inside the limits
        for subset, T in ((f"random, first {args.n_all}", pool[: args.n_all]), (f"all 8 valid, {len(eight)}", eight)):
            for n_starts in (0, 32):
                med, med_total, frac, share = all_solutions(robot, T, n_starts)
                row = (
                    f"| {name} | {subset} | {n_starts} | {med:g} | {med_total:g} | {100 * frac:.0f} % "
                    f"| {100 * share:.0f} % |"
                )
                print(row, flush=True)
                sol_lines.append(row)
    if sol_lines:
        lines += [
            "",
            f"All solutions, `IKSolver(robot, analytic=False).solve_all(T, n_starts=...)` (LM from the 8 branch "
            f"hypotheses, then n_starts uniform starts) against the closed form's valid solutions (a match: every "
            f"joint within 0.01 rad, modulo 2 pi). Targets: {args.n_all} random ones (seed {args.seed + 1}), and "
            f"those of {max(args.n, args.n_all)} random ones (same seed) whose 8 closed-form solutions are all "
            "inside the limits (most targets have only 2 or 4 there):",
            "",
            "| arm | targets | uniform starts | found (median) | valid closed-form solutions (median) "
            "| found / closed form (median) | targets with all found |",
            "|---|---|---:|---:|---:|---:|---:|",
            *sol_lines,
        ]
    if args.paper_budget > 0:
        res = paper_c_given_branch(args.paper_data, args.paper_branch, args.paper_budget)
        lines += [
            "",
            f"Paper C's 6-8-6 tanh net given the branch label (trained and tested on branch {args.paper_branch} "
            f"of `{args.paper_data}` only), {args.paper_budget:g} s per method, seed 0; test split of "
            f"{res[0]['n_test']} poses:",
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
    raise SystemExit(main())
