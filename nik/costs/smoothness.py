"""Smoothness of a path: joint velocity and acceleration by differences (a preference), and a cap on each step
(a constraint).

Path terms: they act on a whole joint path ``q: (N, dof)`` (``path = True``), their residual flat ``(1, M)``:

- :func:`smoothness` (:class:`SmoothnessTerm`, a preference): velocity rows ``w_vel (q_i - q_{i-1})``,
  i = 1..N-1 (and ``q_0 - q_start`` when the path starts from given joints), and acceleration rows
  ``w_acc (q_{i+1} - 2 q_i + q_{i-1})``, per joint (radians per waypoint);
- :func:`step_cap` (:class:`StepCapTerm`, a constraint): rows ``max(0, |q_i - q_{i-1}| - max_step)`` per joint;
  check, per waypoint ``(N,)``: the largest joint motion into it is at most ``max_step``.

Differences are plain (no wrapping): a path's joints are continuous. The Jacobians are exact (difference
matrices times the identity of the joints; constant for velocity and acceleration). Two terms rather than one,
so that the second pass of :func:`nik.lm.problem.solve_problem` (the constraints alone) keeps the cap and drops the
preference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nik.costs.term import Term

__all__ = ["SmoothnessTerm", "StepCapTerm", "smoothness", "step_cap"]


def _steps(q: torch.Tensor, q_start: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(steps (S, dof), D (S, N))``: the steps into each waypoint and the difference matrix that makes them."""
    N = q.shape[0]
    eye = torch.eye(N, dtype=q.dtype, device=q.device)
    D = eye[1:] - eye[:-1]
    steps = q[1:] - q[:-1]
    if q_start is not None:
        D = torch.cat([eye[:1], D])
        steps = torch.cat([q[:1] - q_start.to(dtype=q.dtype, device=q.device), steps])
    return steps, D


@dataclass(eq=False)
class SmoothnessTerm(Term):
    """Velocity and acceleration rows of a path (module docstring); ``q_start: (dof,)`` or None."""

    q_start: torch.Tensor | None = None
    w_vel: float = 0.1
    w_acc: float = 0.1
    weight: float = 1.0
    name: str = "smoothness"
    hard: bool = False
    path: bool = True

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(r (1, M), J (1, M, N * dof))`` for the path ``q: (N, dof)``."""
        N, n = q.shape
        eye_n = torch.eye(n, dtype=q.dtype, device=q.device)
        steps, D = _steps(q, self.q_start)
        rows, jac = [self.w_vel * steps.reshape(-1)], [self.w_vel * torch.kron(D, eye_n)]
        if N >= 3:
            eye = torch.eye(N, dtype=q.dtype, device=q.device)
            A = eye[2:] - 2 * eye[1:-1] + eye[:-2]
            rows.append(self.w_acc * (A @ q).reshape(-1))
            jac.append(self.w_acc * torch.kron(A, eye_n))
        return torch.cat(rows)[None], torch.cat(jac)[None]

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(1, M)`` rows of the path ``q: (N, dof)`` (module docstring)."""
        return self.evaluate(q)[0]

    def check(self, q: torch.Tensor) -> torch.Tensor:
        return torch.ones(q.shape[0], dtype=torch.bool, device=q.device)


@dataclass(eq=False)
class StepCapTerm(Term):
    """The cap ``max_step`` (radians) on each joint's step along a path (module docstring)."""

    q_start: torch.Tensor | None = None
    max_step: float = math.radians(10.0)
    weight: float = 10.0
    name: str = "step_cap"
    path: bool = True

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(r (1, S * dof), J (1, S * dof, N * dof))`` for the path ``q: (N, dof)``."""
        n = q.shape[1]
        steps, D = _steps(q, self.q_start)
        flat = steps.reshape(-1)
        over = flat.abs() - self.max_step
        slope = torch.where(over > 0, torch.sign(flat), torch.zeros_like(flat))
        J = slope[:, None] * torch.kron(D, torch.eye(n, dtype=q.dtype, device=q.device))
        return over.clamp(min=0.0)[None], J[None]

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(1, S * dof)``: how far each joint's step exceeds ``max_step``."""
        return self.evaluate(q)[0]

    def check(self, q: torch.Tensor) -> torch.Tensor:
        """``(N,)`` bool: the largest joint motion into each waypoint is at most ``max_step`` (waypoint 0: True
        without ``q_start``)."""
        steps, _ = _steps(q, self.q_start)
        big = steps.abs().amax(-1)
        if self.q_start is not None:
            return big <= self.max_step
        return torch.cat([torch.ones(1, dtype=torch.bool, device=q.device), big <= self.max_step])

    def why(self) -> str:
        return f"{self.name}: a step above {math.degrees(self.max_step):.3g} deg"


def _q_start(q_start):
    return None if q_start is None else torch.as_tensor(q_start, dtype=torch.float64).reshape(-1)


def smoothness(q_start=None, *, w_vel: float = 0.1, w_acc: float = 0.1, weight: float = 1.0,
               name: str = "smoothness") -> SmoothnessTerm:  # fmt: skip
    """Velocity and acceleration rows of a joint path (a preference); ``q_start: (dof,)`` radians or None."""
    for key, v in (("w_vel", w_vel), ("w_acc", w_acc), ("weight", weight)):
        if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise ValueError(f"smoothness: {key} must be a number >= 0, got {v!r}")
    return SmoothnessTerm(_q_start(q_start), float(w_vel), float(w_acc), float(weight), name)


def step_cap(q_start=None, *, max_step: float = math.radians(10.0), weight: float = 10.0,
             name: str = "step_cap") -> StepCapTerm:  # fmt: skip
    """The cap on each joint's step along a path (a constraint); ``max_step`` radians > 0."""
    if not (isinstance(max_step, int | float) and math.isfinite(max_step) and max_step > 0):
        raise ValueError(f"step_cap: max_step must be a number > 0 (radians), got {max_step!r}")
    if not (isinstance(weight, int | float) and math.isfinite(weight) and weight > 0):
        raise ValueError(f"step_cap: weight must be a number > 0, got {weight!r}")
    return StepCapTerm(_q_start(q_start), float(max_step), float(weight), name)
