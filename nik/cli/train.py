"""``nik compare``: argument parsing only; the work is in :mod:`nik.learn.compare`.

Training itself is ``python train.py fit --config configs/train/<method>.yaml`` (LightningCLI).
"""

from __future__ import annotations

__all__ = ["register"]


def register(sub) -> None:
    from nik.learn.compare import build_parser

    p = sub.add_parser(
        "compare",
        help="compare the training methods (bp, adam, lbfgs, de, de_bp) on one dataset and time budget",
        description="Train every method on the same dataset and split with the same wall-clock budget and "
        "several seeds, for paper C's 6-8-6 net and the realistic default; write a Markdown table, CSVs "
        "and a plot of validation loss against wall-clock time.",
    )
    build_parser(p)
    p.set_defaults(func=_cmd_compare)


def _cmd_compare(args) -> int:
    from nik.learn.compare import compare

    compare(args)
    return 0
