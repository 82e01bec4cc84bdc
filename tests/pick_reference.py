"""The torch form of the choice among closed-form solutions: a test reference, written apart from the one rule
both backends use (:func:`nik.kernels.closed.pick`, which ``nik.ik.guesses.analytic_guess`` calls).

:func:`choose`: per target, the valid solution nearest ``q_near`` (each angle moved by whole turns, inside the
limits, as near ``q_near`` as it goes; all solutions when none is valid), or the one whose worst joint is farthest
inside its range; with none valid and no ``q_near``, the clamped solution nearest the target (metres + 0.1 x
radians). (It was ``nik.ik.guesses.nearest_solution`` and the body of ``analytic_guess``.)
"""

from __future__ import annotations

import math

import torch

from nik.ik.guesses import LIMIT_ROUNDING
from nik.poses import pose_error
from nik.tolerances import score


def choose(
    robot, T: torch.Tensor, sols: torch.Tensor, valid: torch.Tensor, q_near: torch.Tensor | None
) -> torch.Tensor:
    """``(B, dof)`` one of ``sols: (B, K, dof)`` (``valid: (B, K)``) per target of ``T: (B, 4, 4)``."""
    lo, hi = robot.limits_as(T)
    if q_near is not None:
        q, _ = nearest_solution(sols, valid, q_near, lo, hi)
        return robot.clamp(q)
    q = _central_solution(sols, valid, lo, hi)
    none = ~valid.any(-1)
    if bool(none.any()):
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
