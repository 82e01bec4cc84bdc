"""Seconds per DE generation through ``train.py`` (LightningCLI, DEIK) versus the bare batched generation.

    python benchmarks/de_train_overhead.py --data data/kuka_kr_12k [--generations 20] [--threads 1 2] [--repeats 2]

Both in this process, on the same training split (float32, paper C's 6-8-6 tanh net, NP = 220):

- bare: :func:`nik.learn.de_step` with :func:`nik.learn.population_fitness` (what
  ``benchmarks/de_generation.py`` times), median over ``--generations`` generations;
- train.py: ``fit --config configs/train/de.yaml`` for ``--generations`` epochs (one generation each,
  validation every 10, checkpoints, CSV logger: the shipped config), median of the time from one
  epoch's start to the next (so Lightning's per-epoch work is included).

Runs interleave (bare, train.py, bare, train.py, ...) per thread count; prints medians and the ratio.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]


def bare(data: str, generations: int) -> float:
    from nik.data import load_dataset
    from nik.learn import DECfg, de_init, de_step, flat_params, init_population, population_fitness
    from nik.nets import IKNet

    ds = load_dataset(data, mmap=False)
    T, q = ds.train.pose.float(), ds.train.q.float()
    torch.manual_seed(0)
    net = IKNet(ds.robot, hidden=[8], activation="tanh", representation="rpy").fit_normalisation(T, q).float()
    x, y = net.features(T), net.encode(q)
    g = torch.Generator().manual_seed(0)
    x0 = init_population(net, 220, generator=g)
    x0[0] = flat_params(net)
    cfg = DECfg()

    def fit(W):
        return population_fitness(net, W, x, y_target=y)

    lo, hi = torch.tensor(-10.0), torch.tensor(10.0)
    state = de_init(x0, fit(x0), cfg, lower=lo, upper=hi)
    times = []
    for _ in range(generations):
        t = time.perf_counter()
        state = de_step(state, fit, cfg, generator=g)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def through_train_py(data: str, generations: int) -> float:
    import lightning as L

    from nik.learn.cli import cli_main

    starts: list[float] = []

    class EpochClock(L.Callback):
        def on_train_epoch_start(self, trainer, pl_module):
            starts.append(time.perf_counter())

        def on_train_end(self, trainer, pl_module):
            starts.append(time.perf_counter())

    with tempfile.TemporaryDirectory() as root:
        cli = cli_main(
            [
                "--config",
                str(ROOT / "configs" / "train" / "de.yaml"),
                "--data.path",
                data,
                "--trainer.default_root_dir",
                root,
                "--trainer.max_epochs",
                str(generations + 1),
                "--trainer.enable_progress_bar",
                "false",
                "--trainer.enable_model_summary",
                "false",
            ],
            run=False,
        )
        cli.trainer.callbacks.append(EpochClock())
        cli.trainer.fit(cli.model, datamodule=cli.datamodule)
    gaps = [b - a for a, b in zip(starts[1:-1], starts[2:], strict=True)]  # skip epoch 0 (initial population)
    return statistics.median(gaps)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="dataset directory (nik generate)")
    ap.add_argument("--generations", type=int, default=20)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=2, help="interleaved (bare, train.py) pairs per thread count")
    args = ap.parse_args(argv)
    import logging
    import warnings

    warnings.filterwarnings("ignore")
    logging.getLogger("lightning.pytorch").setLevel(logging.ERROR)
    from nik.data import read_meta

    n_train = read_meta(args.data)["split_sizes"]["train"]
    print(f"DE generation (NP 220, 6-8-6 tanh, {n_train} training samples, float32), torch {torch.__version__}")
    for threads in args.threads:
        torch.set_num_threads(threads)
        a, b = [], []
        for _ in range(args.repeats):
            a.append(bare(args.data, args.generations))
            b.append(through_train_py(args.data, args.generations))
        ma, mb = statistics.median(a), statistics.median(b)
        print(
            f"  {threads} thread(s): bare {ma * 1e3:7.1f} ms | train.py {mb * 1e3:7.1f} ms per generation | "
            f"ratio {mb / ma:4.2f}  (runs, ms: bare {[round(v * 1e3, 1) for v in a]}, "
            f"train.py {[round(v * 1e3, 1) for v in b]})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
