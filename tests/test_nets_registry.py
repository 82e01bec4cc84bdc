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


def _tiny(path, seed):
    torch.manual_seed(seed)
    net = MultiHypIKNet(nik.load_robot("panda"), hidden=[8], heads=2).eval()
    return save(net, path, validation={"n": 50}).with_suffix(".safetensors")


@pytest.mark.parametrize("what", ["install", "remove", "save"])
def test_a_kill_at_any_instant_leaves_the_old_or_the_new_pair_whole(tmp_path, kill_at, monkeypatch, what):
    # fault injection: the command dies before its k-th filesystem operation, for every k until one completes;
    # the next run must find the old pair or the new one whole (checksum verified), nothing staged left over, and
    # the command must work again. "save" is nik train's export (nik.nets.pair.save_pair), "install" also the
    # copy of nik train --install.
    from nik.nets import pair as pair_mod
    from nik.nets.pair import load_pair, save_pair

    a, b = _tiny(tmp_path / "a.safetensors", 0), _tiny(tmp_path / "b.safetensors", 1)
    panda = nik.load_robot("panda")
    folder = user_dir() if what != "save" else tmp_path / "runs"
    dst = folder / "mine.safetensors"

    def setup():
        if what == "save":
            save_pair(load_pair(a), dst)
        else:
            install(a, name="mine")

    def act():
        if what == "install":
            install(b, name="mine")
        elif what == "remove":
            remove("mine")
        else:
            save_pair(load_pair(b), dst)

    net_a, net_b = load_pair(a), load_pair(b)

    def same(x, y):
        return all(torch.equal(u, v) for u, v in zip(x.state_dict().values(), y.state_dict().values(), strict=True))

    for k in range(100):
        setup()
        counter = kill_at(k)
        try:
            act()
        except BaseException as err:  # noqa: B036 - the simulated kill is a BaseException
            assert type(err).__name__ == "Killed", err
        counter.undo()
        with monkeypatch.context() as m:
            m.setattr(pair_mod, "_pid_alive", lambda pid: False, raising=False)  # the killed run's process is gone
            found = find_network(panda) if what != "save" else (dst if dst.exists() else None)
            if found is not None and what == "save":
                load_pair(found)  # what nik.IKSolver(checkpoint=...) does first
        if what == "remove" and found is None or found is not None and found.parent != folder:
            assert what == "remove", k  # the shipped panda network serves again: the pair is gone, not half
        else:
            got = load_pair(found)  # whole: its checksum verified
            assert found == dst and (same(got, net_a) or same(got, net_b)), k
        if what != "save":  # the registry's listing tidies the folder; a save tidies its own at the next save
            assert sorted(p.name for p in folder.iterdir() if p.name.startswith(".")) == [], k
        if not counter.killed:
            break
        if what == "remove" and found is None or found is not None and found.parent != folder:
            continue  # removed: nothing left to do again
        with monkeypatch.context() as m:
            m.setattr(pair_mod, "_pid_alive", lambda pid: False, raising=False)
            act()  # the next run (another process) works
        if what != "remove":
            assert same(load_pair(dst), net_b)
        assert sorted(p.name for p in folder.iterdir() if p.name.startswith(".")) == [], k
    assert k >= 3 and not counter.killed  # remove: 3 operations; install and save: more


def _strings(value):
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield str(k)
            yield from _strings(v)
    elif isinstance(value, list):
        for v in value:
            yield from _strings(v)


def test_shipped_jsons_record_no_path_of_the_machine_that_made_them_but_the_command_and_the_data_hash():
    import re

    from nik.learn.recipe import data_sha256
    from nik.nets.registry import SHIPPED_DIR

    absolute = re.compile(r"(^|[\s='\"])(/|~/|[A-Za-z]:[\\/])\w")  # /tmp/..., ~/..., C:\...
    files = sorted(SHIPPED_DIR.glob("*.json"))
    assert len(files) >= 6
    for js in files:
        meta = json.loads(js.read_text())
        bad = [s for s in _strings(meta) if absolute.search(s)]
        assert bad == [], f"{js.name}: {bad}"
        training = meta["training"]
        assert training["command"].startswith("nik train ")
        assert training["data_sha256"] == data_sha256(training["data"], meta["robot_hash"]), js.name


@pytest.mark.long
def test_an_install_whose_process_dies_after_its_commit_point_is_finished_by_the_next_process(tiny_panda, tmp_path):
    # a real death (os._exit in a subprocess, its pid then gone), between the weights' and the JSON's renames
    import os
    import subprocess
    import sys
    from pathlib import Path

    from nik.nets.pair import load_pair

    root = Path(__file__).resolve().parents[1]
    other = _tiny(tmp_path / "other.safetensors", 1)
    install(tiny_panda, name="mine")
    script = (
        "import os\n"
        "replace = os.replace\n"
        "def dying(a, b):\n"
        "    replace(a, b)\n"
        "    os._exit(9)  # killed right after the weights took their name, before the JSON did\n"
        "os.replace = dying\n"
        "from nik.cli import main\n"
        f"main(['networks', 'install', {str(other)!r}, '--name', 'mine'])\n"
    )
    env = {**os.environ, "PYTHONPATH": str(root)}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 9, proc.stderr
    assert any(p.name.startswith(".mine.ready-") for p in user_dir().iterdir())  # the commit point was passed
    found = find_network(nik.load_robot("panda"))  # the next process (this one) finishes it
    assert found == user_dir() / "mine.safetensors"
    got, want = load_pair(found), load_pair(other)
    assert all(torch.equal(a, b) for a, b in zip(got.state_dict().values(), want.state_dict().values(), strict=True))
    assert [p.name for p in user_dir().iterdir() if p.name.startswith(".")] == []


def test_a_missing_network_file_is_a_one_line_checkpoint_error_naming_it(tmp_path, capsys):
    """docs/learned.md: any load failure is a nik.CheckpointError of one line naming the file; a missing file too
    (still a FileNotFoundError for callers catching that)."""
    from nik.cli import main
    from nik.nets import load_checkpoint, load_network

    robot = nik.load_robot("panda")
    for missing in (tmp_path / "missing.safetensors", tmp_path / "missing.ckpt"):
        with pytest.raises(nik.CheckpointError, match=str(missing.name)) as err:
            nik.IKSolver(robot, checkpoint=missing)
        assert isinstance(err.value, FileNotFoundError) and "\n" not in str(err.value)
    with pytest.raises(nik.CheckpointError, match="missing.json"):
        load_network(tmp_path / "missing.json")
    with pytest.raises(nik.CheckpointError, match="missing.ckpt"):
        load_checkpoint(tmp_path / "missing.ckpt")
    missing = tmp_path / "missing.safetensors"
    assert (
        main(["solve", "--robot", "panda", "--pose", *"0.4 0 0.4 0 1 0 0".split(), "--checkpoint", str(missing)]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(missing) in err and "Traceback" not in err


def _erd_panda():
    import importlib.metadata
    from pathlib import Path

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip('example-robot-data not installed (pip install -e ".[urdf-tests]")')
    path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")) / "panda_description/urdf/panda.urdf"
    if not path.is_file():
        pytest.skip("panda_description/urdf/panda.urdf is not in this version of example-robot-data")
    return path


@pytest.mark.parametrize("end_link", [None, "panda_link8", "panda_hand"])
def test_the_same_arm_from_another_file_finds_its_network_whatever_its_end_link(end_link):
    """Issue 37 item 7: example-robot-data's panda (other file, float noise in its placements; default end link
    panda_hand_tcp, a fixed transform past the network's flange panda_link8) gets the shipped panda network."""
    import warnings

    import numpy as np

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(_erd_panda(), **({} if end_link is None else {"end_link": end_link}))
    before = robot.definition_hash
    q = robot.sample(40, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    T_before = robot.fk(q)
    solver = nik.IKSolver(robot)
    assert solver.net is not None and robot.arm_hash == nik.load_robot("panda").arm_hash
    assert robot.definition_hash == before and torch.equal(robot.fk(q), T_before)  # the arm itself unchanged
    T = T_before.numpy()
    res = solver.solve(T)
    assert res.source == "network" and bool(np.all(res.success))
    qs = torch.as_tensor(np.asarray(res.q), dtype=torch.float64)
    assert float((robot.fk(qs)[:, :3, 3] - T_before[:, :3, 3]).norm(dim=-1).max()) < 1e-3  # FK round trip
    one = solver.solve(T[0])
    assert one.source == "network" and bool(np.all(one.success))


def test_another_arm_of_the_same_shape_finds_no_network():
    from nik.nets.registry import find_same_arm
    from nik.robots.frames import tool_between, with_frames

    panda = nik.load_robot("panda")
    limits = panda.limits.clone()
    limits[0, 1] -= 0.01
    other = nik.Robot("other", panda.G, panda.offsets, limits, panda.joint_names)
    assert find_same_arm(other) is None
    G = panda.G.clone()
    G[3, 0, 3] += 0.01  # a link 1 cm longer
    assert find_same_arm(nik.Robot("longer", G, panda.offsets, panda.limits, panda.joint_names)) is None
    X = torch.eye(4, dtype=torch.float64)
    X[:3, 3] = torch.tensor([0.0, 0.02, 0.1])
    tooled = with_frames(panda.arm, tool=X.numpy())
    bare = nik.Robot("bare", tooled.G, tooled.offsets, tooled.limits, tooled.joint_names)
    assert torch.allclose(torch.as_tensor(tool_between(bare, panda.arm)), X, atol=1e-9)
