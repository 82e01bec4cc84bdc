"""The first compile of the kernels (:mod:`nik.kernels.background`): one line says so, at most once per process; on a
cold cache the first answer comes from the torch backend, within the same tolerances, while the compiled solve
compiles; a process that ends meanwhile does not wait for the compile, and the next one resumes it.

Each test runs a fresh process on its own empty ``NUMBA_CACHE_DIR`` (a cold machine) without ``NIK_COMPILE`` (the
suite's ``wait``, tests/conftest.py); the first keeps to one small kernel (under a second of compiling); the tests
marked ``long`` compile the whole solve (minutes on a shared two-core machine).
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


def _run(code: str, cache: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "NIK_COMPILE"}
    env.update(NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT) + os.pathsep + env.get("PYTHONPATH", ""))
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, timeout=timeout, check=False
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


@pytest.mark.long
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


@pytest.mark.long
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


# ---------------------------------------------------------------------------
# A first day with nik: fresh processes on an empty cache, the compile left to the background (long: they compile)
# ---------------------------------------------------------------------------

POSE = "torch.tensor([0.4, 0.1, 0.5, 0, 1, 0, 0], dtype=torch.float64)"  # README's first pose (x, y, z, quaternion)

FOUR_KINDS = f"""
import torch, nik
solver = nik.IKSolver("panda")
q = torch.tensor([0.2, 0.3, -0.2, -1.8, 0.1, 2.0, 0.5], dtype=torch.float64)
print("fk", bool(torch.isfinite(solver.robot.fk(q)).all()), flush=True)  # one configuration: compiled FK
pose = {POSE}
print("pose", bool(solver.solve(pose, representation="quat").success.all()), flush=True)
print("bounded", bool(solver.solve(pose, representation="quat", bounds="axis_z").success.all()), flush=True)
world = nik.World().add_box([0.4, 0.0, -0.05], [1.2, 1.2, 0.1])
print("boxes", bool(nik.IKSolver("panda", world=world).solve(pose, representation="quat").success.all()), flush=True)
q7 = torch.tensor([0.2, 0.3, -0.2, -1.8, 0.1, 2.0, 0.5], dtype=torch.float64)
T7 = solver.robot.fk(q7[None]).expand(30, 4, 4).clone()
T7[:, 2, 3] += torch.linspace(0.0, 0.1, 30, dtype=torch.float64)
print("path", int(solver.solve_path(T7, q_start=q7).success.sum()), flush=True)
"""


@pytest.mark.long
def test_one_process_on_an_empty_cache_says_it_compiles_once_for_fk_a_pose_a_bound_boxes_and_a_path(tmp_path):
    done = _run(FOUR_KINDS, tmp_path, timeout=1800)  # every kernel of the four compiles: minutes on a busy machine
    assert done.returncode == 0, done.stderr[-3000:]
    assert [line.split()[0] for line in done.stdout.splitlines()] == ["fk", "pose", "bounded", "boxes", "path"]
    assert done.stdout.splitlines()[:2] == ["fk True", "pose True"]
    lines = [s for s in done.stderr.splitlines() if s.startswith(LINE)]
    assert len(lines) == 1, done.stderr
    assert "once" in lines[0] and "faster" in lines[0]  # what is compiled, and that later calls get faster


ONE_POSE = f"""
import sys, time
import torch, nik
res = nik.IKSolver("panda").solve({POSE}, representation="quat")
print("answer", bool(res.success.all()), flush=True)
if sys.argv[1:] == ["stay"]:
    time.sleep(900)  # the background compile goes on until the process is killed
"""


def _start(code: str, cache: Path, *args: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "NIK_COMPILE"}
    env.update(NUMBA_CACHE_DIR=str(cache), NIK_COMPILE_VERBOSE="1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.Popen(
        [sys.executable, "-c", code, *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _entries(cache: Path) -> int:
    return sum(1 for _ in cache.rglob("*.nbc"))


@pytest.mark.long
def test_a_process_ends_soon_after_its_answer_and_a_compile_cut_short_leaves_a_cache_the_next_uses(tmp_path):
    import time

    import torch

    import nik
    from nik.poses import vector_to_pose
    from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

    # 1. one pose on an empty cache: the answer at once (torch), the exit within 20 s of it (the background compile
    # stops at exit after the kernel in progress; not waited for to its end, 40-170 s here)
    proc = _start(ONE_POSE, tmp_path)
    answer = proc.stdout.readline()
    answered = time.monotonic()
    proc.wait(timeout=300)
    waited = time.monotonic() - answered
    err = proc.stderr.read()
    assert answer.strip() == "answer True" and proc.returncode == 0, err
    assert waited <= 20.0, (waited, err)
    assert "stopped at exit" in err, err
    print(f"exit {waited:.1f} s after the answer; {_entries(tmp_path)} cache entries saved")
    # 2. the compile resumed by the next process, then killed (SIGKILL) once it has saved a kernel more
    saved = _entries(tmp_path)
    proc = _start(ONE_POSE, tmp_path, "stay")
    try:
        assert proc.stdout.readline().strip() == "answer True"
        deadline = time.monotonic() + 600
        while _entries(tmp_path) <= saved and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
    finally:
        proc.kill()
        proc.communicate()
    assert _entries(tmp_path) > saved
    # 3. the next process loads what was saved and compiles the rest on its thread: the compiled answers, checked by FK
    robot = nik.load_robot("panda")
    code = f"""
import json, torch, nik
res = nik.IKSolver("panda", backend="compiled").solve({POSE}, representation="quat", seed=0)
print(json.dumps([res.success.tolist(), res.q.tolist()]))
"""
    done = _run(code, tmp_path, timeout=1200)
    assert done.returncode == 0, done.stderr[-3000:]
    success, q = json.loads(done.stdout.splitlines()[-1])
    target = vector_to_pose(torch.tensor([[0.4, 0.1, 0.5, 0, 1, 0, 0]], dtype=torch.float64))
    pos, rot = nik.pose_error(target, robot.fk(torch.tensor(q, dtype=torch.float64)))  # FK round trip, here
    assert success == [True] and bool(robot.within_limits(torch.tensor(q, dtype=torch.float64)).all())
    assert float(pos.max()) <= DEFAULT_TOL_POS and float(rot.max()) <= DEFAULT_TOL_ROT
