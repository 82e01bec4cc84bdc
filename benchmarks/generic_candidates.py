"""Candidates for the generic multi-solution network (arms without branch labels, redundant arms), side by side.

    python benchmarks/generic_candidates.py --data data/panda_1m --budget 180 \
        --out benchmarks/results/generic_candidates_panda.md

Same training data (the dataset's train split), same wall-clock budget per candidate, one torch thread,
same evaluation (``--n-eval`` poses from uniform joints inside the limits, seed 12345, as the shipped
networks' recorded validation): position / rotation error of the first hypothesis ("single") and of the
best of K by FK ("best of K"), medians and p95, mm and degrees.

Candidates:

- ``mlp``: one head (a plain regression; it averages solutions), joint loss then pose loss;
- ``multihead``: :class:`nik.nets.multi.MultiHypIKNet`, K = 8 heads, relaxed winner-takes-all joint loss, then
  pose loss (the training of ``configs/train/panda.yaml``, shortened);
- ``flow``: a conditional neural spline flow (``zuko.flows.NSF``, context = the standardised pose) over the
  joints scaled to [-1, 1], trained by maximum likelihood (as IKFlow); hypotheses = K samples of its base
  noise (the first one at the mode z = 0).

Each gradient candidate switches from the joint to the pose loss at half its budget.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import torch

from nik.data import load_dataset
from nik.learn.multi import pose_loss_per_sample
from nik.nets.multi import MultiHypIKNet, hypothesis_pose_error
from nik.tolerances import score


def _evaluate(robot, hyp_fn, n: int, seed: int = 12345) -> dict:
    g = torch.Generator().manual_seed(seed)
    q = robot.sample(n, generator=g, dtype=torch.float64)
    T = robot.fk(q)
    with torch.no_grad():
        hyp = robot.clamp(hyp_fn(T.float()).double())  # (B, K, dof)
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = score(pos, rot).argmin(-1, keepdim=True)
    out = {}
    for name, (p, r) in {
        "single": (pos[:, 0], rot[:, 0]),
        "best": (pos.gather(1, best)[:, 0], rot.gather(1, best)[:, 0]),
    }.items():
        p, r = p * 1e3, torch.rad2deg(r)
        out[name] = (
            float(p.median()),
            float(torch.quantile(p, 0.95)),
            float(r.median()),
            float(torch.quantile(r, 0.95)),
        )
    return out


def _train_multihead(robot, T, q, heads: int, budget: float, seed: int, batch: int = 1024):
    torch.manual_seed(seed)
    net = MultiHypIKNet(robot, hidden=[512, 512, 512], heads=heads).fit_normalisation(T)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    target_all = None
    t0, steps, n = time.perf_counter(), 0, T.shape[0]
    g = torch.Generator().manual_seed(seed)
    while (elapsed := time.perf_counter() - t0) < budget:
        frac = elapsed / budget
        for pg in opt.param_groups:
            pg["lr"] = 1e-3 * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * frac)))
        idx = torch.randint(0, n, (batch,), generator=g)
        Tb, qb = T[idx], q[idx]
        y = net.raw_hypotheses(Tb)
        loss = (y - net.encode(qb)[:, None]).square().sum(-1)
        if frac >= 0.5:
            pl = pose_loss_per_sample(net.decode(y).transpose(0, 1), Tb, robot, length_scale=net.length_scale)
            loss = pl.transpose(0, 1) + 0.01 * loss
        loss = 0.95 * loss.amin(-1) + 0.05 * loss.mean(-1) if heads > 1 else loss[:, 0]
        opt.zero_grad()
        loss.mean().backward()
        opt.step()
        steps += 1
    del target_all
    net.eval()
    return net.hypotheses, steps, net.n_params


def _train_flow(robot, T, q, budget: float, seed: int, k: int, batch: int = 1024):
    import zuko

    torch.manual_seed(seed)
    feat = MultiHypIKNet(robot, hidden=[1], heads=1).fit_normalisation(T)  # its input standardisation only
    lo, hi = robot.limits[:, 0].float(), robot.limits[:, 1].float()
    center, half = (lo + hi) / 2, (hi - lo) / 2
    flow = zuko.flows.NSF(features=robot.dof, context=feat.pose_dim, transforms=5, hidden_features=[256, 256])
    opt = torch.optim.Adam(flow.parameters(), lr=5e-4)
    t0, steps, n = time.perf_counter(), 0, T.shape[0]
    g = torch.Generator().manual_seed(seed)
    while (elapsed := time.perf_counter() - t0) < budget:
        frac = elapsed / budget
        for pg in opt.param_groups:
            pg["lr"] = 5e-4 * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * frac)))
        idx = torch.randint(0, n, (batch,), generator=g)
        x = (q[idx] - center) / half
        loss = -flow(feat.features(T[idx])).log_prob(x).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        steps += 1

    def hyp(Tq: torch.Tensor) -> torch.Tensor:
        c = feat.features(Tq)
        dist = flow(c)
        # the flow's transform of base noise: z = 0 (the mode of the base) first, then K - 1 draws
        gz = torch.Generator().manual_seed(0)
        z = torch.randn(k, Tq.shape[0], robot.dof, generator=gz)
        z[0] = 0
        x = dist.transform.inv(z)  # (K, B, dof)
        return (center + half * x).transpose(0, 1)

    return hyp, steps, sum(p.numel() for p in flow.parameters())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/panda_1m")
    ap.add_argument("--budget", type=float, default=180.0, help="seconds of training per candidate")
    ap.add_argument("--n-train", type=int, default=400_000)
    ap.add_argument("--n-eval", type=int, default=2000)
    ap.add_argument("--k", type=int, default=8, help="hypotheses per pose")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--candidates", nargs="+", default=["mlp", "multihead", "flow"])
    ap.add_argument("--out", default=None, help="markdown file for the table")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    ds = load_dataset(args.data, verify=False, mmap=False)
    robot = ds.robot
    T, q = ds.train.pose[: args.n_train].float(), ds.train.q[: args.n_train].float()
    rows = []
    for name in args.candidates:
        if name == "flow":
            hyp, steps, params = _train_flow(robot, T, q, args.budget, args.seed, args.k)
        else:
            hyp, steps, params = _train_multihead(robot, T, q, 1 if name == "mlp" else args.k, args.budget, args.seed)
        res = _evaluate(robot, hyp, args.n_eval)
        rows.append((name, params, steps, res))
        print(name, params, steps, res, flush=True)
    lines = [
        f"Generic multi-solution candidates on `{args.data}` ({robot.name}): {args.budget:.0f} s of training each on "
        f"one CPU thread, batch 1024, first {args.n_train} training samples, seed {args.seed}; evaluated on "
        f"{args.n_eval} poses from uniform joints inside the full limits (seed 12345). K = {args.k} hypotheses "
        "(mlp: 1). Errors: position mm / rotation degrees, median and p95.",
        "",
        "| candidate | params | steps | single pos median | single pos p95 | single rot median | single rot p95 "
        "| best-of-K pos median | best-of-K pos p95 | best-of-K rot median | best-of-K rot p95 |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, params, steps, res in rows:
        s, b = res["single"], res["best"]
        lines.append(
            f"| {name} | {params} | {steps} | {s[0]:.1f} | {s[1]:.1f} | {s[2]:.2f} | {s[3]:.2f} "
            f"| {b[0]:.1f} | {b[1]:.1f} | {b[2]:.2f} | {b[3]:.2f} |"
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".tmp")
        tmp.write_text(text)
        tmp.replace(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
