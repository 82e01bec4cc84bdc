"""The LightningCLI behind ``python train.py``: ``fit | validate | test --config configs/train/<method>.yaml``.

Every run writes ``<trainer.default_root_dir>/last.ckpt`` (see :class:`nik.learn.callbacks.StableLastCheckpoint`);
the shipped configs set ``default_root_dir`` to ``runs/<method>``. The default logger is a ``CSVLogger`` in
``default_root_dir``. A ``--ckpt_path`` that is not a loadable nik checkpoint is refused with a
:class:`nik.CheckpointError` before training starts.
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings
from pathlib import Path

__all__ = ["TRAIN_CONFIG_DIR", "METHODS", "NET_NAMES", "build_parser", "cli_main", "method_config"]

#: The shipped training configs (``configs/train`` at the repository root), one per method.
TRAIN_CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "train"
METHODS = ("bp", "adam", "lbfgs", "de", "de_bp")
#: The networks ``nik compare`` trains (:data:`nik.learn.compare.NETS`): paper C's 6-8-6 net and the default.
NET_NAMES = ("paper", "default")
#: ``--ckpt_path`` values that Lightning resolves itself (not files).
_SPECIAL_CKPT = ("last", "best", "hpc", "registry")


def build_parser(ap: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """The arguments of ``nik compare`` (:func:`nik.learn.compare.compare`); here, so that parsing imports no torch.

    Every option's help states its default. The values are checked by :func:`nik.learn.compare.check_args`
    before any work (``nik compare`` refuses a bad value in one line, exit status 2)."""
    ap = ap or argparse.ArgumentParser(description="Compare bp, adam, lbfgs, de, de_bp on one dataset and budget")
    ap.add_argument(
        "--data", type=Path, default=Path("data/kuka_kr_100k"), help="dataset folder (default data/kuka_kr_100k)"
    )
    ap.add_argument(
        "--budget",
        type=float,
        default=None,
        metavar="SECONDS",
        help="wall-clock seconds of training per run, kept inside the steps (a DE generation or an L-BFGS step is "
        "abandoned when the time is up); default 60 when --steps is not given, else none. Timed runs differ "
        "from one repetition to the next",
    )
    ap.add_argument(
        "--steps",
        type=int,
        default=None,
        metavar="N",
        help="training steps per run (an optimiser step on a batch, an L-BFGS step of up to 20 iterations, a DE "
        "generation, a BP step of de_bp): the reproducible budget, the same seed gives the same table; "
        "default none. With --budget too, whichever ends first",
    )
    ap.add_argument(
        "--seeds", type=int, nargs="+", default=[0, 1, 2], metavar="SEED", help="seeds, one run each (default 0 1 2)"
    )
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS, help="methods (default all five)")
    ap.add_argument(
        "--nets",
        nargs="+",
        default=list(NET_NAMES),
        choices=list(NET_NAMES),
        help="paper: paper C's 6-8-6 tanh net; default: nik.nets.DEFAULT, 3 x 256 SiLU (default both)",
    )
    ap.add_argument(
        "--de-samples",
        type=int,
        default=1000,
        metavar="N",
        help="de, de_bp: each DE generation scores every individual on the same random N-sample subset of the "
        "training split (parents re-scored on it); 0: the whole split, as paper C (default 1000)",
    )
    ap.add_argument(
        "--de-generations",
        type=int,
        default=500,
        metavar="N",
        help="de, de_bp: DE generations (de_bp then continues by BP; de stops) (default 500, paper C)",
    )
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="PREFIX",
        help="writes PREFIX.md (table and verdict), PREFIX.csv (one row per run), PREFIX_history.csv and "
        "PREFIX.png (validation loss against time) (default runs/compare/DATA/compare, DATA the dataset "
        "folder's name)",
    )
    ap.add_argument(
        "--runs-dir",
        type=Path,
        default=None,
        metavar="RUNS",
        help="folder of the runs' checkpoints, RUNS/NET/METHOD/seedSEED/ (default runs/compare/DATA)",
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads (default 1: on a shared CPU, 2 OpenMP threads stall on each other)",
    )
    return ap


def method_config(method: str) -> Path:
    """Path of the shipped config of ``method`` (one of :data:`METHODS`)."""
    if method not in METHODS:
        raise ValueError(f"unknown training method {method!r}; expected one of {METHODS}")
    return TRAIN_CONFIG_DIR / f"{method}.yaml"


class _DropTips(logging.Filter):
    """Drops Lightning's advertising tips ("💡 Tip: ... try installing litlogger / litmodels")."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith("💡 Tip")


def _quiet_lightning() -> None:
    """Silence what nik's use of Lightning does not need to show. Narrow on purpose:

    - the litlogger / litmodels tips (Lightning's ``rank_zero_info`` advertisements);
    - torch 2.13's ``FutureWarning`` that ``LeafSpec`` is deprecated, raised inside Lightning 2.6's own
      ``lightning/pytorch/utilities/_pytree.py`` (a dependency's use of torch, not nik's).
    """
    for name in ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero"):
        log = logging.getLogger(name)
        if not any(isinstance(f, _DropTips) for f in log.filters):
            log.addFilter(_DropTips())
    warnings.filterwarnings(
        "ignore", message=r"`isinstance\(treespec, LeafSpec\)` is deprecated", category=FutureWarning
    )


def check_resume_checkpoint(path: str | Path) -> None:
    """Refuse a ``--ckpt_path`` that is missing or not a loadable nik checkpoint (one line, no traceback
    from deep inside Lightning). Raises :class:`FileNotFoundError` or :class:`nik.CheckpointError`."""
    from nik.nets import load_checkpoint

    load_checkpoint(path)  # weights_only=True: no code from the file runs


def _ckpt_path_arg(args: list[str]) -> str | None:
    """The value of ``--ckpt_path`` in ``args`` (``--ckpt_path X`` or ``--ckpt_path=X``), else None."""
    for i, a in enumerate(args):
        if a == "--ckpt_path" and i + 1 < len(args):
            return args[i + 1]
        if a.startswith("--ckpt_path="):
            return a.split("=", 1)[1]
    return None


def _class_path(callback) -> str:
    """The class path of a callback as the config holds it (a Namespace before instantiation, or an object)."""
    path = getattr(callback, "class_path", None)
    return str(path) if path is not None else f"{type(callback).__module__}.{type(callback).__name__}"


def _cli_class(command: str | None = None):
    from jsonargparse import Namespace
    from lightning.pytorch.cli import LightningCLI

    class NikCLI(LightningCLI):
        def before_instantiate_classes(self) -> None:
            cfg = self.config[self.subcommand] if self.subcommand else self.config
            trainer = cfg["trainer"]
            root = trainer.get("default_root_dir") or "."
            if trainer.get("logger") in (None, True):  # Lightning's default, said explicitly: CSV, no tensorboard
                trainer["logger"] = Namespace(
                    class_path="lightning.pytorch.loggers.CSVLogger", init_args=Namespace(save_dir=str(root))
                )
            if trainer.get("enable_checkpointing") is not False:  # every run keeps <default_root_dir>/last.ckpt
                trainer["callbacks"] = [
                    *(trainer.get("callbacks") or []),
                    Namespace(class_path="nik.learn.callbacks.StableLastCheckpoint", init_args=Namespace()),
                ]
            if trainer.get("enable_progress_bar") is not False and not sys.stdout.isatty():
                callbacks = trainer.get("callbacks") or []
                if not any("ProgressBar" in _class_path(cb) for cb in callbacks):  # bars would fill the log
                    trainer["callbacks"] = [
                        *callbacks,
                        Namespace(class_path="nik.learn.callbacks.EpochLines", init_args=Namespace()),
                    ]
            ckpt = cfg.get("ckpt_path")
            if ckpt is not None and str(ckpt) not in _SPECIAL_CKPT:
                check_resume_checkpoint(ckpt)

        def instantiate_classes(self) -> None:
            super().instantiate_classes()
            self.model.run_command = command  # what really ran, recorded in the checkpoints

    return NikCLI


def cli_main(args: list[str] | None = None, *, run: bool = True):
    """Run the training CLI with ``args`` (``sys.argv[1:]`` when None); returns the ``LightningCLI``
    (``cli.model``, ``cli.datamodule``, ``cli.trainer``). Lightning is imported here, not at module import.

    Raises:
        CheckpointError, FileNotFoundError: ``--ckpt_path`` names a file that is missing or not a loadable
            nik checkpoint (checked with ``weights_only=True`` before Lightning reads it).
    """
    import shlex
    import sys

    from nik.learn.datamodule import IKDataModule
    from nik.learn.modules import IKModule

    argv = sys.argv[1:] if args is None else [str(a) for a in args]
    command = shlex.join(["python", "train.py", *argv])
    ckpt = _ckpt_path_arg(argv)
    if ckpt is not None and ckpt not in _SPECIAL_CKPT:
        check_resume_checkpoint(ckpt)
    _quiet_lightning()
    return _cli_class(command)(
        IKModule,
        IKDataModule,
        subclass_mode_model=True,
        args=args,
        run=run,
        save_config_kwargs={"overwrite": True},
    )


def main(args: list[str] | None = None) -> int:
    """``train.py``'s entry point: :func:`cli_main`, with nik's input errors (a bad ``--ckpt_path``, a
    missing or corrupt dataset) printed as one line ``train.py: error: ...`` and exit status 2."""
    import sys

    from nik.errors import NikError

    try:
        cli_main(args)
    except (NikError, FileNotFoundError) as err:
        print(f"train.py: error: {err}", file=sys.stderr)
        return 2
    return 0
