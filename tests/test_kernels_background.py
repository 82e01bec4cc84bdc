"""The first compile of the kernels (:mod:`nik.kernels.background`): one line says so, once per machine; on a cold
cache the first answer comes from the torch backend, within the same tolerances, while the compiled solve compiles.

Each test runs a fresh process on its own empty ``NUMBA_CACHE_DIR`` (a cold machine) without ``NIK_COMPILE`` (the
suite's ``wait``, tests/conftest.py); the first keeps to one small kernel (under a second of compiling).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINE = "nik: compiling kernels for this machine"


def _run(code: str, cache: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "NIK_COMPILE"}
    env.update(NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT) + os.pathsep + env.get("PYTHONPATH", ""))
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, timeout=300, check=False
    )


SMALL = """
import json, sys
import numpy as np
from nik.kernels import background, poses
cold = background.cold(poses.poses_ok)
T = np.eye(4)[None].copy()
ok = bool(poses.poses_ok(T, 1e-6)) and bool(poses.poses_ok(T, 1e-6))
print(json.dumps({"cold": cold, "ok": ok, "ready": background.ready(poses.poses_ok, (T, 1e-6))}))
"""


def test_a_cold_cache_compile_says_so_in_one_line_and_a_warm_one_says_nothing(tmp_path):
    first = _run(SMALL, tmp_path)
    assert first.returncode == 0, first.stderr
    assert json.loads(first.stdout) == {"cold": True, "ok": True, "ready": True}
    assert first.stderr.count(LINE) == 1, first.stderr
    line = next(s for s in first.stderr.splitlines() if s.startswith(LINE))
    assert "torch" not in line  # compiled on the caller's thread: no torch answers to promise
    second = _run(SMALL, tmp_path)
    assert second.returncode == 0, second.stderr
    assert json.loads(second.stdout) == {"cold": False, "ok": True, "ready": True}
    assert LINE not in second.stderr


FIRST_SOLVE = """
import json, os, sys
import torch, nik
from nik.kernels import background
T = torch.tensor(json.loads(sys.argv[1]), dtype=torch.float64)
solver = nik.IKSolver("panda")
one = solver.solve(T[:1], seed=0)  # the first call: one pose
res = solver.solve(T, seed=0)  # while the compile runs: torch again
out = {"busy": background.BUSY, "q": res.q.tolist(), "success": res.success.tolist(), "dtype": str(res.q.dtype)}
out.update(q1=one.q.tolist(), success1=one.success.tolist())
print(json.dumps(out), flush=True)
os._exit(0)  # the background compile is not waited for (a test of the first answer only)
"""


def test_a_cold_cache_first_solve_answers_from_torch_within_tolerance(tmp_path):
    import torch

    import nik
    from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

    robot = nik.load_robot("panda")
    g = torch.Generator().manual_seed(0)
    lo, hi = robot.limits[:, 0].double(), robot.limits[:, 1].double()
    T = robot.fk(lo + (hi - lo) * (0.15 + 0.7 * torch.rand(3, robot.dof, generator=g, dtype=torch.float64)))
    done = _run(FIRST_SOLVE, tmp_path, json.dumps(T.tolist()))
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["busy"]  # answered while the compiled solve was compiling
    assert out["success1"] == [True] and out["success"] == [True, True, True] and out["dtype"] == "torch.float64"
    q = torch.tensor(out["q1"] + out["q"], dtype=torch.float64)
    pos, rot = nik.pose_error(torch.cat([T[:1], T]), robot.fk(q))  # FK round trip, here
    assert bool(robot.within_limits(q).all())
    assert float(pos.max()) <= DEFAULT_TOL_POS and float(rot.max()) <= DEFAULT_TOL_ROT
    lines = [s for s in done.stderr.splitlines() if s.startswith(LINE)]
    assert len(lines) == 1 and "answers meanwhile come from the torch backend" in lines[0], done.stderr


@pytest.mark.parametrize("value", ["wait", "WAIT "])
def test_nik_compile_wait_turns_the_torch_answers_off(monkeypatch, value):
    from nik.kernels import background

    monkeypatch.setenv("NIK_COMPILE", value)
    assert not background.defer_allowed()
    monkeypatch.setenv("NIK_COMPILE", "background")
    assert background.defer_allowed()
