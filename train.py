"""Train an IK network: ``python train.py fit --config configs/train/<method>.yaml [--data.path data/NAME] ...``.

Methods (one config each): ``bp``, ``adam``, ``lbfgs``, ``de``, ``de_bp``. LightningCLI supplies
checkpoints, resume (``--ckpt_path``), loggers, progress bars, seeding (``seed_everything``) and the
accelerator choice; see ``docs/training.md``. Every run keeps ``<default_root_dir>/last.ckpt``
(``runs/<method>/last.ckpt`` with the shipped configs); ``python -m nik.nets.export runs/<method>/last.ckpt`` makes
it a network file that installs (``nik networks install``) and loads by path like ``nik train``'s. The CLI itself is
:func:`nik.learn.cli.cli_main`.
"""

from __future__ import annotations

import sys

from nik.learn.cli import cli_main, main

__all__ = ["cli_main", "main"]

if __name__ == "__main__":
    sys.exit(main())
