"""``nik solve`` and ``nik evaluate`` end to end, with a tiny network trained inside the test."""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import nik
from nik.cli import main
from nik.poses import matrix_to_quaternion

ROOT = Path(__file__).resolve().parents[1]
HAS_TRAINING = importlib.util.find_spec("nik.models") is not None and (ROOT / "train.py").is_file()
needs_training = pytest.mark.skipif(not HAS_TRAINING, reason="nik.models / train.py (the training issue) missing")


def _pose_rows(robot, n: int, seed: int):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    T = robot.fk(q)
    return T, torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)


def _write_csv(path: Path, rows: torch.Tensor, header=("x", "y", "z", "qw", "qx", "qy", "qz")) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows.tolist():
            w.writerow([repr(v) for v in r])
    return path


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("data") / "puma_tiny"
    assert main(["generate", "--robot", "puma560", "--n", "600", "--out", str(out), "--no-progress"]) == 0
    return out


@pytest.fixture(scope="module")
def checkpoint(dataset, tmp_path_factory):
    if not HAS_TRAINING:
        pytest.skip("nik.models / train.py (the training issue) missing")
    root = tmp_path_factory.mktemp("runs")
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        "fit",
        "--config",
        str(ROOT / "configs" / "train" / "adam.yaml"),
        "--data.path",
        str(dataset),
        "--trainer.default_root_dir",
        str(root),
        "--trainer.max_epochs",
        "2",
        "--model.init_args.hidden",
        "[16]",
        "--trainer.logger",
        "false",
        "--trainer.enable_progress_bar",
        "false",
        "--trainer.enable_model_summary",
        "false",
    ]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    ckpts = sorted(root.rglob("last.ckpt"))
    assert ckpts, f"no last.ckpt under {root}"
    return ckpts[0]


def test_solve_one_pose_prints_labelled_table(capsys):
    robot = nik.load_robot("puma560")
    _, rows = _pose_rows(robot, 1, 0)
    assert main(["solve", "--robot", "puma560", "--pose", *map(repr, rows[0].tolist())]) == 0
    out = capsys.readouterr().out
    for label in ("joint1 (deg)", "joint6 (deg)", "pos err (mm)", "rot err (deg)", "success", "yes"):
        assert label in out


def test_solve_json_gives_radians_and_degrees_that_reach_the_pose(capsys):
    robot = nik.load_robot("kuka_kr")
    T, rows = _pose_rows(robot, 1, 1)
    pose_mm = rows[0].tolist()
    pose_mm[:3] = [v * 1e3 for v in pose_mm[:3]]
    assert main(["solve", "--robot", "kuka_kr", "--unit", "mm", "--json", "--pose", *map(repr, pose_mm)]) == 0
    doc = json.loads(capsys.readouterr().out)
    (r,) = doc["results"]
    q = torch.tensor(r["q_rad"], dtype=torch.float64)
    torch.testing.assert_close(torch.tensor(r["q_deg"], dtype=torch.float64), torch.rad2deg(q))
    pos, rot = nik.pose_error(T[0], robot.fk(q))
    assert float(pos) <= 1e-4 and float(rot) <= 1e-3
    assert r["success"] is True and math.isclose(r["pos_err_mm"], r["pos_err_m"] * 1e3)
    assert doc["joint_names"] == robot.joint_names


def test_solve_prints_prismatic_joints_in_mm(tmp_path, capsys):
    robot = nik.load_robot("stanford")
    T, rows = _pose_rows(robot, 2, 4)
    assert main(["solve", "--robot", "stanford", "--pose", *map(repr, rows[0].tolist())]) == 0
    out = capsys.readouterr().out
    for label in ("waist (deg)", "boom (mm)", "wrist3 (deg)", "pos err (mm)"):
        assert label in out
    assert main(["solve", "--robot", "stanford", "--json", "--pose", *map(repr, rows[0].tolist())]) == 0
    doc = json.loads(capsys.readouterr().out)
    (r,) = doc["results"]
    assert doc["joint_units_display"] == ["deg", "deg", "mm", "deg", "deg", "deg"]
    assert r["q_rad"][2] is None and r["q_deg"][2] is None  # a length is never labelled as an angle
    q = torch.tensor(r["q_si"], dtype=torch.float64)
    assert math.isclose(r["q_display"][2], r["q_si"][2] * 1e3) and math.isclose(r["q_display"][0], math.degrees(q[0]))
    pos, rot = nik.pose_error(T[0], robot.fk(q))
    assert float(pos) <= 1e-4 and float(rot) <= 1e-3
    poses = _write_csv(tmp_path / "poses.csv", rows)
    assert main(["solve", "--robot", "stanford", "--poses", str(poses), "--out", str(tmp_path / "sol.csv")]) == 0
    with open(tmp_path / "sol.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert "boom_m" in table[0] and "boom_mm" in table[0] and "boom_deg" not in table[0]
    for table_row in table:
        assert math.isclose(float(table_row["boom_mm"]), float(table_row["boom_m"]) * 1e3, rel_tol=1e-9)


@pytest.mark.long
@needs_training
def test_solve_csv_in_csv_out_with_a_trained_checkpoint(checkpoint, tmp_path, capsys):
    robot = nik.load_robot("puma560")
    T, rows = _pose_rows(robot, 6, 2)
    src = _write_csv(tmp_path / "poses.csv", rows)
    out = tmp_path / "solutions.csv"
    rc = main(
        [
            "solve",
            "--robot",
            "puma560",
            "--checkpoint",
            str(checkpoint),
            "--refine",
            "lm",
            "--poses",
            str(src),
            "--out",
            str(out),
        ]
    )
    with out.open() as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 6
    names = robot.joint_names
    q = torch.tensor([[float(r[f"{j}_rad"]) for j in names] for r in table], dtype=torch.float64)
    q_deg = torch.tensor([[float(r[f"{j}_deg"]) for j in names] for r in table], dtype=torch.float64)
    torch.testing.assert_close(q_deg, torch.rad2deg(q), atol=1e-6, rtol=0)
    assert bool(robot.within_limits(q).all())
    # the reported errors and flags are the true ones (a 2-epoch network is a poor guess; the
    # multi-start fallback usually rescues it, and any pose it does not is flagged, exit status 1)
    pos, rot = nik.pose_error(T, robot.fk(q))
    pos_mm = torch.tensor([float(r["pos_err_mm"]) for r in table], dtype=torch.float64)
    torch.testing.assert_close(pos_mm, pos * 1e3, atol=1e-6, rtol=1e-5)
    success = torch.tensor([r["success"] == "1" for r in table])
    assert torch.equal(success, (pos <= 1e-4) & (rot <= math.radians(math.degrees(1e-3))))
    assert rc == (0 if bool(success.all()) else 1)
    assert int(success.sum()) >= 5
    assert "wrote" in capsys.readouterr().out


@needs_training
def test_solutions_csv_is_written_whole_or_not_at_all(tmp_path):
    from nik.cli.solve import write_solutions_csv

    class Broken:  # a result whose third row cannot be written
        q = torch.zeros(3, 2, dtype=torch.float64)
        pos_err = rot_err = torch.zeros(3, dtype=torch.float64)
        success = torch.ones(3, dtype=torch.bool)
        iterations = [1, 1]

        def __len__(self):
            return 3

    out = tmp_path / "solutions.csv"
    out.write_text("old\n")
    with pytest.raises(IndexError):
        write_solutions_csv(out, ["j1", "j2"], Broken())
    assert out.read_text() == "old\n" and sorted(p.name for p in tmp_path.iterdir()) == ["solutions.csv"]
    Broken.iterations = [1, 1, 1]
    write_solutions_csv(out, ["j1", "j2"], Broken())
    assert len(out.read_text().splitlines()) == 4 and sorted(p.name for p in tmp_path.iterdir()) == ["solutions.csv"]


FIVE_JOINTS = """\
name: five_joints  # an SO-101-like arm: base yaw, shoulder, elbow, wrist pitch, wrist roll
convention: dh
unit: mm
angles: deg
joints:
  - {alpha: 90, a: 0, d: 120, limits: [-170, 170]}
  - {alpha: 0, a: 110, d: 0, offset: 90, limits: [-100, 100]}
  - {alpha: 0, a: 130, d: 0, limits: [-140, 140]}
  - {alpha: 90, a: 0, d: 0, offset: 90, limits: [-100, 100]}
  - {alpha: 0, a: 0, d: 100, limits: [-170, 170]}
"""


def test_a_five_joint_arm_says_what_to_ask_for_and_never_calls_an_orientation_out_of_reach(tmp_path, capsys):
    arm = tmp_path / "five.yaml"
    arm.write_text(FIVE_JOINTS)
    robot = nik.load_robot(arm)
    q = torch.tensor([[0.3, 0.2, 0.4, 0.1, 0.2]], dtype=torch.float64)
    T = robot.fk(q)
    turned = T.clone()  # the same position, the tool turned 60 deg about its x axis: no 5-joint configuration has it
    c, s = math.cos(math.radians(60)), math.sin(math.radians(60))
    turned[:, :3, :3] = T[:, :3, :3] @ torch.tensor([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=torch.float64)
    far = T.clone()
    far[:, :3, 3] *= 5  # 5 x the distance: beyond the reach bound
    with pytest.warns(UserWarning, match="1 of 3 target"):  # only the far one is said to be beyond the reach
        res = nik.IKSolver(robot).solve(torch.cat([T, turned, far]), seed=0)
    assert res.success.tolist() == [True, False, False]
    assert res.reachable.tolist() == [True, True, False]  # not proven out of reach: the position is within it

    def solve(T1):
        p, w = T1[0, :3, 3].tolist(), matrix_to_quaternion(T1[0, :3, :3]).tolist()
        rc = main(["solve", "--robot", str(arm), "--pose", *map(str, p + w)])
        return rc, capsys.readouterr().err

    rc, err = solve(T)
    assert rc == 0 and err == ""
    rc, err = solve(turned)
    assert rc == 1 and "5 joints" in err and "--position-only" in err and "--free-axis z" in err
    assert "beyond the reach" not in err and err.count("\n") == 1
    rc, err = solve(far)
    assert rc == 1 and "beyond the reach of five_joints" in err


@pytest.mark.long
def test_checkpoint_for_another_robot_is_one_line_error(checkpoint, capsys):
    pose = ["1", "0", "1", "1", "0", "0", "0"]
    rc = main(["solve", "--robot", "kuka_kr", "--checkpoint", str(checkpoint), "--pose", *pose])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert "puma560" in err and "kuka_kr" in err


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--pose", "0.4", "0.1", "0.3", "0", "2", "0", "0"], "--pose: row 0: quaternion"),
        (["--pose", "0.4", "0.1", "nan", "1", "0", "0", "0"], "--pose: row 0: x, y, z contains NaN"),
        (["--poses", "does/not/exist.csv"], "not found"),
        (["--pose", "0.4", "0.1", "0.3", "1", "0", "0", "0", "--q-near", "0", "0"], "--q-near"),
        (["--pose", "0.4", "0.1", "0.3", "1", "0", "0", "0", "--checkpoint", "missing.ckpt"], "not found"),
    ],
)
def test_solve_errors_are_one_line_and_exit_2(args, match, capsys):
    rc = main(["solve", "--robot", "puma560", *args])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and err.startswith("nik solve: error:")
    assert match in err


def test_solve_csv_errors_name_file_and_line(tmp_path, capsys):
    bad_header = _write_csv(tmp_path / "a.csv", torch.zeros(1, 7), header=("x", "y", "z", "w", "qx", "qy", "qz"))
    assert main(["solve", "--robot", "puma560", "--poses", str(bad_header)]) == 2
    assert "lacks column(s) ['qw']" in capsys.readouterr().err
    bad_value = tmp_path / "b.csv"
    bad_value.write_text("x,y,z,qw,qx,qy,qz\n0.4,0.1,0.3,1,0,0,0\n0.4,abc,0.3,1,0,0,0\n")
    assert main(["solve", "--robot", "puma560", "--poses", str(bad_value)]) == 2
    assert "b.csv line 3: column 'y' must be a number, got 'abc'" in capsys.readouterr().err


def test_solve_reads_a_csv_with_excels_utf8_byte_order_mark(tmp_path, capsys):
    robot = nik.load_robot("puma560")
    T, rows = _pose_rows(robot, 3, 4)
    plain = _write_csv(tmp_path / "plain.csv", rows)
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())  # Excel's "CSV UTF-8"
    assert main(["solve", "--robot", "puma560", "--poses", str(bom), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    q = torch.tensor([r["q_rad"] for r in doc["results"]], dtype=torch.float64)
    pos, rot = nik.pose_error(T, robot.fk(q))
    assert float(pos.max()) < 1e-4 and float(rot.max()) < 1e-3


@pytest.mark.parametrize("command", ["solve", "path"])
def test_csv_errors_count_file_lines_from_1_for_every_check(tmp_path, capsys, command):
    bad = tmp_path / "q.csv"  # header on line 1, a blank line 3: the bad quaternion is on file line 5
    bad.write_text("x,y,z,qw,qx,qy,qz\n0.4,0.1,0.5,0,1,0,0\n\n0.4,0.1,0.5,0,1,0,0\n0.4,0.1,0.5,0,2,0,0\n")
    assert main([command, "--robot", "puma560", "--poses", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad} line 5: quaternion (qw, qx, qy, qz) has norm 2" in err and err.count("\n") == 1
    bad.write_text("x,y,z,qw,qx,qy,qz\n0.4,0.1,0.5,0,1,0,0\n0.4,0.1,nan,0,1,0,0\n")
    assert main([command, "--robot", "puma560", "--poses", str(bad)]) == 2
    assert f"{bad} line 3: a pose contains NaN or inf" in capsys.readouterr().err


def test_plot_of_all_solutions_draws_at_most_8_ghosts_a_pose_and_says_so(tmp_path, capsys, monkeypatch):
    pytest.importorskip("matplotlib")
    import nik.view
    from nik.cli.solve import PLOT_MAX_GHOSTS, _plot

    robot = nik.load_robot("panda")
    gen = torch.Generator().manual_seed(5)
    q = robot.sample(2, generator=gen, dtype=torch.float64)
    res = nik.IKSolver(robot).solve(robot.fk(q), seed=0)
    every = [robot.sample(120, generator=gen, dtype=torch.float64), q[1:]]  # a 7-joint arm's continuum; one
    drawn = {}
    real = nik.view.plot_arm

    def spy(robot, q, path, *, ghosts=None, **kw):
        drawn.update(ghosts=ghosts, title=kw["title"])
        return real(robot, q, path, ghosts=ghosts, **kw)

    monkeypatch.setattr(nik.view, "plot_arm", spy)
    _plot(robot, robot.fk(q), res, every, tmp_path / "arm.png", tolerance="0.1 mm / 0.1 deg")
    assert (tmp_path / "arm.png").stat().st_size > 0
    assert PLOT_MAX_GHOSTS == 8 and drawn["ghosts"].shape == (8 + 1, 7)
    assert all(any(torch.equal(g, s) for s in every[0]) for g in drawn["ghosts"][:8])  # drawn from the found ones
    assert "9 of 121 solutions drawn faint (at most 8 a pose)" in drawn["title"]
    assert "nik: note: --plot draws 9 of the 121 solutions found" in capsys.readouterr().err


def test_unreachable_pose_exits_1_and_says_no(capsys):
    assert main(["solve", "--robot", "puma560", "--refine", "lm", "--pose", "3", "0", "0", "1", "0", "0", "0"]) == 1
    assert "NO" in capsys.readouterr().out


@pytest.mark.long
@needs_training
def test_evaluate_writes_table_json_and_histogram(checkpoint, dataset, tmp_path, capsys):
    out = tmp_path / "eval"
    rc = main(
        [
            "evaluate",
            "--robot",
            "puma560",
            "--checkpoint",
            str(checkpoint),
            "--data",
            str(dataset),
            "--n",
            "6",
            "--out",
            str(out),
            "--refinements",
            "lm",
        ]
    )
    assert rc == 0
    text = (out / "evaluation.md").read_text()
    for row in (
        "| network |",
        "| network + lm |",
        "| uniform-init ipso |",
        "| analytic (closed form) |",
        "| pytorch-kinematics |",
    ):
        assert row in text
    doc = json.loads((out / "evaluation.json").read_text())
    assert all(r["outside_limits"] == 0 for r in doc["rows"])
    rows = {r["method"]: r for r in doc["rows"]}
    assert rows["analytic (closed form)"]["success_01mm_01deg"] == 1.0
    # refining can only help: the network's raw guess never beats network + LM
    assert rows["network + lm"]["success_1mm_1deg"] >= rows["network"]["success_1mm_1deg"]
    assert (out / "errors.png").stat().st_size > 1000
    assert "| method |" in capsys.readouterr().out


def test_pose_beyond_the_reach_is_explained_in_one_line_with_the_millimetre_question(capsys):
    robot = nik.load_robot("ur5")
    _, rows = _pose_rows(robot, 1, 31)
    pose_mm = [str(v * 1000.0) if i < 3 else str(v) for i, v in enumerate(rows[0].tolist())]
    assert main(["solve", "--robot", "ur5", "--threads", "1", "--pose", *pose_mm]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "beyond the reach of ur5" in err[0] and "--unit mm" in err[0]
    # the same numbers with --unit mm are solved, and nothing is said about the reach
    assert main(["solve", "--robot", "ur5", "--unit", "mm", "--pose", *pose_mm]) == 0
    assert "beyond the reach" not in capsys.readouterr().err


def test_threads_option_is_accepted_by_the_computing_commands():
    from nik.cli import build_parser

    parser = build_parser()
    for argv in (["solve", "--robot", "ur5", "--pose", *["0"] * 7], ["evaluate", "--robot", "ur5", "--data", "d"]):
        assert parser.parse_args([*argv, "--threads", "2"]).threads == 2
    assert parser.parse_args(["generate", "--robot", "ur5", "--n", "1", "--out", "x", "--threads", "2"]).threads == 2


def test_end_link_chooses_the_tool_link_and_the_output_names_it(capsys):
    robot = nik.load_robot("ur5", end_link="tool0")
    T, rows = _pose_rows(robot, 1, 5)
    pose = [repr(v) for v in rows[0].tolist()]
    argv = ["solve", "--robot", "ur5", "--end-link", "tool0", "--threads", "1", "--pose", *pose]
    assert main(argv) == 0
    assert "tool link tool0" in capsys.readouterr().out
    assert main([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["end_link"] == "tool0"
    q = torch.tensor([doc["results"][0]["q_si"]], dtype=torch.float64)
    err_pos = (robot.fk(q)[0, :3, 3] - T[0, :3, 3]).norm()
    assert float(err_pos) < 1e-4  # the tool0 pose is reached by tool0, not by the flange
    # without --end-link the built-in's flange is used, and named: tool0 itself, on the trained chain's last link
    assert main(["solve", "--robot", "ur5", "--threads", "1", "--pose", *pose]) == 0
    assert "flange tool0 on wrist_3_link" in capsys.readouterr().out


def test_bad_end_link_is_a_one_line_error(capsys):
    assert main(["solve", "--robot", "ur5", "--end-link", "gripper", "--pose", *["0"] * 3, "1", "0", "0", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "end_link 'gripper' is not a link" in err


def test_evaluate_end_link_names_the_tool_link(tmp_path, capsys):
    data = tmp_path / "ur5_tool0"
    assert main(["generate", "--robot", "ur5", "--end-link", "tool0", "--n", "100", "--out", str(data)]) == 0
    out = tmp_path / "eval"
    argv = ["evaluate", "--robot", "ur5", "--end-link", "tool0", "--data", str(data), "--n", "3", "--no-pk"]
    assert main([*argv, "--out", str(out), "--swarm", "lm"]) == 0
    assert "tool link `tool0`" in (out / "evaluation.md").read_text()
    assert json.loads((out / "evaluation.json").read_text())["end_link"] == "tool0"
    capsys.readouterr()


@pytest.mark.long
def test_solve_with_a_scene_reports_collision_free_per_pose_and_why_poses_failed(tmp_path, capsys):
    scene = tmp_path / "scene.yaml"
    scene.write_text(
        "boxes: [{center: [0.0, 0.0, -0.05], size: [1.0, 1.0, 0.1]},\n"
        "        {center: [0.3, -0.3, 0.3], size: [0.2, 0.2, 0.2]}]\n"
    )
    rows = "x,y,z,qw,qx,qy,qz\n0.4,0.1,0.3,0,1,0,0\n0.3,-0.3,0.3,0,1,0,0\n3,0,0,0,1,0,0\n"
    poses = tmp_path / "poses.csv"
    poses.write_text(rows)
    base = ["solve", "--robot", "ur5", "--poses", str(poses), "--scene", str(scene)]
    assert main(base) == 1
    out = capsys.readouterr().out
    assert "collision-free" in out.splitlines()[0]
    assert "2 of 3 poses not reached: 1 colliding with the scene, 1 out of reach" in out and str(scene) in out
    assert main([*base, "--json"]) == 1
    doc = json.loads(capsys.readouterr().out)
    free = [r["collision_free"] for r in doc["results"]]
    assert free[0] and not free[1] and free == [r["collisions"] == [] for r in doc["results"]]
    assert any(n.endswith("|box 1") for n in doc["results"][1]["collisions"])
    assert doc["not_reached"] == "2 of 3 poses not reached: 1 colliding with the scene, 1 out of reach"
    out_csv = tmp_path / "out.csv"
    assert main([*base, "--out", str(out_csv)]) == 1
    assert "1 colliding with the scene" in capsys.readouterr().out
    with out_csv.open() as fh:
        table = list(csv.DictReader(fh))
    assert [r["collision_free"] for r in table] == ["1" if f else "0" for f in free]
    assert "|box 1" in table[1]["collisions"]
    assert main(["solve", "--robot", "ur5", "--poses", str(poses), "--out", str(out_csv)]) == 1  # no scene
    with out_csv.open() as fh:
        assert "collision_free" not in next(csv.reader(fh))


def test_solve_asks_about_a_scene_written_in_millimetres(tmp_path, capsys):
    scene = tmp_path / "scene.yaml"
    scene.write_text("boxes: [{center: [0, 0, -50], size: [1000, 1000, 100]}]\n")
    main(["solve", "--robot", "ur5", "--pose", "0.4", "0.1", "0.3", "0", "1", "0", "0", "--scene", str(scene)])
    err = capsys.readouterr().err
    assert "written in millimetres? add 'unit: mm'" in err
    scene.write_text("unit: mm\n" + scene.read_text())
    assert (
        main(["solve", "--robot", "ur5", "--pose", "0.4", "0.1", "0.3", "0", "1", "0", "0", "--scene", str(scene)]) == 0
    )
    assert "millimetres" not in capsys.readouterr().err


def test_solve_quat_order_xyzw_reads_the_pose_and_the_tool_w_last(capsys):
    robot = nik.load_robot("kuka_kr")
    T, rows = _pose_rows(robot, 1, 2)
    wxyz = rows[0].tolist()
    tool = [0.0, 0.0, 0.1, math.cos(0.3), 0.0, 0.0, math.sin(0.3)]  # 10 cm along z, turned 0.6 rad about z
    T_tcp = T[0] @ nik.load_robot("kuka_kr", tool=tool).tool.to(T.dtype)
    tcp = [*T_tcp[:3, 3].tolist(), *matrix_to_quaternion(T_tcp[:3, :3]).tolist()]
    answers = []
    for order, pose, frame in (
        ("wxyz", tcp, tool),
        ("xyzw", tcp[:3] + tcp[4:] + tcp[3:4], tool[:3] + tool[4:] + tool[3:4]),
    ):
        args = ["solve", "--robot", "kuka_kr", "--json", "--quat-order", order, "--tool", *map(repr, frame)]
        assert main([*args, "--pose", *map(repr, pose)]) == 0
        (r,) = json.loads(capsys.readouterr().out)["results"]
        assert r["success"] is True
        answers.append(torch.tensor(r["q_rad"], dtype=torch.float64))
    torch.testing.assert_close(answers[1], answers[0], atol=1e-9, rtol=0)
    pos, rot = nik.pose_error(T[0], robot.fk(answers[1]))  # the flange where the TCP pose puts it
    assert float(pos) <= 1e-4 and float(rot) <= 1e-3
    with pytest.raises(SystemExit) as stop:  # argparse refuses another order: exit 2, usage and one error line
        main(["solve", "--robot", "kuka_kr", "--quat-order", "zyxw", "--pose", *map(repr, wxyz)])
    assert stop.value.code == 2 and "argument --quat-order: invalid choice" in capsys.readouterr().err
