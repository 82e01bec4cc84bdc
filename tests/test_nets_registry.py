"""nik.nets.registry: the list of installed and shipped networks, install and remove (a temporary NIK_HOME:
tests/conftest.py)."""

from __future__ import annotations

import json

import pytest
import torch

import nik
from nik.errors import CheckpointError
from nik.nets.multi import MultiHypIKNet
from nik.nets.pretrained import PRETRAINED_DIR, available, save
from nik.nets.registry import find_network, install, list_networks, remove, user_dir


@pytest.fixture
def tiny_panda(tmp_path):
    """A tiny panda network exported with its recorded validation error: tmp_path/tiny.safetensors (+ .json)."""
    torch.manual_seed(0)
    net = MultiHypIKNet(nik.load_robot("panda"), hidden=[8], heads=2).eval()
    js = save(net, tmp_path / "tiny.safetensors", validation={"n": 50})
    return js.with_suffix(".safetensors")


def test_list_networks_gives_the_installed_then_the_shipped_with_arm_hash_kind_and_recorded_error(tiny_panda):
    assert [n.name for n in list_networks()] == sorted(available() + available(single_pose=True))  # nothing installed
    installed = install(tiny_panda, name="my_panda")
    nets = list_networks()
    shipped_names = sorted(available() + available(single_pose=True))
    assert [(n.name, n.where) for n in nets] == [("my_panda", "installed")] + [(s, "shipped") for s in shipped_names]
    mine = nets[0]
    recorded = json.loads(tiny_panda.with_suffix(".json").read_text())["validation"]
    assert mine.path == installed and mine.robot == "panda" and mine.kind == "multihead" and not mine.problem
    assert mine.robot_hash == nik.load_robot("panda").definition_hash
    assert (mine.pos_mm, mine.rot_deg) == (recorded["best_pos_mm_median"], recorded["best_rot_deg_median"])
    shipped = {n.name: n for n in nets[1:]}
    kuka = shipped["kuka_kr"]
    assert kuka.kind == "branch_heads" and kuka.path == PRETRAINED_DIR / "kuka_kr.safetensors"
    assert shipped["panda_one"].kind == "multihead (single pose)"
    assert all(n.pos_mm is not None and n.pos_mm > 0 for n in nets[1:])


def test_a_pair_with_a_damaged_json_is_listed_with_its_problem(tiny_panda):
    installed = install(tiny_panda)
    installed.with_suffix(".json").write_text("{ not json")
    (mine,) = [n for n in list_networks() if n.where == "installed"]
    assert "not valid JSON" in mine.problem and mine.pos_mm is None


def test_remove_deletes_an_installed_pair_and_the_shipped_one_serves_again(tiny_panda):
    robot = nik.load_robot("panda")
    installed = install(tiny_panda)
    assert find_network(robot) == installed
    assert remove("panda") == [installed, installed.with_suffix(".json")]
    assert not installed.exists() and not installed.with_suffix(".json").exists()
    assert find_network(robot) == PRETRAINED_DIR / "panda.safetensors"


def test_remove_refuses_a_shipped_network_a_missing_one_and_a_path(tiny_panda):
    with pytest.raises(CheckpointError, match="'ur5' is shipped with nik.*cannot be removed"):
        remove("ur5")
    assert (PRETRAINED_DIR / "ur5.safetensors").is_file()
    install(tiny_panda, name="mine")
    with pytest.raises(FileNotFoundError, match=r"no installed network 'nope' .*\(installed: mine\)"):
        remove("nope")
    with pytest.raises(CheckpointError, match="plain file name"):
        remove("../mine")
    assert (user_dir() / "mine.safetensors").is_file()
