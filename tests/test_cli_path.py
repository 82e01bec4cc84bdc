"""``nik path``'s trajectory CSV (nik/cli/path.py): each column holds one unit."""

from __future__ import annotations

import csv
import math

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
