"""Refinement benchmark on kuka_kr: success at 0.1 mm / 0.1 deg and time per target.

    python benchmarks/refine.py [--n 1000] [--swarm-n 200] [--noise 0.1] [--threads 1] [--boundary]

Targets: FK of joints drawn uniformly inside the hardware limits (every target reachable).
Rows:
  (a) every swarm from uniform init (paper settings), without and with LM polish;
  (b) every swarm seeded near a guess (the true joints + N(0, noise^2) per joint, clamped), without
      and with LM polish, plus a short seeded improved PSO (10 iterations) + polish;
  (c) LM alone: from the guess, and multi-start (best of LMCfg.first_starts uniform configurations, then
      fresh uniform starts only for the targets that fail; see nik.lm.lm_solve);
  (d) pytorch-kinematics PseudoInverseIK on the same targets: 10 per-target uniform random
      initial configs ((N, R, dof) initial_config), early_stopping_any_converged=True, joint limits
      given, same tolerances; and seeded from the same guess (R = 1). Its answers are re-measured
      with nik's FK and only count when inside the limits.
The uniform-init swarms are slow (thousands of FK per target), so they run on the first
``--swarm-n`` targets only. ``--boundary`` adds the comparison of boundary strategies used to
choose the default. Times are wall-clock on this machine's CPU, shared with other jobs.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np
import torch

import nik
from nik.lm import LMCfg
from nik.poses import matrix_to_rpy
from nik.swarm import default_cfg, refine
from nik.swarm.driver import Polish
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

TOL_POS, TOL_ROT = DEFAULT_TOL_POS, DEFAULT_TOL_ROT  # m, rad: 0.1 mm / 0.1 deg, nik's one tolerance


def dh_urdf(robot_name: str = "kuka_kr") -> str:
    """A URDF string for a built-in standard-DH arm, from its normal form (G, offsets, limits).

    nik's normal form is T = G0 Rz(q1 + o1) G1 ... Rz(qn + on) Gn; joint i of the URDF has origin
    G_{i-1} Rz(o_i) and axis z, and a fixed joint carries G_n to the tool link.
    """
    robot = nik.load_robot(robot_name)
    G, off, lim = robot.G.numpy(), robot.offsets.numpy(), robot.limits.numpy()

    def origin(M):
        rpy = matrix_to_rpy(torch.tensor(M[:3, :3])).numpy()
        return (
            f'<origin xyz="{M[0, 3]:.12g} {M[1, 3]:.12g} {M[2, 3]:.12g}" '
            f'rpy="{rpy[0]:.12g} {rpy[1]:.12g} {rpy[2]:.12g}"/>'
        )

    def rz(a):
        c, s = math.cos(a), math.sin(a)
        M = np.eye(4)
        M[:2, :2] = [[c, -s], [s, c]]
        return M

    parts = [f'<robot name="{robot_name}">', '<link name="link0"/>']
    for i in range(robot.dof):
        parts.append(f'<link name="link{i + 1}"/>')
        parts.append(
            f'<joint name="joint{i + 1}" type="revolute"><parent link="link{i}"/><child link="link{i + 1}"/>'
            f'{origin(G[i] @ rz(off[i]))}<axis xyz="0 0 1"/>'
            f'<limit lower="{lim[i, 0]:.12g}" upper="{lim[i, 1]:.12g}" effort="1" velocity="1"/></joint>'
        )
    parts.append('<link name="tool"/>')
    parts.append(
        f'<joint name="tool_joint" type="fixed"><parent link="link{robot.dof}"/><child link="tool"/>'
        f"{origin(G[-1])}</joint>"
    )
    parts.append("</robot>")
    return "\n".join(parts)


def timed(fn):
    """Run ``fn`` and time it. Fast calls (under 1 s) count as warm-up and are timed 3 more times
    (median), so one-off costs do not dominate sub-millisecond rows; slow ones are timed once.
    nik's rows and pytorch-kinematics' rows go through this same function."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    if first >= 1.0:
        return out, first
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, sorted(times)[1]


def report(rows, name, robot, T, q, dt, extra=""):
    pos, rot = nik.pose_error(T, robot.fk(q))
    ok = (pos <= TOL_POS) & (rot <= TOL_ROT) & robot.within_limits(q)
    n = T.shape[0]
    rows.append((name, n, ok.double().mean().item() * 100, dt / n * 1e3, extra))
    print(f"{name:<48} n={n:<6} success {rows[-1][2]:7.2f} %   {rows[-1][3]:8.4f} ms/target  {extra}", flush=True)


def run_pk(robot, T, q_guess, *, retries, seed, max_iterations=50):
    import pytorch_kinematics as pk

    from nik.robots.urdf import build_pk_chain

    chain = build_pk_chain(dh_urdf(robot.name), "tool").to(dtype=T.dtype)
    g = torch.Generator().manual_seed(seed)
    n = T.shape[0]
    if q_guess is None:
        init = robot.sample(n * retries, generator=g, dtype=T.dtype).reshape(n, retries, robot.dof)
    else:
        init = q_guess.reshape(n, 1, robot.dof)
    ik = pk.PseudoInverseIK(
        chain,
        pos_tolerance=TOL_POS,
        rot_tolerance=TOL_ROT,
        retry_configs=init[0],
        joint_limits=robot.limits.to(T.dtype),
        early_stopping_any_converged=True,
        max_iterations=max_iterations,
    )
    ik.initial_config = init  # (N, R, dof): per-target guesses (the constructor only takes (R, dof))
    sol, dt = timed(lambda: ik.solve(pk.Transform3d(matrix=T)))
    err = sol.err_pos + sol.err_rot + (~sol.converged) * 1e6
    best = err.argmin(dim=1)
    q = sol.solutions[torch.arange(n), best]
    return q, dt, chain


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--swarm-n", type=int, default=200, help="targets for the (slow) uniform-init swarms")
    ap.add_argument("--noise", type=float, default=0.1, help="rad, std of the guess noise")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--dtype", choices=["float64", "float32"], default="float64")
    ap.add_argument("--boundary", action="store_true", help="also compare the boundary strategies")
    ap.add_argument("--skip-uniform", action="store_true")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    dtype = getattr(torch, args.dtype)
    robot = nik.load_robot("kuka_kr")
    g = torch.Generator().manual_seed(args.seed + 777)
    q_true = robot.sample(args.n, generator=g, dtype=dtype)
    T = robot.fk(q_true)
    guess = robot.clamp(q_true + args.noise * torch.randn(q_true.shape, generator=g, dtype=dtype))
    print(
        f"kuka_kr, {args.n} random reachable targets, tolerance 0.1 mm / 0.1 deg, {args.dtype}, "
        f"{args.threads} thread(s), guess noise {args.noise} rad\n"
    )
    rows = []
    # warm up kernels
    refine(robot, T[:8], method="lm", q_init=guess[:8])
    refine(robot, T[:8], method="pso", q_init=guess[:8], max_iters=2)

    # (c) LM alone
    res, dt = timed(lambda: refine(robot, T, method="lm", q_init=guess, tol_pos=TOL_POS, tol_rot=TOL_ROT))
    report(rows, "(c) LM from guess", robot, T, res.q, dt, f"iters mean {res.iterations.double().mean():.1f}")
    res, dt = timed(lambda: refine(robot, T, method="lm", tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=args.seed))
    report(
        rows,
        f"(c) LM, multistart (best of {LMCfg().first_starts} + restarts)",
        robot,
        T,
        res.q,
        dt,
        f"iters mean {res.iterations.double().mean():.1f}",
    )

    # (b) seeded swarms
    for method in ("ipso", "pso", "sapso", "ga"):
        for polish in (False, True):
            res, dt = timed(
                lambda m=method, p=polish: refine(
                    robot, T, method=m, q_init=guess, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=args.seed, polish=p
                )
            )
            report(
                rows,
                f"(b) {method} seeded{' + LM polish' if polish else ''}",
                robot,
                T,
                res.q,
                dt,
                f"iters mean {res.iterations.double().mean():.1f}",
            )
    res, dt = timed(
        lambda: refine(
            robot,
            T,
            method="ipso",
            q_init=guess,
            tol_pos=TOL_POS,
            tol_rot=TOL_ROT,
            seed=args.seed,
            polish=True,
            max_iters=10,
        )
    )
    report(
        rows,
        "(b) ipso seeded, 10 iters + LM polish",
        robot,
        T,
        res.q,
        dt,
        f"polish iters mean {res.polish_iterations.double().mean():.1f}",
    )

    # (d) pytorch-kinematics
    q_pk, dt, chain = run_pk(robot, T, None, retries=10, seed=args.seed)
    Tpk = chain.forward_kinematics(q_true[:4]).get_matrix()
    fk_gap = (Tpk - robot.fk(q_true[:4])).abs().max().item()
    report(rows, "(d) pk PseudoInverseIK, 10 random inits", robot, T, q_pk, dt, f"(pk vs nik FK gap {fk_gap:.1e})")
    q_pk, dt, _ = run_pk(robot, T, guess, retries=1, seed=args.seed)
    report(rows, "(d) pk PseudoInverseIK from guess", robot, T, q_pk, dt)

    # (a) uniform-init swarms on a subset
    if not args.skip_uniform:
        m = min(args.swarm_n, args.n)
        for method in ("ipso", "pso", "sapso", "ga"):
            for polish in (False, True):
                res, dt = timed(
                    lambda mm=method, p=polish: refine(
                        robot,
                        T[:m],
                        method=mm,
                        tol_pos=TOL_POS,
                        tol_rot=TOL_ROT,
                        seed=args.seed,
                        polish=Polish(starts=4) if p else False,
                    )
                )
                report(
                    rows,
                    f"(a) {method} uniform{' + LM polish (4 starts)' if polish else ''}",
                    robot,
                    T[:m],
                    res.q,
                    dt,
                    f"iters mean {res.iterations.double().mean():.1f}",
                )

    if args.boundary:
        m = min(args.swarm_n, args.n)
        for method in ("ipso", "pso"):
            for b in ("reflect", "clamp", "resample"):
                cfg = replace(default_cfg(method), boundary=b)
                res, dt = timed(
                    lambda mm=method, c=cfg: refine(
                        robot, T[:m], method=mm, cfg=c, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=args.seed
                    )
                )
                report(
                    rows,
                    f"boundary {b}: {method} uniform",
                    robot,
                    T[:m],
                    res.q,
                    dt,
                    f"median pos {res.pos_err.median().item() * 1e3:.3g} mm",
                )
                res, dt = timed(
                    lambda mm=method, c=cfg: refine(
                        robot, T, method=mm, cfg=c, q_init=guess, tol_pos=TOL_POS, tol_rot=TOL_ROT, seed=args.seed
                    )
                )
                report(
                    rows,
                    f"boundary {b}: {method} seeded",
                    robot,
                    T,
                    res.q,
                    dt,
                    f"median pos {res.pos_err.median().item() * 1e3:.3g} mm",
                )

    print("\n| configuration | targets | success @0.1 mm/0.1 deg (%) | time per target (ms) |\n|---|---|---|---|")
    for name, n, s, ms, _ in rows:
        print(f"| {name} | {n} | {s:.2f} | {ms:.4f} |")
    _ = LMCfg


if __name__ == "__main__":
    main()
