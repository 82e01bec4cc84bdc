"""The joint limits: a box every answer stays inside.

Residual ``r = q - clamp(q, lo, hi)`` ``(B, dof)`` (the excess beyond a limit, 0 inside); check: every joint inside
its range (:meth:`nik.Robot.within_limits`). The LM of :mod:`nik.lm.problem` keeps the limits as a box rather
than as rows: each step is brought inside by :meth:`LimitsTerm.project` (wrapping joints, whose range is at least a
full turn, move by whole turns; the others are clamped), and a joint held at a limit that the step pushes further
out is left out of the step (the active-set rule of the compiled LM), so the residual stays 0 there and the term is
the verdict. The compiled LM (:mod:`nik.kernels.lm`) applies the same box in its ``_bounds``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.costs.term import Term
from nik.robots.joints import wrap_into, wrap_mask

__all__ = ["LimitsTerm", "limits"]


@dataclass(eq=False)
class LimitsTerm(Term):
    """The joint limits of ``robot`` (module docstring)."""

    robot: object
    weight: float = 1.0
    name: str = "limits"

    def bounds(self, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(lo, hi, wrap)``, each ``(dof,)``, in the dtype and device of ``like`` (limits rounded inward)."""
        lo, hi = self.robot.limits_as(like)
        wrap = wrap_mask(self.robot.limits, prismatic=self.robot.prismatic_or_none).to(like.device)
        return lo, hi, wrap

    def project(self, q: torch.Tensor) -> torch.Tensor:
        """``q: (..., dof)`` inside the limits: wrapping joints by whole turns, the others clamped."""
        lo, hi, wrap = self.bounds(q)
        return torch.where(wrap, wrap_into(q, lo, hi), torch.minimum(torch.maximum(q, lo), hi))

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, dof)``: how far each joint lies beyond its range (0 inside)."""
        lo, hi, _ = self.bounds(q)
        return q - torch.minimum(torch.maximum(q, lo), hi)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lo, hi, _ = self.bounds(q)
        out = ((q < lo) | (q > hi)).to(q.dtype)
        return self.residual(q), torch.diag_embed(out)

    def check(self, q: torch.Tensor) -> torch.Tensor:
        return self.robot.within_limits(q)

    def why(self) -> str:
        return f"{self.name}: a joint beyond its range"


def limits(robot, *, weight: float = 1.0, name: str = "limits") -> LimitsTerm:
    """The joint limits of ``robot`` as a term (a box for the LM, a verdict for the answer)."""
    return LimitsTerm(robot, float(weight), name)
