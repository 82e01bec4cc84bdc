"""Simulated-annealing PSO (paper A, methods.md 3.2), batched over targets.

Each iteration moves every particle by the classic PSO rule (:mod:`nik.swarm.pso`), then
applies a Metropolis test per particle: with ``dE = f(new) - f(old)`` the move is accepted
if ``dE <= 0``, otherwise with probability ``exp(-dE / T)``; a rejected particle stays
where it was (its fitness too) but keeps its new velocity. The temperature cools
geometrically, ``T_t = T0 K^t``; it is in the objective's units, so paper A's ``T0 = 20``
goes with paper A's objective (eq. 4, degrees + millimetres), the default here.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.swarm.problem import SwarmProblem
from nik.swarm.pso import PSOCfg, PSOState, best_update, move, pso_init

__all__ = ["SAPSOCfg", "sapso_init", "sapso_step"]


@dataclass
class SAPSOCfg(PSOCfg):
    """Paper A's SA-PSO: the classic PSO settings plus T0 = 20, K = 0.95, objective eq. (4)."""

    objective: str = "paper_a"
    t0: float = 20.0  # initial temperature, objective units
    cooling: float = 0.95  # K: T <- K T each iteration


def sapso_init(problem: SwarmProblem, cfg: SAPSOCfg, q_init, *, generator: torch.Generator) -> PSOState:
    """Same as :func:`nik.swarm.pso.pso_init`."""
    return pso_init(problem, cfg, q_init, generator=generator)


def sapso_step(state: PSOState, problem: SwarmProblem, cfg: SAPSOCfg, *, generator: torch.Generator) -> PSOState:
    """One SA-PSO iteration: PSO move, Metropolis acceptance per particle, best update."""
    w = cfg.w_start - cfg.w_drop * min(state.t, cfg.iters) / max(cfg.iters, 1)
    x_new, v = move(
        state, problem, inertia=w, c1=cfg.c1, c2=cfg.c2, v_max=cfg.v_max, boundary=cfg.boundary, generator=generator
    )
    f_new = problem.fitness(x_new)
    temperature = cfg.t0 * cfg.cooling**state.t
    dE = f_new - state.f
    u = torch.rand(dE.shape, generator=generator, dtype=dE.dtype, device=dE.device)
    accept = (dE <= 0) | (u < torch.exp(-dE.clamp_min(0) / max(temperature, 1e-300)))
    x = torch.where(accept.unsqueeze(-1), x_new, state.x)
    f = torch.where(accept, f_new, state.f)
    pbest_x, pbest_f, gbest_x, gbest_f = best_update(x, f, state.pbest_x, state.pbest_f)
    return PSOState(x, v, f, pbest_x, pbest_f, gbest_x, gbest_f, state.t + 1)
