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
