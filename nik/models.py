"""The documented face of the IK networks (``nik.models.load_pretrained`` and friends); they live in :mod:`nik.nets`."""

from nik.nets import (
    ACTIVATIONS,
    DEFAULT,
    OUTPUTS,
    PAPER_C,
    REPRESENTATIONS,
    IKNet,
    checkpoint_extra,
    load_checkpoint,
    load_pretrained,
    pretrained_robots,
    save_checkpoint,
)

__all__ = [
    "ACTIVATIONS",
    "DEFAULT",
    "OUTPUTS",
    "PAPER_C",
    "REPRESENTATIONS",
    "IKNet",
    "checkpoint_extra",
    "load_checkpoint",
    "load_pretrained",
    "pretrained_robots",
    "save_checkpoint",
]
