"""The problem a swarm solves: B targets, a subset of free joints, an objective.

:class:`SwarmProblem` separates *what is evaluated* from the algorithms (EvoTorch style):
the solvers only see ``fitness(x)``, the bounds ``lo, hi``, the wrap mask and the problem's
size; the driver also calls ``errors(x)`` to stop targets that reached tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from nik.poses import rotation_angle
from nik.robots.joints import wrap_mask
from nik.robots.model import Robot
from nik.swarm.objectives import Objective

__all__ = ["SwarmProblem", "make_problem"]


@dataclass(frozen=True)
class SwarmProblem:
    """IK over ``n`` free joints for ``B`` targets.

    Attributes:
        robot: the arm.
        T_target: (B, 3, 4) wanted poses (top three rows), metres.
        objective: fitness function ``(T_target (B, 1, 3, 4), T (B, P, 3, 4)) -> (B, P)``.
        free: (n,) long, indices of the joints searched.
        q_fixed: (B, dof) values of all joints; the free ones are overwritten by the particles.
        lo, hi: (n,) bounds of the free joints (inside the robot's limits, in the problem's dtype).
        wrap: (n,) bool, free joints whose range is >= 2 pi (they wrap instead of sticking).
        compiled: use the ``torch.compile``'d FK kernel.
    """

    robot: Robot
    T_target: torch.Tensor
    objective: Objective
    free: torch.Tensor
    q_fixed: torch.Tensor
    lo: torch.Tensor
    hi: torch.Tensor
    wrap: torch.Tensor
    compiled: bool = False

    @property
    def batch(self) -> int:
        return self.T_target.shape[0]

    @property
    def n(self) -> int:
        return self.free.shape[0]

    @property
    def all_free(self) -> bool:
        return self.n == self.robot.dof

    def full(self, x: torch.Tensor) -> torch.Tensor:
        """Free-joint values ``x: (B, ..., n)`` -> full joint vectors ``(B, ..., dof)``."""
        if self.all_free:
            return x
        extra = x.shape[1:-1]
        qf = self.q_fixed.reshape(self.batch, *([1] * len(extra)), self.robot.dof).expand(*x.shape[:-1], -1).clone()
        qf[..., self.free] = x
        return qf

    def fk34(self, q: torch.Tensor) -> torch.Tensor:
        """``q: (..., dof)`` -> ``(..., 3, 4)`` in one FK call over all leading dims."""
        flat = q.reshape(-1, q.shape[-1])
        return self.robot.fk(flat, compiled=self.compiled, check=False)[:, :3, :].reshape(*q.shape[:-1], 3, 4)

    def fitness(self, x: torch.Tensor) -> torch.Tensor:
        """``x: (B, P, n)`` -> ``(B, P)`` objective values (one FK call over all B * P particles)."""
        T = self.fk34(self.full(x))
        return self.objective(self.T_target.unsqueeze(1), T)

    def errors(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x: (B, n)`` -> position error (B,) metres and geodesic rotation error (B,) radians."""
        T = self.fk34(self.full(x))
        pos = torch.linalg.vector_norm(T[..., :3, 3] - self.T_target[..., :3, 3], dim=-1)
        rot = rotation_angle(self.T_target[..., :3, :3].transpose(-1, -2) @ T[..., :3, :3])
        return pos, rot

    def subset(self, idx: torch.Tensor) -> SwarmProblem:
        """The same problem restricted to targets ``idx`` (used to drop converged targets)."""
        return replace(self, T_target=self.T_target[idx], q_fixed=self.q_fixed[idx])


def make_problem(
    robot: Robot,
    T_target: torch.Tensor,
    objective: Objective,
    *,
    free=None,
    q_fixed: torch.Tensor | None = None,
    compiled: bool = False,
) -> SwarmProblem:
    """Build a :class:`SwarmProblem` for ``T_target: (B, 4, 4)`` (dtype/device taken from it).

    ``free``: the joints to search (default all); ``q_fixed: (B, dof)`` or ``(dof,)`` values of the
    others (default zeros).
    """
    dtype, device = T_target.dtype, T_target.device
    B = T_target.shape[0]
    free_t = torch.arange(robot.dof, device=device) if free is None else torch.as_tensor(free, device=device).long()
    if q_fixed is None:
        q_fixed = torch.zeros(B, robot.dof, dtype=dtype, device=device)
    else:
        q_fixed = torch.as_tensor(q_fixed, dtype=dtype, device=device).expand(B, robot.dof).clone()
    lo, hi = robot.limits_as(T_target)
    wrap = wrap_mask(robot.limits, prismatic=robot.prismatic).to(device)
    return SwarmProblem(
        robot=robot,
        T_target=T_target[..., :3, :].contiguous(),
        objective=objective,
        free=free_t,
        q_fixed=q_fixed,
        lo=lo[free_t],
        hi=hi[free_t],
        wrap=wrap[free_t],
        compiled=compiled,
    )
