"""The default tool link of a URDF (nik/robots/urdf.py, ``choose_end_link``): a conventional tool link at the end
of the arm, gripper joints left out and named, the candidates named when several fit; the built-in arms keep
their definitions (the shipped networks are matched by their hash).

The reference FK is pytorch-kinematics' serial chain to the link the rule should pick.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import warnings
from pathlib import Path

import pytest
import torch
from torch.testing import assert_close

import nik
from nik.errors import RobotDefinitionWarning
from nik.robots.urdf import build_pk_chain, choose_end_link

_JOINT = """  <joint name="{name}" type="{type}">
    <parent link="{parent}"/><child link="{child}"/>
    <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
"""


def urdf(*joints: tuple[str, str, str, str]) -> str:
    """A URDF of the 3-joint arm base -> l1 -> l2 -> l3, then ``joints``: (name, type, parent, child) each."""
    arm = [("j1", "revolute", "base", "l1"), ("j2", "revolute", "l1", "l2"), ("j3", "revolute", "l2", "l3")]
    rows = arm + list(joints)
    links = ["base"] + [child for *_, child in rows]
    out = ['<robot name="arm">'] + [f'  <link name="{link}"/>' for link in links]
    for i, (name, jtype, parent, child) in enumerate(rows):
        xyz = f"{0.05 * (i % 3)} {0.02 * i} {0.1 + 0.03 * i}"
        rpy = f"{0.1 * i} {0.2 if i % 2 else -0.3} 0"
        axis = ["0 0 1", "0 1 0", "1 0 0"][i % 3]
        out.append(_JOINT.format(name=name, type=jtype, parent=parent, child=child, xyz=xyz, rpy=rpy, axis=axis))
    return "\n".join(out + ["</robot>"])


def load(tmp_path, text, **kw):
    """``nik.load_robot`` of ``text`` and the RobotDefinitionWarnings it gave."""
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = nik.load_robot(path, **kw)
    notes = [str(w.message) for w in caught if issubclass(w.category, RobotDefinitionWarning)]
    return robot, notes


def assert_fk_is_pk_chain_to(robot, text, link, root_link=""):
    chain = build_pk_chain(text, link, root_link).to(dtype=torch.float64)
    q = robot.sample(6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    assert_close(robot.fk(q), chain.forward_kinematics(q).get_matrix(), atol=1e-9, rtol=0)


@pytest.mark.parametrize(
    "gripper",
    [("jointGripper", "revolute"), ("left_finger_joint", "prismatic"), ("jaw", "revolute"), ("LHand", "revolute")],
)
def test_default_end_link_leaves_gripper_joints_out_and_names_them(tmp_path, gripper):
    name, jtype = gripper
    text = urdf(("gripper_stator", "fixed", "l3", "stator"), (name, jtype, "stator", "mover"))
    robot, notes = load(tmp_path, text)
    assert robot.dof == 3 and robot.joint_names == ["j1", "j2", "j3"]
    assert robot.end_link == "l3"  # no conventional name: the end of the arm's revolute joints
    assert_fk_is_pk_chain_to(robot, text, "l3")
    assert len(notes) == 1 and name in notes[0] and "left out" in notes[0] and "\n" not in notes[0]
    explicit, notes = load(tmp_path, text, end_link="mover")  # asked for: the gripper joint is the arm's
    assert explicit.dof == 4 and not notes


@pytest.mark.parametrize("tool", ["tool0", "j2s6_end_effector", "ee_link", "link_eef", "gripper_tcp", "flange"])
def test_default_end_link_is_a_conventional_tool_link_past_fixed_joints(tmp_path, tool):
    text = urdf(
        ("j_mount", "fixed", "l3", "mount"), ("j_tool", "fixed", "mount", tool), ("j_cam", "fixed", "l3", "cam")
    )
    robot, notes = load(tmp_path, text)
    assert robot.end_link == tool and robot.dof == 3
    assert_fk_is_pk_chain_to(robot, text, tool)
    assert not notes  # one candidate, nothing left out: nothing to say


def test_default_end_link_names_every_candidate_when_several_fit(tmp_path):
    text = urdf(
        ("j_a", "fixed", "l3", "arm_tool"), ("j_b", "fixed", "l3", "ee_link"), ("j_c", "fixed", "ee_link", "flange")
    )
    robot, notes = load(tmp_path, text)
    assert robot.end_link == "ee_link"  # ee before flange and tool
    (note,) = notes
    assert "candidates ee_link, flange, arm_tool" in note and "end_link" in note
    assert choose_end_link(text).candidates == ("ee_link", "flange", "arm_tool")
    text = urdf(("j_a", "fixed", "l3", "flange"), ("j_b", "fixed", "flange", "hand_tcp"))
    assert load(tmp_path, text)[0].end_link == "hand_tcp"  # a TCP before the flange it is mounted on


def test_tool0_is_picked_silently_over_the_other_names_of_a_ur_urdf(tmp_path):
    # the UR URDFs of example-robot-data end in wrist_3_link -> ee_link and -> tool0 (ROS-Industrial's flange)
    text = urdf(
        ("ee_fixed_joint", "fixed", "l3", "ee_link"), ("wrist_3_link-tool0_fixed_joint", "fixed", "l3", "tool0")
    )
    robot, notes = load(tmp_path, text)
    assert robot.end_link == "tool0" and not notes
    assert choose_end_link(text).candidates == ("tool0", "ee_link")  # still known, just not worth a warning


def test_a_hand_link_is_the_default_tool_link_only_where_no_tool_link_is_named(tmp_path):
    # Baxter: right_wrist -> right_hand_link (the flange) -> right_hand_camera_link, right_gripper_base_link ...
    text = urdf(
        ("right_hand_joint", "fixed", "l3", "right_hand_link"),
        ("right_hand_camera_joint", "fixed", "right_hand_link", "right_hand_camera_link"),
        ("right_gripper_base_joint", "fixed", "right_hand_link", "right_gripper_base_link"),
    )
    robot, notes = load(tmp_path, text)
    assert robot.end_link == "right_hand_link" and not notes
    assert_fk_is_pk_chain_to(robot, text, "right_hand_link")
    text = urdf(("j_hand", "fixed", "l3", "panda_hand"), ("j_tcp", "fixed", "panda_hand", "panda_hand_tcp"))
    robot, notes = load(tmp_path, text)
    assert robot.end_link == "panda_hand_tcp" and not notes  # a TCP first; the hand is no candidate next to it


def test_a_tool_link_behind_a_moving_joint_is_no_candidate(tmp_path):
    text = urdf(("finger_joint", "prismatic", "l3", "finger"), ("j_tip", "fixed", "finger", "finger_tcp"))
    robot, notes = load(tmp_path, text)
    assert robot.end_link == "l3" and robot.dof == 3
    assert "finger_joint" in notes[0]


def test_without_a_conventional_name_the_default_is_the_end_of_the_longest_revolute_chain(tmp_path):
    text = urdf(("j_x", "fixed", "l3", "wrist_camera"), ("j4_short", "revolute", "l1", "side"))
    robot, notes = load(tmp_path, text)
    assert robot.end_link == "l3" and robot.dof == 3 and not notes  # interface.md's rule, unchanged


def test_default_end_link_note_repeats_when_the_arm_comes_from_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    text = urdf(("jointGripper", "revolute", "l3", "mover"))
    first, notes1 = load(tmp_path, text)
    assert list((tmp_path / "cache").rglob("*.json"))  # the parse was cached
    second, notes2 = load(tmp_path, text)
    assert notes1 == notes2 and len(notes1) == 1
    assert second.definition_hash == first.definition_hash and second.end_link == first.end_link == "l3"


def test_cli_prints_the_note_as_one_line(tmp_path, capsys):
    from nik.cli import main

    path = tmp_path / "arm.urdf"
    path.write_text(urdf(("jointGripper", "revolute", "l3", "mover")))
    assert main(["solve", "--robot", str(path), "--pose", "0.1", "0.05", "0.3", "1", "0", "0", "0"]) in (0, 1)
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if line.startswith("nik: note:")]
    assert len(notes) == 1 and "jointGripper" in notes[0]
    assert "tool link l3" in captured.out


# ---------------------------------------------------------------------------
# the built-in arms keep their definitions
# ---------------------------------------------------------------------------
WEIGHTS = Path(nik.__file__).parent / "nets" / "weights"


@pytest.mark.parametrize("meta", sorted(WEIGHTS.glob("*.json")), ids=lambda p: p.stem)
def test_builtin_arms_keep_the_definition_hash_their_shipped_network_was_trained_for(meta):
    doc = json.loads(meta.read_text())
    with warnings.catch_warnings():
        warnings.simplefilter("error", RobotDefinitionWarning)  # a built-in names its tool link: no note
        robot = nik.load_robot(doc["robot"])
        # ur5 and panda put their vendor's flange on top of the trained chain as a tool frame (a tool frame
        # changes no joint: the network serves the chain); their own end_link loads that chain alone
        chain = robot if robot.tool is None else nik.load_robot(doc["robot"], end_link=robot.end_link)
    assert chain.tool is None and chain.definition_hash == doc["robot_hash"]


@pytest.mark.parametrize(
    "name, flange, tool, tcp",
    [
        ("ur5", "tool0", [0, 0, 0.15, 1, 0, 0, 0], None),  # the pose the UR pendant reports
        ("panda", "panda_link8", [0, 0, 0.1034, math.cos(math.pi / 8), 0, 0, -math.sin(math.pi / 8)], "panda_hand_tcp"),
    ],
)
def test_builtin_arms_poses_are_of_the_vendors_flange_and_tool_is_given_in_its_frame(name, flange, tool, tcp):
    urdf = f"configs/robots/urdf/{name}.urdf"
    robot = nik.load_robot(name)
    q = robot.sample(6, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    assert_fk_is_pk_chain_to(robot, Path(urdf).read_bytes(), flange)  # the URDF's own chain to the flange link
    T_tool = torch.eye(4, dtype=torch.float64)
    T_tool[:3, 3] = torch.tensor(tool[:3], dtype=torch.float64)
    T_tool[:3, :3] = nik.poses.quaternion_to_matrix(torch.tensor(tool[3:], dtype=torch.float64))
    assert_close(nik.load_robot(name, tool=tool).fk(q), robot.fk(q) @ T_tool, atol=1e-12, rtol=0)
    if tcp is not None:  # Franka's hand TCP: 103.4 mm past the flange, turned -45 deg about z
        assert_close(nik.load_robot(name, tool=tool).fk(q), nik.load_robot(urdf, end_link=tcp).fk(q), atol=1e-6, rtol=0)
    bare = nik.load_robot(name, end_link=robot.end_link)  # a given end_link is the link poses mean: no flange
    assert bare.tool is None and float((bare.fk(q) - robot.fk(q))[:, :3, 3].norm(dim=-1).min()) > 0.08


def test_ur5_with_a_half_turn_base_gives_poses_in_urs_base_frame_as_the_pendant_does():
    robot = nik.load_robot("ur5", base=[0, 0, 0, 0, 0, 0, 1])  # Rz(pi): the README's pendant frame
    text = Path("configs/robots/urdf/ur5.urdf").read_text()
    assert '<origin rpy="0 0 -3.14159265359" xyz="0 0 0" />' in text  # base_link -> base (UR's controller frame)
    c, s = math.cos(-3.14159265359), math.sin(-3.14159265359)
    base_in_base_link = torch.tensor([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=torch.float64)
    chain = build_pk_chain(text, "tool0").to(dtype=torch.float64)  # tool0 in base_link
    q = robot.sample(5, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    expected = torch.linalg.inv(base_in_base_link) @ chain.forward_kinematics(q).get_matrix()
    assert_close(robot.fk(q), expected, atol=1e-9, rtol=0)


def test_builtin_urdf_arms_name_their_end_link():
    import yaml

    for name in nik.builtin_robots():
        data = yaml.safe_load((nik.robots.BUILTIN_DIR / f"{name}.yaml").read_text())
        if "urdf" in data:
            assert data.get("end_link"), f"{name}: a built-in URDF arm must name its end_link (its hash depends on it)"
            assert nik.load_robot(name).end_link == data["end_link"]


# ---------------------------------------------------------------------------
# example-robot-data: the arms of the issue
# ---------------------------------------------------------------------------
def _erd(rel: str) -> Path:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip('example-robot-data not installed (pip install -e ".[urdf-tests]")')
    path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")) / rel
    if not path.is_file():
        pytest.skip(f"{rel} is not in this version of example-robot-data")
    return path


def test_unitree_z1_loads_as_its_six_arm_joints_without_the_gripper(tmp_path):
    path = _erd("z1_description/urdf/z1.urdf")
    robot, notes = load(tmp_path, path.read_text())
    assert robot.dof == 6 and "jointGripper" not in robot.joint_names
    assert robot.end_link == "link06"
    assert "jointGripper" in notes[0]
    assert_fk_is_pk_chain_to(robot, path.read_bytes(), "link06")


def test_kinova_jaco2_ends_at_its_end_effector_160_mm_past_link_6(tmp_path):
    path = _erd("kinova_description/robots/kinova.urdf")
    robot, _ = load(tmp_path, path.read_text())
    assert robot.dof == 6 and robot.end_link == "j2s6s200_end_effector"
    assert_fk_is_pk_chain_to(robot, path.read_bytes(), "j2s6s200_end_effector")
    link6 = nik.load_robot(path, end_link="j2s6s200_link_6")
    q = robot.sample(4, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    gap = torch.linalg.vector_norm(robot.fk(q)[:, :3, 3] - link6.fk(q)[:, :3, 3], dim=-1)
    assert_close(gap, torch.full((4,), 0.16, dtype=torch.float64), atol=2e-3, rtol=0)


@pytest.mark.parametrize(
    "rel", ["tiago_description/robots/tiago.urdf", "pr2_description/urdf/pr2.urdf"], ids=["tiago", "pr2"]
)
def test_root_link_leaves_a_mobile_manipulators_torso_out(rel):
    path = _erd(rel)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotDefinitionWarning)
        whole = nik.load_robot(path)
        arm = nik.load_robot(path, root_link="torso_lift_link")
    assert whole.joint_names[0] == "torso_lift_joint" and bool(whole.prismatic[0])  # the torso lift by default
    assert arm.dof == 7 and arm.joint_names == whole.joint_names[1:] and arm.end_link == whole.end_link
    assert_fk_is_pk_chain_to(arm, path.read_bytes(), arm.end_link, root_link="torso_lift_link")
    q = arm.sample(3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    lift = torch.cat([torch.full((3, 1), float(whole.limits[0, 0])), q], dim=1)
    # the same arm: poses relative to the first one agree (the torso link's placement drops out)
    rel_whole = torch.linalg.inv(whole.fk(lift[:1])) @ whole.fk(lift)
    assert_close(rel_whole, torch.linalg.inv(arm.fk(q[:1])) @ arm.fk(q), atol=1e-9, rtol=0)


def test_root_link_on_the_command_line_and_on_an_arm_without_links(tmp_path, capsys):
    from nik.cli import main

    path = _erd("tiago_description/robots/tiago.urdf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotDefinitionWarning)
        arm = nik.load_robot(path, root_link="torso_lift_link")
    T = arm.fk(arm.sample(1, generator=torch.Generator().manual_seed(4), dtype=torch.float64))[0]
    pose = nik.poses.pose_to_vector(T, "quat").tolist()
    argv = ["solve", "--robot", str(path), "--root-link", "torso_lift_link", "--json", "--pose", *map(repr, pose)]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["joint_names"] == arm.joint_names and doc["results"][0]["success"] is True
    with pytest.raises(nik.RobotDefinitionError, match="root_link applies to URDF arms; puma560"):
        nik.load_robot("puma560", root_link="base")
    assert main(["solve", "--robot", "puma560", "--root-link", "base", "--pose", *map(repr, pose)]) == 2
    assert "root_link applies to URDF arms" in capsys.readouterr().err
