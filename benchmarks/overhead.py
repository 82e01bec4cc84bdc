"""Where the microseconds of one pose go: the kernels against the Python around them.

For each arm, ``IKSolver(robot)`` solves ``--n`` single poses (one call each, after a warm-up), in a tight loop;
each call's time is split by wrapping the pieces with timers (``time.thread_time``, CPU time of this thread, less
sensitive to other processes than the wall clock):

- **kernels**: every call into the numba kernels after the input checks (reach bound, network forward pass and
  ranking, LM, closed form, merging answers), including numba's dispatch of their arguments;
- **validation**: ``nik.ik.targets.pose_array``, the input checks (their kernel included);
- **result**: building the ``IKResult`` of tensors;
- **other Python**: the rest (choosing the backend, the stages' bookkeeping, the wrappers around the kernels).

The calls name their representation (``representation="matrix"``), so that they take the general path of the
compiled backend that these pieces make up; a single pose without it takes the one-kernel-call path of
:mod:`nik.ik.backends.one_pose` (``benchmarks/cold_pose.py``). The timers cost about 0.1 us each; the total is
measured without them, in separate interleaved rounds.

    python benchmarks/overhead.py                       # panda, xarm7, ur5, kuka_kr; 2,000 poses each
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

import nik


def _wrap(holder, attr, bucket, acc):
    fn = getattr(holder, attr)

    def timed(*args, **kwargs):
        t0 = time.thread_time()
        try:
            return fn(*args, **kwargs)
        finally:
            acc[bucket] += time.thread_time() - t0

    setattr(holder, attr, timed)
    return fn


def measure(name: str, n: int, seed: int) -> dict:
    from nik.ik import targets
    from nik.ik.backends import compiled as cb
    from nik.kernels import closed, driver, lm, poses, seeded

    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot)
    T = robot.fk(robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64))
    poses_list = [T[i] for i in range(n)]
    solver.solve(T[:64])
    for t in poses_list[:50]:
        solver.solve(t, representation="matrix")
    plain = []
    for t in poses_list:  # the total, no timers
        c0 = time.thread_time()
        res = solver.solve(t, representation="matrix")
        plain.append(time.thread_time() - c0)
    acc = {"kernels": 0.0, "validation": 0.0, "result": 0.0}
    kernel_names = [
        (poses, "reach_flags"), (lm, "lm_solve"), (lm, "pose_errors"), (seeded, "ranked_hypotheses"),
        (seeded, "rank"), (seeded, "lm_starts"), (seeded, "merge"), (closed, "guess"), (driver, "solve"),
    ]  # fmt: skip
    originals = []
    cb._KERNELS = None  # the backend takes the wrapped kernels
    targets._KP = None
    for mod, attr in kernel_names:
        originals.append((mod, attr, _wrap(mod, attr, "kernels", acc)))
    originals.append((targets, "pose_array", _wrap(targets, "pose_array", "validation", acc)))
    cb.pose_array = targets.pose_array
    originals.append((cb.CompiledBackend, "result", _wrap(cb.CompiledBackend, "result", "result", acc)))
    total = 0.0
    for t in poses_list:
        c0 = time.thread_time()
        solver.solve(t, representation="matrix")
        total += time.thread_time() - c0
    for mod, attr, fn in originals:
        setattr(mod, attr, fn)
    cb.pose_array = targets.pose_array
    cb._KERNELS = None
    targets._KP = None
    per = {k: 1e6 * v / n for k, v in acc.items()}
    per["timed total"] = 1e6 * total / n
    per["median call"] = 1e6 * statistics.median(plain)
    per["mean call"] = 1e6 * statistics.mean(plain)
    per["source"] = res.source
    return per


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "xarm7", "ur5", "kuka_kr"])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    print("| arm | guess | median call us | mean call us | kernels | validation | result | other Python |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name in args.robots:
        m = measure(name, args.n, args.seed)
        other = m["timed total"] - m["kernels"] - m["result"] - m["validation"]
        print(
            f"| {name} | {m['source']} | {m['median call']:.1f} | {m['mean call']:.1f} | {m['kernels']:.1f} | "
            f"{m['validation']:.1f} | {m['result']:.1f} | {other:.1f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
