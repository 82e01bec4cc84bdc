"""The one decorator of the kernels room: ``numba.njit(cache=True, nogil=True)`` with the cache folder of :mod:`.cache`.

Every kernel releases the GIL while it runs, so threads that share a solver run their kernels side by side;
that is safe because no kernel writes memory shared between calls: scratch is allocated inside the kernel
(``np.empty``, tens of nanoseconds) or passed in by the caller, who owns it (one per call or per thread).

Loading a cached kernel: numba first "refreshes" its CPU target, i.e. imports every implementation it could
ever compile (numpy's linear algebra and with it ``scipy.linalg``, the random generators, typed containers,
...): 0.5-1 s in a fresh process, though a kernel loaded from the cache needs none of it, only numba's
runtime (NRT, a few milliseconds). nik's kernels therefore load their cached code without that refresh
(:func:`_cached_loads_without_refresh`); anything that really compiles (a cache miss, a new signature) still
goes through numba's compiler, which refreshes the target itself. Should a load fail that way, or should
numba's private cache API differ from the one expected, numba's own load runs.

The cached code also records an "environment" per compiled function (the globals of the module that defined it,
its constants), and numba rebuilds one by importing that module: for a kernel that allocates an array, numba's
``numba.np.arrayobj`` and with it its unicode, hashing and charseq implementations (25-30 ms of CPU in a fresh
process). Compiled nopython code never reads those globals (only object mode does), so while nik loads a kernel,
the environment of a numba module not yet imported keeps the module's name in place of its globals
(:func:`_rebuild_env_without_import`); a module already imported gives its globals as numba's own rebuild does.

The first compile of a nik kernel in a process (a cache miss: nothing is compiled on a warm cache) writes one line on
stderr, ``nik: compiling kernels for this machine (...)``, at most once per process
(:func:`nik.kernels.background.announce`; numba's ``numba:compile`` event, :class:`_Announce`), so that tens of silent
seconds say what they are.

Building blocks (functions whose name starts with ``_``) are compiled into the kernels that call them, whose
cached code holds them, so they are not cached on their own: each cached function costs numba a probe of
its cache folder when it is decorated (a temporary file) and an index to read when it is first called.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import sys
import threading
import warnings
from pathlib import Path

import numba
from numba.core import config as _numba_config
from numba.core import event as _numba_event

from nik.kernels import background
from nik.kernels.cache import choose_cache, user_cache_folder

__all__ = ["CACHE", "entry_point", "kernel"]

#: The cache location chosen once, when the kernels room is first imported.
CACHE = choose_cache()

if not CACHE.cache:
    warnings.warn(
        "nik.kernels: no writable folder for numba's cache (neither the package folder nor "
        f"{user_cache_folder()}); the compiled kernels are built in every process (seconds). "
        "Set NUMBA_CACHE_DIR to a writable folder to keep them.",
        RuntimeWarning,
        stacklevel=2,
    )


class _Announce(_numba_event.Listener):
    """On the start of a compile of a nik kernel (numba's ``numba:compile`` event: a cache miss), the line of
    :func:`nik.kernels.background.announce`, once per process; a compile on nik's background thread was announced
    with its torch part already."""

    def on_start(self, event):
        if not background.announced():
            dispatcher = (event.data or {}).get("dispatcher")
            module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
            if module.startswith("nik."):
                background.announce(threading.current_thread().name == background.THREAD_NAME)

    def on_end(self, event):
        pass


_numba_event.register("numba:compile", _Announce())


@contextlib.contextmanager
def _cache_folder():
    """Hand the user cache folder to numba while a kernel is decorated (numba reads ``config.CACHE_DIR``
    when it creates a cached function); restore numba's own value afterwards."""
    if CACHE.mode != "user":
        yield
        return
    before = _numba_config.CACHE_DIR
    _numba_config.CACHE_DIR = str(CACHE.folder)
    try:
        yield
    finally:
        _numba_config.CACHE_DIR = before


def _cached_loads_without_refresh(dispatcher):
    """``dispatcher`` (a cached numba function) loads its cached machine code without refreshing the target
    (see the module docstring); numba's own load where that fails; a miss (compiled again, and saved anew) where
    that fails too: an entry that cannot be read never stops a call. Returns ``dispatcher``."""
    cache = getattr(dispatcher, "_cache", None)
    if not all(
        hasattr(cache, name) for name in ("load_overload", "_load_overload", "_guard_against_spurious_io_errors")
    ):
        return dispatcher  # not numba's FunctionCache as nik knows it (no cache, or another numba)
    numba_load = cache.load_overload

    def load_overload(sig, target_context):
        found = None
        try:
            from numba.core import environment
            from numba.core.runtime import nrt

            nrt.rtsys.initialize(target_context)  # what the loaded code calls (allocation, reference counts)
            rebuild = environment._rebuild_env  # what the pickled environments call (by name) as they are read
            environment._rebuild_env = _rebuild_env_without_import
            try:
                with cache._guard_against_spurious_io_errors():
                    found = cache._load_overload(sig, target_context)
            finally:
                environment._rebuild_env = rebuild
        except Exception:  # noqa: BLE001 - numba's own load below decides
            found = None
        if found is not None:
            return found
        try:
            return numba_load(sig, target_context)
        except Exception:  # noqa: BLE001 - an entry that cannot be read (truncated, corrupt): compiled again
            return None

    cache.load_overload = load_overload
    return dispatcher


def _rebuild_env_without_import(modname, consts, env_name):
    """numba's ``environment._rebuild_env`` (read from a cache file), except that a numba module not yet imported
    is not imported for its globals: the environment gets ``{"__name__": modname}`` (see the module docstring)."""
    from numba.core import environment

    env = environment.lookup_environment(env_name)
    if env is not None:
        return env
    module = sys.modules.get(modname)
    if module is None and not modname.startswith("numba."):
        module = importlib.import_module(modname)
    env = environment.Environment(module.__dict__ if module is not None else {"__name__": modname})
    env.consts[:] = consts
    env.env_name = env_name
    environment.Environment._memo[env_name] = env
    return env


def kernel(fn=None, *, fastmath=False, inline="never"):
    """``numba.njit`` in nopython mode, releasing the GIL (``nogil``), cached on disk when a folder allows it
    (see :mod:`.cache`) unless ``fn`` is a building block (its name starts with ``_``: see the module docstring).

    ``error_model="numpy"``: a division by zero gives inf/nan as numpy does instead of raising
    (no exception checks in the inner loops). ``fastmath``: numba's flags (e.g. ``{"reassoc"}`` lets
    long sums be vectorised, changing their rounding). ``inline="always"``: numba inlines the building block into
    each caller before typing, so that a caller's constant arguments (a loop count) are known when it compiles."""
    if fn is None:
        return lambda f: kernel(f, fastmath=fastmath, inline=inline)
    cache = CACHE.cache and not fn.__name__.startswith("_")
    with _cache_folder():
        dispatcher = numba.njit(cache=cache, nogil=True, error_model="numpy", fastmath=fastmath, inline=inline)(fn)
    return _cached_loads_without_refresh(_stamped(dispatcher))


def _room_stamp() -> tuple:
    """``(name, mtime_ns, size)`` of every source file of the kernels room: the stamp each kernel's cache is
    checked against. numba's own stamp is the defining file's alone, and a kernel's machine code holds the
    building blocks it calls from other files, so a changed block (a checkout, an edit) would leave its callers'
    cached code stale; with the room's stamp, any change to a kernel source recompiles every cached kernel."""
    files = sorted(Path(__file__).resolve().parent.glob("*.py"))
    return tuple((f.name, f.stat().st_mtime_ns, f.stat().st_size) for f in files)


#: The kernels room's stamp, read once when the room is imported (20-odd ``stat`` calls).
ROOM_STAMP = _room_stamp()


def _stamped(dispatcher):
    """``dispatcher`` with its cache index checked against :data:`ROOM_STAMP` (numba's private ``_cache_file``;
    left alone where this numba has none) and its entries saved whole (:func:`_saves_whole`). Returns
    ``dispatcher``."""
    index = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if index is not None and hasattr(index, "_source_stamp"):
        index._source_stamp = ROOM_STAMP
        _saves_whole(index)
    return dispatcher


def _saves_whole(index) -> None:
    """numba's cache ``index`` (an ``IndexDataCacheFile``) saves an entry data first, index last, under a data file
    name of its own key. numba writes each file under a temporary name and renames it, but the index first: a
    process killed between the two writes (an exit, a kill) would leave an index that names a data file not written,
    or one left by an older source or by another signature (numba numbers the files from 1 again when the index is
    stale), whose machine code would then be loaded for this one. Here the index names only a data file already
    complete, and one written for its key (a name from a hash of the key, so two processes that save two signatures
    at once cannot swap each other's files). Left alone where numba's private API differs."""
    if not all(hasattr(index, name) for name in ("save", "_load_index", "_save_index", "_save_data", "_data_name")):
        return

    numba_save = index.save

    def save(key, data):
        try:
            overloads = index._load_index()
        except Exception:  # noqa: BLE001 - an unreadable index: started again
            overloads = {}
        try:
            name = index._data_name(int(hashlib.sha256(repr(key).encode()).hexdigest()[:12], 16))
        except Exception:  # noqa: BLE001 - another numba's file names: its own save
            return numba_save(key, data)
        index._save_data(name, data)  # complete (temporary name, renamed) before an index names it
        if overloads.get(key) != name:
            overloads[key] = name
            index._save_index(overloads)

    index.save = save


def entry_point(dispatcher, *args):
    """The compiled function behind ``dispatcher`` for the numba types of ``args`` (loaded or compiled now), or
    ``dispatcher`` itself where numba offers none (``NUMBA_DISABLE_JIT``, another numba).

    Calling it skips numba's dispatch (the type of every argument, the choice of an overload: 0.15 us of the 0.6 us
    a call with four arguments costs), for calls of a microsecond. The caller must pass arguments of
    exactly these types (an array of another dtype, number of dimensions or layout is read as if it were one of
    these): a hot path that builds its arguments itself, e.g. :meth:`nik.Robot.fk` of one configuration."""
    try:
        found = dispatcher.compile(tuple(dispatcher.typeof_pyval(arg) for arg in args))
    except Exception:  # noqa: BLE001 - numba's dispatch still answers
        return dispatcher
    return found if callable(found) else dispatcher
