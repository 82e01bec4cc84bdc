"""Training: losses, differential evolution (state + pure step), batched population evaluation,
and the Lightning modules / data module behind ``train.py``.

The Lightning parts (``modules``, ``datamodule``, ``callbacks``) are imported on first use so that
``import nik.learn`` for DE or the losses does not pull in Lightning.

The room may import every room below it (kinematics, poses, robots, data, nets, analytic, lm, swarm, ik);
only evaluation and cli import it.
"""

from __future__ import annotations

import importlib

# every name is imported on first use, so that the CLI's parsers (nik.learn.cli) import no torch
_LAZY = {
    **dict.fromkeys(("DECfg", "DEState", "de_ask", "de_init", "de_minimize", "de_step", "de_tell"), "nik.learn.de"),
    **dict.fromkeys(("evaluate", "joint_mse", "pose_loss"), "nik.learn.losses"),
    **dict.fromkeys(
        ("flat_params", "init_population", "population_fitness", "population_raw", "set_flat_params"),
        "nik.learn.population",
    ),
    **dict.fromkeys(("IKModule", "IKModuleCfg", "GradientIK", "GradientIKCfg", "DEIK", "DEIKCfg"), "nik.learn.modules"),
    "IKDataModule": "nik.learn.datamodule",
    "DEProgress": "nik.learn.callbacks",
    "History": "nik.learn.callbacks",
    "StableLastCheckpoint": "nik.learn.callbacks",
    "Threads": "nik.learn.callbacks",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'nik.learn' has no attribute {name!r}")
