"""Joint rate limits: one velocity and one acceleration bound per joint, checked once where they enter.

A robot's :attr:`~nik.robots.model.Robot.vel_limits` (rad/s; m/s for prismatic joints) and
:attr:`~nik.robots.model.Robot.acc_limits` (rad/s^2; m/s^2) are each a ``(dof,)`` float64 tensor of positive
finite numbers, or None where unknown (a URDF gives no acceleration; a file may give neither). They bound the
magnitude symmetrically (``|qd_j| <= vel_limits[j]``), as URDF's ``<limit velocity>`` does.

Every way in (URDF, YAML robot files, ``robot.vel_limits = ...``, a per-call ``vel_limits=``) goes through
:func:`check_rates`, so a zero, negative, NaN or infinite value, or a list of the wrong length, is one
``ValueError`` line naming the joint. These limits play no part in the kinematics: they stay out of
:attr:`Robot.definition_hash <nik.robots.model.Robot.definition_hash>` (networks and datasets stay valid).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

__all__ = ["check_rates", "rate_units"]


def rate_units(prismatic: Sequence[bool], *, order: int = 1) -> list[str]:
    """The SI unit of each joint's rate: ``rad/s`` / ``m/s`` (``order=1``) or ``rad/s^2`` / ``m/s^2`` (2)."""
    tail = "/s" if order == 1 else "/s^2"
    return [("m" if p else "rad") + tail for p in prismatic]


def check_rates(
    values,
    dof: int,
    *,
    what: str = "vel_limits",
    names: Sequence[str] | None = None,
    where: str = "",
) -> torch.Tensor | None:
    """``values`` (a sequence, array or tensor of ``dof`` numbers, or None) as a ``(dof,)`` float64 CPU tensor.

    None stays None. Raises ValueError, one line, naming ``where`` (a robot or file), ``what`` and the first bad
    joint (by name when ``names`` is given): not ``dof`` values, not numbers, or a value that is not a finite
    number > 0.
    """
    if values is None:
        return None
    head = f"{where}: " if where else ""
    if isinstance(values, torch.Tensor):
        values = values.detach().cpu().numpy()
    if isinstance(values, (str, bytes)) or np.ndim(values) != 1:
        raise ValueError(f"{head}{what}: expected a list of {dof} numbers (one per joint), got {values!r}")
    if len(values) != dof:
        raise ValueError(f"{head}{what}: expected {dof} values (one per joint), got {len(values)}")
    out = np.empty(dof)
    for j, v in enumerate(values):
        label = names[j] if names is not None else f"joint {j}"
        try:
            if isinstance(v, (bool, np.bool_)):
                raise TypeError
            x = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{head}{what}: {label}: expected a number, got {v!r}") from None
        if not (math.isfinite(x) and x > 0):
            raise ValueError(f"{head}{what}: {label}: must be a finite number > 0, got {x!r}")
        out[j] = x
    return torch.from_numpy(out)
