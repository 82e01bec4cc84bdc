"""Classic particle swarm optimisation (paper A eq. 2-3, paper D eq. 4-5), batched over targets.

    v <- W(t) v + C1 r1 (pbest - x) + C2 r2 (gbest - x),   |v| <= v_max,   x <- x + v,
    W(t) = w_start - w_drop * t / N    (paper A: 1 - 0.7 t / N).

Particles are ``(B, P, n)``: B targets, P particles, n free joints; one step is pure tensor
work with no loop over targets or particles. ``r1, r2 ~ U(0, 1)`` are drawn per particle and
joint. On wrapping joints (range >= 2 pi) the attractions ``pbest - x`` and ``gbest - x`` are
the shortest signed angles.

This module also holds what the other swarms share: :class:`SwarmCfg`, :class:`PSOState`,
the velocity move and the personal/global best update.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import torch

from nik.robots.joints import angle_diff
from nik.swarm.bounds import apply_bounds
from nik.swarm.init import InitCfg, init_particles
from nik.swarm.problem import SwarmProblem

__all__ = ["SwarmCfg", "PSOCfg", "PSOState", "pso_init", "pso_step", "best_update", "move"]


@dataclass
class SwarmCfg:
    """Fields every swarm shares."""

    particles: int = 40  # particles (population) per target
    iters: int = 200  # iteration limit N (also the horizon of time schedules such as W(t))
    boundary: str = "reflect"  # reflect | clamp | resample, see nik.swarm.bounds
    objective: str = "pose"  # pose | paper_a | paper_d_position | paper_d_orientation
    rot_weight: float = 0.5  # m/rad, weight of the rotation angle in the 'pose' objective (measured: 0.1 traps
    # the swarms in the wrong IK branch more often, see the README, Swarm refinement)
    init: InitCfg = field(default_factory=InitCfg)


@dataclass
class PSOCfg(SwarmCfg):
    """Classic PSO; defaults are paper A's (40 particles, |v| <= 0.8, C1 = C2 = 2, W(t) = 1 - 0.7 t / N)."""

    c1: float = 2.0  # cognitive coefficient
    c2: float = 2.0  # social coefficient
    w_start: float = 1.0  # inertia at t = 0
    w_drop: float = 0.7  # inertia decrease over the N iterations: W(t) = w_start - w_drop * t / N
    v_max: float | None = 0.8  # rad per iteration, per joint; None: no velocity clamp


class PSOState(NamedTuple):
    """State of a PSO-family swarm; every tensor has the targets B as its first dimension."""

    x: torch.Tensor  # (B, P, n) positions, radians
    v: torch.Tensor  # (B, P, n) velocities, radians per iteration
    f: torch.Tensor  # (B, P) fitness of x
    pbest_x: torch.Tensor  # (B, P, n) personal bests
    pbest_f: torch.Tensor  # (B, P)
    gbest_x: torch.Tensor  # (B, n) global best
    gbest_f: torch.Tensor  # (B,)
    t: int  # iterations done

    @property
    def memory(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The candidates a polish may start from: ``(B, M, n)`` and their fitness ``(B, M)``."""
        return self.pbest_x, self.pbest_f


def best_update(
    x: torch.Tensor, f: torch.Tensor, pbest_x: torch.Tensor, pbest_f: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """New personal bests and the global best (the best personal best) of each target."""
    better = f < pbest_f
    pbest_x = torch.where(better.unsqueeze(-1), x, pbest_x)
    pbest_f = torch.where(better, f, pbest_f)
    gbest_f, i = pbest_f.min(dim=1)
    gbest_x = torch.gather(pbest_x, 1, i[:, None, None].expand(-1, 1, pbest_x.shape[-1])).squeeze(1)
    return pbest_x, pbest_f, gbest_x, gbest_f


def move(
    state: PSOState,
    problem: SwarmProblem,
    *,
    inertia: torch.Tensor | float,
    c1: float,
    c2: float,
    v_max: float | None,
    boundary: str,
    gamma: float = 1.0,
    generator: torch.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``v' = gamma [inertia v + c1 r1 (pbest - x) + c2 r2 (gbest - x)]``, clamped to ``v_max``.

    Returns ``(x', v')`` with ``x' = bounds(x + v')``.
    """
    x = state.x
    r1 = torch.rand(x.shape, generator=generator, dtype=x.dtype, device=x.device)
    r2 = torch.rand(x.shape, generator=generator, dtype=x.dtype, device=x.device)
    wrap = problem.wrap
    v = (
        inertia * state.v
        + c1 * r1 * angle_diff(state.pbest_x, x, wrap)
        + c2 * r2 * angle_diff(state.gbest_x.unsqueeze(1), x, wrap)
    )
    if gamma != 1.0:
        v = gamma * v
    if v_max is not None:
        v = v.clamp(-v_max, v_max)
    return apply_bounds(x + v, v, problem.lo, problem.hi, wrap, boundary, generator=generator)


def pso_init(
    problem: SwarmProblem, cfg: PSOCfg, q_init: torch.Tensor | None, *, generator: torch.Generator
) -> PSOState:
    """Initial swarm (see :func:`nik.swarm.init.init_particles`), evaluated."""
    x, v = init_particles(problem, cfg.particles, q_init, cfg.init, generator=generator)
    if cfg.v_max is not None:
        v = v.clamp(-cfg.v_max, cfg.v_max)
    f = problem.fitness(x)
    pbest_x, pbest_f, gbest_x, gbest_f = best_update(x, f, x, f)
    return PSOState(x, v, f, pbest_x, pbest_f, gbest_x, gbest_f, 0)


def pso_step(state: PSOState, problem: SwarmProblem, cfg: PSOCfg, *, generator: torch.Generator) -> PSOState:
    """One PSO iteration for every target and particle (pure: returns a new state)."""
    w = cfg.w_start - cfg.w_drop * min(state.t, cfg.iters) / max(cfg.iters, 1)
    x, v = move(
        state, problem, inertia=w, c1=cfg.c1, c2=cfg.c2, v_max=cfg.v_max, boundary=cfg.boundary, generator=generator
    )
    f = problem.fitness(x)
    pbest_x, pbest_f, gbest_x, gbest_f = best_update(x, f, state.pbest_x, state.pbest_f)
    return PSOState(x, v, f, pbest_x, pbest_f, gbest_x, gbest_f, state.t + 1)
