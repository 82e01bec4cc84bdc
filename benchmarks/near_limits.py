"""``q_near`` on a joint limit: how often the answer lands far from ``q_near`` (issue 37 item 3).

Per robot, N targets built so that an exact solution lies within ``--within`` rad of ``q_near`` in every joint and
one joint of ``q_near`` (chosen at random) sits on one of its limits: a uniform configuration ``q``, the chosen joint
moved to ``limit -+ u`` (``u`` uniform in ``[0, within]``, inside), ``q_near`` = ``q`` + uniform noise of ``within``
clamped to the limits, the chosen joint set to its limit. Counted: answers more than 0.5 rad from ``q_near`` in some
joint, and failures. The second block: ``q_near`` = truth + noise clamped to the limits (no joint forced).

    python benchmarks/near_limits.py                      # xarm7, panda, ur5, tiago right arm; 300 targets, 3 seeds
    python benchmarks/near_limits.py --backend torch
"""

from __future__ import annotations

import argparse

import torch

import nik


def erd_robot(rel: str, **kw):
    """A robot of example-robot-data (``robots/<rel>``), or None when the package is missing."""
    import importlib.metadata
    from pathlib import Path

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    path = Path(dist.locate_file(f"cmeel.prefix/share/example-robot-data/robots/{rel}"))
    return nik.load_robot(str(path), **kw) if path.is_file() else None


def tiago():
    """Tiago Pro's right arm (example-robot-data), or None."""
    return erd_robot(
        "tiago_pro_description/robots/tiago_pro.urdf", root_link="torso_lift_link", end_link="arm_right_tool_link"
    )


def near_limit_targets(robot, n: int, within: float, seed: int, force: bool = True):
    """``(T (n, 4, 4), q_near (n, dof))`` float64 (module docstring)."""
    g = torch.Generator().manual_seed(seed)
    lo, hi = robot.limits[:, 0].double(), robot.limits[:, 1].double()
    q = robot.sample(n, generator=g, dtype=torch.float64)
    noise = (torch.rand(q.shape, generator=g, dtype=torch.float64) * 2 - 1) * within
    if not force:
        return robot.fk(q), torch.maximum(torch.minimum(q + noise, hi), lo)
    j = torch.randint(robot.dof, (n,), generator=g)
    upper = torch.rand(n, generator=g) < 0.5
    u = torch.rand(n, generator=g, dtype=torch.float64) * within
    rows = torch.arange(n)
    q[rows, j] = torch.where(upper, hi[j] - u, lo[j] + u)
    near = torch.maximum(torch.minimum(q + noise, hi), lo)
    near[rows, j] = torch.where(upper, hi[j], lo[j])
    return robot.fk(q), near


def count(solver, T, q_near, seed: int) -> tuple[int, int]:
    """``(answers more than 0.5 rad from q_near in some joint, failures)``."""
    res = solver.solve(T, q_near=q_near, seed=seed)
    far = ((res.q - q_near).abs().amax(dim=1) > 0.5) & res.success
    return int(far.sum()), int((~res.success).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--within", type=float, default=0.3)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--backend", default="auto")
    args = ap.parse_args()
    robots = [nik.load_robot("xarm7"), nik.load_robot("panda"), nik.load_robot("ur5")]
    t = tiago()
    if t is not None:
        robots.append(t)
    print("| robot | q_near | targets | far (> 0.5 rad) | failed |")
    print("|---|---|---|---|---|")
    for robot in robots:
        solver = nik.IKSolver(robot, backend=args.backend)
        for force, what in ((True, f"one joint on a limit, exact within {args.within}"), (False, "truth + noise")):
            far = fail = 0
            for seed in range(args.seeds):
                T, q_near = near_limit_targets(robot, args.n, args.within, seed, force)
                f, x = count(solver, T, q_near, seed)
                far, fail = far + f, fail + x
            print(f"| {robot.name} | {what} | {args.n * args.seeds} | {far} | {fail} |")


if __name__ == "__main__":
    main()
