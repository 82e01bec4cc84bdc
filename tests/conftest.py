"""Shared test set-up: every test sees an empty user network folder (``NIK_HOME``), never the real one; the kernels
compile on the caller's thread (``NIK_COMPILE=wait``: on a cold kernel cache ``backend="auto"`` would otherwise answer
from torch until the compiled solve is ready, :mod:`nik.kernels.background`, and tests that compare the compiled
answers with the staged ones need them from the first call; ``tests/test_kernels_background.py`` unsets it)."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("NIK_COMPILE", "wait")


@pytest.fixture(autouse=True)
def _private_nik_home(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NIK_HOME", str(tmp_path_factory.mktemp("nik_home")))


class Killed(BaseException):
    """A simulated kill (tests/conftest.py ``kill_at``): not an ``Exception``, so no ``except Exception`` stops it."""


@pytest.fixture
def kill_at(monkeypatch):
    """``kill_at(k)``: from the ``k``-th filesystem operation on (0-based: mkdir, rename/replace, unlink, rmdir,
    fsync), every operation raises :class:`Killed` instead of running, as if the process had died there: nothing
    it would have done afterwards (its clean-up included) touches the disk. Returns a counter whose ``.count`` is
    the number of operations seen and ``.killed`` whether the kill happened; ``kill_at(None)`` only counts.
    Undone at the end of the test (or by calling ``.undo()``)."""
    import os
    import shutil

    patched = {name: getattr(os, name) for name in ("mkdir", "rename", "replace", "unlink", "rmdir", "fsync")}

    class Counter:
        count = 0
        killed = False

        def undo(self):
            for name, fn in patched.items():
                monkeypatch.setattr(os, name, fn)

    def arm(k):
        c = Counter()

        def wrap(fn):
            def op(*args, **kwargs):
                if c.killed or (k is not None and c.count >= k):
                    c.killed = True
                    raise Killed
                c.count += 1
                return fn(*args, **kwargs)

            return op

        for name, fn in patched.items():
            monkeypatch.setattr(os, name, wrap(fn))
        monkeypatch.setattr(shutil, "_use_fd_functions", False, raising=False)  # rmtree through os.unlink/rmdir
        return c

    return arm


@pytest.fixture
def xarm7_circle_37():
    """``(robot, q0, T)``: a 60-waypoint circle (radius 5 cm, orientation fixed) on xarm7 from ``q0``: path 37 of
    benchmarks/paths.py's xarm7 stream, where the waypoint chain reaches every pose but needs a step of 3.4 deg."""
    import math

    import torch

    import nik

    robot = nik.load_robot("xarm7")
    q0 = torch.tensor(
        [-3.7690758749285, 0.085624766732189, -1.3870104036149629, 1.5032070640616755, 3.346257153772674,
         2.1736983269078713, -2.187432020684759], dtype=torch.float64,
    )  # fmt: skip
    u = torch.tensor([-0.7748731305753529, -0.32139997072311666, -0.5443102886511807], dtype=torch.float64)
    v = torch.tensor([-0.5406809388525697, -0.1090946657939946, 0.8341237775395208], dtype=torch.float64)
    T0 = robot.fk(q0[None])[0]
    a = torch.linspace(0.0, 2 * math.pi, 60, dtype=torch.float64)
    T = T0.expand(60, 4, 4).clone()
    T[:, :3, 3] = T0[:3, 3] + 0.05 * u - 0.05 * (torch.cos(a)[:, None] * u + torch.sin(a)[:, None] * v)
    return robot, q0, T


@pytest.fixture
def panda_circle_chain():
    """``(robot, q0, T, model, run, q, its)``: an 8 cm panda circle through FK(``q0``) in a seeded plane (60
    waypoints, orientation fixed, closed), ``q0`` seeded in the middle 60 % of the ranges, and the waypoint chain's
    answer ``q: (60, 7)`` (with its ``run`` and iterations), which drifts: the loop it leaves is open."""
    import math

    import numpy as np
    import torch

    import nik
    from nik.ik.model import model_of
    from nik.paths import solve as P

    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot, checkpoint=None)
    gen = torch.Generator().manual_seed(3)
    lim = robot.limits
    mid = lim.mean(1)
    u01 = torch.rand(robot.dof, generator=gen, dtype=torch.float64)
    q0 = (mid + 0.6 * (lim[:, 0] + u01 * (lim[:, 1] - lim[:, 0]) - mid)).numpy()
    u, v = torch.linalg.qr(torch.randn(3, 2, generator=gen, dtype=torch.float64))[0].T.numpy()
    N = 60
    a = np.linspace(0.0, 2 * math.pi, N)[:, None]
    T = np.repeat(robot.fk(q0)[None], N, 0)
    T[:, :3, 3] += 0.08 * (u - np.cos(a) * u - np.sin(a) * v)  # an 8 cm circle through FK(q0), closed
    plan = P._plan(solver, 1e-4, math.radians(0.1), 0)
    model = model_of(robot, plan.lm_cfg)
    run = P._Run(plan, model, np.ascontiguousarray(T), q0, model.reach(T)[0])
    q, its, _ = P._chain_path(run)
    return robot, q0, T, model, run, q, its
