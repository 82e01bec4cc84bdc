"""The one decorator of the kernels room: ``numba.njit(cache=True, nogil=True)`` with the cache folder of :mod:`.cache`.

Every kernel releases the GIL while it runs, so threads that share a solver run their kernels side by side;
that is safe because no kernel writes memory shared between calls: scratch is allocated inside the kernel
(``np.empty``, tens of nanoseconds) or passed in by the caller, who owns it (one per call or per thread).
"""

from __future__ import annotations

import contextlib
import warnings

import numba
from numba.core import config as _numba_config

from nik.kernels.cache import choose_cache, user_cache_folder

__all__ = ["CACHE", "kernel"]

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


def kernel(fn=None, *, fastmath=False):
    """``numba.njit`` in nopython mode, releasing the GIL (``nogil``), cached on disk when a folder allows it
    (see :mod:`.cache`).

    ``error_model="numpy"``: a division by zero gives inf/nan as numpy does instead of raising
    (no exception checks in the inner loops). ``fastmath``: numba's flags (e.g. ``{"reassoc"}`` lets
    long sums be vectorised, changing their rounding)."""
    if fn is None:
        return lambda f: kernel(f, fastmath=fastmath)
    with _cache_folder():
        return numba.njit(cache=CACHE.cache, nogil=True, error_model="numpy", fastmath=fastmath)(fn)
