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
import threading

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


_lock = threading.Lock()
_open = 0  # calls inside threads_for, in every thread
_restore: int | None = None  # the count to put back when the last of them leaves (None: nothing was changed)


@contextlib.contextmanager
def threads_for(batch: int):
    """Context in which a call on ``batch`` targets runs with the thread count of the policy above.

    torch's thread count is process-wide, so calls that overlap (threads sharing a solver) share one setting: the
    first to enter sets it, the last to leave puts back what was there before, and none changes it while another
    runs (per call it was set and restored by each, and one thread's restore changed the count under another's
    work)."""
    global _open, _restore
    want = _threads if _threads is not None else (1 if batch < SMALL_BATCH else None)
    with _lock:
        if _open == 0:
            before = torch.get_num_threads()
            _restore = None
            if want is not None and want != before:
                torch.set_num_threads(want)
                _restore = before
        _open += 1
    try:
        yield
    finally:
        with _lock:
            _open -= 1
            if _open == 0 and _restore is not None:
                torch.set_num_threads(_restore)
                _restore = None
