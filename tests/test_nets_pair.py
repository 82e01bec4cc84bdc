"""nik.nets.pair / registry: exported networks load from anywhere, by definition hash, and damaged files are refused."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import nik
from nik.errors import CheckpointError
from nik.nets import load_network, save_checkpoint
from nik.nets.multi import MultiHypIKNet
from nik.nets.pair import load_pair, save_pair
from nik.nets.pretrained import PRETRAINED_DIR
from nik.nets.registry import find_network, install, user_dir

ROOT = Path(__file__).resolve().parents[1]
_MAIN = "import sys; from nik.cli import main; sys.exit(main())"


def _renamed(name: str, new: str) -> nik.Robot:
    d = nik.load_robot(name).to_definition()
    d["name"] = new
    return nik.Robot.from_definition(d)


@pytest.fixture
def pair(tmp_path):
    """A tiny panda network exported to tmp_path/net.safetensors (+ net.json)."""
    robot = nik.load_robot("panda")
    torch.manual_seed(0)
    net = MultiHypIKNet(robot, hidden=[8], heads=3).eval()
    path = save_pair(net, tmp_path / "net.safetensors", training={"command": "test"})
    return path, net


def _poses(robot, n=5, seed=1):
    return robot.fk(robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64))


def _refused(path, match, **kw):
    with pytest.raises(CheckpointError, match=match) as info:
        load_pair(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg and str(Path(path).with_suffix("")) in msg  # names the file (.safetensors or .json)
    return msg


# -- loading from anywhere ----------------------------------------------------------------
def test_an_exported_pair_loads_by_path_under_another_robot_name(pair):
    path, net = pair
    other = _renamed("panda", "my_franka")
    back = load_pair(path, robot=other)
    assert back.robot.name == "my_franka"
    T = _poses(other)
    assert torch.equal(back.hypotheses(T), net.hypotheses(T))
    solver = nik.IKSolver(other, checkpoint=str(path), refine="none")
    torch.testing.assert_close(solver.solve(T).q, net.predict(T))
    # the JSON path names the same pair
    assert torch.equal(load_network(path.with_suffix(".json"), robot=other).hypotheses(T), net.hypotheses(T))


def test_a_pair_for_another_definition_is_refused_naming_both_hashes(pair):
    path, _ = pair
    d = nik.load_robot("panda").to_definition()
    d["limits"][0][1] -= 0.1
    msg = _refused(path, "trained for robot 'panda'", robot=nik.Robot.from_definition(d))
    assert nik.load_robot("panda").definition_hash in msg


def test_a_lightning_style_checkpoint_loads_under_another_name(tmp_path):
    robot = nik.load_robot("panda")
    net = MultiHypIKNet(robot, hidden=[8], heads=2).eval()
    path = save_checkpoint(net, tmp_path / "x.ckpt")
    other = _renamed("panda", "franka_from_urdf")
    back = load_network(path, robot=other)
    assert back.robot.name == "franka_from_urdf"
    T = _poses(robot)
    assert torch.equal(back.hypotheses(T), net.hypotheses(T))


def test_auto_finds_the_shipped_network_by_hash_for_a_renamed_arm():
    other = _renamed("panda", "franka")
    assert find_network(other) == PRETRAINED_DIR / "panda.safetensors"
    solver = nik.IKSolver(other)
    assert solver.initial_source == "network" and solver.net.robot.name == "franka"


def test_an_installed_network_replaces_the_shipped_one_for_its_arm(pair):
    path, net = pair
    installed = install(path)
    assert installed == user_dir() / "panda.safetensors" and installed.with_suffix(".json").is_file()
    robot = nik.load_robot("panda")
    assert find_network(robot) == installed
    T = _poses(robot)
    assert torch.equal(nik.IKSolver(robot).net.hypotheses(T), net.hypotheses(T))
    assert torch.equal(nik.models.load_pretrained(_renamed("panda", "p2")).hypotheses(T), net.hypotheses(T))


def test_install_refuses_a_damaged_pair(pair):
    path, _ = pair
    data = bytearray(path.read_bytes())
    data[-1] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="SHA-256"):
        install(path)
    assert not user_dir().exists() or not any(user_dir().iterdir())


# -- integrity ------------------------------------------------------------------------
def test_json_records_the_sha256_and_size_of_the_weights(pair):
    import hashlib

    path, _ = pair
    meta = json.loads(path.with_suffix(".json").read_text())
    data = path.read_bytes()
    assert meta["weights_sha256"] == hashlib.sha256(data).hexdigest() and meta["weights_bytes"] == len(data)
    assert meta["format"] == 2


@pytest.mark.parametrize("name", sorted(p.stem for p in PRETRAINED_DIR.glob("*.json")))
def test_every_shipped_json_records_the_sha256_of_its_weights(name):
    import hashlib

    meta = json.loads((PRETRAINED_DIR / f"{name}.json").read_text())
    assert meta["weights_sha256"] == hashlib.sha256((PRETRAINED_DIR / f"{name}.safetensors").read_bytes()).hexdigest()


def test_a_truncated_file_is_refused(pair):
    path, _ = pair
    path.write_bytes(path.read_bytes()[:-100])
    msg = _refused(path, "SHA-256")
    assert "truncated" in msg


def test_a_flipped_header_byte_is_refused(pair):
    path, _ = pair
    data = bytearray(path.read_bytes())
    data[12] ^= 0x20  # inside the safetensors JSON header
    path.write_bytes(bytes(data))
    _refused(path, "SHA-256.*damaged")


def test_a_flipped_weight_byte_is_refused(pair):
    path, _ = pair
    data = bytearray(path.read_bytes())
    data[-5] ^= 0x01  # among the tensor bytes: the file still parses
    path.write_bytes(bytes(data))
    _refused(path, "SHA-256.*damaged")


def test_a_wrong_recorded_hash_is_refused(pair):
    path, _ = pair
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["weights_sha256"] = "0" * 64
    js.write_text(json.dumps(meta))
    _refused(path, "differs from 0000000000000000")


def test_a_folder_instead_of_the_file_is_refused(pair, tmp_path):
    path, _ = pair
    path.unlink()
    path.mkdir()
    _refused(path, "is a folder")
    with pytest.raises(CheckpointError, match="is a folder"):
        load_network(tmp_path)  # a folder given as a checkpoint


def test_a_corrupt_file_with_a_matching_hash_never_raises_a_raw_safetensors_error(pair):
    """Damage the hash check cannot see (the JSON was rewritten to match): the parser's error is ours."""
    import hashlib

    path, _ = pair
    bad = path.read_bytes()[:50]
    path.write_bytes(bad)
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta.update(weights_sha256=hashlib.sha256(bad).hexdigest(), weights_bytes=len(bad))
    js.write_text(json.dumps(meta))
    _refused(path, "not a readable safetensors file")


def test_missing_or_broken_json_is_refused(pair):
    path, _ = pair
    js = path.with_suffix(".json")
    text = js.read_text()
    js.write_text(text[: len(text) // 2])
    _refused(path, "not valid JSON")
    js.unlink()
    _refused(path, "no net.json beside it")


def test_a_format_1_file_without_a_hash_is_refused(pair):
    path, _ = pair
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    del meta["weights_sha256"]
    meta["format"] = 1
    js.write_text(json.dumps(meta))
    _refused(path, "records no SHA-256")


def test_an_architecture_mismatch_names_the_field(pair):
    import hashlib

    path, _ = pair
    js = path.with_suffix(".json")
    meta = json.loads(js.read_text())
    meta["net"]["hidden"] = [16]
    js.write_text(json.dumps(meta))
    msg = _refused(path, r"net\.hidden\[0\]=16")
    assert "(16, 9)" in msg and "(8, 9)" in msg
    meta["net"].update(hidden=[8], heads=4)
    js.write_text(json.dumps(meta))
    _refused(path, r"net\.heads=4")
    meta["net"].update(heads=3, hidden=[8, 8])
    js.write_text(json.dumps(meta))
    _refused(path, r"net\.hidden=\[8, 8\] makes 3 layers, the weights have 2")
    meta["net"].update(hidden=[8], kind="nonsense")
    js.write_text(json.dumps(meta))
    _refused(path, "field 'net'.*nonsense")
    assert hashlib  # the weights were never touched: only the JSON's architecture


def test_a_damaged_checkpoint_is_refused_in_one_line(tmp_path):
    robot = nik.load_robot("panda")
    path = save_checkpoint(MultiHypIKNet(robot, hidden=[8], heads=2), tmp_path / "x.ckpt")
    path.write_bytes(path.read_bytes()[:-200])
    with pytest.raises(CheckpointError, match="not a loadable nik checkpoint") as info:
        load_network(path, robot=robot)
    assert "\n" not in str(info.value)


def test_a_damaged_shipped_network_stops_the_solver_in_one_line(tmp_path, monkeypatch):
    import nik.nets.registry as registry

    shipped = tmp_path / "weights"
    shutil.copytree(PRETRAINED_DIR, shipped)
    st = shipped / "panda.safetensors"
    st.write_bytes(st.read_bytes()[:1000])
    monkeypatch.setattr(registry, "SHIPPED_DIR", shipped)
    with pytest.raises(CheckpointError, match=r"panda\.safetensors: SHA-256.*truncated"):
        nik.IKSolver("panda")
    assert nik.IKSolver("panda", checkpoint=None).initial_source == "multistart"


@pytest.mark.long
def test_cli_refuses_a_damaged_network_with_exit_2_and_no_traceback(pair, tmp_path):
    path, _ = pair
    data = bytearray(path.read_bytes())
    data[-5] ^= 0x01
    path.write_bytes(bytes(data))
    # a damaged installed network for panda: picked by 'auto', refused
    home = tmp_path / "home"
    (home / "networks").mkdir(parents=True)
    for p in (path, path.with_suffix(".json")):
        shutil.copy(p, home / "networks" / p.name.replace("net", "panda"))
    env = {**os.environ, "NIK_HOME": str(home), "OMP_NUM_THREADS": "1"}
    pose = ["0.4", "0", "0.5", "0", "1", "0", "0"]
    for extra in (["--checkpoint", str(path)], []):
        proc = subprocess.run(
            [sys.executable, "-c", _MAIN, "solve", "--robot", "panda", *extra, "--pose", *pose],
            capture_output=True,
            text=True,
            env=env,
            cwd=ROOT,
        )
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
        assert "SHA-256" in proc.stderr and ".safetensors" in proc.stderr


def test_nik_evaluate_takes_an_exported_pair(pair, tmp_path, capsys):
    from nik.cli import main

    path, _ = pair
    data = tmp_path / "data"
    assert main(["generate", "--robot", "panda", "--n", "200", "--out", str(data), "--no-progress"]) == 0
    args = ["evaluate", "--robot", "panda", "--checkpoint", str(path), "--data", str(data), "--n", "3"]
    args += ["--refinements", "lm", "--swarm", "lm", "--no-pk", "--out", str(tmp_path / "eval")]
    assert main(args) == 0
    assert "| network + lm |" in (tmp_path / "eval" / "evaluation.md").read_text()
