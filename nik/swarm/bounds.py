"""Keeping particles inside the joint limits (angle wrapping itself is :mod:`nik.robots.joints`).

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

import torch

from nik.robots.joints import wrap_into

__all__ = ["BOUNDARY_STRATEGIES", "apply_bounds"]

BOUNDARY_STRATEGIES = ("reflect", "clamp", "resample")


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
