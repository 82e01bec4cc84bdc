"""nik.set_threads and the thread policy for small batches."""

from __future__ import annotations

import pytest
import torch

import nik
from nik.threads import SMALL_BATCH, get_threads, set_threads, threads_for


def test_small_batches_run_on_one_thread_by_default_and_set_threads_overrides():
    before = torch.get_num_threads()
    try:
        set_threads(None)
        with threads_for(1):
            assert torch.get_num_threads() == 1
        assert torch.get_num_threads() == before
        with threads_for(SMALL_BATCH):
            assert torch.get_num_threads() == before
        nik.set_threads(2)
        assert get_threads() == 2 and torch.get_num_threads() == 2
        with threads_for(1):
            assert torch.get_num_threads() == 2
    finally:
        set_threads(None)
        torch.set_num_threads(before)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_set_threads_refuses_what_is_not_a_positive_integer(bad):
    with pytest.raises(ValueError, match="set_threads"):
        set_threads(bad)


def test_overlapping_calls_from_threads_set_the_count_once_and_restore_it_once(monkeypatch):
    """Two threads inside ``threads_for`` at once (a shared solver): the first sets the count, the last restores it,
    and nobody changes it while the other is still inside (per call, each set and restored it under the other)."""
    import threading

    import nik.threads as nt

    calls = []
    monkeypatch.setattr(torch, "set_num_threads", lambda n: calls.append(n))
    monkeypatch.setattr(torch, "get_num_threads", lambda: calls[-1] if calls else 4)
    set_threads(None)
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def a():
        with nt.threads_for(1):
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def b():
        a_in.wait(5)
        with nt.threads_for(1):
            b_in.set()
            a_out.wait(5)
            seen["inside_b_after_a_left"] = torch.get_num_threads()

    threads = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert seen["inside_b_after_a_left"] == 1  # A's exit left B's count alone
    assert calls == [1, 4]  # set once, restored once


def test_threads_sharing_a_torch_solver_get_the_answers_of_one_thread():
    import threading

    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot, backend="torch")
    g = torch.Generator().manual_seed(5)
    batches = [robot.fk(robot.sample(8, generator=g, dtype=torch.float64)) for _ in range(4)]
    alone = [solver.solve(T, seed=i).q for i, T in enumerate(batches)]
    before = torch.get_num_threads()
    out = [None] * 4

    def work(i):
        out[i] = solver.solve(batches[i], seed=i).q

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    for a, b in zip(alone, out, strict=True):
        torch.testing.assert_close(a, b, atol=1e-9, rtol=0)
    assert torch.get_num_threads() == before
