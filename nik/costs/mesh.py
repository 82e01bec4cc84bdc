"""Collisions on the robot's real collision meshes (coal), a constraint: the arm against itself and a world.

Rows ``r = max(0, margin - d)`` metres, one per pair a :class:`nik.collision.meshcheck.MeshCheck` tests (the
SRDF's disabled pairs and the others its model leaves out by decision left out) and per moving link and obstacle:
:class:`nik.collision.mesh_distance.MeshDistance` (coal's distance and nearest points; the convex hulls' signed
distance where the meshes overlap), with the Jacobian ``n^T (J_p(a, p_a) - J_p(b, p_b))`` of the nearest points.
Check: every distance above 0 (the meshes' verdict at margin 0, :meth:`MeshCheck.collides`, from the pairs that
can touch). Where the sphere model calls every free answer
colliding (it overreaches the meshes by centimetres), these rows steer the collision stage (:mod:`nik.ik.collide`).

The torch residual is a custom autograd function over the same rows (coal is not differentiable: its backward
multiplies by the explicit Jacobian), CPU only; :meth:`MeshCollisionTerm.evaluate` gives the rows and Jacobian
directly (float64 numpy inside). Cost: 1-10 ms a configuration on a 7-joint arm (one coal query per near pair).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nik.costs.collision import MARGIN
from nik.costs.term import Term

__all__ = ["MeshCollisionTerm", "mesh_collision"]


class _Rows(torch.autograd.Function):
    """``r (B, M)`` of the term's rows, the backward ``grad @ J`` with the explicit Jacobian."""

    @staticmethod
    def forward(ctx, q, term):
        r, J = term.compiled(q.detach().cpu().numpy())
        ctx.save_for_backward(torch.from_numpy(J).to(q))
        return torch.from_numpy(r).to(q)

    @staticmethod
    def backward(ctx, grad):
        (J,) = ctx.saved_tensors
        return (grad[:, None, :] @ J)[:, 0, :], None


@dataclass(eq=False)
class MeshCollisionTerm(Term):
    """The mesh rows of ``distance`` (a :class:`nik.collision.mesh_distance.MeshDistance`; module docstring),
    judged by its check at margin 0 with ``world`` and ``self_collision``."""

    distance: object
    world: object = None
    self_collision: bool = True
    margin: float = MARGIN
    weight: float = 1.0
    name: str = "mesh collision"

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, M)``: ``max(0, margin - d)`` metres (differentiable through the explicit Jacobian)."""
        return _Rows.apply(q, self)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        r, J = self.compiled(q.detach().cpu().numpy())
        return torch.from_numpy(r).to(q), torch.from_numpy(J).to(q)

    def compiled(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(r (B, M), J (B, M, dof))`` for numpy ``q: (B, dof)``."""
        r, J, _ = self.distance.rows_at(q, self.margin)
        return r, J

    def check(self, q: torch.Tensor) -> torch.Tensor:
        """``(B,)`` bool: every mesh distance above 0 (coal's distances of the pairs whose bounding spheres touch:
        the verdict of :meth:`MeshCheck.collides` without asking about the pairs that cannot touch)."""
        d = self.distance.rows_at(q.detach().cpu().numpy(), 0.0)[2]
        return torch.as_tensor((d > 1e-9).all(1) if d.shape[1] else np.ones(len(d), dtype=bool), device=q.device)

    def why(self) -> str:
        return f"{self.name}: colliding on the meshes"


def mesh_collision(robot, world=None, *, self_collision: bool = True, margin: float = MARGIN, check=None,
                   weight: float = 1.0, name: str = "mesh collision") -> MeshCollisionTerm:  # fmt: skip
    """Collisions of ``robot``'s collision meshes with themselves (``self_collision``) and ``world`` (a
    :class:`nik.World` or None), rows ``max(0, margin - d)`` metres; ``check`` a
    :class:`nik.collision.meshcheck.MeshCheck` (default: the one of the robot's collision model,
    :func:`nik.collision.meshcheck.mesh_check`; needs coal and the URDF's meshes, a one-line error otherwise)."""
    from nik.collision.mesh_distance import MeshDistance

    if not (isinstance(margin, int | float) and np.isfinite(margin) and margin >= 0):
        raise ValueError(f"mesh_collision: margin must be a number >= 0 (metres), got {margin!r}")
    if check is None:
        from nik.collision.meshcheck import mesh_check
        from nik.collision.model import collision_model

        check = mesh_check(robot, collision_model(robot), required=True)
    distance = MeshDistance(check, world, self_collision=bool(self_collision))
    return MeshCollisionTerm(distance, world, bool(self_collision), float(margin), float(weight), name)
