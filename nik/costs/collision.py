"""Collisions: the arm against itself and against a world, as signed distances with a margin.

Rows ``(B, P + L)`` (:func:`nik.collision.signed_distances`): one per active link pair of the arm's sphere model
(:func:`nik.collision.collision_model`), then one per link against the world (``inf`` where nothing is checked).
Residual ``r = max(0, margin - d)`` metres (the margin, 5 mm by default as :class:`nik.ik.collide.CollideCfg`'s,
pushes the spheres that far apart); check: no row below 0 (touching is free, overlapping collides: the sphere
verdict of :func:`nik.collision.collides`, conservative, so an answer called free is free on the meshes too).

The torch twin is :func:`nik.collision.collision_residual` (differentiable through the minimising spheres); the
compiled kernel :func:`nik.kernels.collision.collision_residual` gives the same rows with their exact Jacobian
(``-n . dc/dq`` of the minimising pair): :meth:`CollisionTerm.evaluate` uses it for float64 CPU joints, autograd of
the twin elsewhere (a GPU); the tests compare the two.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nik.collision.check import collides, collision_residual
from nik.collision.model import collision_model
from nik.costs.term import Term, autograd_jacobian

__all__ = ["MARGIN", "CollisionTerm", "collision"]

#: Default margin of the rows, metres (the collision stage's).
MARGIN = 0.005


@dataclass(eq=False)
class CollisionTerm(Term):
    """Self- and world collisions of ``robot`` (module docstring); ``world`` a :class:`nik.World` or None,
    ``model`` a :class:`nik.collision.CollisionModel`."""

    robot: object
    world: object = None
    model: object = None
    self_collision: bool = True
    margin: float = MARGIN
    weight: float = 1.0
    name: str = "collision"

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, P + L)``: ``max(0, margin - d)`` metres."""
        return collision_residual(self.robot, q, self.world, margin=self.margin, model=self.model,
                                  self_collision=self.self_collision)  # fmt: skip

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if q.device.type == "cpu" and q.dtype == torch.float64:
            r, J = self.compiled(q.detach().numpy())
            return torch.from_numpy(r), torch.from_numpy(J)
        return autograd_jacobian(self.residual, q, self.name)

    def check(self, q: torch.Tensor) -> torch.Tensor:
        hit = collides(self.robot, q.detach(), self.world, margin=0.0, model=self.model,
                       self_collision=self.self_collision)  # fmt: skip
        return ~torch.as_tensor(hit, device=q.device)

    def why(self) -> str:
        return f"{self.name}: colliding"

    def compiled(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(r (B, P + L), J (B, P + L, dof))`` of :func:`nik.kernels.collision.collision_residual`, numpy ``q``."""
        from nik.collision.compiled import kernel_arguments
        from nik.kernels.collision import collision_residual as kernel

        Q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, self.robot.dof))
        (G, joints), rest = kernel_arguments(self.robot, self.model, self.world, self_collision=self.self_collision)
        R = len(self.model.pairs) + len(self.model.links)
        r, J = np.zeros((len(Q), R)), np.zeros((len(Q), R, self.robot.dof))
        for b in range(len(Q)):
            kernel(G, joints, Q[b], *rest, float(self.margin), r[b], J[b])
        return r, J


def collision(robot, world=None, *, self_collision: bool = True, margin: float = MARGIN, model=None,
              weight: float = 1.0, name: str = "collision") -> CollisionTerm:  # fmt: skip
    """Collisions of ``robot`` with itself (``self_collision``) and ``world`` (a :class:`nik.World` or None), rows
    ``max(0, margin - d)`` (metres); ``model`` defaults to :func:`nik.collision.collision_model` of the robot."""
    if not (isinstance(margin, int | float) and np.isfinite(margin) and margin >= 0):
        raise ValueError(f"collision: margin must be a number >= 0 (metres), got {margin!r}")
    model = collision_model(robot) if model is None else model
    return CollisionTerm(robot, world, model, bool(self_collision), float(margin), float(weight), name)
