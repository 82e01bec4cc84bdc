"""nik.evaluate: the URDF export, the table header and the cumulative error plot."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.testing import assert_close

import nik
from nik.evaluate import EvalReport, line_style, markdown_table, plot_errors, robot_to_urdf, write_report
from nik.robots.urdf import build_pk_chain


def test_robot_to_urdf_writes_prismatic_joints_that_pytorch_kinematics_follows():
    robot = nik.load_robot("stanford")
    text, end = robot_to_urdf(robot)
    assert text.count('type="prismatic"') == 1
    chain = build_pk_chain(text, end).to(dtype=torch.float64)
    q = robot.sample(50, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    # pytorch-kinematics parses rpy through float32: about 1e-9 m here
    assert_close(chain.forward_kinematics(q).get_matrix(), robot.fk(q), atol=1e-7, rtol=0)


@pytest.mark.parametrize(("threads", "text"), [(1, "CPU (1 thread),"), (2, "CPU (2 threads),")])
def test_table_header_says_thread_or_threads(threads, text):
    header = markdown_table(EvalReport(robot="puma560", data="data/x", n=3, threads=threads)).splitlines()[0]
    assert text in header


def test_ten_lines_have_pairwise_different_styles():
    colours = [f"C{k}" for k in range(10)]
    styles = [line_style(i, 10, colours) for i in range(10)]
    for key in ("color", "marker", "markevery"):
        assert len({str(s[key]) for s in styles}) == 10, key
    assert len({s["linestyle"] for s in styles}) == 4


def test_write_report_writes_table_json_and_a_png_plot(tmp_path):
    rng = np.random.default_rng(0)
    report = EvalReport(robot="puma560", data="data/x", n=50, threads=1)
    report.errors = {
        "a": (10 ** rng.uniform(-4, 1, 50), 10 ** rng.uniform(-4, 1, 50)),
        "b (same as a)": (10 ** rng.uniform(-4, 1, 50), 10 ** rng.uniform(-4, 1, 50)),
        "exact": (np.zeros(50), np.zeros(50)),  # below the 1e-12 floor: drawn at the floor, not lost
    }
    paths = write_report(report, tmp_path / "eval")
    png = paths["plot"].read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert paths["markdown"].read_text().startswith("Robot `puma560`")
    assert sorted(p.name for p in (tmp_path / "eval").iterdir()) == ["errors.png", "evaluation.json", "evaluation.md"]
    assert plot_errors(report, tmp_path / "again.png").stat().st_size > 10_000
