"""Robot loading: built-ins, YAML files in every unit, URDF options, sampling, and clear errors."""

import math
import warnings
from pathlib import Path

import pytest
import torch
from torch.testing import assert_close

import nik
from nik.errors import RobotDefinitionError

PAPER_A_PUMA = """\
name: puma560_paper_a
convention: dh
unit: mm
angles: deg
joints:
  - {alpha: -90, a: 0, d: 0, offset: 0, limits: [-160, 160]}
  - {alpha: 0, a: 431.8, d: 149.09, limits: [-225, 45]}
  - {alpha: 90, a: 0, d: 0, limits: [-45, 225]}
  - {alpha: -90, a: 0, d: 433.07, limits: [-110, 170]}
  - {alpha: 90, a: 0, d: 0, limits: [-100, 100]}
  - {alpha: 0, a: 0, d: 56.25, limits: [-266, 266]}
"""


def write(tmp_path, text, name="arm.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_builtins_are_listed_and_load():
    names = nik.builtin_robots()
    for required in ["puma560", "kuka_kr", "rebot_v_6r", "panda", "ur5", "xarm7"]:
        assert required in names
    dofs = {n: nik.load_robot(n).dof for n in names}
    assert dofs["panda"] == 7 and dofs["ur5"] == 6 and dofs["kuka_kr"] == 6 and dofs["xarm7"] == 7


def test_robot_attributes_follow_the_interface():
    robot = nik.load_robot("puma560")
    assert robot.name == "puma560" and robot.dof == 6 and len(robot.joint_names) == 6
    assert robot.end_link is None
    assert robot.limits.dtype == torch.float64 and robot.limits.shape == (6, 2)
    assert_close(robot.limits[1], torch.tensor([-225.0, 45.0], dtype=torch.float64) * math.pi / 180)


def test_user_defined_paper_a_puma_needs_no_code(tmp_path):
    robot = nik.load_robot(write(tmp_path, PAPER_A_PUMA))
    assert robot.name == "puma560_paper_a"
    # zero pose with a3 = 0: p = (a2, d2, d4 + d6)
    T = robot.fk(torch.zeros(6, dtype=torch.float64))
    assert_close(T[:3, 3], torch.tensor([0.4318, 0.14909, 0.48932], dtype=torch.float64), atol=1e-12, rtol=0)


def test_metres_and_radians_give_the_same_robot_as_mm_and_degrees(tmp_path):
    mm = nik.load_robot(write(tmp_path, PAPER_A_PUMA))
    rows = [
        (-90, 0, 0, (-160, 160)),
        (0, 431.8, 149.09, (-225, 45)),
        (90, 0, 0, (-45, 225)),
        (-90, 0, 433.07, (-110, 170)),
        (90, 0, 0, (-100, 100)),
        (0, 0, 56.25, (-266, 266)),
    ]
    r = math.pi / 180
    text = "name: si\nconvention: dh\nunit: m\nangles: rad\njoints:\n" + "".join(
        f"  - {{alpha: {al * r!r}, a: {a / 1000!r}, d: {d / 1000!r}, limits: [{lo * r!r}, {hi * r!r}]}}\n"
        for al, a, d, (lo, hi) in rows
    )
    si = nik.load_robot(write(tmp_path, text, "si.yaml"))
    q = si.sample(50, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    assert_close(si.fk(q), mm.fk(q), atol=1e-12, rtol=0)
    assert_close(si.limits, mm.limits, atol=1e-12, rtol=0)
    assert si.definition_hash == mm.definition_hash


def test_default_limits_are_plus_minus_180_degrees(tmp_path):
    robot = nik.load_robot(write(tmp_path, "convention: dh\njoints:\n  - {alpha: 0, a: 1, d: 0}\n"))
    assert_close(robot.limits, torch.tensor([[-math.pi, math.pi]], dtype=torch.float64))
    assert robot.name == "arm"


def test_urdf_default_end_link_is_the_tcp_and_builtins_keep_theirs():
    with pytest.warns(nik.RobotDefinitionWarning, match="panda_finger_joint1, panda_finger_joint2"):
        assert nik.load_robot("configs/robots/urdf/panda.urdf").end_link == "panda_hand_tcp"
    assert nik.load_robot("panda").end_link == "panda_link7"  # configs/robots/panda.yaml names it
    assert nik.load_robot("ur5").end_link == "wrist_3_link"


def test_sample_is_within_limits_reproducible_and_uniform():
    robot = nik.load_robot("kuka_kr")
    a = robot.sample(20000, generator=torch.Generator().manual_seed(3))
    b = robot.sample(20000, generator=torch.Generator().manual_seed(3))
    assert a.shape == (20000, 6) and a.dtype == torch.get_default_dtype()
    assert torch.equal(a, b)
    assert robot.within_limits(a).all()
    lo, hi = robot.limits[:, 0].float(), robot.limits[:, 1].float()
    mean = (a.mean(0) - lo) / (hi - lo)
    assert_close(mean, torch.full((6,), 0.5), atol=0.02, rtol=0)  # uniform: mean at the middle of the range


def test_definition_round_trip_keeps_fk_and_hash():
    robot = nik.load_robot("rebot_v_6r")
    again = nik.Robot.from_definition(robot.to_definition())
    q = robot.sample(10, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    assert_close(again.fk(q), robot.fk(q), atol=0, rtol=0)
    assert again.definition_hash == robot.definition_hash
    assert nik.load_robot("puma560").definition_hash != robot.definition_hash


def test_clamp_and_within_limits():
    robot = nik.load_robot("puma560")
    q = torch.full((1, 6), 10.0)
    assert not robot.within_limits(q).item()
    assert robot.within_limits(robot.clamp(q)).item()


# ---- errors ---------------------------------------------------------------
def test_unknown_robot_name_is_a_clear_error():
    with pytest.raises(RobotDefinitionError, match="unknown robot 'not_a_robot'.*puma560"):
        nik.load_robot("not_a_robot")


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(RobotDefinitionError, match="not found"):
        nik.load_robot(tmp_path / "missing.yaml")
    with pytest.raises(RobotDefinitionError, match="not found"):
        nik.load_robot(tmp_path / "missing.urdf")


@pytest.mark.parametrize(
    "text, message",
    [
        ("convention: dh\njoints:\n  - {alpha: 0, d: 0}\n", r"joints\[0\]: missing field 'a'"),
        ("convention: xyz\njoints:\n  - {alpha: 0, a: 1, d: 0}\n", "convention must be one of dh, mdh, poe"),
        (
            "convention: dh\njoints:\n  - {alpha: 0, a: 1, d: 0, limits: [-90, 0, 90]}\n",
            r"joints\[0\]\.limits: expected a list of 2 numbers",
        ),
        ("convention: dh\njoints:\n  - {alpha: 0, a: 1, d: 0, limits: [90, -90]}\n", "lower must be < upper"),
        ("convention: dh\njoints:\n  - {alpha: 0, a: 1, d: 0, lenght: 2}\n", r"unknown field\(s\) \['lenght'\]"),
        ("convention: dh\nunit: inch\njoints:\n  - {alpha: 0, a: 1, d: 0}\n", "unit must be 'mm' or 'm'"),
        ("convention: dh\njoints: []\n", "'joints' must be a non-empty list"),
        ("convention: dh\njoints:\n  - {alpha: 0, a: .nan, d: 0}\n", r"joints\[0\]\.a: expected a finite number"),
        ("convention: poe\njoints:\n  - {axis: [0, 0, 1], point: [0, 0, 0]}\n", "missing field 'home'"),
        (
            "convention: poe\nhome: {position: [1, 0, 0]}\njoints:\n  - {axis: [0, 0], point: [0, 0, 0]}\n",
            r"axis: expected a list of 3 numbers",
        ),
        ("- just a list\n", "expected a mapping"),
        ("convention: dh\njoints: [\n", "not valid YAML"),
    ],
)
def test_malformed_yaml_names_the_problem(tmp_path, text, message):
    with pytest.raises(RobotDefinitionError, match=message):
        nik.load_robot(write(tmp_path, text))


def test_bad_urdf_end_link_names_the_links():
    with pytest.raises(RobotDefinitionError, match="end_link 'gripper' is not a link"):
        nik.load_robot("configs/robots/urdf/panda.urdf", end_link="gripper")


def test_corrupt_urdf_is_a_clear_error(tmp_path):
    path = write(tmp_path, "<robot name='x'><link name='a'/><joint name=", "bad.urdf")
    with pytest.raises(RobotDefinitionError, match="not a readable URDF"):
        nik.load_robot(path)


@pytest.mark.parametrize("origins", ["pk", "float64"])
def test_urdf_with_an_encoding_declaration_loads(tmp_path, origins):
    # example-robot-data's URDFs start with <?xml version="1.0" encoding="utf-8"?>, which lxml refuses in a str
    from nik.robots.urdf import load_urdf

    text = Path("configs/robots/urdf/ur5.urdf").read_text()
    assert "encoding=" not in text.splitlines()[0]
    body = text.split("?>", 1)[1] if text.lstrip().startswith("<?xml") else text
    path = write(tmp_path, '<?xml version="1.0" encoding="utf-8"?>\n' + body, "declared.urdf")
    declared, plain = load_urdf(path, origins=origins), load_urdf("configs/robots/urdf/ur5.urdf", origins=origins)
    assert declared.definition_hash == plain.definition_hash


def test_robot_errors_are_value_errors():
    assert issubclass(RobotDefinitionError, ValueError)


# ---------------------------------------------------------------------------
# Joint types, names and theta
# ---------------------------------------------------------------------------
STANFORD_M_RAD = """\
name: stanford_si
convention: dh
unit: m
angles: rad
joints:
  - {alpha: -1.5707963267948966, a: 0, d: 0.412, limits: [-2.9670597283903604, 2.9670597283903604]}
  - {alpha: 1.5707963267948966, a: 0, d: 0.154, limits: [-2.9670597283903604, 2.9670597283903604]}
  - {type: prismatic, alpha: 0, a: 0.0203, theta: -1.5707963267948966, limits: [0.3048, 1.27]}
  - {type: revolute, alpha: -1.5707963267948966, a: 0, d: 0, limits: [-2.9670597283903604, 2.9670597283903604]}
  - {alpha: 1.5707963267948966, a: 0, d: 0, limits: [-1.5707963267948966, 1.5707963267948966]}
  - {alpha: 0, a: 0, d: 0, limits: [-2.9670597283903604, 2.9670597283903604]}
"""


def test_yaml_prismatic_joint_in_metres_equals_the_builtin_in_mm(tmp_path):
    # before prismatic joints existed this file was refused: "joints[2]: unknown field(s) ['type']"
    robot = nik.load_robot(write(tmp_path, STANFORD_M_RAD))
    builtin = nik.load_robot("stanford")
    assert robot.prismatic.tolist() == builtin.prismatic.tolist() == [False, False, True, False, False, False]
    assert_close(robot.limits, builtin.limits, atol=1e-12, rtol=0)
    assert_close(builtin.limits[2], torch.tensor([0.3048, 1.27], dtype=torch.float64), atol=1e-15, rtol=0)
    q = builtin.sample(50, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    assert_close(robot.fk(q), builtin.fk(q), atol=1e-12, rtol=0)
    assert builtin.joint_names == ["waist", "shoulder", "boom", "wrist1", "wrist2", "wrist3"]


def test_prismatic_offset_is_a_length_added_to_d(tmp_path):
    base = (
        "name: slide\nconvention: dh\nunit: mm\nangles: deg\njoints:\n  - {alpha: 0, a: 0, d: 0, limits: [-90, 90]}\n"
    )
    plain = nik.load_robot(write(tmp_path, base + "  - {type: prismatic, alpha: 0, a: 0, d: 100, limits: [0, 500]}\n"))
    shifted = nik.load_robot(
        write(tmp_path, base + "  - {type: prismatic, alpha: 0, a: 0, d: 60, offset: 40, limits: [0, 500]}\n", "b.yaml")
    )
    assert_close(shifted.offsets, torch.tensor([0.0, 0.04], dtype=torch.float64))
    assert_close(shifted.limits[1], torch.tensor([0.0, 0.5], dtype=torch.float64))
    q = torch.tensor([[0.3, 0.25]], dtype=torch.float64)
    assert_close(shifted.fk(q), plain.fk(q), atol=1e-15, rtol=0)
    assert_close(plain.fk(q)[0, 2, 3], torch.tensor(0.35, dtype=torch.float64), atol=1e-15, rtol=0)


def test_revolute_theta_is_the_offset_and_name_names_the_joint(tmp_path):
    with_theta = nik.load_robot(write(tmp_path, PAPER_A_PUMA.replace("offset: 0,", "theta: 30, name: base,")))
    with_offset = nik.load_robot(write(tmp_path, PAPER_A_PUMA.replace("offset: 0,", "offset: 30,"), "b.yaml"))
    assert with_theta.joint_names[0] == "base" and with_theta.joint_names[1] == "joint2"
    assert_close(with_theta.offsets, with_offset.offsets, atol=0, rtol=0)
    assert math.isclose(float(with_theta.offsets[0]), math.radians(30))


@pytest.mark.parametrize(
    "joint, message",
    [
        (
            "{type: slider, alpha: 0, a: 0, d: 0}",
            r"joints\[1\] \(joint2\): type must be 'revolute' or 'prismatic', got 'slider'",
        ),
        ("{type: prismatic, alpha: 0, a: 0, d: 0}", r"joints\[1\]: missing field 'limits'"),
        ("{alpha: 0, a: 0, d: 0, offset: 10, theta: 10}", r"joints\[1\]: give 'offset' or 'theta'"),
    ],
)
def test_bad_joint_type_fields_name_the_joint(tmp_path, joint, message):
    text = f"name: x\nconvention: dh\njoints:\n  - {{alpha: 0, a: 0, d: 0}}\n  - {joint}\n"
    with pytest.raises(RobotDefinitionError, match=message):
        nik.load_robot(write(tmp_path, text))


# Hashes of the built-in arms computed before prismatic joints existed (commit 551f566): datasets and
# checkpoints carry them, so they must never change.
BUILTIN_HASHES = {
    "kuka_kr": "7794b517321d26a1",
    "panda": "5342c808e10da6e3",
    "puma560": "fb981885b160f3ba",
    "rebot_v_6r": "8d3894bcab69275a",
    "ur5": "aaa9508f945aac99",
}


@pytest.mark.parametrize("name", sorted(BUILTIN_HASHES))
def test_definition_hash_of_revolute_builtins_is_unchanged(name):
    robot = nik.load_robot(name)
    # ur5 and panda add their vendor's flange as a tool frame (configs/robots/*.yaml flange:) on top of the
    # trained chain, which a given end_link (the file's own) loads without it: that chain keeps its hash
    chain = robot if robot.tool is None else nik.load_robot(name, end_link=robot.end_link)
    assert chain.tool is None and chain.definition_hash == BUILTIN_HASHES[name]
    assert nik.load_robot(chain, tool=robot.tool).definition_hash == robot.definition_hash
    assert "prismatic" not in robot.to_definition()


def test_definition_round_trip_keeps_joint_types_and_they_enter_the_hash():
    robot = nik.load_robot("stanford")
    definition = robot.to_definition()
    again = nik.Robot.from_definition(definition)
    assert again.prismatic.tolist() == robot.prismatic.tolist()
    assert again.definition_hash == robot.definition_hash
    q = robot.sample(10, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    assert_close(again.fk(q), robot.fk(q), atol=0, rtol=0)
    del definition["prismatic"]
    as_revolute = nik.Robot.from_definition(definition)
    assert not bool(as_revolute.prismatic.any())
    assert as_revolute.definition_hash != robot.definition_hash


# ---------------------------------------------------------------------------
# the cache of parsed URDF arms: load_robot("panda") without importing pytorch-kinematics
# ---------------------------------------------------------------------------
def test_a_urdf_arm_is_parsed_once_and_read_back_identical(tmp_path, monkeypatch):
    import json

    from nik.robots import urdf

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    parsed = []
    real = urdf._parse_robot
    monkeypatch.setattr(urdf, "_parse_robot", lambda *a: parsed.append(1) or real(*a))
    first = nik.load_robot("panda")
    again = nik.load_robot("panda")
    assert parsed == [1]  # the second load read the cache
    assert again.definition_hash == first.definition_hash and again.source == first.source
    assert torch.equal(again.G, first.G) and again.joint_names == first.joint_names
    (stored,) = (tmp_path / "nik" / "robots").glob("*.json")
    doc = json.loads(stored.read_text())
    doc["robot"]["G"][1][0][3] += 0.1  # a changed file no longer matches its checksum: parsed again
    stored.write_text(json.dumps(doc))
    third = nik.load_robot("panda")
    assert parsed == [1, 1] and torch.equal(third.G, first.G)


def test_an_unwritable_cache_folder_only_means_parsing_every_time(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))  # nik/robots cannot be created under a file
    a, b = nik.load_robot("ur5"), nik.load_robot("ur5")
    assert a.definition_hash == b.definition_hash


def test_a_folder_named_like_a_builtin_does_not_hide_it(tmp_path, monkeypatch):
    from nik.robots import config

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(config, "_SHADOW_WARNED", set(), raising=False)
    (tmp_path / "panda").mkdir()  # users keep folders named after their robot
    with pytest.warns(nik.RobotDefinitionWarning, match=r"built-in arm.*\./panda"):
        robot = nik.load_robot("panda")
    assert robot.definition_hash == nik.load_robot(config.BUILTIN_DIR / "panda.yaml").definition_hash
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said once
        nik.load_robot("panda")
    with pytest.raises(nik.RobotDefinitionError, match="folder, not a robot file"):
        nik.load_robot("./panda")  # written as a path: the folder


def test_a_robot_file_path_wins_over_a_builtin_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, PAPER_A_PUMA, "ur5.yaml")
    assert nik.load_robot("ur5.yaml").dof == 6 and nik.load_robot("ur5.yaml").name != "ur5"
    assert nik.load_robot("./ur5.yaml").name == nik.load_robot("ur5.yaml").name
    assert nik.load_robot("ur5").name == "ur5"  # the plain name stays the built-in
