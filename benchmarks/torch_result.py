"""How a torch pose's one-pose result should hand back its tensors: the ways measured, cold and warm (issue 34 item 5).

A torch pose gets a :class:`nik.ik.result.TensorResult`: the kernel writes into one of the solver's two output slots
whose ``q`` and ``success`` tensors exist already (made once; a slot is taken only while nothing else refers to it),
else its fields become tensors when first read (``torch.from_numpy`` of the kernel's arrays,
:mod:`nik.ik.backends.one_pose`). This compares, per arm, in one process, each call timed with what a control loop
reads and the result dropped (``res = solver.solve(T); res.q; res.success; del res``):

- ``numpy pose``: the same pose as a numpy array (the reference: no torch on the way);
- ``torch pose``: the shipped path (an output slot);
- ``first read``: the shipped path with the slots off (``one_pose._POOL = False``: the tensors made on first read,
  as before the slots);
- ``made at once``: the same kernel call, its six arrays made tensors by ``torch.from_numpy`` at once;
- ``torch.empty first``: the six outputs allocated as tensors before the kernel call and the kernel writing into
  their ``Tensor.numpy()`` views;
- ``from_numpy first``: the six numpy outputs made tensors before the kernel call.

The three variants run the one-pose path's own steps (the solver's kept :class:`~nik.ik.backends.one_pose.Entry`,
the pose read at its address, the driver kernel) outside ``IKSolver.solve``; their answers are checked equal to the
shipped path's. Settings: ``tight`` (call after call) and ``idle`` (0.5 ms asleep before each call, as
``benchmarks/cold_pose.py``). Order: ``rotated`` (pose by pose, each call after the one before it in the list: a
call follows the same other one each time) or ``blocks`` (``--block`` calls of one way in a row, as a loop that
calls one way, the ways' blocks in a seeded random order, the first two of each block not counted). Medians in
microseconds and the difference to the numpy pose; with ``--rounds`` the median over rounds and its range.

    python benchmarks/torch_result.py --robots ur5,panda --n 300 --out benchmarks/results/torch_result
    python benchmarks/torch_result.py --ways slots --order blocks --rounds 4 --out benchmarks/results/cold_pose_w40
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from peers import TOL_POS, TOL_ROT, latency_robot, targets  # noqa: E402

import nik  # noqa: E402
from nik.ik.backends import one_pose as op  # noqa: E402
from nik.ik.result import TensorResult  # noqa: E402

VARIANTS = ("made at once", "torch.empty first", "from_numpy first")


def variant(mode: str):
    """The one-pose path's steps for a contiguous float64 CPU tensor pose, its result made as ``mode`` says."""

    def call(solver, T):
        e = solver._one[(TOL_POS, TOL_ROT, 0, False)]
        a = np.empty((1, 4, 4))
        if T.dtype is not torch.float64 or not T.is_cpu or T.shape != (4, 4):
            raise ValueError("a (4, 4) float64 CPU tensor")
        if not T.is_contiguous() or T.is_neg() or not op._POSE_AT(T.data_ptr(), op._ORTHONORMAL_TOL, a):
            raise ValueError("a contiguous, valid pose")
        model = e.model
        n = model.dof
        if mode == "torch.empty first":
            made = (torch.empty((1, n), dtype=torch.float64), torch.empty(1, dtype=torch.float64),
                    torch.empty(1, dtype=torch.float64), torch.empty(1, dtype=torch.bool),
                    torch.empty(1, dtype=torch.int64), torch.empty(1, dtype=torch.bool))  # fmt: skip
            arrays = tuple(t.numpy() for t in made)
        else:
            arrays = (np.empty((1, n)), np.empty(1), np.empty(1), np.empty(1, dtype=np.bool_),
                      np.empty(1, dtype=np.int64), np.empty(1, dtype=np.bool_))  # fmt: skip
            if mode == "from_numpy first":
                made = tuple(torch.from_numpy(x) for x in arrays)
        q, pos, rot, ok, it, reach = arrays
        Tin = model.arm_targets(a) if e.arm_frame else a
        op._SOLVE(*e.a0, a, *e.a1, Tin, *e.a2, q, False, *e.a3, q, pos, rot, ok, it, reach)
        if mode == "made at once":
            made = tuple(torch.from_numpy(x) for x in arrays)
        res = TensorResult.__new__(TensorResult)
        res.__dict__.update(zip(("q", "pos_err", "rot_err", "success", "iterations", "reachable"), made, strict=True))
        res.__dict__["source"] = e.source
        return res

    return call


def measure(name: str, n: int, modes: list[str], ways: str, order: str, block: int, rounds: int) -> list[str]:
    robot, _, _ = latency_robot(name)
    if robot is None:
        return [f"| {name} | left out (example-robot-data is not installed) |"]
    T = targets(robot, n, 0)
    poses_np = [T[i].numpy().copy() for i in range(n)]
    poses_t = [T[i] for i in range(n)]
    solver = nik.IKSolver(robot)

    def first_read(i):
        op._POOL = False
        try:
            return solver.solve(poses_t[i], tol_pos=TOL_POS, tol_rot=TOL_ROT)
        finally:
            op._POOL = True

    calls = {
        "numpy pose": lambda i: solver.solve(poses_np[i], tol_pos=TOL_POS, tol_rot=TOL_ROT),
        "torch pose": lambda i: solver.solve(poses_t[i], tol_pos=TOL_POS, tol_rot=TOL_ROT),
        "first read": first_read,
    }
    if ways == "all":
        for mode in VARIANTS:
            calls[mode] = (lambda f: lambda i: f(solver, poses_t[i]))(variant(mode))
    for i in range(min(n, 20)):  # warm, and the variants' answers checked against the shipped path's
        ref = calls["torch pose"](i)
        for label, call in calls.items():
            res = call(i)
            assert torch.equal(torch.as_tensor(res.q), ref.q) and bool(res.success[0]) == bool(ref.success[0]), label
        del ref, res
    labels = list(calls)
    rows = []
    for mode in modes:
        rng = np.random.default_rng(0)
        per = {k: [] for k in labels}
        for r in range(rounds):
            times = {k: [] for k in labels}
            if order == "rotated":
                plan = [(labels[(i + j + r) % len(labels)], i, True) for i in range(n) for j in range(len(labels))]
            else:
                plan = [(labels[x], i, i - i0 >= 2) for i0 in range(0, n, block) for x in rng.permutation(len(labels))
                        for i in range(i0, min(n, i0 + block))]  # fmt: skip
            for label, i, counted in plan:
                if mode == "idle":
                    time.sleep(0.0005)
                t = time.perf_counter_ns()
                res = calls[label](i)
                res.q, res.success  # noqa: B018 (what a control loop reads)
                del res
                if counted:
                    times[label].append((time.perf_counter_ns() - t) / 1e3)
            for k in labels:
                per[k].append(statistics.median(times[k]))
        ref = [per["numpy pose"][r] for r in range(rounds)]
        cells = []
        for k in labels:
            d = [per[k][r] - ref[r] for r in range(rounds)]
            spread = f" [{min(d):+.1f}, {max(d):+.1f}]" if rounds > 1 else ""
            cells.append(f"{statistics.median(per[k]):.1f} ({statistics.median(d):+.1f}{spread})")
        rows.append(f"| {name} | {mode} | " + " | ".join(cells) + " |")
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default="ur5,panda")
    p.add_argument("--n", type=int, default=300, help="poses per arm")
    p.add_argument("--modes", default="tight,idle")
    p.add_argument("--ways", default="all", choices=["all", "slots"], help="slots: numpy, torch pose, first read")
    p.add_argument("--order", default="rotated", choices=["rotated", "blocks"])
    p.add_argument("--block", type=int, default=10, help="calls per block (--order blocks)")
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--out", default=None, help="write OUT.md")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    nik.set_threads(1)
    warnings.simplefilter("ignore", UserWarning)
    import os

    lines = [
        f"nik {nik.__version__}, torch {torch.__version__}, load {os.getloadavg()[0]:.1f}, "
        f"{time.strftime('%Y-%m-%d %H:%M:%S %Z')}",
        f"`python benchmarks/torch_result.py --robots {args.robots} --n {args.n} --modes {args.modes} --ways "
        f"{args.ways} --order {args.order} --block {args.block} --rounds {args.rounds}`",
        "",
        (
            "| robot | setting | numpy pose us | torch pose (output slot) | first read (slots off) | "
            + ("made at once | torch.empty first | from_numpy first |" if args.ways == "all" else "")
        ).rstrip(),
        "|---|---|---|---|---|" + ("---|---|---|" if args.ways == "all" else ""),
    ]
    print("\n".join(lines), flush=True)
    for name in args.robots.split(","):
        rows = measure(name.strip(), args.n, args.modes.split(","), args.ways, args.order, args.block, args.rounds)
        print("\n".join(rows), flush=True)
        lines += rows
    lines.append("")
    lines.append(
        "Medians (us), one thread; in brackets the difference to the numpy pose (with rounds: the median over rounds "
        "and its range)."
    )
    if args.out:
        Path(args.out + ".md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
