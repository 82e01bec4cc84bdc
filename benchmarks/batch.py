"""The README's batch figures: the default ``IKSolver`` on batches of random reachable targets, per target.

For panda (its shipped network; and without it, ``checkpoint=None``: LM from uniform starts) and ur5 (the
closed form), batches of 1,000 and 10,000 FK poses of seeded uniform joints inside the limits: the median of
3 solves of CPU time and wall time per target (one torch thread; CPU time is what a shared machine does not
inflate), the share within 0.1 mm / 0.1 deg, and whether every joint stayed inside its limits.

    python benchmarks/batch.py
"""

import time

import torch

import nik


def main() -> None:
    torch.set_num_threads(1)
    for name, checkpoint in (("panda", "auto"), ("panda", None), ("ur5", "auto")):
        solver = nik.IKSolver(name, checkpoint=checkpoint)
        robot = solver.robot
        for B in (1000, 10000):
            q = robot.sample(B, generator=torch.Generator().manual_seed(B), dtype=torch.float64)
            T = robot.fk(q)
            solver.solve(T[:10], seed=0)  # compiled kernels loaded, caches warm
            cpu, wall = [], []
            for r in range(3):
                c, w = time.process_time(), time.perf_counter()
                res = solver.solve(T, seed=r)
                cpu.append(time.process_time() - c)
                wall.append(time.perf_counter() - w)
            ok = 100 * res.success.double().mean().item()
            print(
                f"{name:6s} checkpoint={str(checkpoint):5s} B={B:6d} guess={res.source:10s} success {ok:6.2f} % "
                f"limits held {bool(robot.within_limits(res.q).all())} CPU {1e3 * sorted(cpu)[1] / B:.4f} ms/target, "
                f"wall {1e3 * sorted(wall)[1] / B:.4f} ms/target",
                flush=True,
            )


if __name__ == "__main__":
    main()
