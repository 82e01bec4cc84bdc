"""Best and mean fitness over generations of paper C's DE on its 6-8-6 net (what the settings really do).

    python benchmarks/de_trajectory.py --data D [--generations 500] [--strategy rand1bin] [--init default]

The module's flow (``nik.learn.modules.DEIK``): the population is drawn like PyTorch's default
``nn.Linear`` init (``nik.learn.init_population``; the net's own initial weights are individual 0),
kept inside the +-``bound`` box, and scored by paper C's joint-space MSE (eq. 4, outputs scaled to
[-1, 1]) on the whole training split (float32). ``--init uniform10`` draws every weight uniformly in
+-10 instead (what the box bound might suggest; it saturates tanh). Prints the mean predictor's
fitness (a constant output equal to the targets' mean) for scale. 1 torch thread.
"""

from __future__ import annotations

import argparse
import time

import torch


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--generations", type=int, default=500)
    ap.add_argument("--strategy", default="rand1bin", choices=["rand1bin", "current_to_best1bin"])
    ap.add_argument("--jde", action="store_true")
    ap.add_argument("--init", default="default", choices=["default", "uniform10"])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)

    from nik.data import load_dataset
    from nik.learn import DECfg, de_init, de_step, flat_params, init_population, population_fitness
    from nik.nets import IKNet

    torch.manual_seed(args.seed)
    ds = load_dataset(args.data, mmap=False)
    T, q = ds.train.pose.float(), ds.train.q.float()
    net = IKNet(ds.robot, hidden=[8], activation="tanh", representation="rpy").fit_normalisation(T, q).float()
    x, y = net.features(T), net.encode(q)
    g = torch.Generator().manual_seed(args.seed + 1)
    cfg = DECfg(pop_size=220, F=0.6, CR=0.5, strategy=args.strategy, jde=args.jde)
    if args.init == "default":
        x0 = init_population(net, cfg.pop_size, generator=g)
    else:
        x0 = torch.rand(cfg.pop_size, flat_params(net).numel(), generator=g) * 20 - 10
    x0[0] = flat_params(net)

    def fitness(W):
        return population_fitness(net, W, x, y_target=y)

    state = de_init(x0, fitness(x0), cfg, lower=torch.tensor(-10.0), upper=torch.tensor(10.0))
    mean_pred = float((y - y.mean(0)).square().sum(-1).mean())
    print(
        f"DE {cfg.strategy}{' + jDE' if cfg.jde else ''}, NP {cfg.pop_size}, F {cfg.F}, CR {cfg.CR}, init {args.init}, "
        f"{T.shape[0]} training samples; mean predictor's fitness {mean_pred:.4f}"
    )
    marks = {0, 1, 2, 5, 8, 10, 20, 38, 50, 100, 200, 300, 400, 500, 1000}
    t0 = time.perf_counter()
    for gen in range(args.generations + 1):
        if gen:
            state = de_step(state, fitness, cfg, generator=g)
        if gen in marks or gen == args.generations:
            f = state.fitness
            print(
                f"  generation {gen:4d}: best {float(f.min()):.4f}  mean {float(f.mean()):.4f}  "
                f"worst {float(f.max()):.4f}  ({time.perf_counter() - t0:.0f} s)",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
