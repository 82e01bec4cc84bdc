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

import nik
from nik.models import load_checkpoint

pytestmark = pytest.mark.long  # every test trains with train.py in a fresh process

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


@pytest.fixture(scope="module")
def logged_run(dataset, tmp_path_factory):
    """A 3-epoch run with stdout and stderr going to pipes (as in ``train.py ... > log``), keeping the network as
    the fit ends (FinalCheckpoint, as the shipped-network configs do)."""
    root = tmp_path_factory.mktemp("logged")
    done = _train(dataset, root, "--trainer.max_epochs", "3", "--trainer.callbacks+=nik.learn.multi.FinalCheckpoint")
    assert done.returncode == 0, done.stderr[-3000:]
    return root, done


def test_progress_is_one_line_per_epoch_when_stdout_is_not_a_terminal(logged_run):
    _, done = logged_run
    text = done.stdout + done.stderr  # (subprocess' text mode turns the bars' carriage returns into newlines)
    assert "it/s" not in text and "s/it" not in text and "Validation DataLoader" not in text  # no tqdm bars
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("epoch ")]
    assert [ln.split()[1] for ln in lines] == ["1/3", "2/3", "3/3"]
    assert all("train_loss" in ln and "val_loss" in ln for ln in lines)


def test_final_checkpoint_is_saved_without_the_weights_only_notice(logged_run):
    root, done = logged_run
    assert "weights_only" not in done.stdout + done.stderr
    assert load_checkpoint(root / "final.ckpt", robot="kuka_kr").robot.name == "kuka_kr"


# -- refusals in one line (issue 50): another robot's run, a zero budget, a key that does not exist ----------------
def _main_lines(args):
    """``train.py``'s ``main(args)`` in this process: (exit status, the non-empty lines it wrote on stderr)."""
    from nik.learn.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main([str(a) for a in args])
    return rc, [ln for ln in err.getvalue().splitlines() if ln.strip()]


def _fit_args(data, root, *extra):
    return [
        "fit",
        "--config",
        ROOT / "configs/train/adam.yaml",
        "--data.path",
        data,
        "--trainer.default_root_dir",
        root,
        "--model.hidden",
        "[16]",
        "--data.batch_size",
        "64",
        "--trainer.logger",
        "false",
        "--trainer.enable_progress_bar",
        "false",
        "--trainer.enable_model_summary",
        "false",
        *extra,
    ]


@pytest.fixture(scope="module")
def kuka_run(dataset, tmp_path_factory):
    """A one-epoch kuka_kr run: its last.ckpt."""
    root = tmp_path_factory.mktemp("kuka_run")
    rc, lines = _main_lines(_fit_args(dataset, root, "--trainer.max_epochs", "1"))
    assert rc == 0, lines
    return root / "last.ckpt"


@pytest.mark.parametrize("other", ["panda", "puma560"])  # 7 joints (crashed in load_state_dict), 6 (resumed silently)
def test_resuming_a_run_on_another_robots_data_is_refused_in_one_line(other, kuka_run, tmp_path):
    from nik.data import generate_dataset

    data = generate_dataset(other, 200, tmp_path / other, seed=0, progress=False)
    root = tmp_path / "runs"
    rc, lines = _main_lines(_fit_args(data, root, "--trainer.max_epochs", "2", "--ckpt_path", kuka_run))
    assert rc == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith("train.py: error: ") and "'kuka_kr'" in lines[0] and f"'{other}'" in lines[0]
    assert nik.load_robot(other).definition_hash in lines[0]
    assert not (root / "last.ckpt").exists()


def test_resuming_through_the_python_api_checks_the_robot_too(kuka_run, tmp_path):
    import lightning as L

    from nik.data import generate_dataset
    from nik.learn import GradientIK, IKDataModule

    data = generate_dataset("puma560", 200, tmp_path / "puma", seed=0, progress=False)
    model = GradientIK(hidden=(16,), activation="silu", representation="rot6d", optimizer="adam")
    trainer = L.Trainer(
        max_epochs=2, logger=False, enable_progress_bar=False, enable_model_summary=False, default_root_dir=tmp_path
    )
    with pytest.raises(nik.CheckpointError, match="'kuka_kr'.*'puma560'"):
        trainer.fit(model, datamodule=IKDataModule(str(data), batch_size=64), ckpt_path=str(kuka_run))


def test_resuming_a_run_of_the_same_robot_still_works(kuka_run, dataset, tmp_path):
    root = tmp_path / "again"
    rc, lines = _main_lines(_fit_args(dataset, root, "--trainer.max_epochs", "2", "--ckpt_path", kuka_run))
    assert rc == 0, lines
    assert torch.load(root / "last.ckpt", weights_only=True)["epoch"] == 1


@pytest.mark.parametrize(
    "budget",
    [("--trainer.max_time", "00:00:00:00"), ("--trainer.max_time", "00:00:-1:55"), ("--trainer.max_steps", "0")],
)
def test_a_zero_budget_is_refused_in_one_line_and_writes_nothing(budget, dataset, tmp_path):
    root = tmp_path / "runs"
    rc, lines = _main_lines(_fit_args(dataset, root, *budget))
    assert rc == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"train.py: error: {budget[0]} ") and "last.ckpt" in lines[0]
    assert not root.exists()


@pytest.mark.parametrize(
    "typo, wrong, right",
    [
        (["--model.hiden", "64"], "model.hiden", "model.hidden"),
        (["--model.init_args.hiden", "64"], "model.hiden", "model.hidden"),
        (["--config", "model:\n  init_args:\n    hiden: [8]\n"], "model.hiden", "model.hidden"),
        (["--data.paht", "x"], "data.paht", "data.path"),
        (["--config", "trainer:\n  max_epoch: 3\n"], "trainer.max_epoch", "trainer.max_epochs"),
    ],
)
def test_a_config_typo_is_one_line_with_the_closest_accepted_key(typo, wrong, right, dataset, tmp_path):
    if typo[0] == "--config":  # a YAML file with the typo, given after the method's config
        path = tmp_path / "typo.yaml"
        path.write_text(typo[1])
        typo = ["--config", str(path)]
    root = tmp_path / "runs"
    rc, lines = _main_lines(_fit_args(dataset, root, *typo))
    assert rc == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith("train.py: error: ")
    assert wrong in lines[0] and f"did you mean {right}" in lines[0].replace("'", "")
    assert not root.exists()


def test_train_py_points_to_the_training_docs():
    text = (ROOT / "train.py").read_text()
    assert "README (Training)" not in text
    assert "docs/training.md" in text and (ROOT / "docs" / "training.md").is_file()
