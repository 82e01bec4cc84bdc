"""How many torch intra-op threads nik's work uses.

Measured (issue 10, ``benchmarks/results/peers.md``): on a busy 2-core machine, two intra-op
threads made the same LM solve 5-60x slower than one (panda, 1,000 targets: 0.37 -> 21.9 ms per
target; 10,000 targets: 0.20 -> 1.15 ms), because OpenMP threads wait on each other when the cores
are taken; and each op on a batch of a few thousand targets is too short to gain from threads
anyway. So, unless :func:`set_threads` was called, nik runs a call on fewer than
:data:`SMALL_BATCH` targets with one thread and leaves larger ones to torch's setting
(``torch.get_num_threads()``). :func:`set_threads` fixes the count for every call.
"""

from __future__ import annotations

import contextlib

import torch

__all__ = ["SMALL_BATCH", "get_threads", "set_threads", "threads_for"]

#: Below this many targets a call runs on one thread unless :func:`set_threads` chose a count.
SMALL_BATCH = 100_000

_threads: int | None = None


def set_threads(n: int | None) -> None:
    """Use ``n`` torch intra-op threads for nik's work (``n >= 1``); None restores the default
    policy (one thread below :data:`SMALL_BATCH` targets, torch's setting above). Also sets
    ``torch.set_num_threads(n)``."""
    global _threads
    if n is None:
        _threads = None
        return
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"set_threads: expected a positive integer number of threads, got {n!r}")
    _threads = n
    torch.set_num_threads(n)


def get_threads() -> int | None:
    """The count chosen by :func:`set_threads`, or None (default policy)."""
    return _threads


@contextlib.contextmanager
def threads_for(batch: int):
    """Context in which a call on ``batch`` targets runs with the thread count of the policy above."""
    want = _threads if _threads is not None else (1 if batch < SMALL_BATCH else None)
    before = torch.get_num_threads()
    if want is None or want == before:
        yield
        return
    torch.set_num_threads(want)
    try:
        yield
    finally:
        torch.set_num_threads(before)
