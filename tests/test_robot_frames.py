"""Base and tool (TCP) frames (nik/robots/frames.py): ``load_robot(..., base=T, tool=T)`` for built-ins, YAML and
URDF files, YAML ``base:`` / ``tool:``, the CLI's ``--base`` / ``--tool``, and every solver honouring them.

The reference is independent of nik's frames: the FK of the same robot loaded without frames, multiplied by
the frames written here as matrices (rotations by Rodrigues' formula, not by nik's quaternion conversion).
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import torch
from torch.testing import assert_close

import nik
from nik.analytic import family, solve
from nik.cli import main
from nik.lm import lm_solve


def rodrigues(axis, angle) -> np.ndarray:
    """Rotation about the unit ``axis`` by ``angle`` (3x3), written out: ``I + sin K + (1 - cos) K^2``."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def frame(xyz, axis, angle) -> tuple[torch.Tensor, list[float]]:
    """The same frame as a (4, 4) tensor (Rodrigues) and as x, y, z, qw, qx, qy, qz (half-angle formula)."""
    T = np.eye(4)
    T[:3, :3] = rodrigues(axis, angle)
    T[:3, 3] = xyz
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    vec = [float(v) for v in (*xyz, math.cos(angle / 2), *(math.sin(angle / 2) * k))]
    return torch.from_numpy(T), vec


TOOL, TOOL7 = frame([0.012, -0.025, 0.16], [0.6, 0.0, 0.8], 0.7)
BASE, BASE7 = frame([0.5, -0.2, 0.1], [0.0, 0.3, 1.0], 0.9)
ARM_URDF = "configs/robots/urdf/ur5.urdf"


def _q(robot, n, seed=0):
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


# ---------------------------------------------------------------------------
# FK: with a frame = without it, times the frame
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["kuka_kr", "rebot_v_6r", "stanford", "panda", ARM_URDF])
@pytest.mark.parametrize("form", ["matrix", "xyz_quat"])
def test_fk_with_tool_and_base_is_fk_without_them_times_the_frames(name, form):
    plain = nik.load_robot(name)
    tool, base = (TOOL, BASE) if form == "matrix" else (TOOL7, BASE7)
    with_tool = nik.load_robot(name, tool=tool)
    with_base = nik.load_robot(name, base=base)
    both = nik.load_robot(name, base=base, tool=tool)
    for n in (3, 700):  # the compiled FK (few configurations) and the torch FK
        q = _q(plain, n)
        ref = plain.fk(q)
        assert_close(with_tool.fk(q), ref @ TOOL, atol=1e-12, rtol=0)
        assert_close(with_base.fk(q), BASE @ ref, atol=1e-12, rtol=0)
        assert_close(both.fk(q), BASE @ ref @ TOOL, atol=1e-12, rtol=0)
    q = _q(plain, 4).requires_grad_(True)  # the differentiable path
    assert_close(both.fk(q), BASE @ plain.fk(q) @ TOOL, atol=1e-12, rtol=0)
    T, J = both.fk_and_jacobian(q.detach())
    assert_close(T, BASE @ plain.fk(q.detach()) @ TOOL, atol=1e-12, rtol=0)
    num = torch.autograd.functional.jacobian(lambda x: both.fk(x)[:3, 3], q.detach()[0])
    assert_close(J[0, :3], num, atol=1e-9, rtol=0)  # the linear part: derivative of the TCP position


def test_frames_change_the_definition_hash_and_identity_or_none_keeps_it():
    for name in ("kuka_kr", "panda", ARM_URDF):
        plain = nik.load_robot(name)
        assert nik.load_robot(name, tool=None, base=None).definition_hash == plain.definition_hash
        assert nik.load_robot(name, tool=torch.eye(4), base=[0, 0, 0, 1, 0, 0, 0]).definition_hash == (
            plain.definition_hash
        )
        hashes = {
            plain.definition_hash,
            nik.load_robot(name, tool=TOOL).definition_hash,
            nik.load_robot(name, base=BASE).definition_hash,
            nik.load_robot(name, base=BASE, tool=TOOL).definition_hash,
        }
        assert len(hashes) == 4


def test_frames_survive_the_definition_round_trip_and_a_robot_takes_frames_too():
    robot = nik.load_robot("panda", base=BASE7, tool=TOOL7)
    again = nik.Robot.from_definition(json.loads(json.dumps(robot.to_definition())))
    assert again.definition_hash == robot.definition_hash
    flange = nik.load_robot("panda").tool  # panda_link8, the flange: tool= is given in its frame
    assert_close(again.tool, flange @ TOOL, atol=1e-15, rtol=0)
    assert_close(again.base, BASE, atol=1e-15, rtol=0)
    q = _q(robot, 5)
    assert_close(again.fk(q), robot.fk(q), atol=0, rtol=0)
    plain = nik.load_robot("panda")
    assert nik.load_robot(plain, base=BASE, tool=TOOL).definition_hash == robot.definition_hash
    assert nik.load_robot(plain) is plain


# ---------------------------------------------------------------------------
# YAML files: base / tool for URDF-based, DH and screw-axis files
# ---------------------------------------------------------------------------
def _yaml_frame(T: torch.Tensor, unit: float) -> str:
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in T[:3, :3])
    pos = ", ".join(repr(float(v) / unit) for v in T[:3, 3])
    return f"{{position: [{pos}], rotation: [{rows}]}}"


def test_yaml_base_and_tool_of_a_urdf_file_match_the_keywords(tmp_path):
    from pathlib import Path

    urdf = Path(ARM_URDF).resolve()
    path = tmp_path / "ur5_tcp.yaml"
    path.write_text(
        f"name: ur5_tcp\nurdf: {urdf}\nend_link: wrist_3_link\nunit: mm\n"
        f"base: {_yaml_frame(BASE, 1e-3)}\ntool: {_yaml_frame(TOOL, 1e-3)}\n"
    )
    from_file = nik.load_robot(path)
    keywords = nik.load_robot(urdf, end_link="wrist_3_link", base=BASE, tool=TOOL)
    plain = nik.load_robot(urdf, end_link="wrist_3_link")
    q = _q(plain, 6)
    assert_close(from_file.fk(q), BASE @ plain.fk(q) @ TOOL, atol=1e-12, rtol=0)
    assert from_file.definition_hash == keywords.definition_hash
    # keywords replace the file's frames
    replaced = nik.load_robot(path, tool=torch.eye(4), base=torch.eye(4))
    assert replaced.definition_hash == plain.definition_hash


@pytest.mark.parametrize("convention", ["dh", "poe"])
def test_yaml_tool_of_dh_and_poe_files_is_the_tool_frame(tmp_path, convention):
    if convention == "dh":
        body = "convention: dh\nunit: mm\nangles: deg\njoints:\n"
        body += "  - {alpha: -90, a: 50, d: 400}\n  - {alpha: 0, a: 300, d: 0}\n  - {alpha: 90, a: 20, d: 0}\n"
    else:
        body = "convention: poe\nunit: mm\nangles: deg\nhome: {position: [350, 0, 400]}\njoints:\n"
        body += "  - {axis: [0, 0, 1], point: [0, 0, 0]}\n  - {axis: [0, 1, 0], point: [0, 0, 400]}\n"
    (tmp_path / "plain.yaml").write_text(body)
    (tmp_path / "tcp.yaml").write_text(body + f"tool: {_yaml_frame(TOOL, 1e-3)}\nbase: {_yaml_frame(BASE, 1e-3)}\n")
    plain, tcp = nik.load_robot(tmp_path / "plain.yaml"), nik.load_robot(tmp_path / "tcp.yaml")
    q = _q(plain, 8)
    assert_close(tcp.fk(q), BASE @ plain.fk(q) @ TOOL, atol=1e-12, rtol=0)


# ---------------------------------------------------------------------------
# every solver honours the frames
# ---------------------------------------------------------------------------
def _round_trip(robot, plain, n, *, seed):
    q = _q(plain, n, seed)
    T = BASE @ plain.fk(q) @ TOOL  # the targets from the robot without frames: the independent reference
    res = nik.IKSolver(robot).solve(T, seed=0)
    assert bool(res.success.all()), f"{int((~res.success).sum())} of {n} failed"
    pos, rot = nik.pose_error(T, BASE @ plain.fk(res.q) @ TOOL)
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= 1e-3
    assert bool(plain.within_limits(res.q).all())
    return res


@pytest.mark.parametrize("name", ["kuka_kr", "ur5"])
def test_iksolver_closed_form_arm_with_tool_and_base_round_trips_on_both_paths(name):
    plain = nik.load_robot(name)
    robot = nik.load_robot(name, base=BASE7, tool=TOOL7)
    assert family(robot) == family(plain) is not None  # a tool offset keeps the wrist / the parallel axes
    assert _round_trip(robot, plain, 30, seed=1).source == "analytic"  # compiled path (few CPU poses)
    assert _round_trip(robot, plain, 2_100, seed=2).source == "analytic"  # above 2,048: the torch path


def test_iksolver_lm_arm_with_tool_and_base_round_trips():
    plain = nik.load_robot("panda")
    robot = nik.load_robot("panda", base=BASE, tool=TOOL)
    _round_trip(robot, plain, 40, seed=3)  # the default solver on CPU: the compiled LM
    q = _q(plain, 48, 4)
    T = BASE @ plain.fk(q) @ TOOL
    sol, ok = lm_solve(robot, T, None, generator=torch.Generator().manual_seed(0))  # the batched torch LM
    assert bool(ok.all())
    pos, rot = nik.pose_error(T, BASE @ plain.fk(sol) @ TOOL)
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= 2e-3


@pytest.mark.parametrize("name", ["kuka_kr", "ur5", "puma560"])
def test_analytic_solve_with_tool_and_base_returns_solutions_of_the_tcp_pose(name):
    plain = nik.load_robot(name)
    robot = nik.load_robot(name, base=BASE, tool=TOOL)
    q = _q(plain, 64, 5)
    T = BASE @ plain.fk(q) @ TOOL
    sols, valid = solve(robot, T)
    assert bool(valid.any(dim=-1).all())
    reached = BASE @ plain.fk(sols[valid]) @ TOOL
    pos, rot = nik.pose_error(T[:, None].expand(-1, 8, 4, 4)[valid], reached)
    assert float(pos.max()) <= 1e-9 and float(rot.max()) <= 1e-9
    if name == "puma560":  # paper B's closed form too
        sols, valid = nik.analytic.puma560_ik(robot, T)
        pos, rot = nik.pose_error(T[:, None].expand(-1, 8, 4, 4)[valid], BASE @ plain.fk(sols[valid]) @ TOOL)
        assert bool(valid.any(dim=-1).all()) and float(pos.max()) <= 1e-9


# ---------------------------------------------------------------------------
# bad frames: one line, a ValueError
# ---------------------------------------------------------------------------
def _scaled():
    T = TOOL.clone()
    T[:3, :3] *= 1.3
    return T


def _nan():
    T = TOOL.clone()
    T[0, 3] = math.nan
    return T


@pytest.mark.parametrize(
    "bad, words",
    [
        (_scaled(), "not orthonormal"),
        (_nan(), "NaN or inf"),
        ([0.0, 0.0, 0.1, 2.0, 0.0, 0.0, 0.0], "norm 2"),
        ([0.0, 0.0, 0.1, 1.0], "shape (4,)"),
        ("tool0", "expected a (4, 4) transform"),
        ([0.0, 0.0, math.inf, 1.0, 0.0, 0.0, 0.0], "NaN or inf"),
    ],
)
def test_bad_frame_is_a_one_line_value_error_naming_it(bad, words):
    for key in ("tool", "base"):
        with pytest.raises(ValueError) as err:
            nik.load_robot("ur5", **{key: bad})
        msg = str(err.value)
        assert msg.startswith(f"{key}:") and words in msg and "\n" not in msg


# ---------------------------------------------------------------------------
# the CLI: --tool / --base
# ---------------------------------------------------------------------------
def test_cli_solve_with_tool_and_base_answers_for_the_tcp(capsys):
    plain = nik.load_robot("ur5")
    q = _q(plain, 1, 6)
    T = BASE @ plain.fk(q) @ TOOL
    pose = nik.poses.pose_to_vector(T[0], "quat").tolist()
    args = ["solve", "--robot", "ur5", "--tool", *map(repr, TOOL7), "--base", *map(repr, BASE7)]
    assert main([*args, "--json", "--pose", *map(repr, pose)]) == 0
    doc = json.loads(capsys.readouterr().out)
    (r,) = doc["results"]
    assert r["success"] is True
    got = BASE @ plain.fk(torch.tensor(r["q_rad"], dtype=torch.float64)) @ TOOL
    pos, rot = nik.pose_error(T[0], got)
    assert float(pos) <= 1e-4 and float(rot) <= 1e-3
    assert_close(torch.tensor(doc["tool"], dtype=torch.float64), plain.tool @ TOOL, atol=1e-12, rtol=0)  # tool0 @ TCP


@pytest.mark.parametrize("command", ["solve", "path"])
def test_cli_base_and_tool_positions_follow_unit_mm(tmp_path, capsys, command):
    plain = nik.load_robot("kuka_kr")
    q = _q(plain, 2, 7)
    if command == "path":  # a path's two waypoints a small joint step apart (a jump between them fails the path)
        q = torch.minimum(torch.maximum(q[:1] + torch.tensor([[0.0], [0.05]]), plain.limits[:, 0]), plain.limits[:, 1])
    T = BASE @ plain.fk(q) @ TOOL
    mm = [[*(1e3 * p[:3]).tolist(), *p[3:].tolist()] for p in nik.poses.pose_to_vector(T, "quat")]
    poses = tmp_path / "poses.csv"
    poses.write_text("x,y,z,qw,qx,qy,qz\n" + "".join(",".join(map(repr, p)) + "\n" for p in mm))
    out = tmp_path / "q.csv"
    in_mm = [[*(1e3 * np.array(v[:3])).tolist(), *v[3:]] for v in (TOOL7, BASE7)]  # a 160 mm tool, not 160 m
    args = [
        command,
        "--robot",
        "kuka_kr",
        "--unit",
        "mm",
        "--tool",
        *map(repr, in_mm[0]),
        "--base",
        *map(repr, in_mm[1]),
    ]
    assert main([*args, "--poses", str(poses), "--out", str(out)]) == 0, capsys.readouterr().err
    rows = list(csv.DictReader(out.open()))
    q = torch.tensor([[float(r[f"{n}_deg"]) for n in plain.joint_names] for r in rows], dtype=torch.float64)
    pos, rot = nik.pose_error(T, BASE @ plain.fk(q.deg2rad()) @ TOOL)  # the frames read as millimetres
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= 1e-3


def test_cli_generate_with_tool_records_it_in_the_dataset(tmp_path, capsys):
    out = tmp_path / "ds"
    args = ["generate", "--robot", "kuka_kr", "--tool", *map(repr, TOOL7), "--n", "50", "--out", str(out)]
    assert main([*args, "--no-progress"]) == 0
    ds = nik.data.load_dataset(out)
    plain = nik.load_robot("kuka_kr")
    assert_close(ds.pose, plain.fk(ds.q.double()).to(ds.pose.dtype) @ TOOL.to(ds.pose.dtype), atol=1e-6, rtol=0)
    assert ds.meta["robot"]["definition_hash"] == nik.load_robot("kuka_kr", tool=TOOL).definition_hash


@pytest.mark.parametrize(
    "frame_args, words",
    [
        (["--tool", "0", "0", "0.1", "2", "0", "0", "0"], "tool: quaternion"),
        (["--base", "0", "0", "nan", "1", "0", "0", "0"], "base: contains NaN"),
    ],
)
def test_cli_bad_tool_or_base_exits_2_with_one_line(capsys, frame_args, words):
    rc = main(["solve", "--robot", "ur5", *frame_args, "--pose", "0.4", "0.1", "0.5", "0", "1", "0", "0"])
    err = capsys.readouterr().err
    assert rc == 2
    assert words in err and err.count("\n") == 1 and "Traceback" not in err
