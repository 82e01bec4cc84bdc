"""``nik path``'s trajectory CSV (nik/cli/path.py): each column holds one unit."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
import torch

import nik
from nik.cli import main
from nik.poses import matrix_to_quaternion


def test_trajectory_csv_steps_are_degrees_for_revolute_and_mm_for_prismatic_joints(tmp_path, capsys):
    robot = nik.load_robot("stanford")  # joint 3 (boom) slides
    q0 = robot.sample(1, generator=torch.Generator().manual_seed(3), dtype=torch.float64)[0]
    s = torch.linspace(0, 1, 8, dtype=torch.float64)[:, None]
    q_line = q0 + s * torch.tensor([0.2, -0.1, 0.05, 0.1, 0.1, -0.2], dtype=torch.float64)  # radians; boom metres
    T = robot.fk(robot.clamp(q_line))
    poses = tmp_path / "path.csv"
    rows = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    poses.write_text("x,y,z,qw,qx,qy,qz\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows.tolist()))
    start = [math.degrees(v) if not p else 1e3 * v for v, p in zip(q0.tolist(), robot.prismatic.tolist(), strict=True)]
    out = tmp_path / "traj.csv"
    argv = ["path", "--robot", "stanford", "--poses", str(poses), "--out", str(out), "--q-start", *map(repr, start)]
    assert main(argv) == 0, capsys.readouterr().err
    with out.open() as fh:
        table = list(csv.DictReader(fh))
    cols = [f"{n}_{'mm' if p else 'deg'}" for n, p in zip(robot.joint_names, robot.prismatic.tolist(), strict=True)]
    q = torch.tensor([[float(r[c]) for c in cols] for r in table], dtype=torch.float64)
    prev = torch.cat([torch.tensor([start], dtype=torch.float64), q[:-1]])
    dq = (q - prev).abs()  # degrees and millimetres, as written
    slide = robot.prismatic
    torch.testing.assert_close(
        torch.tensor([float(r["step_deg"]) for r in table], dtype=torch.float64),
        dq[:, ~slide].amax(1),
        atol=1e-5,
        rtol=0,
    )
    torch.testing.assert_close(
        torch.tensor([float(r["step_mm"]) for r in table], dtype=torch.float64),
        dq[:, slide].amax(1),
        atol=1e-5,
        rtol=1e-5,
    )
    assert float(dq[:, slide].max()) > 1.0  # the boom moves millimetres a step: a unit mix-up would show


def _ur5_poses(tmp_path):
    robot = nik.load_robot("ur5")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = robot.fk(q0[None])[0].expand(12, 4, 4).clone()
    T[:, 1, 3] += torch.linspace(0.0, 0.1, 12, dtype=torch.float64)
    poses = tmp_path / "path.csv"
    rows = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    poses.write_text("x,y,z,qw,qx,qy,qz\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows.tolist()))
    return robot, T, poses


def test_a_timed_trajectory_round_trips_through_its_csv(tmp_path, capsys):
    pytest.importorskip("toppra")
    from nik.paths.timing import read_time_column

    robot, T, poses = _ur5_poses(tmp_path)
    out = tmp_path / "traj.csv"
    argv = ["path", "--robot", "ur5", "--poses", str(poses), "--out", str(out), "--timing", "--vel-scale", "0.5"]
    assert main(argv) == 0, capsys.readouterr().err
    t = read_time_column(out)
    res = nik.IKSolver(robot).solve_path(T, timing={"vel_scale": 0.5})
    np.testing.assert_allclose(t, res.path.t.numpy(), atol=1e-6, rtol=0)
    assert t[-1] > 0
    with out.open() as fh:
        assert next(csv.reader(fh))[:2] == ["index", "t_s"]


def test_timing_says_in_one_line_when_accelerations_were_assumed(tmp_path, capsys):
    """Issue 37 item 8: ur5 has speed limits but no acceleration limits; the CLI says what it assumed."""
    pytest.importorskip("toppra")
    _, _, poses = _ur5_poses(tmp_path)
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--out", str(tmp_path / "t.csv"), "--timing"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "acceleration" in line]
    assert len(notes) == 1 and "assumed 10x its speed limits" in notes[0]


def test_a_timed_plot_writes_a_png(tmp_path):
    pytest.importorskip("toppra")
    pytest.importorskip("matplotlib")
    _, _, poses = _ur5_poses(tmp_path)
    png = tmp_path / "timed.png"
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--timing", "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--timing", "--vel-scale", "0"], "--vel-scale"),
        (["--timing", "--acc-scale", "1.5"], "--acc-scale"),
        (["--timing", "--vel-scale", "nan"], "--vel-scale"),
        (["--vel-scale", "0.5"], "need --timing"),
    ],
)
def test_bad_timing_scales_exit_2_with_one_line(tmp_path, capsys, extra, match):
    _, _, poses = _ur5_poses(tmp_path)
    assert main(["path", "--robot", "ur5", "--poses", str(poses), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("nik path: error:") and match in err and "\n" not in err


def test_free_axis_on_the_command_line_frees_the_tool_axis(tmp_path, capsys):
    _, _, poses = _ur5_poses(tmp_path)
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--free-axis", "z"]) == 0
    assert "rz free" in capsys.readouterr().out
