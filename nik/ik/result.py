"""``IKResult``: what :meth:`nik.IKSolver.solve` returns for B targets."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from nik.ik.paths import PathReport

__all__ = ["IKResult"]


@dataclass
class IKResult:
    """Result of :meth:`IKSolver.solve` for B targets.

    Attributes:
        q: (B, dof) joint angles, radians, inside the joint limits.
        pos_err: (B,) position error of ``q`` (FK), metres.
        rot_err: (B,) geodesic rotation error of ``q``, radians.
        success: (B,) bool, ``pos_err <= tol_pos`` and ``rot_err <= tol_rot``.
        iterations: (B,) long, refinement iterations spent (0 where the guess was already within tolerance).
        source: where the initial guess came from: ``network``, ``analytic`` or ``multistart``.
        reachable: (B,) bool, False where no configuration can reach the target (provable reach
            bound, :func:`nik.robots.reach.within_reach`); such targets get ``success=False`` and a best effort.
        path: for :meth:`IKSolver.solve_path`, how the trajectory follows its path (:class:`nik.ik.paths.PathReport`:
            every step, the largest and where, reconfigurations, why a waypoint failed); None otherwise.
    """

    q: torch.Tensor
    pos_err: torch.Tensor
    rot_err: torch.Tensor
    success: torch.Tensor
    iterations: torch.Tensor
    source: str = ""
    reachable: torch.Tensor | None = None
    path: PathReport | None = None

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def to(self, device: str | torch.device) -> IKResult:
        """The same result with every tensor on ``device``."""
        moved = {f.name: getattr(self, f.name) for f in fields(self)}
        moved = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in moved.items()}
        return IKResult(**moved)
