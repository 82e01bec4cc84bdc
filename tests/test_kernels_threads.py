"""Threads sharing one solver: the compiled kernels release the GIL and keep no scratch shared between calls."""

from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
import pytest
import torch

import nik
from nik.ik import backends
from nik.kernels import chain


def _run_in_threads(jobs):
    """Run each ``jobs[i]()`` in its own thread, all released at once; their results in order (a failure in a
    thread is raised here)."""
    barrier = threading.Barrier(len(jobs))
    results, errors = [None] * len(jobs), []

    def work(i):
        try:
            barrier.wait()
            results[i] = jobs[i]()
        except BaseException as err:  # noqa: BLE001 - handed to the test
            errors.append(err)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return results


def _runs_during(kernel_call) -> int:
    """How often this thread ran (stamps at least 0.1 ms apart) in the middle half of one ``kernel_call()`` made in
    another thread (near its ends, a held GIL may still be handed over between the clock and the kernel, late
    when the OS is slow to wake the other thread)."""
    started, done, call = threading.Event(), threading.Event(), []

    def compute():  # one kernel call, timed
        started.set()
        t0 = time.perf_counter()
        kernel_call()
        call.extend((t0, time.perf_counter()))
        done.set()

    thread = threading.Thread(target=compute)
    thread.start()
    started.wait()
    stamps = [-math.inf]
    while not done.is_set():
        now = time.perf_counter()
        if now - stamps[-1] >= 1e-4:
            stamps.append(now)
    thread.join()
    margin = max(0.25 * (call[1] - call[0]), 4 * sys.getswitchinterval())
    return sum(call[0] + margin < t < call[1] - margin for t in stamps)


def test_a_kernel_lets_other_python_threads_run_while_it_computes():
    robot = nik.load_robot("panda")
    G, joints = robot.chain_arrays()
    q = robot.sample(300_000, generator=torch.Generator().manual_seed(0), dtype=torch.float64).numpy()
    T = np.empty((q.shape[0], 4, 4))
    chain.fk_batch(G, joints, q[:1], T[:1])  # loaded before the measurement
    # a kernel holding the GIL keeps this thread from running at all in the middle of the call, every time; the
    # OS of a loaded machine may too, now and then: three tries
    runs = [_runs_during(lambda: chain.fk_batch(G, joints, q, T)) for _ in range(3)]
    assert max(runs) > 0, "this thread never ran while the kernel computed: it holds the GIL"


@pytest.mark.parametrize("name", ["panda", "kuka_kr"])  # the network's hypotheses, then LM; the closed form, then LM
def test_four_threads_sharing_one_solver_get_the_answers_of_the_same_calls_made_alone(name, monkeypatch):
    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot)
    calls = []
    for i in range(4):  # each thread: its own targets, seed, and (in two of them) q_near
        q = robot.sample(25, generator=torch.Generator().manual_seed(10 + i), dtype=torch.float64)
        near = q + 0.05 if i % 2 else None
        calls.append({"T_target": robot.fk(q), "seed": i, "q_near": near})
    alone = [solver.solve(**kw) for kw in calls]

    def refuse(*args, **kwargs):
        raise AssertionError("the torch backend ran: not the compiled one")

    monkeypatch.setattr(backends, "torch_backend", refuse)
    jobs = [lambda kw=kw: [solver.solve(**kw) for _ in range(3)] for kw in calls]
    for ref, answers in zip(alone, _run_in_threads(jobs), strict=True):
        for res in answers:
            assert res.source == ref.source
            for field in ("q", "pos_err", "rot_err", "success", "iterations", "reachable"):
                torch.testing.assert_close(getattr(res, field), getattr(ref, field), atol=0, rtol=0)
    assert all(bool(r.success.all()) for r in alone)
