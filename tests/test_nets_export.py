"""``python -m nik.nets.export``: a network trained by any method exports, installs and loads by path the same way."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

import nik
from nik.nets import load_checkpoint
from nik.nets.export import main as export_main

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [
    pytest.mark.filterwarnings("ignore:LightningCLI's args parameter"),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*treespec"),
    pytest.mark.filterwarnings("ignore:.*guesses no better than uniform starts"),
]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from nik.data import generate_dataset

    return generate_dataset("kuka_kr", 400, tmp_path_factory.mktemp("data") / "kuka", seed=0, progress=False)


def _train(method: str, data: Path, root: Path) -> Path:
    """A few steps of ``train.py fit --config configs/train/<method>.yaml``: its ``last.ckpt``."""
    from nik.learn.cli import cli_main

    extra = {"de_bp": ["--model.pop_size", "8", "--model.generations", "1"], "adam": ["--model.hidden", "[16]"]}
    cli_main(
        [
            *("fit", "--config", str(ROOT / "configs" / "train" / f"{method}.yaml"), "--data.path", str(data)),
            *("--trainer.default_root_dir", str(root), "--trainer.logger", "false"),
            *("--trainer.enable_progress_bar", "false", "--trainer.enable_model_summary", "false"),
            *("--trainer.max_steps", "3", "--trainer.check_val_every_n_epoch", "1"),
            *extra.get(method, []),
        ]
    )
    return root / "last.ckpt"


@pytest.mark.parametrize("method", ["bp", "adam", "lbfgs", "de_bp"])
def test_a_plain_network_of_any_method_exports_installs_and_loads_by_path(method, dataset, tmp_path, capsys):
    from nik.nets.pair import read_pair_meta
    from nik.nets.registry import install, list_networks

    ckpt = _train(method, dataset, tmp_path / method)
    capsys.readouterr()
    assert export_main([str(ckpt)]) == 0
    out = capsys.readouterr().out
    pair = ckpt.parent / "kuka_kr.safetensors"  # beside its checkpoint, not over the arm's multi-solution network
    assert f"wrote {pair}" in out and "the guess" in out
    meta = read_pair_meta(pair)
    assert meta["net"]["kind"] == "plain" and meta["robot_hash"] == nik.load_robot("kuka_kr").definition_hash
    assert "train.py" in meta["training"]["command"] and f"{method}.yaml" in meta["training"]["command"]

    robot = nik.load_robot("kuka_kr")
    T = robot.fk(robot.sample(32, generator=torch.Generator().manual_seed(1), dtype=torch.float64))
    trained = load_checkpoint(ckpt, robot=robot).float()
    # by path: the checkpoint and the exported pair give the same guesses (load_checkpoint reads both)
    for path in (pair, pair.with_suffix(".json")):
        net = load_checkpoint(path, robot=robot)
        assert isinstance(net, nik.nets.IKNet)
        torch.testing.assert_close(net.predict(T), trained.predict(T), atol=0, rtol=0)
    # installed, listed with its kind, and a solver takes it by path
    installed = install(pair, name=f"kuka_{method}")
    assert any(n.path == installed and n.kind == "plain" for n in list_networks())
    solver = nik.IKSolver("kuka_kr", checkpoint=installed, analytic=False)
    torch.testing.assert_close(solver.net.predict(T), trained.predict(T), atol=0, rtol=0)
    res = solver.solve(T)
    assert bool(res.success.all())
    # the recorded validation error is the network's guess, reproduced
    val = json.loads(pair.with_suffix(".json").read_text())["validation"]
    g = torch.Generator().manual_seed(val["seed"])
    qv = robot.sample(val["n"], generator=g, dtype=torch.float64)
    pos = (robot.fk(net.predict(robot.fk(qv)).double())[:, :3, 3] - robot.fk(qv)[:, :3, 3]).norm(dim=-1)
    assert val["best_pos_mm_median"] == pytest.approx(float(pos.median()) * 1e3, rel=1e-4)


def test_an_exported_pair_is_refused_as_a_resume_checkpoint_and_as_export_input(dataset, tmp_path, capsys):
    from nik.nets.export import cli

    ckpt = _train("adam", dataset, tmp_path / "adam")
    assert export_main([str(ckpt)]) == 0
    pair = ckpt.parent / "kuka_kr.safetensors"
    capsys.readouterr()
    assert cli([str(pair)]) == 2
    assert "exported network already" in capsys.readouterr().err
    from nik.learn.cli import check_resume_checkpoint

    with pytest.raises(nik.CheckpointError, match="exported network"):
        check_resume_checkpoint(pair)
