"""FK throughput: nik (eager and compiled) vs pytorch-kinematics on the same URDF arms; one configuration
against Pinocchio.

Both run in this process, on the same joint samples; the table gives configurations per
second and the ratio nik / pytorch-kinematics.

The second table (skipped when Pinocchio is not installed: ``pip install pin``) times one configuration per
call, float64: ``robot.fk(q)`` with a tensor in and out, and with a numpy array in and out (as Pinocchio takes and
gives), against Pinocchio's ``forwardKinematics`` + ``updateFramePlacements`` on the same URDF (the joints nik
does not model, e.g. the Panda's fingers, locked at 0), the three interleaved by blocks of calls over the same 64
configurations; medians over the blocks (and the ratios of the fastest blocks).

    python benchmarks/fk.py            # panda (7-DOF) and ur5 (6-DOF), batch 1 / 1,000 / 100,000, float32 / float64
    python benchmarks/fk.py --quick    # smaller batches, fewer repeats
    python benchmarks/fk.py --pinocchio-only --blocks 200    # only the one-configuration table
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time

import numpy as np
import torch

import nik
from nik.robots.urdf import build_pk_chain


def throughput(fn, batch: int, min_time: float, repeats: int) -> float:
    """Configurations per second: the median over ``repeats`` timings of at least ``min_time`` s each."""
    fn()
    fn()
    rates = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while True:
            fn()
            calls += 1
            elapsed = time.perf_counter() - start
            if elapsed >= min_time:
                break
        rates.append(calls * batch / elapsed)
    return statistics.median(rates)


def pinocchio_model(robot):
    """Pinocchio's model and data of ``robot``'s URDF reduced to nik's joints (the others locked at 0), and the
    id of its tool frame; the FK of both is checked to agree."""
    import pinocchio as pin

    full = pin.buildModelFromUrdf(robot.source)
    locked = [j for j in range(1, full.njoints) if full.names[j] not in robot.joint_names]
    model = pin.buildReducedModel(full, locked, pin.neutral(full)) if locked else full
    if [model.names[j] for j in range(1, model.njoints)] != list(robot.joint_names):
        raise SystemExit(f"{robot.name}: Pinocchio's joints {list(model.names)[1:]} are not nik's {robot.joint_names}")
    data, frame = model.createData(), model.getFrameId(robot.flange_link or robot.end_link)
    q = robot.sample(4, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    for row in q:
        pin.forwardKinematics(model, data, row.numpy())
        pin.updateFramePlacements(model, data)
        gap = np.abs(data.oMf[frame].homogeneous - robot.fk(row).numpy()).max()
        if gap > 1e-6:
            raise SystemExit(f"{robot.name}: nik and Pinocchio disagree by {gap:.2e} m")
    return model, data, frame


def time_one_configuration(robot, blocks: int, calls: int) -> dict[str, list[float]]:
    """Microseconds per call of ``robot.fk(q)`` (a tensor, then a numpy array) and of Pinocchio's FK + frame update,
    one block of ``calls`` configurations after the other, ``blocks`` times each, interleaved."""
    import pinocchio as pin

    model, data, _ = pinocchio_model(robot)
    qs = list(robot.sample(calls, generator=torch.Generator().manual_seed(2), dtype=torch.float64))
    qn = [q.numpy().copy() for q in qs]
    fk, forward, frames = robot.fk, pin.forwardKinematics, pin.updateFramePlacements

    def run_nik():
        for q in qs:
            fk(q)

    def run_numpy():
        for q in qn:
            fk(q)

    def run_pin():
        for q in qn:
            forward(model, data, q)
            frames(model, data)

    times = {"nik": [], "numpy": [], "pin": []}
    runs = (("nik", run_nik), ("numpy", run_numpy), ("pin", run_pin))
    for _ in range(3):
        for _, run in runs:
            run()
    for _ in range(blocks):
        for key, run in runs:
            start = time.perf_counter()
            run()
            times[key].append((time.perf_counter() - start) / calls * 1e6)
    return times


def one_configuration(robots, blocks: int, calls: int = 64) -> None:
    """The one-configuration table: nik ``robot.fk`` against Pinocchio, interleaved (see the module docstring)."""
    if importlib.util.find_spec("pinocchio") is None:
        print("\nPinocchio is not installed (pip install pin): one-configuration comparison skipped")
        return
    print(f"\none configuration per call, float64, {blocks} blocks of {calls} calls each, interleaved; microseconds")
    print(
        "\n| robot | nik robot.fk, tensor | nik robot.fk, numpy | Pinocchio FK + frames | tensor / Pinocchio "
        "| numpy / Pinocchio | best blocks, tensor / numpy / Pinocchio |"
    )
    print("|---|---:|---:|---:|---:|---:|---|")
    for name in robots:
        times = time_one_configuration(nik.load_robot(name), blocks, calls)
        a, n, b = (statistics.median(times[key]) for key in ("nik", "numpy", "pin"))
        best = [min(times[key]) for key in ("nik", "numpy", "pin")]
        print(
            f"| {name} | {a:.2f} | {n:.2f} | {b:.2f} | {a / b:.2f}x | {n / b:.2f}x "
            f"| {best[0] / best[2]:.2f}x / {best[1] / best[2]:.2f}x |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 1_000, 100_000])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="batches 1 and 1,000 only, short timings")
    parser.add_argument("--pinocchio-only", action="store_true", help="only the one-configuration table")
    parser.add_argument("--blocks", type=int, default=100, help="blocks of the one-configuration table")
    args = parser.parse_args()
    if args.pinocchio_only:
        torch.set_num_threads(1)
        one_configuration(args.robots, args.blocks)
        return
    if args.quick:
        args.batches = [b for b in args.batches if b <= 1_000]
    min_time, repeats = (0.05, 3) if args.quick else (0.3, 5)
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; configurations per second (M = 1e6)\n")
    header = "| robot | dtype | batch | nik eager | nik compiled | pytorch-kinematics | eager / pk | compiled / pk |"
    print(header)
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name in args.robots:
        robot = nik.load_robot(name)
        chain = build_pk_chain(open(robot.source).read(), robot.flange_link or robot.end_link)
        for dtype in (torch.float32, torch.float64):
            pk_chain = chain.to(dtype=dtype)
            for batch in args.batches:
                q = robot.sample(batch, generator=torch.Generator().manual_seed(0), dtype=dtype)
                with torch.no_grad():
                    eager = throughput(lambda r=robot, q=q: r.fk(q), batch, min_time, repeats)
                    compiled = throughput(lambda r=robot, q=q: r.fk(q, compiled=True), batch, min_time, repeats)
                    peer = throughput(
                        lambda c=pk_chain, q=q: c.forward_kinematics(q).get_matrix(), batch, min_time, repeats
                    )
                print(
                    f"| {name} | {str(dtype)[6:]} | {batch:,} | {eager / 1e6:.3f} M | {compiled / 1e6:.3f} M "
                    f"| {peer / 1e6:.3f} M | {eager / peer:.1f}x | {compiled / peer:.1f}x |",
                    flush=True,
                )
    one_configuration(args.robots, 20 if args.quick else args.blocks)


if __name__ == "__main__":
    main()
