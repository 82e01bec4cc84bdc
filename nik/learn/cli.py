"""The LightningCLI behind ``python train.py``: ``fit | validate | test --config configs/train/<method>.yaml``."""

from __future__ import annotations

from pathlib import Path

__all__ = ["TRAIN_CONFIG_DIR", "METHODS", "cli_main", "method_config"]

#: The shipped training configs (``configs/train`` at the repository root), one per method.
TRAIN_CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "train"
METHODS = ("bp", "adam", "lbfgs", "de", "de_bp")


def method_config(method: str) -> Path:
    """Path of the shipped config of ``method`` (one of :data:`METHODS`)."""
    if method not in METHODS:
        raise ValueError(f"unknown training method {method!r}; expected one of {METHODS}")
    return TRAIN_CONFIG_DIR / f"{method}.yaml"


def cli_main(args: list[str] | None = None, *, run: bool = True):
    """Run the training CLI with ``args`` (``sys.argv[1:]`` when None); returns the ``LightningCLI``
    (``cli.model``, ``cli.datamodule``, ``cli.trainer``). Lightning is imported here, not at module import."""
    from lightning.pytorch.cli import LightningCLI

    from nik.learn.datamodule import IKDataModule
    from nik.learn.modules import IKModule

    return LightningCLI(
        IKModule,
        IKDataModule,
        subclass_mode_model=True,
        args=args,
        run=run,
        save_config_kwargs={"overwrite": True},
    )
