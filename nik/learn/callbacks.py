"""Callbacks: a wall-clock history of the validation metrics (for loss-versus-time plots)."""

from __future__ import annotations

import csv
from pathlib import Path

import lightning as L

__all__ = ["History"]


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
        if not self.filename or not self.rows or trainer.fast_dev_run:
            return
        path = Path(trainer.default_root_dir) / self.filename
        path.parent.mkdir(parents=True, exist_ok=True)
        keys = sorted({k for r in self.rows for k in r})
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(self.rows)
