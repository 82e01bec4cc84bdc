"""``train.py``: a stable ``<default_root_dir>/last.ckpt``, no noise from Lightning, clear errors for a bad
``--ckpt_path``."""

from __future__ import annotations

import contextlib
import io
import os
import pickle
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from nik.models import load_checkpoint

ROOT = Path(__file__).resolve().parents[1]
NOISE = [
    "args parameter is intended",  # LightningCLI: args and command line both given
    "Tip:",  # litlogger / litmodels advertisements
    "tensorboardX",  # the implicit default logger
    "LeafSpec",  # torch's _pytree deprecation raised inside Lightning
    "was not set, defaulting",  # weights_only of the checkpoints we save
    "Traceback",
]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from nik.data import generate_dataset

    out = tmp_path_factory.mktemp("data") / "kuka_tiny"
    generate_dataset("kuka_kr", 400, out, seed=0, progress=False)
    return out


def _train(dataset, root, *extra):
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        "fit",
        "--config",
        str(ROOT / "configs" / "train" / "adam.yaml"),
        "--data.path",
        str(dataset),
        "--trainer.default_root_dir",
        str(root),
        "--model.init_args.hidden",
        "[16]",
        "--data.batch_size",
        "64",
        *extra,
    ]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)


def test_every_run_updates_a_stable_last_ckpt_without_lightning_noise(dataset, tmp_path):
    root = tmp_path / "runs" / "tiny"
    done = _train(dataset, root, "--trainer.max_epochs", "2")
    assert done.returncode == 0, done.stderr[-3000:]
    text = done.stdout + done.stderr
    for noise in NOISE:
        assert noise not in text, f"{noise!r} in train.py output:\n{text[-3000:]}"
    last = root / "last.ckpt"
    assert last.is_file()
    assert torch.load(last, weights_only=True)["epoch"] == 1
    assert load_checkpoint(last, robot="kuka_kr").robot.name == "kuka_kr"
    # one last.ckpt per run, no temporaries left; the versioned folders keep only the best by val_loss
    assert sorted(p.relative_to(root) for p in root.rglob("*last*.ckpt")) == [Path("last.ckpt")]
    assert not [p for p in root.rglob(".*tmp*")]

    # a second run (resumed from the stable path) updates the same file
    done = _train(dataset, root, "--trainer.max_epochs", "3", "--ckpt_path", str(last))
    assert done.returncode == 0, done.stderr[-3000:]
    assert "could not find the monitored key" not in done.stderr
    assert torch.load(last, weights_only=True)["epoch"] == 2
    assert len(list(root.glob("lightning_logs/version_*"))) == 2


class _Evil:
    def __reduce__(self):
        return (print, ("this must never print",))


@pytest.mark.parametrize("kind", ["evil", "noise", "missing"])
def test_bad_ckpt_path_ends_in_one_clear_line(kind, dataset, tmp_path):
    bad = tmp_path / f"{kind}.ckpt"
    if kind == "evil":
        bad.write_bytes(pickle.dumps({"state_dict": {}, "nik": _Evil()}, protocol=4))
    elif kind == "noise":
        bad.write_bytes(os.urandom(2048))
    from nik.learn.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(
            [
                "fit",
                "--config",
                str(ROOT / "configs/train/adam.yaml"),
                "--data.path",
                str(dataset),
                "--trainer.default_root_dir",
                str(tmp_path / "runs"),
                "--ckpt_path",
                str(bad),
            ]
        )
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    assert rc == 2
    assert len(lines) == 1, err.getvalue()
    assert lines[0].startswith("train.py: error: ") and str(bad) in lines[0]
    expected = "not found" if kind == "missing" else "not a loadable nik checkpoint"
    assert expected in lines[0]
    assert not (tmp_path / "runs").exists()
