"""Manipulability: a preference for configurations far from singularities (Yoshikawa's measure).

``w(q) = sqrt(det(J J^T))``, ``J = robot.jacobian(q): (6, dof)`` (base frame, linear rows in metres, angular rows in
radians, unweighted); below 6 joints ``sqrt(det(J^T J))`` (both: the product of ``J``'s singular values). Residual
``r = 1 / (w + 1e-6)`` ``(B, 1)`` (PyRoki's ``manipulability_cost`` form), weighted by ``weight``: minimising
``|weight r|^2`` raises ``w``. A preference (``hard = False``): its check always passes and it never costs the goal.

**How the solver uses it** (``solve(T, costs=[nik.costs.manipulability(robot, weight=0.1)])``, ``solve_all``,
``solve_path``): the route of ``q_rest=`` (:mod:`nik.ik.goals`), compiled, no other solver loop:

- a redundant arm (more joints than live task rows: 7 joints, or a free tool axis) moves each successful answer in
  the null space of its task (:func:`nik.kernels.driver.rest_posture`, generalised): the preference step is
  ``z = s * weight * (w + eps) grad(w) / |grad(w)|^2`` (``weight`` times the Gauss-Newton step of ``r``: the step
  that would double ``w`` to first order), projected so the pose holds, kept only where the answer still meets the
  goal and ``w`` rose (``s`` halved on a refused step, at most 50 steps). With ``q_rest=`` as well, both steps
  add and the cost ``rest_weight^2 |q - q_rest|^2 / 2 + |weight r|^2 / 2`` must fall;
- any arm with a closed form (a 6-joint arm has no null space): among the closed form's solutions that meet the goal
  (within tolerance and the limits), the one of the highest ``w`` (without a collision check; with one the
  collision stage's answer stands);
- ``solve_all``: every solution moved as above (redundant arms), the solutions highest ``w`` first;
- ``solve_path``: each waypoint moved as above, the path kept only where no waypoint is lost and no step grows
  above ``max_step`` (nor above the path's largest step before).

The network's hypotheses are not compared by ``w`` (each would need its own LM: the cost of a restart per target).
The compiled residual and its exact Jacobian are :func:`nik.kernels.manipulability.manipulability_rows`
(:meth:`ManipulabilityTerm.evaluate` uses them for float64 CPU joints; torch's autograd of :meth:`residual`
elsewhere); the tests compare them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from nik.costs.term import Term, autograd_jacobian

__all__ = ["EPS", "ManipulabilityTerm", "manipulability", "measure"]

#: ``r = 1 / (w + EPS)`` (the compiled kernel's ``nik.kernels.manipulability.EPS``; a test checks they agree).
EPS = 1e-6


def measure(robot, q: torch.Tensor) -> torch.Tensor:
    """``(...,)``: Yoshikawa's ``w`` of ``q: (..., dof)`` (module docstring), differentiable (torch)."""
    J = robot.jacobian(q)
    A = J @ J.transpose(-1, -2) if robot.dof >= 6 else J.transpose(-1, -2) @ J
    return torch.linalg.det(A).clamp(min=1e-300).sqrt()


@dataclass(eq=False)
class ManipulabilityTerm(Term):
    """``weight / (w(q) + EPS)`` (module docstring)."""

    robot: object
    weight: float = 0.1
    name: str = "manipulability"
    hard: bool = False

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, 1)``: ``1 / (w + EPS)``, unweighted."""
        return (1.0 / (measure(self.robot, q) + EPS))[:, None]

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if q.device.type == "cpu" and q.dtype == torch.float64:
            r, J = self.compiled(q.detach().numpy())
            return torch.from_numpy(r), torch.from_numpy(J)
        return autograd_jacobian(self.residual, q, self.name)

    def compiled(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(r (B, 1), J (B, 1, dof))`` of :func:`nik.kernels.manipulability.manipulability_rows`, numpy ``q``."""
        from nik.kernels.manipulability import manipulability_rows

        Q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, self.robot.dof))
        G, joints = self.robot.chain_arrays()
        r, J = np.empty((len(Q), 1)), np.empty((len(Q), 1, self.robot.dof))
        manipulability_rows(G, joints, Q, r, J)
        return r, J


def manipulability(robot, *, weight: float = 0.1, name: str = "manipulability") -> ManipulabilityTerm:
    """A preference for a high manipulability ``w`` of ``robot`` (module docstring); ``weight`` (> 0, at most 1 in
    the compiled pipeline: the share of the step that would double ``w``)."""
    if not (isinstance(weight, int | float) and math.isfinite(weight) and 0 < weight):
        raise ValueError(f"manipulability: weight must be a number > 0, got {weight!r}")
    return ManipulabilityTerm(robot, float(weight), name)
