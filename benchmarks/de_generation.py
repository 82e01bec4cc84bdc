"""One DE generation (NP = 220, paper C's 6-8-6 net, 10,000 samples): batched versus a per-individual loop.

    python benchmarks/de_generation.py [--samples 10000 1000 100] [--pop 220] [--repeats 5] [--loss joint|pose]

Both paths run in this process on the same population and data: the batched path is
:func:`nik.learn.population_fitness` (stacked weights, ``torch.baddbmm``); the loop writes each
individual's weights into one ``IKNet`` and runs it (``set_flat_params`` + forward + loss). The
ask/tell part of the generation (mutation, crossover, selection) is the same batched code in both
and is timed with each. Prints the median time of each and the ratio; checks both give the same fitness.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

import nik
from nik.learn import (
    DECfg,
    de_init,
    de_step,
    init_population,
    joint_mse,
    population_fitness,
    pose_loss,
    set_flat_params,
)
from nik.nets import IKNet


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--samples",
        type=int,
        nargs="+",
        default=[10_000, 1_000, 100],
        help="sample counts per generation (the first is the goal's 10,000)",
    )
    ap.add_argument("--pop", type=int, default=220)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--loss", choices=["joint", "pose"], default="joint")
    ap.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's choice)")
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)

    robot = nik.load_robot("kuka_kr")
    print(
        f"DE generation, NP={args.pop}, paper C's 6-8-6 tanh net, {args.loss} loss, "
        f"{torch.get_num_threads()} threads, torch {torch.__version__}"
    )
    for n in args.samples:
        t_batched, t_loop = run(robot, n, args)
        print(
            f"  {n:6d} samples: batched {t_batched * 1e3:8.1f} ms | per-individual loop {t_loop * 1e3:8.1f} ms | "
            f"ratio {t_loop / t_batched:5.1f}x (goal >= 20x)"
        )
    return 0


def run(robot, n_samples: int, args) -> tuple[float, float]:
    """Median seconds of one generation: (batched, loop)."""
    g = torch.Generator().manual_seed(0)
    q = robot.sample(n_samples, generator=g)
    T = robot.fk(q)
    net = IKNet(robot, hidden=[8], activation="tanh", representation="rpy").fit_normalisation(T, q)
    x, y_t = net.features(T), net.encode(q)
    cfg = DECfg(pop_size=args.pop)

    def batched(W):
        return population_fitness(net, W, x, y_target=y_t, T_target=T, loss=args.loss)

    @torch.no_grad()
    def loop(W):
        out = torch.empty(W.shape[0])
        for i in range(W.shape[0]):
            set_flat_params(net, W[i])
            y = net.raw(x)
            if args.loss == "joint":
                out[i] = joint_mse(y, y_t)
            else:
                out[i] = pose_loss(net.decode(y), T, robot, length_scale=net.length_scale)
        return out

    W0 = init_population(net, args.pop, generator=g)
    torch.testing.assert_close(batched(W0), loop(W0), rtol=1e-4, atol=1e-6)

    def time_generation(fn) -> float:
        state = de_init(W0, fn(W0), cfg)
        gen = torch.Generator().manual_seed(1)
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            state = de_step(state, fn, cfg, generator=gen)
            times.append(time.perf_counter() - t)
        return statistics.median(times)

    return time_generation(batched), time_generation(loop)


if __name__ == "__main__":
    raise SystemExit(main())
