"""Paper A check: SA-PSO on the PUMA 560 with the paper's settings, on random reachable targets.

Settings: 40 particles, |v| <= 0.8 rad, C1 = C2 = 2, W(t) = 1 - 0.7 t / N, T0 = 20, K = 0.95,
objective eq. (4) (arccos of the rotation entries in degrees + positions in mm). Paper A does
not give N; ``--iters`` (default 1000) is N, and a target stops early once it meets the paper's
claim (position 1e-3 mm, rotation 1e-2 degrees). Targets: FK of joints drawn uniformly in the limits.

    python benchmarks/paper_a.py [--n 200] [--iters 1000] [--threads 1]

Reports the position error (mm) and the direction-angle errors (degrees: the angles between
corresponding axes n, o, a of the reached and wanted frames) against the paper's claim.
"""

from __future__ import annotations

import argparse
import math
import time

import torch

import nik
from nik.swarm import SAPSOCfg, refine

CLAIM_MM, CLAIM_DEG = 1e-3, 1e-2


def direction_angles(T_target: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """(B, 3) angles in degrees between the n, o, a axes (columns of R) of the two frames."""
    c = (T_target[:, :3, :3] * T[:, :3, :3]).sum(dim=1).clamp(-1, 1)
    # acos loses precision near 1: use atan2(|a x b|, a . b)
    cross = torch.linalg.vector_norm(torch.linalg.cross(T_target[:, :3, :3], T[:, :3, :3], dim=1), dim=1)
    return torch.rad2deg(torch.atan2(cross, c))


def summary(name: str, v: torch.Tensor) -> str:
    v = v.double()
    return (
        f"{name:<28} median {v.median().item():.3g}  mean {v.mean().item():.3g}  "
        f"p90 {v.quantile(0.9).item():.3g}  max {v.max().item():.3g}"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="random targets")
    ap.add_argument("--iters", type=int, default=1000, help="N, the iteration limit")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--polish", action="store_true", help="also finish with LM (not part of paper A)")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    robot = nik.load_robot("puma560")
    g = torch.Generator().manual_seed(args.seed + 12345)
    q_true = robot.sample(args.n, generator=g, dtype=torch.float64)
    T = robot.fk(q_true)
    t0 = time.perf_counter()
    res = refine(
        robot,
        T,
        method="sapso",
        cfg=SAPSOCfg(),
        max_iters=args.iters,
        seed=args.seed,
        tol_pos=CLAIM_MM * 1e-3,
        tol_rot=math.radians(CLAIM_DEG),
        polish=args.polish,
    )
    dt = time.perf_counter() - t0
    T_reached = robot.fk(res.q)
    pos_mm = res.pos_err * 1000
    dirs = direction_angles(T, T_reached)
    worst_dir = dirs.amax(dim=1)
    geo = torch.rad2deg(res.rot_err)
    meets = (pos_mm <= CLAIM_MM) & (worst_dir <= CLAIM_DEG)
    print(
        f"paper A check: SA-PSO (paper settings, N = {args.iters}) on puma560, {args.n} random reachable targets, "
        f"float64, {args.threads} thread(s){', + LM polish' if args.polish else ''}"
    )
    print(summary("position error (mm)", pos_mm))
    for k, axis in enumerate("noa"):
        print(summary(f"direction angle {axis} (deg)", dirs[:, k]))
    print(summary("geodesic rotation (deg)", geo))
    print(summary("iterations", res.iterations.double()))
    print(
        f"paper A claim (position <= {CLAIM_MM:g} mm and every direction angle <= {CLAIM_DEG:g} deg): "
        f"met on {meets.double().mean().item() * 100:.1f} % of targets"
    )
    print(
        f"within limits: {bool(robot.within_limits(res.q).all())}; time {dt:.1f} s "
        f"({dt / args.n * 1000:.2f} ms per target)"
    )


if __name__ == "__main__":
    main()
