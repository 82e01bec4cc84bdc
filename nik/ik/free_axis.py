"""Closed forms for goals with a free tool axis: search the free angle, solve in closed form at each, refine by LM.

A goal with rotation about tool axis ``k`` free (``bounds="axis_z"``, :mod:`nik.ik.bounds`) is the one-parameter
family of poses ``T Rk(gamma)``: the same position, the same tool axis ``k``, the tool turned by ``gamma`` about it.
A closed form (:func:`nik.analytic.solve`: arms of a known family, e.g. ur5, kuka_kr) solves each member exactly.
:func:`closed_form_free_axis` samples ``gamma`` on ``samples`` evenly spaced angles (36: every 10 degrees), keeps
the solutions that exist, lie inside the joint limits and reach their pose (the closed form's own check), and
answers with the one of the smallest ``|gamma|`` (the orientation closest to the one asked; ties: the first
branch). A target none of whose samples is solved (its feasible angles lie between samples, or every member is
out of reach or limits and the bounds' other axes give room) goes to the bounded LM
(:func:`nik.lm.batched.lm_solve` with ``bounds``) from the ``starts`` sampled solutions nearest the goal, clamped
into the limits. Success is measured at the end, honestly: FK of the answer and
:func:`nik.poses.within_bounds`.

Where the tool axis ``k`` is the last joint's axis the free angle only shifts that joint, so free rotation
helps only where the last joint's limits bind; with a tool frame off that axis (a torch, a suction cup offset
from the flange) the wrist centre moves with ``gamma`` and poses out of reach at the given orientation become
reachable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nik.ik.bounds import parse_bounds
from nik.poses import bounded_error, within_bounds

__all__ = ["FreeAxisResult", "closed_form_free_axis"]


@dataclass
class FreeAxisResult:
    """What :func:`closed_form_free_axis` returns for B targets.

    Attributes:
        q: (B, 6) answers inside the joint limits (best effort where ``success`` is False).
        success: (B,) bool: FK of ``q`` within every bound.
        gamma: (B,) the free angle of the closed-form answer (rad; NaN where LM served or nothing was found).
        refined: (B,) bool: the answer came from the LM refinement.
        solutions: (B, samples * 8, 6) every sampled closed-form solution; ``valid``: (B, samples * 8) bool,
            those that exist, lie inside the limits and reach their pose (all distinct answers, for ``solve_all``).
    """

    q: torch.Tensor
    success: torch.Tensor
    gamma: torch.Tensor
    refined: torch.Tensor
    solutions: torch.Tensor
    valid: torch.Tensor


def _about(k: int, gamma: torch.Tensor) -> torch.Tensor:
    """``(S, 4, 4)`` rotations by ``gamma: (S,)`` about axis ``k``."""
    c, s = torch.cos(gamma), torch.sin(gamma)
    R = torch.zeros(gamma.shape[0], 4, 4, dtype=gamma.dtype)
    i, j = (k + 1) % 3, (k + 2) % 3
    R[:, k, k] = 1.0
    R[:, 3, 3] = 1.0
    R[:, i, i], R[:, i, j], R[:, j, i], R[:, j, j] = c, -s, s, c
    return R


def closed_form_free_axis(
    robot,
    T: torch.Tensor,
    *,
    bounds="axis_z",
    samples: int = 36,
    refine: bool = True,
    starts: int = 4,
    seed: int = 0,
) -> FreeAxisResult:
    """IK of ``T: (B, 4, 4)`` with rotation about one tool axis free, on an arm with a closed form.

    Args:
        robot: an arm :func:`nik.analytic.solve` serves (ValueError naming why not otherwise).
        T: (B, 4, 4) target poses, metres (float64 recommended; the tool axis is the target's).
        bounds: a goal with exactly one free rotation axis on every target (``"axis_x" | "axis_y" | "axis_z"``, 6
            numbers or (B, 6) with one rotation ``inf``; :func:`nik.ik.bounds.parse_bounds`).
        samples: angles sampled about the free axis (evenly, from 0).
        refine: run the bounded LM on the targets no sample solved.
        starts: LM starts per such target (the sampled solutions with the smallest bounded error).
        seed: the LM's random restarts.

    Returns:
        :class:`FreeAxisResult`.
    """
    from nik.analytic import solve as closed_solve

    if not isinstance(T, torch.Tensor) or T.ndim != 3 or T.shape[-2:] != (4, 4):
        raise ValueError(f"closed_form_free_axis: T must be a (B, 4, 4) tensor, got {getattr(T, 'shape', T)!r}")
    B = T.shape[0]
    goal = parse_bounds(bounds, batch=B)
    modes = None if goal is None else set(goal.rot_mode.tolist())
    if modes is None or len(modes) != 1 or next(iter(modes)) not in (0, 1, 2):
        raise ValueError(
            'closed_form_free_axis: bounds must leave exactly one rotation axis free on every target ("axis_z"), '
            f"got {bounds!r:.60}"
        )
    k = next(iter(modes))
    half = torch.from_numpy(goal.expand(B)).to(dtype=T.dtype, device=T.device)
    if samples < 1:
        raise ValueError(f"closed_form_free_axis: samples must be >= 1, got {samples}")
    gamma = 2.0 * math.pi * torch.arange(samples, dtype=torch.float64) / samples
    gamma = torch.where(gamma > math.pi, gamma - 2.0 * math.pi, gamma)  # (-pi, pi]: |gamma| orders the choice
    Tm = T[:, None] @ _about(k, gamma).to(dtype=T.dtype, device=T.device)  # (B, S, 4, 4)
    sols, valid = closed_solve(robot, Tm)  # (B, S, 8, dof), (B, S, 8)
    dof = sols.shape[-1]
    sols = sols.reshape(B, samples * 8, dof)
    valid = valid.reshape(B, samples * 8)
    g_of = gamma.to(T.device).repeat_interleave(8)  # (S * 8,)
    # the valid solution of the smallest |gamma| (argmin over a score that is inf where invalid)
    score = torch.where(valid, g_of.abs().to(T.dtype), torch.full_like(valid, math.inf, dtype=T.dtype))
    best = score.argmin(dim=1)
    q = sols[torch.arange(B), best].clone()
    found = valid.any(dim=1)
    gam = torch.where(found, g_of.to(T.dtype)[best], torch.full((B,), math.nan, dtype=T.dtype, device=T.device))
    refined = torch.zeros(B, dtype=torch.bool, device=T.device)
    lo, hi = robot.limits_as(T)
    if refine and not bool(found.all()):
        from nik.lm.batched import lm_solve

        todo = (~found).nonzero().squeeze(1)
        cand = torch.minimum(torch.maximum(sols[todo], lo), hi)  # (m, S * 8, dof), inside the limits
        cand = torch.nan_to_num(cand, nan=0.0)
        Tc = robot.fk(cand.reshape(-1, dof), check=False).reshape(todo.numel(), -1, 4, 4)
        err = bounded_error(T[todo, None], Tc, half[todo, None]).square().sum(-1)
        pick = err.topk(min(starts, err.shape[1]), dim=1, largest=False).indices
        q0 = torch.gather(cand, 1, pick[..., None].expand(-1, -1, dof))
        gen = torch.Generator(device=T.device).manual_seed(seed)
        q_lm, _ = lm_solve(robot, T[todo], q0, bounds=half[todo], generator=gen)
        q[todo] = q_lm.to(q.dtype)
        refined[todo] = True
    q = torch.minimum(torch.maximum(torch.nan_to_num(q, nan=0.0), lo), hi)
    success = within_bounds(T, robot.fk(q, check=False), half)
    return FreeAxisResult(q, success, gam, refined, sols, valid)
