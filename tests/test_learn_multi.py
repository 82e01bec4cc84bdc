"""nik.learn.multi: the shipped configs train multi-solution networks through train.py; export to the package."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest
import torch
import yaml

import nik
from nik.learn.multi import MultiSolutionIK, plot_history
from nik.models import load_checkpoint
from nik.nets.export import main as export_main
from nik.nets.multi import BranchHeadsIKNet, MultiHypIKNet
from nik.nets.pretrained import load, validation_error

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [
    pytest.mark.filterwarnings("ignore:LightningCLI's args parameter"),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*treespec"),
    pytest.mark.filterwarnings("ignore:.*does not have many workers"),
]


def _cli():
    spec = importlib.util.spec_from_file_location("nik_train_script", ROOT / "train.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.cli_main


def _config(robot: str, tmp_path: Path, data: Path) -> Path:
    """The shipped config of ``robot``, pointed at tiny data and a temp folder, with a tiny net."""
    cfg = yaml.safe_load((ROOT / "configs" / "train" / f"{robot}.yaml").read_text())
    cfg["trainer"].update(default_root_dir=str(tmp_path), max_time=None, max_epochs=4, logger=False)
    cfg["trainer"]["enable_progress_bar"] = False
    cfg["model"]["init_args"].update(hidden=[32, 32], eval_samples=200)
    cfg["data"].update(path=str(data), batch_size=128)
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.mark.long
@pytest.mark.parametrize("robot,cls", [("kuka_kr", BranchHeadsIKNet), ("panda", MultiHypIKNet)])
def test_shipped_config_trains_in_two_phases_and_exports(robot, cls, tmp_path):
    from nik.data import generate_dataset

    data = generate_dataset(robot, 1500, tmp_path / "data", seed=0, progress=False)
    cli = _cli()(["fit", "--config", str(_config(robot, tmp_path, data))])
    model = cli.model
    assert isinstance(model, MultiSolutionIK) and isinstance(model.net, cls)
    assert model.in_pose_phase()  # half-way through it switched to the FK pose loss
    hist = next(cb for cb in cli.trainer.callbacks if type(cb).__name__ == "History").rows
    assert len(hist) == 4 and hist[-1]["val_pos_mm"] < hist[0]["val_pos_mm"]  # it learns
    assert (tmp_path / "curve.png").stat().st_size > 0
    assert (tmp_path / "final.ckpt").is_file()  # the network as the fit ended
    ckpt = tmp_path / "last.ckpt"
    net = load_checkpoint(ckpt, robot=robot)  # loadable as a solver checkpoint too
    T = cli.datamodule.val_data[0][:20].double()
    torch.testing.assert_close(net.hypotheses(T), model.net.eval().hypotheses(T))
    # fallback="none": the network itself, whatever nik.ik.judge makes of a network trained for 4 short epochs
    assert nik.IKSolver(robot, checkpoint=ckpt, analytic=False, fallback="none").initial_source == "network"
    out = tmp_path / "pretrained"
    assert export_main([str(ckpt), "--robot", robot, "--out", str(out)]) == 0
    shipped = load(robot, out)
    assert torch.equal(shipped.hypotheses(T), net.hypotheses(T))
    meta = (out / f"{robot}.json").read_text()
    rec = validation_error(shipped, seed=12345, n=2000)
    assert f'"best_pos_mm_median": {rec["best_pos_mm_median"]}' in meta
    training = json.loads(meta)["training"]
    # what really ran: the training command with its config file, the dataset (checksums), this export
    assert training["command"] == f"python train.py fit --config {tmp_path / 'cfg.yaml'}"
    assert training["data"]["path"] == str(data) and training["data"]["sha256"]["q.npy"]
    assert training["export_command"].startswith("python -m nik.nets.export ")
    assert "config_file" not in training  # no config file is claimed unless --config names one


def test_export_writes_under_runs_by_default_never_into_the_package(tmp_path, monkeypatch):
    from nik.nets.checkpoint import save_checkpoint
    from nik.nets.multi import MultiHypIKNet
    from nik.nets.pretrained import PRETRAINED_DIR

    before = sorted(p.name for p in PRETRAINED_DIR.iterdir())
    ckpt = save_checkpoint(MultiHypIKNet(nik.load_robot("panda"), hidden=[8], heads=2), tmp_path / "x.ckpt")
    monkeypatch.chdir(tmp_path)
    assert export_main([str(ckpt)]) == 0
    assert (tmp_path / "runs" / "panda" / "panda.safetensors").is_file()
    assert (tmp_path / "runs" / "panda" / "panda.json").is_file()
    assert sorted(p.name for p in PRETRAINED_DIR.iterdir()) == before


def test_plot_history_writes_a_png(tmp_path):
    rows = [{"wall_s": 10.0 * i, "val_pos_mm": 100.0 / (i + 1), "val_rot_deg": 10.0 / (i + 1)} for i in range(4)]
    path = plot_history(rows, tmp_path / "c.png", title="t")
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_bad_module_arguments_are_refused():
    with pytest.raises(ValueError, match="kind"):
        MultiSolutionIK(kind="flow")
    with pytest.raises(ValueError, match="pose_start"):
        MultiSolutionIK(pose_start=1.5)


def test_settings_come_as_a_dataclass_or_keywords_and_old_checkpoints_load(tmp_path):
    """At most 12 parameters; MultiSolutionCfg or keywords give the same hparams; a checkpoint written with the
    keyword signature (flat hyper_parameters, the fixed choices among them) builds the same module."""
    import inspect

    import lightning

    from nik.learn.multi import FIXED, MultiSolutionCfg

    assert len(inspect.signature(MultiSolutionIK.__init__).parameters) <= 12
    a = MultiSolutionIK(MultiSolutionCfg(kind="multihead", hidden=(32, 32)), heads=4)
    b = MultiSolutionIK(kind="multihead", hidden=(32, 32), heads=4)
    assert dict(a.hparams) == dict(b.hparams)
    assert set(a.hparams) == set(MultiSolutionCfg.__dataclass_fields__) | set(FIXED)  # flat, no dataclass object
    assert (a.hparams.heads, a.hparams.optimizer, a.hparams.output, a.hparams.schedule) == (
        4,
        "adam",
        "sincos",
        "cosine",
    )
    with pytest.raises(ValueError, match="loss"):
        MultiSolutionIK(loss="joint")  # a choice the module fixes
    old = {"kind": "multihead", "hidden": [32, 32], "activation": "silu", "heads": 4, "pose_start": 0.3}
    old |= {"joint_weight": 0.01, "wta_eps": 0.05, "rot_weight": 1.0, "lr": 0.003, "schedule": "cosine"}
    old |= {"min_lr_ratio": 0.01, "weight_decay": 0.0, "eval_samples": 100, **FIXED}
    path = tmp_path / "old.ckpt"
    torch.save({"state_dict": {}, "hyper_parameters": old, "pytorch-lightning_version": lightning.__version__}, path)
    m = MultiSolutionIK.load_from_checkpoint(path)
    assert (m.hparams.kind, list(m.hparams.hidden), m.hparams.lr, m.hparams.pose_start) == (
        "multihead",
        [32, 32],
        0.003,
        0.3,
    )
