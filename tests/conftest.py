"""Shared test set-up: every test sees an empty user network folder (``NIK_HOME``), never the real one."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _private_nik_home(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NIK_HOME", str(tmp_path_factory.mktemp("nik_home")))
