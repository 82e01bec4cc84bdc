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

Rows beyond theirs: ``+ k GN steps``: the network's hypotheses followed by ``k`` damped Gauss-Newton steps through the
differentiable FK (fixed damping, no line search, clamped to the limits; not the solver's LM): what a network with
refinement steps in its forward pass reaches, reported apart from the network alone. ``us / target``: wall time of
the forward pass (all heads), and of the forward pass plus the steps (torch, autograd Jacobians, one thread: an upper
bound of what compiled steps would cost).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from nik.nets import load_pretrained
from nik.nets.multi import hypothesis_pose_error
from nik.nets.pair import load_pair
from nik.poses import rotation_vector
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


def gn_steps(robot, T: torch.Tensor, q: torch.Tensor, k: int, damping: float = 1e-3) -> torch.Tensor:
    """``k`` damped Gauss-Newton steps on ``q: (B, K, dof)`` toward ``T: (B, 4, 4)``: residual (position m, rotation
    vector rad), Jacobian by autograd of the FK, ``dq = (J^T J + damping I)^-1 J^T r``, clamped to the limits."""
    B, K, dof = q.shape
    Tt = T[:, None].expand(B, K, 4, 4).reshape(-1, 4, 4)
    x = q.reshape(-1, dof).clone()

    def residual(x):
        Tq = robot.fk(x)
        dp = Tt[:, :3, 3] - Tq[:, :3, 3]
        dr = rotation_vector(Tt[:, :3, :3] @ Tq[:, :3, :3].transpose(-1, -2))
        return torch.cat([dp, dr], -1)

    eye = torch.eye(dof, dtype=x.dtype)
    for _ in range(k):
        r = residual(x)
        # each row's residual depends on its own joints only: the Jacobian of the batch sum is every row's (6 passes)
        J = torch.autograd.functional.jacobian(lambda v: residual(v).sum(0), x).permute(1, 0, 2)  # (N, 6, dof)
        Jt = J.transpose(-1, -2)
        dq = torch.linalg.solve(Jt @ J + damping * eye, Jt @ r[..., None])[..., 0]
        x = robot.clamp(x - dq)
    return x.reshape(B, K, dof)


def measure(net, n: int, seed: int, gn: tuple[int, ...]) -> list[tuple[str, dict]]:
    """Rows ``(label, stats)`` of one network on ``n`` targets: every head, head 0, best of heads, and ``+ k GN``."""
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
    rows[0][1]["us"] = 1e6 * fwd_s / n
    for k in gn:
        t0 = time.perf_counter()
        qk = gn_steps(robot, T, hyp, k)
        gn_s = time.perf_counter() - t0
        pk, rk = hypothesis_pose_error(robot, T, qk)
        rows.append((f"per sample + {k} GN steps", {**stats(pk, rk), "us": 1e6 * (fwd_s + gn_s) / n}))
    return rows


def table(name: str, meta: str, rows: list[tuple[str, dict]]) -> str:
    out = [
        f"### {name}",
        "",
        meta,
        "",
        "| samples | n | pos mean mm | pos median mm | pos p95 mm | rot mean deg | rot median deg | rot p95 deg "
        "| us / target |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, s in rows:
        out.append(
            f"| {label} | {s['n']} | {s['pos_mean']:.2f} | {s['pos_median']:.2f} | {s['pos_p95']:.2f} | "
            f"{s['rot_mean']:.2f} | {s['rot_median']:.2f} | {s['rot_p95']:.2f} | "
            + (f"{s['us']:.0f} |" if "us" in s else " |")
        )
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "xarm7"])
    ap.add_argument("--net", nargs="*", default=None, help="network files (.safetensors), one per robot, in order")
    ap.add_argument("--n", type=int, default=2000, help="targets per arm")
    ap.add_argument("--seed", type=int, default=4848)
    ap.add_argument("--gn", type=int, nargs="*", default=[1, 3], help="rows with k GN steps after the network")
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
        rows = measure(net, a.n, a.seed, tuple(a.gn))
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
