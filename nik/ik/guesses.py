"""Guess providers: ``(robot, T, ...) -> q (B, dof)`` initial joint guesses inside the limits.

:class:`nik.IKSolver` composes one of these with a refiner (:mod:`nik.ik.refiners`):

- :func:`analytic_guess`: the closed form of arms that have one (:func:`nik.analytic.solve`; the valid
  solution nearest ``q_near``, or the one farthest inside the joint ranges; out of reach, the clamped one
  that comes closest);
- :func:`multistart_guess`: the best of ``n_starts`` uniform configurations by pose error;
- :func:`network_guess`: a trained network's prediction, clamped to the limits.

Also here: choosing among several solutions (:func:`nearest_solution`, used by ``q_near``) and
dropping duplicates (:func:`dedupe`, used by ``solve_all``).
"""

from __future__ import annotations

import math

import torch

from nik.poses import pose_error
from nik.tolerances import score

__all__ = ["LIMIT_ROUNDING", "analytic_guess", "dedupe", "multistart_guess", "nearest_solution", "network_guess"]

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
    """``(B, dof)``: the closed-form solution (arms with a closed form) for ``T: (B, 4, 4)``; see the module text."""
    from nik.analytic import solve

    sols, valid = solve(robot, T)
    lo, hi = robot.limits_as(T)
    if q_near is not None:
        q, _ = nearest_solution(sols, valid, q_near, lo, hi)
        return robot.clamp(q)
    q = _central_solution(sols, valid, lo, hi)
    none = ~valid.any(-1)
    if bool(none.any()):  # unreachable or outside the limits: the clamped solution that comes closest
        clamped = robot.clamp(sols[none])
        pos, rot = pose_error(T[none, None], robot.fk(clamped))
        idx = score(pos, rot).argmin(-1)
        q = q.clone()
        q[none] = torch.gather(clamped, 1, idx[:, None, None].expand(-1, 1, clamped.shape[-1])).squeeze(1)
    return robot.clamp(q)


def _near_representative(sols: torch.Tensor, q_near: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Each angle of ``sols: (B, K, dof)`` moved by a multiple of 2 pi, staying inside ``[lo, hi]``,
    as near as possible to ``q_near: (B, dof)`` (matters for joints with more than a full turn of range)."""
    two_pi = 2 * math.pi
    target = q_near[:, None]
    k = torch.round((target - sols) / two_pi)
    best = sols
    best_d = (sols - target).abs()
    # a turn that lands within rounding of a limit counts as inside (and is clamped onto it): q_near
    # often sits exactly on a limit (a previous answer, clamped), and sols + 2 pi k differs from it by 1e-15
    tol = LIMIT_ROUNDING * (1.0 + torch.maximum(lo.abs(), hi.abs()))
    for shift in (k - 1, k, k + 1):
        cand = sols + shift * two_pi
        ok = (cand >= lo - tol) & (cand <= hi + tol)
        cand = torch.minimum(torch.maximum(cand, lo), hi)
        d = torch.where(ok, (cand - target).abs(), torch.full_like(cand, float("inf")))
        take = d < best_d
        best = torch.where(take, cand, best)
        best_d = torch.where(take, d, best_d)
    return best


def nearest_solution(
    sols: torch.Tensor, valid: torch.Tensor, q_near: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Among ``sols: (B, K, dof)`` with ``valid: (B, K)``, the one nearest ``q_near: (B, dof)``.

    Distance: Euclidean norm of the joint differences after each angle is moved by multiples of
    2 pi (inside the limits) as near ``q_near`` as it goes, i.e. the joint motion to reach it.

    Returns:
        ``q: (B, dof)`` and ``found: (B,)`` bool (False where no solution is valid; ``q`` is then
        the nearest of all).
    """
    rep = _near_representative(sols, q_near, lo, hi)
    dist = torch.linalg.vector_norm(rep - q_near[:, None], dim=-1)
    found = valid.any(-1)
    dist = torch.where(valid | ~found[:, None], dist, torch.full_like(dist, float("inf")))
    idx = dist.argmin(-1)
    q = torch.gather(rep, 1, idx[:, None, None].expand(-1, 1, rep.shape[-1])).squeeze(1)
    return q, found


def _central_solution(sols: torch.Tensor, valid: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Among valid ``sols: (B, K, dof)``, the one whose worst joint is farthest inside its range."""
    margin = torch.minimum(sols - lo, hi - sols) / (hi - lo)
    score = margin.amin(-1)
    score = torch.where(valid, score, torch.full_like(score, -float("inf")))
    idx = score.argmax(-1)
    return torch.gather(sols, 1, idx[:, None, None].expand(-1, 1, sols.shape[-1])).squeeze(1)


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
