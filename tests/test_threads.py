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
