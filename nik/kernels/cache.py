"""Where numba keeps the compiled kernels, decided before the first one is decorated.

numba's ``cache=True`` writes machine code next to the source (``nik/kernels/__pycache__``), so a
kernel is compiled once per machine and every later process loads it in milliseconds. A read-only
install (a system site-packages, a container image) has no writable ``__pycache__``; numba would
then fall back to its own user-wide folder and, when even that is not writable, refuse to
decorate. nik decides once, in this order:

1. ``NUMBA_CACHE_DIR`` is set: numba's setting is respected as it is (``"numba"``);
2. ``nik/kernels/__pycache__`` is writable: numba's default next to the source (``"package"``);
3. otherwise ``$XDG_CACHE_HOME/nik/numba`` (default ``~/.cache/nik/numba``), when it can be
   created and written (``"user"``);
4. otherwise no cache on disk: the kernels compile in every process (``"none"``; a one-time
   warning says so).

The folder of case 3 is handed to numba only while nik's own kernels are decorated (numba reads
``config.CACHE_DIR`` when a cached function is created), so other numba users in the same process
keep their own cache location. Nothing here imports numba.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CacheChoice", "cache_home", "choose_cache", "user_cache_folder", "writable"]

#: The kernels' source folder (numba's in-tree cache goes to its ``__pycache__``).
PACKAGE_DIR = Path(__file__).resolve().parent


@dataclass(frozen=True)
class CacheChoice:
    """Where compiled kernels are cached.

    Attributes:
        mode: ``"numba"`` (``NUMBA_CACHE_DIR`` set), ``"package"`` (next to the source), ``"user"``
            (``folder`` below the user's cache home) or ``"none"`` (nothing writable: no cache).
        folder: the folder the cache files go to (``None`` for ``"none"``).
    """

    mode: str
    folder: Path | None

    @property
    def cache(self) -> bool:
        """True when compiled code is kept on disk."""
        return self.mode != "none"


def writable(folder: Path) -> bool:
    """True when ``folder`` exists or can be created, and a file can be written in it (numba's own test)."""
    try:
        os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def cache_home(environ=None) -> Path:
    """nik's user cache folder: ``$XDG_CACHE_HOME/nik``, or ``~/.cache/nik`` when ``XDG_CACHE_HOME`` is unset or
    empty (compiled kernels in ``numba/``, parsed URDF arms in ``robots/``)."""
    environ = os.environ if environ is None else environ
    base = environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nik"


def user_cache_folder(environ=None) -> Path:
    """``$XDG_CACHE_HOME/nik/numba``, or ``~/.cache/nik/numba`` when ``XDG_CACHE_HOME`` is unset or empty."""
    return cache_home(environ) / "numba"


def choose_cache(*, environ=None, package_dir: Path = PACKAGE_DIR, is_writable=writable) -> CacheChoice:
    """The cache location by the rules of the module docstring (``environ`` defaults to ``os.environ``)."""
    environ = os.environ if environ is None else environ
    if environ.get("NUMBA_CACHE_DIR"):
        return CacheChoice("numba", Path(environ["NUMBA_CACHE_DIR"]))
    in_tree = Path(package_dir) / "__pycache__"
    if is_writable(in_tree):
        return CacheChoice("package", in_tree)
    user = user_cache_folder(environ)
    if is_writable(user):
        return CacheChoice("user", user)
    return CacheChoice("none", None)
