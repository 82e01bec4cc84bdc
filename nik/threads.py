"""How many torch intra-op threads nik's work uses.

Measured (issue 10): on a busy machine two or more intra-op threads on small batches can stall
(the same eager call took 0.05 s or 1.2 s), and a batch below a few thousand targets gains little
from threads anyway, since each tensor op is short. So, unless :func:`set_threads` was called,
nik runs a call on fewer than :data:`SMALL_BATCH` targets with one thread and leaves larger ones
to torch's setting (``torch.get_num_threads()``). :func:`set_threads` fixes the count for every call.
"""

from __future__ import annotations

import contextlib

import torch

__all__ = ["SMALL_BATCH", "get_threads", "set_threads", "threads_for"]

#: Below this many targets a call runs on one thread unless :func:`set_threads` chose a count.
SMALL_BATCH = 4096

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
