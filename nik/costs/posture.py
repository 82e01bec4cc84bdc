"""A rest posture: a preference for joints near ``q_rest``, traded against nothing that must hold.

Residual ``r = q - q_rest`` ``(B, dof)`` (radians; on wrapping joints the shortest angle, so a full turn away is
no distance; metres on prismatic joints), weighted by ``weight`` (the pipeline's ``rest_weight``, default 0.1).
A preference: its check always passes (``hard = False``). The LM of :mod:`nik.lm.problem` minimises it together
with the constraints, then, where a constraint was given up for it, solves the constraints alone from there
(:func:`nik.lm.problem.solve_problem`): the posture never costs the goal. ``q_rest="mid"`` is the middle of each
joint's range (0 for a joint without finite limits), as :func:`nik.ik.goals.rest_target` reads it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nik.costs.term import Term
from nik.robots.joints import angle_diff, wrap_mask

__all__ = ["PostureTerm", "posture", "rest_joints"]


def rest_joints(robot, q_rest) -> torch.Tensor:
    """``q_rest`` (``"mid"``, ``(dof,)`` or ``(B, dof)``) as a float64 tensor ``(1 | B, dof)``; one line if bad."""
    if isinstance(q_rest, str):
        if q_rest != "mid":
            raise ValueError(f"q_rest: expected 'mid' or joint angles, got {q_rest!r}")
        lim = robot.limits.double()
        mid = 0.5 * (lim[:, 0] + lim[:, 1])
        return torch.where(torch.isfinite(mid), mid, torch.zeros_like(mid))[None]
    r = torch.as_tensor(q_rest.detach().cpu() if isinstance(q_rest, torch.Tensor) else q_rest, dtype=torch.float64)
    if r.shape[-1:] != (robot.dof,) or r.dim() > 2:
        raise ValueError(f"q_rest: expected 'mid', ({robot.dof},) or (B, {robot.dof}) radians, got {tuple(r.shape)}")
    if not bool(torch.isfinite(r).all()):
        raise ValueError("q_rest: NaN or inf joint angles")
    return r.reshape(-1, robot.dof)


@dataclass(eq=False)
class PostureTerm(Term):
    """``weight * (q - q_rest)`` (module docstring); ``q_rest: (1 | B, dof)`` float64."""

    robot: object
    q_rest: torch.Tensor
    weight: float = 0.1
    name: str = "posture"
    hard: bool = False

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, dof)``: ``q - q_rest`` (the shortest angle on wrapping joints)."""
        wrap = wrap_mask(self.robot.limits, prismatic=self.robot.prismatic_or_none).to(q.device)
        return angle_diff(q, self.q_rest.to(dtype=q.dtype, device=q.device), wrap)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        eye = torch.eye(q.shape[1], dtype=q.dtype, device=q.device)
        return self.residual(q), eye.expand(q.shape[0], -1, -1)


def posture(robot, q_rest="mid", *, weight: float = 0.1, name: str = "posture") -> PostureTerm:
    """A preference for ``q_rest`` (``"mid"``, ``(dof,)`` or ``(B, dof)`` radians) with ``weight``."""
    if not (isinstance(weight, int | float) and math.isfinite(weight) and weight >= 0):
        raise ValueError(f"posture: weight must be a number >= 0, got {weight!r}")
    return PostureTerm(robot, rest_joints(robot, q_rest), float(weight), name)
