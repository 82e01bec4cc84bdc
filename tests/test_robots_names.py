"""Mistyped names get the closest known ones first (nik/robots/names.py): links of a URDF (end_link, root_link),
joints, built-in robot names and the fields of a robot file."""

from __future__ import annotations

import re

import pytest

import nik
from nik.errors import RobotDefinitionError
from nik.robots.names import closest, did_you_mean

UR5_URDF = "configs/robots/urdf/ur5.urdf"


def _suggestion_comes_before_the_list(message: str, suggested: str) -> None:
    hint = message.index(f"did you mean {suggested!r}")
    assert hint < message.index("(links:"), message


def test_a_mistyped_end_link_is_answered_with_the_closest_link_first():
    with pytest.raises(RobotDefinitionError) as err:
        nik.load_robot(UR5_URDF, end_link="wrist_3")
    message = str(err.value)
    assert "end_link 'wrist_3' is not a link of this URDF" in message and "\n" not in message
    _suggestion_comes_before_the_list(message, "wrist_3_link")


def test_a_mistyped_root_link_is_answered_with_the_closest_link_first():
    with pytest.raises(RobotDefinitionError) as err:
        nik.load_robot(UR5_URDF, end_link="tool0", root_link="bse_link")
    _suggestion_comes_before_the_list(str(err.value), "base_link")


def test_a_link_unlike_every_other_gets_no_suggestion_but_the_list():
    with pytest.raises(RobotDefinitionError) as err:
        nik.load_robot(UR5_URDF, end_link="gripper")
    assert "did you mean" not in str(err.value) and "(links: [" in str(err.value)


def test_a_mistyped_built_in_robot_name_suggests_the_built_in():
    with pytest.raises(RobotDefinitionError, match=r"unknown robot 'pandaa': did you mean 'panda'\?"):
        nik.load_robot("pandaa")
    with pytest.raises(RobotDefinitionError, match=r"did you mean 'xarm7'\?"):
        nik.load_robot("xarm_7")


def test_a_mistyped_field_of_a_robot_file_suggests_the_field(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text("name: arm\nconvention: dh\njoints:\n  - {alpha: 0, a: 1, d: 0, limit: [-90, 90]}\n")
    with pytest.raises(RobotDefinitionError, match=r"unknown field\(s\) \['limit'\] \(did you mean 'limits'\?\)"):
        nik.load_robot(path)


def test_joint_names_are_suggested_closest_first():
    names = nik.load_robot("ur5").joint_names
    assert closest("shoulder_pan", names)[0] == "shoulder_pan_joint"
    assert closest("elbow_jont", names)[0] == "elbow_joint"
    assert re.fullmatch(r"did you mean 'wrist_1_joint'( or '[\w]+')*\?", did_you_mean("wrist_1", names))
    assert did_you_mean("gripper", names) == ""


def test_case_is_ignored_and_the_name_itself_is_never_suggested():
    assert closest("PANDA", nik.builtin_robots()) == ["panda"]
    assert "panda" not in closest("panda", ["panda", "panda_link0"])
