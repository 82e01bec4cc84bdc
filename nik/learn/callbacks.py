"""Callbacks: a wall-clock history of the validation metrics (for loss-versus-time plots), the
number of torch threads per process, a checkpoint at a stable path (``<default_root_dir>/last.ckpt``)
that the docs and scripts can name, and one progress line per epoch for logs (:class:`EpochLines`)."""

from __future__ import annotations

import csv
import math
import os
import time
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import Checkpoint, ProgressBar

__all__ = ["EpochLines", "History", "StableLastCheckpoint", "Threads"]


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
            when the fit ends (written to a temporary name, then renamed).

    ``rows`` holds one dict per validation (floats).
    """

    def __init__(self, filename: str | None = "history.csv"):
        super().__init__()
        self.filename = filename
        self.rows: list[dict] = []

    def state_dict(self) -> dict:
        """The rows so far (saved in checkpoints, so a resumed run's history and curve cover the whole run)."""
        return {"rows": [dict(r) for r in self.rows]}

    def load_state_dict(self, state_dict: dict) -> None:
        self.rows = [dict(r) for r in state_dict.get("rows", [])]

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
        tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
        keys = sorted({k for r in self.rows for k in r})
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(self.rows)
        os.replace(tmp, path)


class StableLastCheckpoint(Checkpoint):
    """Keeps ``<trainer.default_root_dir>/<filename>`` (default ``last.ckpt``) up to date: a full Lightning
    checkpoint (resumable with ``--ckpt_path``, loadable by :func:`nik.nets.load_checkpoint`) written at
    the end of every training epoch that ran a validation, and when training ends, so every run of
    ``train.py`` has one path that does not depend on the logger's ``version_N`` folders.

    The file is written to a hidden temporary name in the same folder and renamed over the old one, so a
    reader never sees a half-written checkpoint and an interrupted save leaves the previous one intact.
    ``train.py`` adds this callback to every run; the best checkpoints by ``val_loss`` stay with
    Lightning's ``ModelCheckpoint`` (``<default_root_dir>/<logger dirs>/checkpoints/``).

    It is a :class:`~lightning.pytorch.callbacks.Checkpoint`, so Lightning runs it after the other callbacks
    (``ModelCheckpoint`` included), and it saves at the epoch's end, after the validation: the file holds
    their state after that validation, and resuming from it neither repeats the epoch nor a save.
    """

    def __init__(self, filename: str = "last.ckpt"):
        super().__init__()
        if not filename or Path(filename).name != filename:
            raise ValueError(f"StableLastCheckpoint: filename must be a plain file name, got {filename!r}")
        self.filename = filename
        self._saved_step: int | None = None
        self._validated = False

    def path(self, trainer) -> Path:
        """Where the checkpoint goes: ``<trainer.default_root_dir>/<filename>``."""
        return Path(trainer.default_root_dir) / self.filename

    def _save(self, trainer) -> None:
        if trainer.fast_dev_run or trainer.sanity_checking or self._saved_step == trainer.global_step:
            return
        path = self.path(trainer)
        tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
        # full state, for resume; every rank calls it (collective), only global rank 0 writes
        trainer.save_checkpoint(tmp, weights_only=False)
        if trainer.is_global_zero:
            os.replace(tmp, path)
        self._saved_step = trainer.global_step

    def on_validation_end(self, trainer, pl_module) -> None:
        if not trainer.sanity_checking:
            self._validated = True

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        if self._validated:
            self._validated = False
            self._save(trainer)

    def on_train_end(self, trainer, pl_module) -> None:
        self._save(trainer)


class EpochLines(ProgressBar):
    """Progress as one line per training epoch (and one per ``validate`` / ``test`` run) on stdout, in place of
    Lightning's redrawn tqdm bars, which fill a redirected log (``train.py ... > log``) with megabytes.

    ``train.py`` uses it when stdout is not a terminal and the run has a progress bar and no progress bar
    callback of its own. A line: ``epoch 3/100  step 42  12.3 s  train_loss 0.0123  val_loss 0.0456 ...``
    (every scalar in ``trainer.callback_metrics``; the losses first).
    """

    def __init__(self):
        super().__init__()
        self._enabled = True
        self._t0 = time.perf_counter()

    def disable(self) -> None:
        self._enabled = False

    def enable(self) -> None:
        self._enabled = True

    @staticmethod
    def _metrics(trainer) -> str:
        items = {k: float(v) for k, v in trainer.callback_metrics.items() if getattr(v, "numel", lambda: 1)() == 1}
        keys = sorted(items, key=lambda k: (not k.endswith("loss"), k))
        return "  ".join(f"{k} {items[k]:.4g}" for k in keys)

    def _say(self, trainer, head: str) -> None:
        if not self._enabled or not trainer.is_global_zero:
            return
        metrics = self._metrics(trainer)
        print(f"{head}  {time.perf_counter() - self._t0:.1f} s" + (f"  {metrics}" if metrics else ""), flush=True)

    def on_train_start(self, trainer, pl_module) -> None:
        self._t0 = time.perf_counter()

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        total = trainer.max_epochs
        of = f"/{total}" if total is not None and 0 < total < math.inf else ""
        self._say(trainer, f"epoch {trainer.current_epoch + 1}{of}  step {trainer.global_step}")

    @staticmethod
    def _validate_run(trainer) -> bool:
        """``train.py validate`` (not the validations inside a fit)."""
        return getattr(trainer.state.fn, "value", trainer.state.fn) == "validate"

    def on_validation_start(self, trainer, pl_module) -> None:
        if self._validate_run(trainer):
            self._t0 = time.perf_counter()

    def on_validation_end(self, trainer, pl_module) -> None:
        if self._validate_run(trainer):
            self._say(trainer, "validation")

    def on_test_start(self, trainer, pl_module) -> None:
        self._t0 = time.perf_counter()

    def on_test_end(self, trainer, pl_module) -> None:
        self._say(trainer, "test")
