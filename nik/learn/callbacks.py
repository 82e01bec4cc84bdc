"""Callbacks: a wall-clock history of the validation metrics (for loss-versus-time plots), and the
number of torch threads per process."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import lightning as L
import torch

__all__ = ["History", "Threads"]


class Threads(L.Callback):
    """Sets torch's intra-op threads for the fit (restored afterwards).

    Args:
        threads: threads per process; ``None``: on CPU with several processes on this machine, the
            cores divided among them (at least 1), else torch's own choice is left alone.

    Why: torch's thread pool slows down several-fold when it has more threads than free cores. A DE
    generation on 12,500 samples took 279 ms with 1 thread and 1,466 ms with 2 threads on a 2-core
    machine that other processes kept busy (``benchmarks/de_train_overhead.py``); ``N`` DDP ranks with
    all cores each oversubscribe the machine ``N`` times.
    """

    def __init__(self, threads: int | None = None):
        super().__init__()
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
            raise ValueError(f"Threads: threads must be a positive integer or null, got {threads!r}")
        self.threads = threads
        self._before: int | None = None

    def chosen(self, trainer) -> int | None:
        """The thread count for ``trainer``'s processes (None: leave torch's setting)."""
        if self.threads is not None:
            return self.threads
        local = int(getattr(trainer, "num_devices", 1) or 1)
        if local > 1 and type(trainer.accelerator).__name__ == "CPUAccelerator":
            return max(1, (os.cpu_count() or 1) // local)
        return None

    def setup(self, trainer, pl_module, stage: str) -> None:
        n = self.chosen(trainer)
        if n is not None:
            self._before = torch.get_num_threads()
            torch.set_num_threads(n)

    def teardown(self, trainer, pl_module, stage: str) -> None:
        if self._before is not None:
            torch.set_num_threads(self._before)
            self._before = None


class History(L.Callback):
    """Records ``trainer.callback_metrics`` after every validation, with ``wall_s``, ``epoch`` and ``step``.

    Args:
        filename: if set, the rows are also written as CSV to ``<trainer.default_root_dir>/<filename>``
            when the fit ends.

    ``rows`` holds one dict per validation (floats).
    """

    def __init__(self, filename: str | None = "history.csv"):
        super().__init__()
        self.filename = filename
        self.rows: list[dict] = []

    def on_validation_end(self, trainer, pl_module) -> None:
        if trainer.sanity_checking:
            return
        row = {"epoch": trainer.current_epoch, "step": trainer.global_step}
        row.update({k: float(v) for k, v in trainer.callback_metrics.items() if v.numel() == 1})
        self.rows.append(row)

    def on_fit_end(self, trainer, pl_module) -> None:
        if not self.filename or not self.rows or trainer.fast_dev_run or not trainer.is_global_zero:
            return  # under DDP the metrics are reduced over ranks: rank 0 writes the one file
        path = Path(trainer.default_root_dir) / self.filename
        path.parent.mkdir(parents=True, exist_ok=True)
        keys = sorted({k for r in self.rows for k in r})
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(self.rows)
