"""Does a network pay per call type? The solver's choice (:attr:`nik.IKSolver.network_use`) against no network.

    python benchmarks/network_use.py --pair runs/ARM/ARM.safetensors --robot ARM.urdf [--end-link LINK] \
        --out benchmarks/results/network_use.md
    python benchmarks/network_use.py --pair auto --robot ARM.urdf --root-link R --end-link T   # what is installed
    python benchmarks/network_use.py --record-shipped      # write the shipped pairs' records (nik/nets/weights)

One torch thread, one process, CPU. For the pair given (e.g. from ``nik train ARM --minutes 2``):

``--pair auto``: the networks ``IKSolver(robot)`` finds installed (``nik train --install``: the main network and the
single-pose one beside it, which guesses on the CPU) instead of a file.

- what the solver decided per call type (``network_use``: from the pair's record, no measurement) and the figures
  of that record (microseconds per pose with and without the network on the probes of :mod:`nik.ik.judge`);
- **one pose per call**: ``IKSolver(robot, checkpoint=PAIR)`` (the solver's choice) against
  ``IKSolver(robot, checkpoint=None)``, ``--n-one`` (500) FK targets of uniform joints (seeded), the two solvers
  interleaved pose by pose (A B A B ...), numpy ``(4, 4)`` poses (the one-pose path); median and p99 of one call,
  microseconds of wall time, and the median CPU time of this thread (``time.thread_time``: on a shared machine, wall
  time counts what else ran), the ratios of the medians; also the network forced
  (``network_use = {"pose": True, ...}``) to show what it would cost;
- **a batch** of ``--n-batch`` (2,000) targets: the same three, ``--reps`` (5) interleaved rounds, the median per
  target (wall and CPU); the ratio (no network / with) is the speed-up.

Goals (issue 48): one pose <= 1.0x no network; batch >= 1.5x faster. ``--record-shipped`` measures the shipped
networks' records (:func:`nik.learn.report.record_use`, ``--rounds`` rounds of the probes, one thread) and writes
them into their JSON files.
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

import numpy as np
import torch

import nik


def _targets(robot, n: int, seed: int) -> np.ndarray:
    q = robot.sample(int(n), generator=torch.Generator().manual_seed(int(seed)), dtype=torch.float64)
    return np.ascontiguousarray(robot.fk(q).numpy())


def _q(values, p: float) -> float:
    return float(np.quantile(np.asarray(values), p))


def record_shipped(rounds: int) -> list[str]:
    """Write the record of every shipped pair (module docstring); the lines printed."""
    from nik.ik import judge
    from nik.learn.report import record_use
    from nik.nets.pretrained import PRETRAINED_DIR

    judge.TIME_ROUNDS = rounds
    lines = []
    for st in sorted(PRETRAINED_DIR.glob("*.safetensors")):
        rec = record_use(st)
        for b, r in rec["against"].items():
            lines.append(
                f"{st.name:<24} against {b:<10} pose {'yes' if r['pose'] else 'no ':<3} "
                f"({r['pose_us'][0]:7.1f} vs {r['pose_us'][1]:7.1f} us)  batch {'yes' if r['batch'] else 'no ':<3} "
                f"({r['batch_us'][0]:7.1f} vs {r['batch_us'][1]:7.1f} us)"
            )
            print(lines[-1], flush=True)
    return lines


def measure(robot, pair: str, n_one: int, n_batch: int, reps: int, seed: int) -> list[str]:
    """The A/B of the module docstring; the lines of the results."""
    checkpoint = "auto" if pair == "auto" else pair
    choice = nik.IKSolver(robot, checkpoint=checkpoint)
    forced = nik.IKSolver(robot, checkpoint=checkpoint)
    forced.network_use = {"pose": True, "batch": True}
    none = nik.IKSolver(robot, checkpoint=None)
    use = choice.network_use
    names = {"solver's choice": choice, "network forced": forced, "no network": none}
    lines = [
        f"robot {robot.name} ({robot.dof} joints), network {pair}"
        + (" (installed; its single-pose network guesses on the CPU)" if choice.single_pose_net is not None else "")
        + "; one torch thread",
        f"network_use ({use['how']}): single poses {'network' if use['pose'] else 'no network'}, batches "
        f"{'network' if use['batch'] else 'no network'}; probes: one pose {use['pose_us'][0]:.1f} us with, "
        f"{use['pose_us'][1]:.1f} us without; batch {use['batch_us'][0]:.1f} us with, {use['batch_us'][1]:.1f} us "
        f"without a pose (wins {use['wins']:.0%}, against {use['baseline']})",
        "",
        "| case | solver | guess | success | median us (wall) | p99 us (wall) | median us (CPU) | vs no network "
        "(wall / CPU) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    To = _targets(robot, n_one, seed)
    for s in names.values():  # first calls (kernels, packing) not timed
        s.solve(To[0])
        s.solve(To[:300])
    one = {k: [] for k in names}
    cpu = {k: [] for k in names}
    ok = {k: 0 for k in names}
    src = {}
    for i in range(n_one):
        for k, s in names.items():
            t0, c0 = time.perf_counter(), time.thread_time()
            res = s.solve(To[i])
            one[k].append(time.perf_counter() - t0)
            cpu[k].append(time.thread_time() - c0)
            ok[k] += int(res.success[0])
            src[k] = res.source
    base, base_cpu = statistics.median(one["no network"]), statistics.median(cpu["no network"])
    for k in names:
        med, med_cpu = statistics.median(one[k]), statistics.median(cpu[k])
        lines.append(
            f"| one pose per call ({n_one}) | {k} | {src[k]} | {100 * ok[k] / n_one:.1f}% | {1e6 * med:.1f} | "
            f"{1e6 * _q(one[k], 0.99):.1f} | {1e6 * med_cpu:.1f} | {med / base:.2f}x / {med_cpu / base_cpu:.2f}x "
            "the time |"
        )
    Tb = _targets(robot, n_batch, seed + 1)
    many = {k: [] for k in names}
    many_cpu = {k: [] for k in names}
    for _ in range(reps):
        for k, s in names.items():
            t0, c0 = time.perf_counter(), time.thread_time()
            res = s.solve(Tb)
            many[k].append(time.perf_counter() - t0)
            many_cpu[k].append(time.thread_time() - c0)
            ok[k], src[k] = float(np.mean(res.success)), res.source
    base, base_cpu = statistics.median(many["no network"]), statistics.median(many_cpu["no network"])
    for k in names:
        med, med_cpu = statistics.median(many[k]), statistics.median(many_cpu[k])
        lines.append(
            f"| batch of {n_batch} ({reps} rounds) | {k} | {src[k]} | {100 * ok[k]:.1f}% | "
            f"{1e6 * med / n_batch:.1f} / pose | {1e6 * max(many[k]) / n_batch:.1f} (max) | "
            f"{1e6 * med_cpu / n_batch:.1f} / pose | {base / med:.2f}x / {base_cpu / med_cpu:.2f}x faster |"
        )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pair", help="an exported network (NAME.safetensors), or auto: the installed ones")
    ap.add_argument("--robot", help="the robot (built-in name, YAML or URDF)")
    ap.add_argument("--end-link", default=None)
    ap.add_argument("--root-link", default=None)
    ap.add_argument("--n-one", type=int, default=500)
    ap.add_argument("--n-batch", type=int, default=2000)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=48)
    ap.add_argument("--record-shipped", action="store_true")
    ap.add_argument("--rounds", type=int, default=7, help="probe rounds for --record-shipped")
    ap.add_argument("--out", default=None, help="write the lines here too (markdown)")
    a = ap.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    if a.record_shipped:
        lines = record_shipped(a.rounds)
    else:
        kw = {k: v for k, v in (("end_link", a.end_link), ("root_link", a.root_link)) if v is not None}
        robot = nik.load_robot(a.robot, **kw)
        lines = measure(robot, a.pair, a.n_one, a.n_batch, a.reps, a.seed)
    lines.append(
        f"\n(wall {time.perf_counter() - t0:.0f} s; command: python benchmarks/network_use.py "
        f"{' '.join(__import__('sys').argv[1:])})"
    )
    print("\n".join(lines))
    if a.out:
        Path(a.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
