"""Raw accuracy of the shipped 7-joint networks (no LM), measured as IKFlow and PAIK measure it (issue 48).

    python benchmarks/raw_accuracy.py --out benchmarks/results/raw_accuracy.md
    python benchmarks/raw_accuracy.py --robots panda --n 500 --net path/to/panda.safetensors   # another file

How this matches their protocol:

- **Errors.** IKFlow (``ikflow/evaluation_utils.py``, ``solution_pose_errors`` / ``get_solution_errors``) and PAIK
  (which evaluates with the same ``jrl`` helper) compute, per IK solution, the L2 norm of the end effector's position
  error and the geodesic angle between the reached and the target orientation (``geodesic_distance`` of the rotation
  matrices). Here: :func:`nik.poses.pose_error` (Euclidean position distance, angle of ``R_target^T R``), float64 FK,
  printed in mm and degrees.
- **Samples.** Their samplers draw M solutions per target and every one counts; a multi-hypothesis network's every
  head is such a sample (``per sample``: all K heads of all targets). The ``best of heads`` row (the head with the
  smallest FK error, :func:`nik.tolerances.score`) is reported separately: it is not their per-sample figure.
- **Targets.** FK poses of joints drawn uniformly inside the limits (seeded ``torch.Generator``), as their test sets
  are; mean and median over samples and targets together.
- **Raw.** The network's hypotheses clamped to the limits (``net.hypotheses``), no LM, no restarts.

Rows beyond theirs: ``+ k LM iterations``: every head polished on its own by ``k`` iterations of nik's LM
(:func:`nik.ik.samples.network_samples`: no restarts, the limits held; the samples a user gets from the network),
reported apart from the network alone. ``distinct / target``: samples of a target more than 0.1 rad apart in some
joint from every earlier one (the polish must not collapse the heads onto one solution). ``us / target``: wall time
of the forward pass (all heads), and of the forward pass plus the iterations (torch, one thread).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from nik.ik.samples import SampleCfg, network_samples
from nik.nets import load_pretrained
from nik.nets.multi import hypothesis_pose_error
from nik.nets.pair import load_pair
from nik.tolerances import score

#: The results file's hand-written section (what was tried to improve the figures) starts here; a rerun keeps it.
NOTES = "## What was tried"
#: Published per-sample figures on panda (mean position / rotation error), for the table.
PUBLISHED = {"PAIK (panda)": (2.9, 1.5), "IKFlow (panda)": (5.4, 2.0)}


def targets(robot, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` uniform joint vectors inside the limits (seeded) and their float64 FK poses."""
    q = robot.sample(int(n), generator=torch.Generator().manual_seed(int(seed)), dtype=torch.float64)
    return q, robot.fk(q)


def stats(pos: torch.Tensor, rot: torch.Tensor) -> dict:
    """Mean / median / p95 of position (mm) and rotation (deg) errors given in m and rad (any shape, flattened)."""
    p, r = pos.reshape(-1) * 1e3, torch.rad2deg(rot.reshape(-1))
    q95 = torch.tensor(0.95, dtype=p.dtype)
    return {
        "n": p.numel(),
        "pos_mean": float(p.mean()),
        "pos_median": float(p.median()),
        "pos_p95": float(torch.quantile(p, q95)),
        "rot_mean": float(r.mean()),
        "rot_median": float(r.median()),
        "rot_p95": float(torch.quantile(r, q95)),
    }


def distinct(q: torch.Tensor, tol: float = 0.1) -> float:
    """Mean number of distinct samples per target in ``q: (B, K, dof)``: a sample counts when every earlier one of
    its target differs from it by more than ``tol`` rad in some joint (how many solutions the samples really give)."""
    d = (q[:, :, None] - q[:, None]).abs().amax(-1)  # (B, K, K)
    earlier = torch.ones(q.shape[1], q.shape[1], dtype=torch.bool).tril(-1)
    same = (d <= tol) & earlier
    return float((~same.any(-1)).sum(-1).double().mean())


def measure(net, n: int, seed: int, iters: tuple[int, ...]) -> list[tuple[str, dict]]:
    """Rows ``(label, stats)`` of one network on ``n`` targets: every head, head 0, best of heads, and every head
    polished by ``k`` LM iterations (:func:`nik.ik.samples.network_samples`)."""
    robot = net.robot
    _, T = targets(robot, n, seed)
    t0 = time.perf_counter()
    hyp = net.hypotheses(T)
    fwd_s = time.perf_counter() - t0
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = score(pos, rot).argmin(-1, keepdim=True)
    rows = [
        (f"per sample (all {hyp.shape[1]} heads)", stats(pos, rot)),
        ("head 0 only", stats(pos[:, 0], rot[:, 0])),
        ("best of heads", stats(pos.gather(1, best), rot.gather(1, best))),
    ]
    rows[0][1].update(us=1e6 * fwd_s / n, distinct=distinct(hyp))
    for k in iters:
        t0 = time.perf_counter()
        qk = network_samples(net, T, SampleCfg(iters=k))
        s = time.perf_counter() - t0
        pk, rk = hypothesis_pose_error(robot, T, qk)
        row = {**stats(pk, rk), "us": 1e6 * s / n, "distinct": distinct(qk)}
        rows.append((f"per sample, + {k} LM iterations", row))
    return rows


def table(name: str, meta: str, rows: list[tuple[str, dict]]) -> str:
    out = [
        f"### {name}",
        "",
        meta,
        "",
        "| samples | n | pos mean mm | pos median mm | pos p95 mm | rot mean deg | rot median deg | rot p95 deg "
        "| distinct / target | us / target |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, s in rows:
        out.append(
            f"| {label} | {s['n']} | {s['pos_mean']:.2f} | {s['pos_median']:.2f} | {s['pos_p95']:.2f} | "
            f"{s['rot_mean']:.2f} | {s['rot_median']:.2f} | {s['rot_p95']:.2f} | "
            + (f"{s['distinct']:.2f} | " if "distinct" in s else " | ")
            + (f"{s['us']:.0f} |" if "us" in s else " |")
        )
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "xarm7"])
    ap.add_argument("--net", nargs="*", default=None, help="network files (.safetensors), one per robot, in order")
    ap.add_argument("--n", type=int, default=2000, help="targets per arm")
    ap.add_argument("--seed", type=int, default=4848)
    ap.add_argument("--iters", type=int, nargs="*", default=[3, 5], help="rows of every head + k LM iterations")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    parts = [
        f"Command: `python benchmarks/raw_accuracy.py {' '.join(sys.argv[1:] if argv is None else argv)}`".rstrip()
        + "\n",
        f"Targets: {a.n} per arm, FK of uniform joints inside the limits (seed {a.seed}); float64 FK; CPU, "
        f"{a.threads} thread(s). Published per sample (mean): "
        + ", ".join(f"{k} {p} mm / {r} deg" for k, (p, r) in PUBLISHED.items())
        + ".\n",
    ]
    for i, name in enumerate(a.robots):
        if a.net:
            net = load_pair(Path(a.net[i])).eval()
            src = a.net[i]
        else:
            net = load_pretrained(name).eval()
            src = f"shipped network of {name}"
        cfg = net.config()
        meta = f"{src}: {cfg.get('kind')} {cfg.get('hidden')}, {net.n_hypotheses} hypotheses, {net.n_params} params"
        rows = measure(net, a.n, a.seed, tuple(a.iters))
        text = table(name, meta, rows)
        print(text, flush=True)
        parts.append(text)
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        old = a.out.read_text() if a.out.exists() else ""
        notes = old[old.index(NOTES) :] if NOTES in old else ""  # the hand-written section is kept
        tmp = a.out.with_name(a.out.name + ".tmp")
        tmp.write_text("\n".join(parts) + ("\n" + notes if notes else ""))
        tmp.replace(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
