"""The first compile of the kernels, off the caller's path: a line that says so, a background thread, a torch answer.

On an empty cache (a fresh install, a new ``NUMBA_CACHE_DIR``) the compiled solve of one arm's plan
(:func:`nik.kernels.driver.solve`: every stage it might run, LM, closed forms, the network's forward pass, ...) is
compiled before it can answer: 72.7 s of CPU for panda on a shared two-core machine (``benchmarks/cold_start.py``,
``benchmarks/results/cold_start.txt``; 27.6 s wall on the machine of issue 37), about 128 s each for four processes
that start together on two cores. Once compiled, it is cached for every later process of the machine.

What nik does instead (the compiled backend, ``backend="auto"``; :mod:`nik.ik.backends.compiled`):

1. :func:`ready` tells, without compiling, whether a kernel's machine code for the argument types of a call is loaded
   or in the cache (numba's cache index, read as numba reads it);
2. where it is not, :func:`announce` writes one line on stderr, at most once per process (the first compile of a nik
   kernel, here or on the caller's thread): ``nik: compiling kernels for this machine (...; answers meanwhile come from
   the torch backend, ...)``; the call is answered by the torch backend
   (the same stages in torch: same tolerances, same success contract) while :data:`BUSY` is set, which keeps the torch
   path off every kernel not yet loaded (one-pose LM, compiled FK): numba compiles under one process-wide lock, so a
   kernel compiled on the caller's thread would wait for the background compile;
3. :func:`compile_later` then compiles the kernel for those types in a thread (once per signature); the calls that
   come meanwhile are answered by torch again, and the first after it is done by the compiled kernel.

Why a thread and not only a smaller compile: the stages of a plan share most of the compile (the LM and its
multi-start variant, about 40 %), so compiling only what a call needs saves at most the closed form of a network arm
(about 13 %); the torch backend answers one pose in about 0.1 s without compiling anything (3.0 s of CPU from the
process start to panda's first answer, ``import torch`` included, against 72.7 s). numba's compiler is mostly Python,
so it shares the GIL with the caller's thread: the answers given while it runs took 2.9x as long (median 288 ms
against 99 ms a pose, wall, on that busy machine), but they come, and the compile goes on meanwhile (its LLVM passes
release the GIL).

A process that ends while the compile runs does not wait for the rest of it: at interpreter exit (before Python joins
its threads) the compile stops at the end of the kernel in progress, which is saved first, so the next process loads
every cached kernel finished and compiles only the rest (:func:`_stop_at_exit`, :class:`_StopListener`). The wait is
the rest of one kernel's own compile, its callees done: 0.3-2.7 s (wall, panda, a shared two-core machine at load 9)
after one pose or 20 s of answers; the longest step, the driver's own machine code after all its callees, took 23 s
wall at load 3 (about 8 s of CPU), the most a process can wait. The thread is not a daemon: a daemon thread would be
cut off inside an LLVM pass (GIL released) while the interpreter tears down, which can crash the exit. Each cache
entry is complete or absent, never half-written (:func:`nik.kernels._jit._saves_whole`: the data file is written
under a temporary name and renamed before the index that names it; an entry that fails to load is compiled again).

``NIK_COMPILE=wait`` (or ``backend="compiled"``) compiles on the caller's thread (benchmarks and tests that
need the compiled answers from the first call); the line (without the torch part) is then written on the first
compile of a nik kernel in the process (:func:`nik.kernels._jit.kernel` listens for numba's compile events).
This module imports numba only inside its functions (``busy``-style checks on the torch path stay light).
"""

from __future__ import annotations

import os
import sys
import threading
import time

__all__ = [
    "BUSY",
    "ESTIMATE",
    "Stopped",
    "THREAD_NAME",
    "announce",
    "announced",
    "begin",
    "compile_later",
    "defer_allowed",
    "failed",
    "ready",
    "wait",
]

#: True from the moment a call is answered by torch because a kernel is not compiled yet, until every background
#: compile has ended: the torch path then keeps off the kernels (one-pose LM, compiled FK).
BUSY = False

#: How long the first compile of one arm's compiled solve takes, as the line on stderr quotes it: 27.6 s wall for
#: panda on the machine of issue 37, 62-71 s of CPU on a shared two-core machine (``benchmarks/cold_start.py``,
#: ``benchmarks/results/cold_start.txt``).
ESTIMATE = "30-70"

#: The name of the background compile threads.
THREAD_NAME = "nik-compile"

_LOCK = threading.Lock()
_THREADS: dict = {}  # signature key -> running Thread
_FAILED: dict = {}  # signature key -> the exception of a failed background compile
_ANNOUNCED = False
_STOP = threading.Event()  # set at interpreter exit: the background compile stops after the kernel in progress
_LOCAL = threading.local()  # .compiling: True on nik's compile threads
_HOOKED = False  # the exit hook and the numba listener are installed (once, with the first thread)


def defer_allowed() -> bool:
    """False when ``NIK_COMPILE=wait`` asks for the kernels to be compiled on the caller's thread."""
    return os.environ.get("NIK_COMPILE", "background").strip().lower() != "wait"


def _signature(dispatcher, args) -> tuple:
    return tuple(dispatcher.typeof_pyval(a) for a in args)


def ready(dispatcher, args) -> bool:
    """True when ``dispatcher`` (a nik kernel) runs ``args`` without compiling: its machine code for their numba types
    is loaded, or numba's cache holds it (fresh: same source, same CPU; the call then loads it in milliseconds). True
    also where this cannot be told (no numba cache, ``NUMBA_DISABLE_JIT``, another numba's private API: the call then
    compiles as it always did) or where a background compile for these types failed (the call then raises its error).
    """
    cache = getattr(dispatcher, "_cache", None)
    try:
        sig = _signature(dispatcher, args)
        if sig in dispatcher.overloads or (id(dispatcher), sig) in _FAILED:
            return True
        index = cache._cache_file._load_index()
        key = cache._index_key(sig, dispatcher.targetctx.codegen())
    except Exception:  # noqa: BLE001 - not numba's cache as nik knows it: compile it here
        return True
    return key in index


def cold(dispatcher) -> bool:
    """True when ``dispatcher`` has compiled nothing on this machine: no machine code loaded and an empty (or stale,
    or absent) cache index; False where this cannot be told. A cheap first look, before the arguments of a call
    exist (their types are what :func:`ready` asks about)."""
    try:
        return not dispatcher.overloads and not dispatcher._cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - not numba's cache as nik knows it
        return False


def announce(background: bool) -> None:
    """Write the line that kernels are being compiled, at most once per process (the first compile of a nik kernel):
    what is compiled, that it happens once per machine, and that later calls are faster; with ``background`` (the
    compile runs on nik's thread) that the torch backend answers meanwhile. Kernels that compile later in the same
    process (another arm, a bounded goal, obstacles, a path) are covered by this one line."""
    global _ANNOUNCED
    if _ANNOUNCED:
        return
    _ANNOUNCED = True
    if background:
        how = "in the background; answers meanwhile come from the torch backend, later calls are faster"
    else:
        how = "in all, as each is first used; later calls and processes are faster"
    print(
        f"nik: compiling kernels for this machine (the solvers' numba code, once per machine: ~{ESTIMATE} s {how})",
        file=sys.stderr,
        flush=True,
    )


def begin() -> None:
    """Set :data:`BUSY` (a call is about to be answered by torch; :func:`compile_later` follows)."""
    global BUSY
    BUSY = True


def announced() -> bool:
    """True once the line of :func:`announce` has been written in this process."""
    return _ANNOUNCED


def end_if_idle() -> None:
    """Clear :data:`BUSY` unless a background compile runs (a call that set it took another path)."""
    global BUSY
    with _LOCK:
        BUSY = bool(_THREADS)


def compile_later(dispatcher, args, also=()) -> threading.Thread | None:
    """Compile ``dispatcher`` for the numba types of ``args`` in a background thread (one per signature; a second
    call while it runs returns the same thread), then each ``(dispatcher, args)`` of ``also`` (small kernels the
    compiled call needs too). Sets :data:`BUSY` until every such thread has ended. Returns the thread (None where the
    types cannot be told: nothing is started)."""
    global BUSY
    try:
        jobs = [(d, _signature(d, a)) for d, a in ((dispatcher, args), *also)]
    except Exception:  # noqa: BLE001 - the caller's foreground call compiles
        with _LOCK:
            BUSY = bool(_THREADS)
        return None
    key = (id(dispatcher), jobs[0][1])
    with _LOCK:
        running = _THREADS.get(key)
        if running is not None:
            return running
        BUSY = True
        _hook()
        thread = threading.Thread(target=_compile, args=(jobs, key), name=THREAD_NAME, daemon=False)
        _THREADS[key] = thread
    thread.start()
    return thread


class Stopped(BaseException):
    """Raised on a background compile thread at interpreter exit, after the kernel in progress was saved (a
    ``BaseException``: numba's typing catches ``Exception`` subclasses and would go on compiling)."""


def _stop_at_exit() -> None:
    """Run by Python at exit before it joins the threads: the background compiles stop (module docstring)."""
    _STOP.set()


def _hook() -> None:
    """Install, once, :func:`_stop_at_exit` (``threading._register_atexit``: run before non-daemon threads are joined;
    where this Python has none, the process waits for the compile as it did) and :class:`_StopListener`."""
    global _HOOKED
    if _HOOKED:
        return
    _HOOKED = True
    register = getattr(threading, "_register_atexit", None)
    if register is None:
        return
    try:
        register(_stop_at_exit)
    except RuntimeError:  # the interpreter is already shutting down
        _STOP.set()
    from numba.core import event

    event.register("numba:compile", _listener())


def _listener():
    """The :class:`_StopListener` (defined here: numba is imported only once a compile is started)."""
    from numba.core import event

    class _StopListener(event.Listener):
        """On nik's compile threads, once :data:`_STOP` is set: at the start of a kernel's compile, stop; at its end,
        save the kernel to the cache (numba would save it right after this event) and stop. Elsewhere: nothing."""

        def on_start(self, ev):
            if _STOP.is_set() and getattr(_LOCAL, "compiling", False):
                raise Stopped

        def on_end(self, ev):
            if not (_STOP.is_set() and getattr(_LOCAL, "compiling", False)):
                return
            data = ev.data or {}
            dispatcher, args, ret = data.get("dispatcher"), data.get("args"), data.get("return_type")
            try:
                cres = dispatcher.overloads.get(tuple(args))  # None where this compile failed or was stopped
                if cres is not None:
                    dispatcher._cache.save_overload(tuple(args) if ret is None else ret(*args), cres)
            except Exception:  # noqa: BLE001 - not saved: compiled again by the next process
                pass
            raise Stopped

    return _StopListener()


def _compile(jobs, key) -> None:
    global BUSY
    start = time.perf_counter()
    _LOCAL.compiling = True
    stopped = False
    try:
        for dispatcher, sig in jobs:
            if _STOP.is_set():
                raise Stopped
            dispatcher.compile(sig)
    except Stopped:
        stopped = True  # at exit: what was compiled is cached, the next process compiles the rest
    except Exception as err:  # noqa: BLE001 - recorded: the foreground call raises it again, with its context
        _FAILED[key] = err
        print(f"nik: compiling kernels failed ({type(err).__name__}); the next call compiles again", file=sys.stderr)
    finally:
        with _LOCK:
            _THREADS.pop(key, None)
            BUSY = bool(_THREADS)
        if os.environ.get("NIK_COMPILE_VERBOSE"):
            what = "stopped at exit after" if stopped else "compiled in"
            print(f"nik: kernels {what} {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)


def failed() -> dict:
    """The background compiles that failed: ``(id(dispatcher), numba signature)`` -> exception."""
    return dict(_FAILED)


def wait(timeout: float | None = None) -> bool:
    """Wait until every background compile has ended (at most ``timeout`` seconds); True when none runs."""
    deadline = None if timeout is None else time.monotonic() + timeout
    while True:
        with _LOCK:
            threads = list(_THREADS.values())
        if not threads:
            return True
        for t in threads:
            t.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
        if deadline is not None and time.monotonic() >= deadline:
            with _LOCK:
                return not _THREADS
