"""Training across processes: ``train.py`` under DDP on the CPU (gloo backend, 2 processes).

Each test starts ``python train.py fit ... --trainer.strategy ddp --trainer.devices 2`` in a
subprocess (Lightning launches the second rank itself), on a tiny dataset, and checks what the run
leaves behind: the checkpoint, the logged metrics and the printed messages.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml

import nik

ROOT = Path(__file__).resolve().parents[1]
QUIET = ["--trainer.enable_progress_bar", "false", "--trainer.enable_model_summary", "false"]
pytestmark = [
    pytest.mark.long,  # two-process training runs
    pytest.mark.filterwarnings("ignore:LightningCLI's args parameter"),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*treespec"),
]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from nik.data import generate_dataset

    # 400 train | 50 val | 50 test
    return generate_dataset("kuka_kr", 500, tmp_path_factory.mktemp("data") / "kuka_tiny", seed=0, progress=False)


def _train(config, dataset, root: Path, *extra: str, devices: int = 2) -> subprocess.CompletedProcess:
    """``python train.py fit`` in a subprocess; 1 torch thread per rank (the machine has 2 cores).
    ``config``: a method name (its shipped config) or a config file."""
    if isinstance(config, str):
        config = ROOT / "configs" / "train" / f"{config}.yaml"
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        "fit",
        "--config",
        str(config),
        "--data.path",
        str(dataset),
        "--trainer.default_root_dir",
        str(root),
        "--trainer.accelerator",
        "cpu",
        "--trainer.devices",
        str(devices),
        *(["--trainer.strategy", "ddp"] if devices > 1 else []),
        *QUIET,
        *extra,
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    proc = subprocess.run(cmd, cwd=root.parent, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


def test_two_process_gradient_training_logs_reduced_metrics_and_leaves_one_loadable_checkpoint(dataset, tmp_path):
    root = tmp_path / "adam_ddp"
    proc = _train(
        "adam",
        dataset,
        root,
        "--model.hidden",
        "[16]",
        "--data.batch_size",
        "100",
        "--data.eval_batch_size",
        "25",  # val: 2 batches of 25, one per rank
        "--trainer.max_epochs",
        "2",
    )
    out = proc.stdout + proc.stderr
    assert "Starting with 2 processes" in out  # really two ranks
    assert out.count("`Trainer.fit` stopped") == 1  # rank 0 speaks for both
    ckpts = sorted(root.rglob("last.ckpt"))
    assert len(ckpts) == 1
    kuka = nik.load_robot("kuka_kr")
    solver = nik.IKSolver(kuka, checkpoint=ckpts[0], refine="lm")
    net = solver.net
    # the logged validation loss is the mean over BOTH ranks' batches: the whole validation split
    metrics = sorted(root.rglob("metrics.csv"))
    assert len(metrics) == 1
    rows = [r for r in csv.DictReader(open(metrics[0])) if r.get("val_joint_mse")]
    logged = float(rows[-1]["val_joint_mse"])
    ds = nik.data.load_dataset(dataset)
    T, q = ds.val.pose.float(), ds.val.q.float()
    with torch.no_grad():
        whole = float((net.raw(net.features(T)) - net.encode(q)).square().sum(-1).mean())
        halves = [
            float((net.raw(net.features(T[s])) - net.encode(q[s])).square().sum(-1).mean())
            for s in (slice(0, 25), slice(25, 50))
        ]
    assert logged == pytest.approx(whole, rel=1e-5)
    history = list(csv.DictReader(open(root / "history.csv")))  # written once, by rank 0
    assert float(history[-1]["val_joint_mse"]) == pytest.approx(whole, rel=1e-5)
    assert abs(halves[0] - halves[1]) > 1e-3 * whole  # so a rank-0-only value would have been caught
    # both ranks counted: 4 training batches per epoch split 2 + 2, summed over ranks
    assert float(rows[-1]["loss_evals"]) == 8
    # the solver works from the checkpoint
    q0 = kuka.sample(3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    assert bool(solver.solve(kuka.fk(q0)).success.all())


def test_de_on_two_ranks_gives_the_same_population_as_on_one(dataset, tmp_path):
    # de.yaml with a checkpoint of the latest state at every validation (not only when val_loss improves)
    config = yaml.safe_load((ROOT / "configs" / "train" / "de.yaml").read_text())
    config["trainer"]["callbacks"] = [
        {"class_path": "lightning.pytorch.callbacks.ModelCheckpoint", "init_args": {"save_last": True}}
    ]
    (tmp_path / "de_latest.yaml").write_text(yaml.safe_dump(config))
    extra = ["--model.pop_size", "25", "--trainer.max_epochs", "4", "--trainer.check_val_every_n_epoch", "1"]
    # a small memory cap: several sample chunks, whose size would differ for a slice of 13 networks
    extra += ["--model.max_elements", str(25 * 8 * 64)]
    states = []
    for devices in (1, 2):
        root = tmp_path / f"de_{devices}"
        _train(tmp_path / "de_latest.yaml", dataset, root, *extra, devices=devices)
        (ckpt,) = root.glob("lightning_logs/*/checkpoints/last.ckpt")  # the ModelCheckpoint's, saved every epoch
        full = torch.load(ckpt, weights_only=True)
        states.append({**full["nik_de"], "rank0_loss_evals": full["nik"]["counters"]["loss_evals"]})
    one, two = states
    # the work is split: in 2 processes rank 0 scored 13 of the 25 networks of each of the 4 steps
    assert one["rank0_loss_evals"] == 4 * 25
    assert two["rank0_loss_evals"] == 4 * 13
    assert one["generation"] == two["generation"] == 3  # the first step draws and scores the initial population
    # bit-identical: every rank draws the same trials, each scores its slice with the whole population's
    # sample chunking, so each individual's fitness is the same arithmetic as in one process
    assert torch.equal(one["x"], two["x"])
    assert torch.equal(one["fitness"], two["fitness"])
    assert one["history"] == two["history"]
