"""benchmarks/peers.py: its smoke run reads well without the optional peer (Robotics Toolbox)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _peers():
    spec = importlib.util.spec_from_file_location("nik_bench_peers", ROOT / "benchmarks" / "peers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(importlib.util.find_spec("roboticstoolbox") is not None, reason="Robotics Toolbox is installed")
def test_quick_run_without_robotics_toolbox_says_so_once_and_prints_no_nan(capsys, tmp_path):
    peers = _peers()
    assert peers.main(["--quick", "--latency-n", "3", "--out", str(tmp_path / "peers")]) == 0
    out = capsys.readouterr().out
    assert out.count("roboticstoolbox-python is not installed") == 1
    assert "nan" not in out.lower()
    table = (tmp_path / "peers.md").read_text()
    assert "nan" not in table.lower() and "| panda | 200 | 1 | nik" in table and "| ur5 | 200 | 1 | nik" in table


def test_pyroki_comparison_says_why_it_skips_without_pyroki(capsys, monkeypatch):
    spec = importlib.util.spec_from_file_location("nik_bench_pyroki", ROOT / "benchmarks" / "pyroki_collisions.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setitem(__import__("sys").modules, "pyroki", None)  # as if not installed
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")  # the script sets them for JAX; restored after the test
    monkeypatch.setenv("XLA_FLAGS", "")
    assert module.main(["--targets", "2"]) == 0
    assert capsys.readouterr().out.startswith("skipped: PyRoki is not installed")
