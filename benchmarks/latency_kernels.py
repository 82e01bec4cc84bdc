"""One-pose latency of the compiled kernels (:mod:`nik.kernels`) against the torch and numpy paths they replace.

Per robot, in this process, one call at a time, the paths interleaved by blocks of calls (50 A, 50 B, 50 A, ...;
call by call, each path would run in the caches the other just filled):

- FK of one configuration: the kernel (numpy in/out) / ``robot.fk`` (torch in and out: its compiled path) / the
  torch kernel it used before (``FKKernel``, eager);
- FK + geometric Jacobian: the kernel / ``robot.fk_and_jacobian`` / the numpy one-pose LM's ``fk_jacobian``;
- Levenberg-Marquardt for one pose, no network (300 reachable targets, each with its own seed): the kernel
  (best of ``--first-starts`` uniform configurations, then LM with up to 274 uniform restarts: the restart
  budget of the numpy one-pose path) / the numpy path (``tests/lm_reference.py``, what ``IKSolver.solve`` ran for
  one pose before the kernels). Median, p95, max per call; success within 0.1 mm and
  0.1 deg by torch FK of the answer; joints outside the limits;
- the MLP forward pass of the shipped network (one pose: 1 row for a multi-head network, 8 rows for a
  branch network), kernel (float64) / torch (float32, its own dtype);
- the cold compile time of the kernels (a subprocess with an empty cache folder) and the first use with
  a warm cache (another subprocess).

Numbers are microseconds per call. The kernels are single-threaded; torch runs with ``--threads``.

    python benchmarks/latency_kernels.py                 # panda, ur5, kuka_kr, stanford
    python benchmarks/latency_kernels.py --quick         # 60 targets, short timings
    python benchmarks/latency_kernels.py --sweep         # also: LM median / p95 against --first-starts 1..64
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(1, str(ROOT / "tests"))  # the numpy one-pose LM, the tests' reference (tests/lm_reference.py)

import nik  # noqa: E402
from nik import kernels as K  # noqa: E402
from nik.kernels import mlp as kmlp  # noqa: E402

TOL_POS = 1e-4  # m
TOL_ROT = np.radians(0.1)  # rad
TARGET_SEED_BASE = 1_000_003  # targets from their own stream (as benchmarks/peers.py)
RESTARTS = 2 + 16 * (1 + 16)  # the numpy one-pose path's budget: LMCfg restarts + tail_starts * (1 + tail_restarts)


def per_call(fns, calls: int, block: int = 50) -> list[list[float]]:
    """Microseconds of each call of each of ``fns``, interleaved by blocks (``block`` calls of fn0, then of fn1,
    ...): call by call, each function would run in the caches the others just filled."""
    for fn in fns:
        fn()
        fn()
    out = [[] for _ in fns]
    for _ in range(0, calls, block):
        for k, fn in enumerate(fns):
            for _ in range(block):
                t = time.perf_counter_ns()
                fn()
                out[k].append((time.perf_counter_ns() - t) / 1e3)
    return out


def med(ts) -> str:
    return f"{statistics.median(ts):.2f}"


def fk_rows(robot, calls: int) -> list[str]:
    from lm_reference import SingleLM

    from nik.kinematics import FKKernel

    G, joints = K.chain_model(robot.G, robot.offsets, robot.limits, robot.prismatic)
    q = robot.sample(1, generator=torch.Generator().manual_seed(0), dtype=torch.float64)[0]
    qn, q1 = q.numpy().copy(), q[None]
    T, J = np.empty((4, 4)), np.empty((6, robot.dof))
    torch_fk = FKKernel(robot.G.numpy(), robot.offsets.numpy(), prismatic=robot.prismatic.tolist())
    single = SingleLM.from_robot(robot)
    fk_k, fk_r, fk_t = per_call([lambda: K.fk(G, joints, qn, T), lambda: robot.fk(q), lambda: torch_fk(q1)], calls)
    fj_k, fj_t, fj_n = per_call(
        [lambda: K.fk_jacobian(G, joints, qn, T, J), lambda: robot.fk_and_jacobian(q), lambda: single.fk_jacobian(qn)],
        calls,
    )
    return [
        f"| {robot.name} | FK, one configuration | {med(fk_k)} | robot.fk (torch in/out) {med(fk_r)}, torch kernel "
        f"{med(fk_t)} | {statistics.median(fk_t) / statistics.median(fk_r):.0f}x (robot.fk vs torch) |",
        f"| {robot.name} | FK + Jacobian | {med(fj_k)} | torch {med(fj_t)}, numpy {med(fj_n)} | "
        f"{statistics.median(fj_n) / statistics.median(fj_k):.0f}x vs numpy |",
    ]


def lm_compare(robot, n_targets: int, first_starts: int, *, with_numpy: bool = True):
    """Per-call microseconds, successes and joints outside the limits of the kernel LM (and of the numpy one-pose
    LM of ``tests/lm_reference.py``, the path ``IKSolver.solve`` took for one pose before the kernels)."""
    from lm_reference import SingleLM, best_of, lm_solve_one

    from nik.lm import LMCfg

    G, joints = K.chain_model(robot.G, robot.offsets, robot.limits, robot.prismatic)
    qt = robot.sample(n_targets, generator=torch.Generator().manual_seed(TARGET_SEED_BASE), dtype=torch.float64)
    Tt = robot.fk(qt)
    Tn = Tt.numpy()
    opts, iopts = K.lm_options(tol_pos=TOL_POS, tol_rot=TOL_ROT, first_starts=first_starts)
    q0, budget = np.zeros((1, robot.dof)), np.array([RESTARTS], dtype=np.int64)
    answers = np.empty((n_targets, robot.dof))
    info = np.empty(1, dtype=np.int64), np.empty(1, dtype=bool), np.empty(1), np.empty(1)
    cfg, single = LMCfg(), SingleLM.from_robot(robot)
    times_k, times_n, answers_n = [], [], []
    K.lm_solve(G, joints, Tn[:1], q0, opts, iopts, budget, K.seed_state(0), (answers[:1], *info))  # warm-up
    for start in range(0, n_targets, 30):  # kernel and numpy interleaved by blocks of 30 targets
        block = range(start, min(start + 30, n_targets))
        for k in block:
            t = time.perf_counter_ns()
            K.lm_solve(G, joints, Tn[k : k + 1], q0, opts, iopts, budget, K.seed_state(k), (answers[k : k + 1], *info))
            times_k.append((time.perf_counter_ns() - t) / 1e3)
        if not with_numpy:
            continue
        for k in block:
            g = torch.Generator().manual_seed(k)

            def sample(g=g):
                return robot.sample(1, generator=g, dtype=torch.float64)[0].numpy()

            t = time.perf_counter_ns()
            start_q = best_of(single, Tn[k], robot.sample(64, generator=g, dtype=torch.float64).numpy(), cfg.rot_weight)
            q, _ = lm_solve_one(
                single, Tn[k], start_q, cfg=cfg, tol_pos=TOL_POS, tol_rot=TOL_ROT, first_iters=cfg.iters,
                restarts=RESTARTS, sample=sample,
            )  # fmt: skip
            times_n.append((time.perf_counter_ns() - t) / 1e3)
            answers_n.append(torch.as_tensor(q))
    out = {"kernel": (times_k, *score(robot, Tt, torch.from_numpy(answers)))}
    if with_numpy:
        out["numpy"] = (times_n, *score(robot, Tt, torch.stack(answers_n)))
    return out


def score(robot, T, q) -> tuple[int, int]:
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    outside = (q < lo) | (q > hi)
    pos, rot = nik.pose_error(T, robot.fk(q))
    return int(((pos <= TOL_POS) & (rot <= TOL_ROT) & ~outside.any(-1)).sum()), int(outside.sum())


def lm_row(name: str, label: str, ts, ok: int, outside: int, n: int) -> str:
    ts = np.asarray(ts)
    return (
        f"| {name} | {label} | {np.median(ts):.1f} | {np.percentile(ts, 95):.1f} | {ts.max():.0f} | "
        f"{(ts > 2000).sum()} | {ok}/{n} | {outside} |"
    )


def mlp_row(robot, calls: int) -> str | None:
    from nik.models import load_pretrained

    try:
        net = load_pretrained(robot)
    except Exception:
        return None
    rows = 8 if type(net).__name__ == "BranchIKNet" else 1
    flat, layout = kmlp.mlp_pack([(layer.weight.detach(), layer.bias.detach()) for layer in net.layers])
    x = np.random.default_rng(0).standard_normal((rows, int(layout[0, 1])))
    y, work = np.empty((rows, int(layout[-1, 0]))), kmlp.mlp_work(layout, rows)
    code = kmlp.ACTIVATIONS[net.activation]
    xt = torch.from_numpy(x).float()
    with torch.no_grad():
        tk, tt = per_call([lambda: kmlp.mlp_forward(flat, layout, code, x, y, work), lambda: net.mlp(xt)], calls)
    return (
        f"| {robot.name} | MLP forward {type(net).__name__} ({rows} row{'s' * (rows > 1)}, "
        f"{int(sum(r[0] * r[1] + r[0] for r in layout))} weights) | {med(tk)} | torch float32 {med(tt)} | "
        f"{statistics.median(tt) / statistics.median(tk):.1f}x |"
    )


_COMPILE = """
import time, numpy as np
t0 = time.perf_counter()
import nik.kernels as K
from nik.kernels import closed, mlp, poses
t1 = time.perf_counter()
import nik
from nik.analytic.solve import closed_form
ur5 = nik.load_robot("ur5")
k = closed.closed_form_array(closed_form(ur5))
G6, j6 = K.chain_model(ur5.G, ur5.offsets, ur5.limits)
G, joints = K.chain_model(np.tile(np.eye(4), (8, 1, 1)), np.zeros(7), [[-3.0, 3.0]] * 7)
q, T, J, E = np.zeros(7), np.empty((4, 4)), np.empty((6, 7)), np.eye(4)[None]
opts, iopts = K.lm_options()
flat, layout = mlp.mlp_pack([(np.ones((4, 3)), np.ones(4)), (np.ones((2, 4)), np.ones(2))])
one = np.empty(1)
calls = {
    "fk": lambda: K.fk(G, joints, q, T),
    "fk_batch": lambda: K.fk_batch(G, joints, q[None], T[None]),
    "fk_jacobian": lambda: K.fk_jacobian(G, joints, q, T, J),
    "lm_solve": lambda: K.lm_solve(G, joints, E, q[None], opts, iopts, np.ones(1, dtype=np.int64),
                                   K.seed_state(0), (np.empty((1, 7)), np.empty(1, dtype=np.int64),
                                   np.empty(1, dtype=bool), one, one.copy())),
    "pose_errors": lambda: K.pose_errors(G, joints, E, q[None], one, one.copy()),
    "uniform_configurations": lambda: K.uniform_configurations(joints, K.seed_state(0), np.empty((2, 7))),
    "poses_ok": lambda: poses.poses_ok(E, 1e-4),
    "quat_poses": lambda: poses.quat_poses(np.array([[0, 0, 0, 1.0, 0, 0, 0]]), 1e-2, np.empty((1, 4, 4))),
    "rpy_poses": lambda: poses.rpy_poses(np.zeros((1, 6)), np.empty((1, 4, 4))),
    "reach_flags": lambda: poses.reach_flags(E, np.zeros(3), 1.0, 1e-9, np.empty(1, dtype=bool)),
    "closed.guess": lambda: closed.guess(k, G6, j6, 1e-9, E, np.zeros((1, 6)), False, 1e-9, 1e-4, 1e-3,
                                         np.ones(1, dtype=bool), np.empty((1, 6)), one, one.copy(),
                                         np.empty(1, dtype=bool)),
    "closed.solutions (tests only)": lambda: closed.solutions(k, G6, j6, 1e-9, 1e-9, E, np.empty((1, 8, 6)),
                                                              np.empty((1, 8), dtype=bool)),
    "mlp_forward": lambda: mlp.mlp_forward(flat, layout, 2, np.ones((1, 3)), np.empty((1, 2)), mlp.mlp_work(layout, 1)),
}
out = {}
for name, call in calls.items():
    t = time.perf_counter(); call(); out[name] = time.perf_counter() - t
print("import nik.kernels %.2f s; " % (t1 - t0) + ", ".join("%s %.2f s" % kv for kv in out.items())
      + "; all kernels %.2f s" % sum(out.values()))
"""


def compile_times() -> list[str]:
    lines = []
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "NUMBA_CACHE_DIR": folder}
        for label in ("cold cache", "warm cache"):
            done = subprocess.run([sys.executable, "-c", _COMPILE], env=env, capture_output=True, text=True, cwd=ROOT)
            lines.append(f"{label}: {done.stdout.strip() or done.stderr.strip()[-500:]}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5", "kuka_kr", "stanford"])
    parser.add_argument("--targets", type=int, default=300)
    parser.add_argument("--first-starts", type=int, default=8)
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads (the kernels use one)")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--sweep", action="store_true", help="LM median / p95 against first_starts")
    parser.add_argument("--no-compile", action="store_true", help="skip the compile-time subprocesses")
    args = parser.parse_args()
    if args.quick:
        args.targets = 60
    calls = 300 if args.quick else 3000
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__} ({torch.get_num_threads()} threads), numba {K._jit.numba.__version__}")
    folder = K.CACHE.folder
    if folder is not None and folder.is_relative_to(ROOT):
        folder = folder.relative_to(ROOT)
    print(f"numba cache: {K.CACHE.mode} ({folder})\n")
    if not args.no_compile:
        print("\n".join(compile_times()) + "\n")

    print(f"## FK, FK + Jacobian, MLP: microseconds per call (median of {calls}, interleaved by blocks of 50)\n")
    print("| robot | what | kernel | reference | speed-up |\n|---|---|---:|---:|---:|")
    robots = {name: nik.load_robot(name) for name in args.robots}
    for robot in robots.values():
        print("\n".join(fk_rows(robot, calls)))
        row = mlp_row(robot, max(calls // 10, 30))
        if row:
            print(row)

    n = args.targets
    print(
        f"\n## One pose, no network: microseconds per call ({n} reachable targets, kernel and numpy by blocks of 30)\n"
    )
    print(f"Kernel: best of {args.first_starts} uniform configurations, then LM, up to {RESTARTS} uniform restarts.\n")
    print("| robot | path | median | p95 | max | > 2 ms | success | outside limits |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for robot in robots.values():
        res = lm_compare(robot, n, args.first_starts)
        for label, (ts, ok, outside) in res.items():
            print(lm_row(robot.name, label, ts, ok, outside, n))
    if args.sweep:
        print("\n## Kernel LM against the number of uniform first starts (median / p95 us)\n")
        sizes = [1, 4, 8, 16, 32, 64]
        print("| robot | " + " | ".join(str(s) for s in sizes) + " |\n|---|" + "---:|" * len(sizes))
        for robot in robots.values():
            cells = []
            for s in sizes:
                ts = np.asarray(lm_compare(robot, n, s, with_numpy=False)["kernel"][0])
                cells.append(f"{np.median(ts):.0f} / {np.percentile(ts, 95):.0f}")
            print(f"| {robot.name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
