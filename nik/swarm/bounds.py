"""Keeping particles inside the joint limits, and angle wrapping.

Every function is batched over any leading shape; ``lo, hi, wrap`` are ``(n,)`` for the
``n`` joints being searched.

Revolute joints whose range is at least ``2 pi`` *wrap* (prismatic joints never do): a value past
a bound is moved by whole turns (``2 pi k``) to the physically identical angle inside the range,
and its velocity is kept.
The other joints follow the boundary strategy:

``reflect``
    mirror the overshoot back into the range (folded repeatedly for huge steps) and reverse
    the velocity component.
``clamp``
    clamp to the bound and set that velocity component to zero ("clamp with velocity reset").
``resample``
    draw the offending component uniformly in the range and set its velocity to zero.

The default is ``reflect``. ``benchmarks/refine.py --boundary`` compares the three strategies;
that comparison has not been run to completion yet, so the default is provisional.
"""

from __future__ import annotations

import math

import torch

__all__ = ["BOUNDARY_STRATEGIES", "apply_bounds", "wrap_mask", "wrap_into", "angle_diff"]

BOUNDARY_STRATEGIES = ("reflect", "clamp", "resample")
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


def angle_diff(a: torch.Tensor, b: torch.Tensor, wrap: torch.Tensor) -> torch.Tensor:
    """``a - b``, taken as the shortest signed angle (in ``[-pi, pi)``) on wrapping joints."""
    d = a - b
    if bool(wrap.any()):
        d = torch.where(wrap, torch.remainder(d + math.pi, TWO_PI) - math.pi, d)
    return d


def apply_bounds(
    x: torch.Tensor,
    v: torch.Tensor | None,
    lo: torch.Tensor,
    hi: torch.Tensor,
    wrap: torch.Tensor,
    strategy: str = "reflect",
    *,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Bring positions ``x: (..., n)`` into ``[lo, hi]`` and adjust velocities ``v`` (same shape, or None).

    Returns ``(x, v)``; every returned ``x`` satisfies ``lo <= x <= hi`` exactly.
    """
    if strategy not in BOUNDARY_STRATEGIES:
        raise ValueError(f"unknown boundary strategy {strategy!r}; expected one of {list(BOUNDARY_STRATEGIES)}")
    below, above = x < lo, x > hi
    out = (below | above) & ~wrap
    if strategy == "reflect":
        span = hi - lo
        # triangle-wave fold of x into [lo, hi]
        u = torch.remainder(x - lo, 2 * span)
        folded = lo + torch.where(u > span, 2 * span - u, u)
        xn = torch.where(out, folded, x)
        if v is not None:
            # odd number of reflections reverses the velocity
            flips = torch.floor((x - lo) / span)
            odd = torch.remainder(flips, 2) != 0
            v = torch.where(out & odd, -v, v)
    elif strategy == "clamp":
        xn = torch.where(out, torch.minimum(torch.maximum(x, lo), hi), x)
        if v is not None:
            v = torch.where(out, torch.zeros_like(v), v)
    else:
        r = torch.rand(x.shape, generator=generator, dtype=x.dtype, device=x.device)
        xn = torch.where(out, lo + r * (hi - lo), x)
        if v is not None:
            v = torch.where(out, torch.zeros_like(v), v)
    if bool(wrap.any()):
        xn = torch.where(wrap, wrap_into(xn, lo, hi), xn)
    xn = torch.minimum(torch.maximum(xn, lo), hi)  # guard against rounding at the bounds
    return xn, v
