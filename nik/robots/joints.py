"""Joint-range arithmetic: which joints turn without end, and angles taken modulo whole turns.

Revolute joints whose range is at least ``2 pi`` *wrap* (prismatic joints never do): a value past a
bound is the same physical angle as one moved by whole turns (``2 pi k``) into the range. The
Levenberg-Marquardt solvers (:mod:`nik.lm`) and the swarms (:mod:`nik.swarm.bounds`) share these.
Every function is batched over any leading shape; ``lo, hi, wrap`` are ``(n,)`` for ``n`` joints.
"""

from __future__ import annotations

import math

import torch

__all__ = ["TWO_PI", "angle_diff", "turns_toward", "wrap_into", "wrap_mask"]

TWO_PI = 2.0 * math.pi


def wrap_mask(limits: torch.Tensor, *, tol: float = 1e-6, prismatic: torch.Tensor | None = None) -> torch.Tensor:
    """``(n,)`` bool: revolute joints whose range ``hi - lo`` (``limits: (n, 2)``, float64) is at least ``2 pi``.

    ``prismatic: (n,)`` bool marks joints that never wrap (a slide of 7 m is not a turn); None: all revolute.
    """
    wrap = (limits[:, 1] - limits[:, 0]) >= TWO_PI - tol
    if prismatic is not None:
        wrap = wrap & ~torch.as_tensor(prismatic, dtype=torch.bool, device=wrap.device)
    return wrap


def wrap_into(x: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Shift ``x`` by whole turns into ``[lo, hi]`` (valid when ``hi - lo >= 2 pi``); clamped against rounding."""
    up = torch.ceil((lo - x) / TWO_PI).clamp_min(0)
    down = torch.ceil((x - hi) / TWO_PI).clamp_min(0)
    x = x + TWO_PI * (up - down)
    return torch.minimum(torch.maximum(x, lo), hi)


def turns_toward(x: torch.Tensor, target: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor, wrap: torch.Tensor):
    """``x: (..., n)`` with each wrapping joint (``wrap: (n,)``) moved by whole turns, inside ``[lo, hi]``, as near
    ``target`` as it goes; the other joints as they are."""
    y = x + TWO_PI * torch.round((target - x) / TWO_PI)
    y = torch.where(y > hi, y - TWO_PI, torch.where(y < lo, y + TWO_PI, y))
    return torch.where(wrap, torch.minimum(torch.maximum(y, lo), hi), x)


def angle_diff(a: torch.Tensor, b: torch.Tensor, wrap: torch.Tensor) -> torch.Tensor:
    """``a - b``, taken as the shortest signed angle (in ``[-pi, pi)``) on wrapping joints."""
    d = a - b
    if bool(wrap.any()):
        d = torch.where(wrap, torch.remainder(d + math.pi, TWO_PI) - math.pi, d)
    return d
