"""nik.pretrained / nik.models.load_pretrained: the shipped networks, their files and their recorded errors."""

from __future__ import annotations

import json
import math

import pytest
import torch

import nik
from nik.errors import CheckpointError
from nik.models import load_pretrained, pretrained_robots
from nik.nets.multi import BranchIKNet, MultiHypIKNet
from nik.nets.pretrained import PRETRAINED_DIR, available, load, read_meta, save, validation_error

SHIPPED = available()


def test_the_issue_arms_have_a_shipped_network():
    assert {"kuka_kr", "ur5", "panda", "xarm7"} <= set(SHIPPED)
    assert pretrained_robots() == SHIPPED


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_file_matches_its_robot_and_reproduces_its_recorded_validation_error(name):
    meta = read_meta(name)
    robot = nik.load_robot(name)
    assert meta["robot"] == name and meta["robot_hash"] == robot.arm_hash  # trained for the arm, flange aside
    assert (PRETRAINED_DIR / f"{name}.safetensors").stat().st_size < 8 * 2**20  # a few MB
    net = load_pretrained(name)
    assert not net.training and net.config() == meta["net"]
    rec = meta["validation"]
    now = validation_error(net, seed=rec["seed"], n=rec["n"])
    for key, value in rec.items():
        assert math.isclose(now[key], value, rel_tol=1e-4, abs_tol=1e-9), (key, now[key], value)
    command = meta["training"]["command"]
    assert command.startswith(f"nik train {name} ") or "train.py fit --config configs/train/" in command


@pytest.mark.parametrize("name", available(single_pose=True))
def test_shipped_single_pose_network_matches_its_arm_and_reproduces_its_recorded_validation_error(name):
    from nik.nets.pair import load_pair
    from nik.nets.registry import find_network, find_single_pose_network

    meta = read_meta(name)
    robot = nik.load_robot(meta["robot"])
    assert meta["role"] == "single_pose" and meta["robot_hash"] == robot.arm_hash
    assert find_single_pose_network(robot.arm).stem == name and find_network(robot.arm).stem == meta["robot"]
    net = load_pair(PRETRAINED_DIR / f"{name}.safetensors", robot=robot.arm)
    assert net.n_params < load_pretrained(robot).n_params / 3  # a cheaper forward pass than the main network's
    rec = meta["validation"]
    now = validation_error(net, seed=rec["seed"], n=rec["n"])
    for key, value in rec.items():
        assert math.isclose(now[key], value, rel_tol=1e-4, abs_tol=1e-9), (key, now[key], value)
    # analytic=False: on an arm with a closed form (ur5) the closed form stays the default guess and loads no network
    assert nik.IKSolver(robot, analytic=False).single_pose_net is not None


def test_an_unknown_definition_names_the_robots_that_have_one():
    definition = nik.load_robot("ur5").to_definition()
    definition["name"] = "my_arm"
    definition["limits"][0][0] += 0.1  # another arm: the hash differs
    with pytest.raises(CheckpointError, match="my_arm.*pretrained networks exist for: .*panda"):
        load_pretrained(nik.Robot.from_definition(definition))


def test_the_same_arm_under_another_name_gets_its_network():
    definition = nik.load_robot("ur5").to_definition()
    definition["name"] = "my_arm"
    net = load_pretrained(nik.Robot.from_definition(definition))
    assert net.robot.name == "my_arm" and net.config() == read_meta("ur5")["net"]


def _tiny(tmp_path, name="ur5"):
    robot = nik.load_robot(name)
    torch.manual_seed(0)
    net = BranchIKNet(robot, hidden=[8]) if name != "panda" else MultiHypIKNet(robot, hidden=[8], heads=3)
    save(net, tmp_path, training={"command": "test"}, validation={"seed": 3, "n": 50})
    return robot, net


def test_save_then_load_gives_the_same_network_without_pickle(tmp_path):
    robot, net = _tiny(tmp_path, "panda")
    assert available(tmp_path) == ["panda"]
    back = load(robot, tmp_path)
    _, T = robot.fk(robot.sample(7, generator=torch.Generator().manual_seed(1))), None
    T = robot.fk(robot.sample(7, generator=torch.Generator().manual_seed(1), dtype=torch.float64))
    assert torch.equal(back.hypotheses(T), net.eval().hypotheses(T))
    meta = json.loads((tmp_path / "panda.json").read_text())
    assert meta["validation"] == validation_error(back, seed=3, n=50)
    assert meta["net"] == {
        "kind": "multihead",
        "hidden": [8],
        "activation": "silu",
        "representation": "rot6d",
        "heads": 3,
    }


def test_a_network_for_another_definition_of_the_robot_is_refused(tmp_path):
    _tiny(tmp_path, "ur5")
    meta = json.loads((tmp_path / "ur5.json").read_text())
    meta["robot_hash"] = "0123456789abcdef"
    (tmp_path / "ur5.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match="hash 0123456789abcdef"):
        load("ur5", tmp_path)


def _best_hypothesis(robot, net, T):
    """``(B, dof)``: the hypothesis of ``net`` (made for the bare arm: the built-in panda without its flange) for the
    targets ``T`` of the robot's tool, given in the arm's frame and ranked by the robot's own FK (the solver's rule)."""
    from nik.poses import pose_error
    from nik.tolerances import score

    hyp = net.hypotheses(T @ torch.linalg.inv(robot.tool))
    pos, rot = pose_error(T[:, None].expand(-1, hyp.shape[1], 4, 4), robot.fk(robot.clamp(hyp.to(T.dtype))))
    return hyp[torch.arange(T.shape[0]), score(pos, rot).argmin(1)].to(T.dtype)


def test_solver_uses_the_shipped_network_by_default_and_not_with_checkpoint_none():
    robot = nik.load_robot("panda")
    T = robot.fk(robot.sample(4, generator=torch.Generator().manual_seed(2), dtype=torch.float64))
    res = nik.IKSolver("panda", refine="none").solve(T)
    assert res.source == "network"
    torch.testing.assert_close(res.q, _best_hypothesis(robot, load_pretrained("panda"), T))
    assert nik.IKSolver("panda", checkpoint=None).initial_source == "multistart"
    # PUMA-like arms keep the closed form unless analytic=False
    assert nik.IKSolver("kuka_kr").initial_source == "analytic"
    assert nik.IKSolver("kuka_kr", analytic=False).initial_source == "network"


def test_nik_solve_panda_uses_the_shipped_network_without_training(capsys, tmp_path, monkeypatch):
    from nik.cli import main
    from nik.poses import matrix_to_quaternion

    robot = nik.load_robot("panda")
    T = robot.fk(robot.sample(3, generator=torch.Generator().manual_seed(4), dtype=torch.float64))
    rows = [torch.cat([t[:3, 3], matrix_to_quaternion(t[:3, :3])]).tolist() for t in T]
    csv = tmp_path / "poses.csv"
    csv.write_text("x,y,z,qw,qx,qy,qz\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows))
    # one pose and a batch: the shipped network's guess, on the compiled backend
    assert main(["solve", "--robot", "panda", "--refine", "lm", "--json", "--pose", *map(repr, rows[0])]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["results"][0]["success"] is True and doc["initial_guess"] == "network"
    assert main(["solve", "--robot", "panda", "--refine", "lm", "--json", "--poses", str(csv)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert all(r["success"] for r in doc["results"]) and doc["initial_guess"] == "network"


def test_one_pose_on_the_cpu_uses_the_network_on_both_backends():
    robot = nik.load_robot("panda")
    T = robot.fk(robot.sample(2, generator=torch.Generator().manual_seed(6), dtype=torch.float64))
    for backend in ("compiled", "torch"):
        with_net = nik.IKSolver(robot, backend=backend)
        one = with_net.solve(T[:1], seed=3)
        assert one.source == "network" and with_net.plan().source == "network" and bool(one.success.all())
        assert with_net.solve(T, seed=3).source == "network"
    raw = nik.IKSolver(robot, refine="none").solve(T[:1])
    assert raw.source == "network"  # the raw guess was asked for
    torch.testing.assert_close(raw.q, _best_hypothesis(robot, load_pretrained("panda"), T[:1]))
