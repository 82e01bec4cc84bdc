"""nik.learn.finetune: every hypothesis pulled onto the pose through the FK; the command writes a loadable pair."""

from __future__ import annotations

import pytest
import torch

import nik
from nik.learn.finetune import FinetuneCfg, finetune, hypotheses_pose_loss, main
from nik.nets.multi import MultiHypIKNet, hypothesis_pose_error
from nik.nets.pair import load_pair, read_pair_meta
from nik.nets.pretrained import save


def _net(seed: int = 0) -> MultiHypIKNet:
    torch.manual_seed(seed)
    robot = nik.load_robot("panda")
    T = robot.fk(robot.sample(2000, generator=torch.Generator().manual_seed(1), dtype=torch.float64)).float()
    return MultiHypIKNet(robot, hidden=(32, 32), heads=4).fit_normalisation(T)


def _per_sample_mm(net) -> float:
    robot = net.robot
    T = robot.fk(robot.sample(300, generator=torch.Generator().manual_seed(99), dtype=torch.float64))
    pos, _ = hypothesis_pose_error(robot, T, net.hypotheses(T).double())
    return float(pos.mean()) * 1e3


def test_finetuning_lowers_the_error_of_every_hypothesis_as_measured_by_fk():
    net = _net()
    T = net.robot.fk(net.robot.sample(256, generator=torch.Generator().manual_seed(5), dtype=torch.float64)).float()
    with torch.no_grad():
        loss_before = float(hypotheses_pose_loss(net, T))
    before = _per_sample_mm(net)
    counters = finetune(net, FinetuneCfg(minutes=5, max_steps=60, lr=3e-3, batch_size=256, seed=3))
    assert counters["steps"] == 60 and counters["sample_evals"] == 60 * 256
    with torch.no_grad():
        assert float(hypotheses_pose_loss(net, T)) < 0.7 * loss_before
    assert _per_sample_mm(net) < 0.8 * before  # the mean over all heads, FK of the clamped hypotheses
    assert not net.training


def test_finetuning_is_seeded():
    a, b = _net(), _net()
    cfg = FinetuneCfg(minutes=5, max_steps=5, lr=1e-3, batch_size=64, seed=2)
    finetune(a, cfg)
    finetune(b, cfg)
    assert all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values(), strict=True))


def test_bad_settings_are_refused_in_one_line():
    with pytest.raises(ValueError, match="minutes"):
        FinetuneCfg(minutes=0)
    with pytest.raises(ValueError, match="lr"):
        FinetuneCfg(lr=-1.0)


def test_the_command_writes_a_pair_that_loads_and_keeps_how_it_was_made_and_adds_the_finetuning(tmp_path, capsys):
    src = tmp_path / "panda_src.safetensors"
    save(_net(), src, training={"command": "made in a test"}, validation={"n": 50})
    out = tmp_path / "panda_ft.safetensors"
    args = [str(src), "--out", str(out), "--max-steps", "3", "--batch-size", "32", "--lr", "1e-3"]
    assert main(args) == 0
    meta = read_pair_meta(out)
    assert meta["training"]["command"] == "made in a test"  # how it was made, then the fine-tuning
    (run,) = meta["training"]["finetune"]
    assert run["command"].startswith("python -m nik.learn.finetune ") and run["counters"]["steps"] == 3
    assert "network_use" in meta
    assert load_pair(out).n_hypotheses == 4
    with pytest.raises(SystemExit) as e:
        main([str(src), "--out", str(tmp_path / "x.pt")])
    assert e.value.code == 2
    assert main([str(tmp_path / "missing.safetensors"), "--out", str(out)]) == 2
    assert "error" in capsys.readouterr().err
