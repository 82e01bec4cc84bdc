"""``nik networks``: list, install (checked) and remove, through nik.cli.main (a temporary NIK_HOME:
tests/conftest.py)."""

from __future__ import annotations

import pytest
import torch

import nik
from nik.cli import main
from nik.nets.multi import MultiHypIKNet
from nik.nets.pretrained import available, save
from nik.nets.registry import user_dir


@pytest.fixture
def pair(tmp_path):
    torch.manual_seed(0)
    net = MultiHypIKNet(nik.load_robot("panda"), hidden=[8], heads=2).eval()
    return save(net, tmp_path / "exported.safetensors", validation={"n": 50}).with_suffix(".safetensors")


def _rows(out: str) -> dict[str, list[str]]:
    """The table of ``nik networks list``: ``{name: cells}`` (cells split on runs of two spaces)."""
    import re

    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("name "))
    return {re.split(r"\s{2,}", line)[0]: re.split(r"\s{2,}", line) for line in lines[start + 1 :]}


def test_nik_networks_lists_installs_and_removes(pair, capsys):
    assert main(["networks"]) == 0
    out = capsys.readouterr().out
    rows = _rows(out)
    assert sorted(rows) == sorted(available() + available(single_pose=True))
    assert all(r[5] == "shipped" for r in rows.values())
    assert str(user_dir()) in out
    panda = rows["panda"]
    assert panda[1] == "panda" and panda[2] == nik.load_robot("panda").arm_hash and panda[3] == "multihead"
    assert panda[4].endswith(" deg") and " mm / " in panda[4]

    assert main(["networks", "install", str(pair), "--name", "mine"]) == 0
    out = capsys.readouterr().out
    assert f"installed {user_dir() / 'mine.safetensors'}" in out and 'nik.IKSolver("panda")' in out

    assert main(["networks", "list"]) == 0
    rows = _rows(capsys.readouterr().out)
    assert rows["mine"][5] == "installed" and rows["mine"][6] == str(user_dir() / "mine.safetensors")

    assert main(["networks", "remove", "mine"]) == 0
    assert "removed" in capsys.readouterr().out
    assert not (user_dir() / "mine.safetensors").exists() and not (user_dir() / "mine.json").exists()


@pytest.mark.parametrize("damage", ["flipped byte", "truncated", "no json"])
def test_nik_networks_install_refuses_a_damaged_pair_with_one_line_and_exit_2(pair, damage, capsys):
    data = bytearray(pair.read_bytes())
    if damage == "flipped byte":
        data[len(data) // 2] ^= 0x01
        pair.write_bytes(bytes(data))
    elif damage == "truncated":
        pair.write_bytes(bytes(data[:-100]))
    else:
        pair.with_suffix(".json").unlink()
    assert main(["networks", "install", str(pair)]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("nik networks: error: ") and captured.err.count("\n") == 1
    assert ("SHA-256" in captured.err) if damage != "no json" else ("exported.json" in captured.err)
    assert not user_dir().exists() or not any(user_dir().iterdir())


def test_nik_networks_remove_of_a_shipped_network_is_a_one_line_error(capsys):
    assert main(["networks", "remove", "panda"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "shipped with nik" in err and "cannot be removed" in err


def test_nik_networks_install_says_the_call_that_loads_the_arm_the_pair_was_trained_from(tmp_path, capsys):
    import shutil
    from pathlib import Path

    from nik.nets.pair import save_pair

    urdf = tmp_path / "my_franka.urdf"
    shutil.copy(Path(__file__).resolve().parents[1] / "configs" / "robots" / "urdf" / "panda.urdf", urdf)
    robot = nik.load_robot(urdf, end_link="panda_link8")
    torch.manual_seed(0)
    net = MultiHypIKNet(robot, hidden=[8], heads=2).eval()
    command = f"nik train {urdf} --end-link panda_link8 --minutes 1"  # as nik train records it
    pair = save_pair(net, tmp_path / "out" / "my_franka.safetensors", training={"command": command})
    assert main(["networks", "install", str(pair)]) == 0
    out = capsys.readouterr().out
    assert out.rstrip().endswith(f'nik.IKSolver(nik.load_robot("{urdf.resolve()}", end_link="panda_link8"))')
    urdf.unlink()  # the file is gone: the message falls back to the definition hash
    assert main(["networks", "install", str(pair), "--name", "again"]) == 0
    out = capsys.readouterr().out
    assert robot.definition_hash in out and 'nik.load_robot(ARM, end_link="panda_link8")' in out
