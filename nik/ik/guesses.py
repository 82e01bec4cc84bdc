"""Guess providers: ``(robot, T, ...) -> q (B, dof)`` initial joint guesses inside the limits.

:class:`nik.IKSolver` composes one of these with a refiner (:mod:`nik.ik.refiners`):

- :func:`analytic_guess`: the closed form of arms that have one (:func:`nik.analytic.solve`; the choice among its
  solutions is :func:`nik.kernels.closed.pick`, the one rule of both backends: the valid solution nearest
  ``q_near``, or the one farthest inside the joint ranges; out of reach, the clamped one that comes closest);
- :func:`multistart_guess`: the best of ``n_starts`` uniform configurations by pose error;
- :func:`network_guess`: a trained network's prediction, clamped to the limits.

Also here: dropping duplicates (:func:`dedupe`, used by ``solve_all``). The torch form of the choice among
closed-form solutions that lived here (``nearest_solution``) is now the tests' reference
(``tests/pick_reference.py``).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.poses import pose_error
from nik.tolerances import score

__all__ = ["LIMIT_ROUNDING", "analytic_guess", "dedupe", "multistart_guess", "network_guess"]

#: Relative tolerance (radians per radian of limit) within which an angle counts as on a joint limit.
LIMIT_ROUNDING = 1e-9


def network_guess(net, robot, T: torch.Tensor) -> torch.Tensor:
    """``(B, dof)``: the network's prediction for ``T: (B, 4, 4)``, clamped to the limits."""
    return robot.clamp(net.predict(T))


def multistart_guess(robot, T: torch.Tensor, *, seed: int = 0, n_starts: int = 64) -> torch.Tensor:
    """``(B, dof)``: per target ``T: (B, 4, 4)``, the best of ``n_starts`` uniform configurations
    (position error in metres + 0.1 x rotation error in radians)."""
    g = torch.Generator(device=T.device).manual_seed(int(seed))
    B = T.shape[0]
    q = robot.sample(B * n_starts, generator=g, dtype=T.dtype, device=T.device).reshape(B, n_starts, -1)
    pos, rot = pose_error(T[:, None], robot.fk(q))
    idx = score(pos, rot).argmin(-1)
    return torch.gather(q, 1, idx[:, None, None].expand(-1, 1, q.shape[-1])).squeeze(1)


def analytic_guess(robot, T: torch.Tensor, *, q_near: torch.Tensor | None = None) -> torch.Tensor:
    """``(B, dof)``: the closed-form solution (arms with a closed form) for ``T: (B, 4, 4)``: the 8 solutions of
    :func:`nik.analytic.solve` (on ``T``'s device), one chosen per target by the one rule of both backends,
    :func:`nik.kernels.closed.pick` (the valid solution nearest ``q_near``, each angle moved by whole turns as near
    it as the limits allow, or the one whose worst joint is farthest inside its range; with none valid, the clamped
    solution nearest the target), computed on the CPU in float64 and returned in ``T``'s dtype and device."""
    from nik.analytic import solve
    from nik.kernels.closed import pick

    sols, valid = solve(robot, T)
    G, joints = robot.chain_arrays()
    cpu = {"device": "cpu", "dtype": torch.float64}
    B, n = T.shape[0], robot.dof
    out = np.empty((B, n))
    near = np.zeros((B, n)) if q_near is None else np.ascontiguousarray(q_near.detach().to(**cpu).numpy())
    pick(
        np.ascontiguousarray(sols.detach().to(**cpu).numpy()), np.ascontiguousarray(valid.cpu().numpy()), G, joints,
        np.ascontiguousarray(T.detach().to(**cpu).numpy()), near, q_near is not None, LIMIT_ROUNDING, out,
    )  # fmt: skip
    return robot.clamp(torch.from_numpy(out).to(device=T.device, dtype=T.dtype))


def dedupe(q: torch.Tensor, *, tol: float = 1e-3, prismatic: torch.Tensor | None = None) -> torch.Tensor:
    """Drop from ``q: (K, dof)`` every row within ``tol`` (max abs joint difference, radians or metres;
    wrapped modulo 2 pi except on ``prismatic: (dof,)`` joints) of an earlier row; the order of the rest is kept."""
    if q.shape[0] <= 1:
        return q
    diff = q[:, None] - q[None]
    wrapped = torch.remainder(diff + math.pi, 2 * math.pi) - math.pi
    diff = wrapped if prismatic is None else torch.where(prismatic.to(q.device), diff, wrapped)
    close = diff.abs().amax(-1) < tol
    dup = torch.triu(close, diagonal=1).any(dim=0)
    return q[~dup]
