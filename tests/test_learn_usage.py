"""nik.learn.usage: the lines printed after installing a network say calls that really solve with it (each call
is run here as printed, from another working directory; a temporary NIK_HOME: tests/conftest.py)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
import torch

import nik
from nik.learn.usage import network_usage, robot_expression
from nik.nets.multi import MultiHypIKNet
from nik.nets.pair import save_pair
from nik.nets.registry import install

URDF = Path(__file__).resolve().parents[1] / "configs" / "robots" / "urdf"


def _installed(robot, tmp_path) -> Path:
    torch.manual_seed(0)
    net = MultiHypIKNet(robot, hidden=[8], heads=2).eval()
    return install(save_pair(net, tmp_path / "export" / "net.safetensors"), name="mine")


def _run(code: str):
    return eval(code, {"nik": nik})  # the line's Python, as a user pastes it


def _poses(robot, n=8):
    return robot.fk(robot.sample(n, generator=torch.Generator().manual_seed(5), dtype=torch.float64))


def test_on_a_urdf_arm_the_printed_call_loads_the_same_arm_and_gets_the_installed_network(tmp_path, monkeypatch):
    urdf = tmp_path / "arms" / "my_franka.urdf"  # an arm nik does not ship under this name: a URDF of one's own
    urdf.parent.mkdir()
    shutil.copy(URDF / "panda.urdf", urdf)
    robot = nik.load_robot(urdf, end_link="panda_link8")
    installed = _installed(robot, tmp_path)
    (line,) = network_usage(robot, installed, source=urdf, end_link="panda_link8")
    code = re.search(r": (nik\.IKSolver\(.*\))$", line).group(1)
    assert code == f'nik.IKSolver(nik.load_robot("{urdf.resolve()}", end_link="panda_link8"))'
    assert robot.definition_hash in line
    monkeypatch.chdir(tmp_path / "export")  # the path is absolute: it works from anywhere
    solver = _run(code)
    T = _poses(robot)
    assert solver.robot.definition_hash == robot.definition_hash and solver.has_network
    torch.manual_seed(0)
    ref = MultiHypIKNet(robot, hidden=[8], heads=2).eval()
    assert torch.equal(solver.net.hypotheses(T), ref.hypotheses(T))  # the installed weights


def test_on_a_closed_form_arm_the_default_keeps_the_closed_form_and_the_printed_checkpoint_call_uses_the_network(
    tmp_path,
):
    urdf = tmp_path / "my_ur.urdf"
    shutil.copy(URDF / "ur5.urdf", urdf)
    robot = nik.load_robot(urdf)  # the default tool link: the printed call names it
    installed = _installed(robot, tmp_path)
    default_line, network_line = network_usage(robot, installed, source=urdf)
    assert "closed form (three_parallel)" in default_line and "does not use the network" in default_line
    default = _run(re.search(r": (nik\.IKSolver\(.*\)) does not use", default_line).group(1))
    with_net = _run(re.search(r": (nik\.IKSolver\(.*\))$", network_line).group(1))
    assert f'end_link="{robot.end_link}"' in network_line and f'checkpoint="{installed}"' in network_line
    T = _poses(robot)
    assert default.solve(T).source == "analytic" and not default.has_network
    assert with_net.has_network and with_net.net.robot.definition_hash == robot.definition_hash
    # this network is untrained (8 units): no better a start than uniform ones, it gives way (nik.ik.judge)
    with pytest.warns(UserWarning, match="no better than uniform starts"):
        res = with_net.solve(T)
    assert res.source == "analytic" and bool(res.success.all())
    assert with_net.solve(T[:1]).source == "analytic"  # one CPU pose too


@pytest.mark.parametrize(
    ("source", "end_link", "expected"),
    [("panda", None, '"panda"'), ("xarm7", None, '"xarm7"'), (URDF / "panda.urdf", "panda_link8", "load_robot")],
)
def test_robot_expression_names_a_call_that_gives_the_same_definition(source, end_link, expected):
    robot = nik.load_robot(source, end_link=end_link)
    expr = robot_expression(robot, source, end_link)
    assert expected in expr
    again = _run(expr if expr.startswith("nik.") else f"nik.load_robot({expr})")
    assert again.definition_hash == robot.definition_hash


def test_a_renamed_arm_that_no_call_reloads_is_described_by_its_hash():
    d = nik.load_robot("panda").to_definition()
    d["name"] = "renamed"
    robot = nik.Robot.from_definition(d)
    assert robot_expression(robot) is None
    (line,) = network_usage(robot, "/x/mine.safetensors")
    assert f"definition hash {robot.definition_hash}" in line and "nik.load_robot(ARM" in line
    (line,) = network_usage(robot, "/x/mine.safetensors", source=robot)
    assert line.endswith("nik.IKSolver(robot)")


def test_the_printed_call_keeps_the_root_link_the_arm_was_trained_from():
    urdf = (URDF / "panda.urdf").resolve()
    robot = nik.load_robot(urdf, end_link="panda_link8", root_link="panda_link1")
    code = robot_expression(robot, urdf, "panda_link8", root_link="panda_link1")
    assert code == f'nik.load_robot("{urdf}", end_link="panda_link8", root_link="panda_link1")'
    assert eval(code, {"nik": nik}).definition_hash == robot.definition_hash  # the same 6-joint arm
    assert robot_expression(robot, urdf, "panda_link8") is None  # without it, the call would load another arm
