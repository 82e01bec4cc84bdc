"""Callbacks: a wall-clock history of the validation metrics (for loss-versus-time plots), the
number of torch threads per process, a checkpoint at a stable path (``<default_root_dir>/last.ckpt``)
that the docs and scripts can name, one progress line per epoch for logs (:class:`EpochLines`), and the progress of a
DE / DE-BP run with a closing line of the phases it ran (:class:`DEProgress`)."""

from __future__ import annotations

import csv
import math
import os
import sys
import time
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import Checkpoint, ProgressBar

__all__ = ["DEProgress", "EpochLines", "History", "StableLastCheckpoint", "Threads", "stop_reason"]


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


def _duration(seconds: float) -> str:
    """``"12.3 s"`` below two minutes, else ``"8.6 min"``."""
    return f"{seconds:.1f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def stop_reason(trainer) -> str:
    """What ended the fit, in words: ``max_time``, ``max_steps``, ``max_epochs``, an interrupt, or ``the model``
    (it asked to stop, e.g. DE alone after its generations); checked in that order."""
    timer = next((cb for cb in trainer.callbacks if type(cb).__name__ == "Timer"), None)
    remaining = timer.time_remaining() if timer is not None else None
    if remaining is not None and remaining <= 0:
        return f"max_time ({_duration(timer._duration)})"
    if trainer.max_steps is not None and trainer.max_steps >= 0 and trainer.global_step >= trainer.max_steps:
        return f"max_steps ({trainer.max_steps})"
    if trainer.max_epochs is not None and trainer.max_epochs >= 0 and trainer.current_epoch >= trainer.max_epochs:
        return f"max_epochs ({trainer.max_epochs})"
    if trainer.interrupted:
        return "an interrupt"
    return "the model"


class DEProgress(L.Callback):
    """Progress of a DE or DE-BP run (:class:`nik.learn.modules.DEIK`) as lines on stderr, in ``nik train``'s style
    (``train.py: ...``): a DE generation scores every network on the whole batch (``data.batch_size: null``: the
    training split, 80,000 samples of ``data/kuka_kr_100k``: about 1 s a generation for paper C's 220 networks, some
    9 minutes before DE-BP reaches BP), and a bar that redraws once a second says little of that. ``train.py`` adds it
    to every DE run.

    Lines (``every_s`` None: only the last):

    - after the first generation: its time, the samples it scored, the expected time of the DE phase and whether
      ``max_time`` ends before BP would start;
    - every ``every_s`` seconds of DE: generation, time, best fitness, the DE time left;
    - when DE hands over to BP (DE-BP);
    - when the fit ends, always: the phases that ran (DE generations of how many, BP steps or that BP did not run) and
      what stopped the run (:func:`stop_reason`). The same text is kept in :attr:`summary`.

    Args:
        every_s: seconds between progress lines during DE; None: no progress lines.
        prefix: the start of each line.
        write: where lines go (default: stderr, flushed).
    """

    def __init__(self, every_s: float | None = 10.0, prefix: str = "train.py", write=None):
        super().__init__()
        if every_s is not None and not every_s >= 0:
            raise ValueError(f"DEProgress: every_s must be >= 0 or null, got {every_s!r}")
        self.every_s = every_s
        self.prefix = prefix
        self.write = write or (lambda line: print(line, file=sys.stderr, flush=True))
        self.summary: str | None = None
        self._reset()

    def _reset(self) -> None:
        self._t0 = time.perf_counter()
        self._first: tuple[int, float] | None = None  # (generation, seconds) at the first step's end
        self._last_line = 0.0
        self._told_first = False
        self._bp_from: tuple[int, float] | None = None  # (global step, seconds) when BP began
        self._de_s: float | None = None

    def _say(self, trainer, text: str) -> None:
        if trainer.is_global_zero:
            self.write(f"{self.prefix}: {text}")

    def on_train_start(self, trainer, pl_module) -> None:
        self._reset()
        state = getattr(pl_module, "de_state", None)
        self._g_prev = None if state is None else int(state.generation)  # a resumed run's generation

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        state = getattr(pl_module, "de_state", None)
        if state is None:
            return
        now = time.perf_counter() - self._t0
        h = pl_module.hparams
        total = h.generations
        g = int(state.generation)
        was_de, self._g_prev = self._g_prev is None or g != self._g_prev, g  # a DE step makes a generation
        if not was_de:  # a BP step
            if self._bp_from is None:
                self._bp_from = (int(trainer.global_step), now)
                if self._de_s is None:  # DE ended before this fit (a resumed run)
                    self._de_s = 0.0
            return
        if self._first is None:
            self._first = (g, now)
            return
        if self.every_s is None:
            if total is not None and g >= total and self._de_s is None:
                self._de_s = now
            return
        g0, t0 = self._first
        per = (now - t0) / max(1, g - g0)
        left = f", about {_duration(per * (total - g))} of DE left" if total is not None and g < total else ""
        if not self._told_first:
            self._told_first = True
            n = int(batch[0].shape[0])
            scored = min(n, h.fitness_samples) if h.fitness_samples else n
            plan = f"{total} generations (about {_duration(per * (total - g0))})" if total is not None else "no end set"
            then = f", then BP ({h.bp_optimizer}, lr {h.bp_lr:g})" if h.bp else ""
            line = (
                f"DE generation {g}{'' if total is None else f'/{total}'}: {per:.2f} s a generation "
                f"({h.pop_size} networks x {scored:,} samples); {plan}{then}"
            )
            timer = next((cb for cb in trainer.callbacks if type(cb).__name__ == "Timer"), None)
            budget = getattr(timer, "_duration", None)
            if h.bp and total is not None and budget is not None and now + per * (total - g) > budget:
                line += f"; max_time ({_duration(budget)}) ends before BP starts"
            self._say(trainer, line)
            self._last_line = now
        elif now - self._last_line >= self.every_s:
            self._say(
                trainer,
                f"DE generation {g}{'' if total is None else f'/{total}'}, {_duration(now)}, best fitness "
                f"{float(state.best_fitness):.5g}{left}",
            )
            self._last_line = now
        if total is not None and g >= total and self._de_s is None:
            self._de_s = now
            if h.bp:
                self._say(
                    trainer,
                    f"DE done: {g} generations in {_duration(now)}, best fitness {float(state.best_fitness):.5g}; "
                    f"BP ({h.bp_optimizer}, lr {h.bp_lr:g}) continues from the best individual",
                )

    def on_fit_end(self, trainer, pl_module) -> None:
        state = getattr(pl_module, "de_state", None)
        h = getattr(pl_module, "hparams", None)
        if h is None or "generations" not in h:
            return
        now = time.perf_counter() - self._t0
        total = h.generations
        g = 0 if state is None else int(state.generation)
        de = f"DE {g} of {total} generations" if total is not None else f"DE {g} generations"
        de_s = self._de_s if self._de_s is not None else (None if self._bp_from is not None else now)
        if de_s:  # 0 or None: DE ran in an earlier fit (resumed)
            de += f" ({_duration(de_s)})"
        if h.bp:
            if self._bp_from is not None:
                step0, t0 = self._bp_from
                steps = int(trainer.global_step) - step0 + 1
                bp = f"then BP {steps} step{'s' if steps != 1 else ''} ({_duration(now - (self._de_s or t0))})"
            else:
                bp = "BP did not run (DE had not finished its generations)"
            text = f"phases run: {de}; {bp}; stopped by {stop_reason(trainer)}"
        else:
            text = f"phases run: {de}; stopped by {stop_reason(trainer)}"
        self.summary = text
        self._say(trainer, text)
