"""Improved PSO of paper D (methods.md 3.3): CMA-ES step-size inertia plus a constriction factor.

Per iteration, per particle::

    mu = w_min + (w_max - w_min) U(0, 1),   w = mu + sigma_t r3,   r3 ~ N(0, 1)
    v <- gamma [w v + c1 r1 (pbest - x) + c2 r2 (gbest - x)],   x <- x + v
    gamma = 2 / |2 - phi - sqrt(phi^2 - 4 phi)|,  phi = c1 + c2 > 4   (0.7298 for 2 + 2.1)

Choices where the paper is silent (documented, as methods.md asks):

- **w and gamma combine** as above: gamma multiplies the whole velocity update, inertia
  term included (Clerc-Kennedy constriction form); paper D's eq. (12) misprints gbest as
  p_ij, here gbest is the swarm's global best.
- **Evolution path**: standard CMA-ES cumulative step-size adaptation with an identity
  covariance, driven by the swarm's normalised mean displacement:
  ``d = mean_p(x_new - x_old)`` (shortest angle on wrapping joints),
  ``p_sigma <- (1 - c_s) p_sigma + sqrt(c_s (2 - c_s) mu_eff) d / sigma_t``,
  ``sigma_{t+1} = sigma_t exp((c_s / d_s)(||p_sigma|| / E||N(0, I_n)|| - 1))``,
  with ``mu_eff = P`` (all particles weigh alike), ``c_s = (mu_eff + 2) / (n + mu_eff + 5)``,
  ``d_s = 1 + 2 max(0, sqrt((mu_eff - 1) / (n + 1)) - 1) + c_s`` (Hansen's defaults),
  ``E||N(0, I_n)|| = sqrt(n)(1 - 1/(4n) + 1/(21 n^2))``. sigma is one scalar per target and is
  kept in ``[sigma_min, sigma_max]`` so that a fast-moving swarm cannot make w explode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import torch

from nik.robots.joints import angle_diff
from nik.swarm.init import init_particles
from nik.swarm.problem import SwarmProblem
from nik.swarm.pso import PSOState, SwarmCfg, best_update, move

__all__ = ["IPSOCfg", "IPSOState", "ipso_init", "ipso_step", "constriction", "expected_normal_norm"]


@dataclass
class IPSOCfg(SwarmCfg):
    """Paper D's improved PSO: 30 particles, w in [0.4, 0.9], c1 = 2, c2 = 2.1, sigma_0 = 0.65, 100 generations."""

    particles: int = 30
    iters: int = 100
    w_max: float = 0.9  # upper end of the inertia mean mu
    w_min: float = 0.4  # lower end of the inertia mean mu
    c1: float = 2.0
    c2: float = 2.1  # c1 + c2 must exceed 4 for the constriction factor
    sigma0: float = 0.65  # initial CMA-ES step size (inertia spread)
    sigma_min: float = 1e-6
    sigma_max: float = 1.0
    mu_eff: float | None = None  # CMA-ES variance-effective selection mass; None: the particle count P
    v_max: float | None = None  # rad per iteration; None: constriction alone bounds the velocity


class IPSOState(NamedTuple):
    """Improved-PSO state: the PSO fields plus the step size and evolution path (per target)."""

    x: torch.Tensor  # (B, P, n)
    v: torch.Tensor  # (B, P, n)
    f: torch.Tensor  # (B, P)
    pbest_x: torch.Tensor  # (B, P, n)
    pbest_f: torch.Tensor  # (B, P)
    gbest_x: torch.Tensor  # (B, n)
    gbest_f: torch.Tensor  # (B,)
    sigma: torch.Tensor  # (B,) CMA-ES step size
    p_sigma: torch.Tensor  # (B, n) evolution path
    t: int

    @property
    def memory(self) -> tuple[torch.Tensor, torch.Tensor]:
        return self.pbest_x, self.pbest_f


def constriction(c1: float, c2: float) -> float:
    """Clerc's constriction factor ``2 / |2 - phi - sqrt(phi^2 - 4 phi)|`` for ``phi = c1 + c2 > 4``."""
    phi = c1 + c2
    if phi <= 4:
        raise ValueError(f"improved PSO needs c1 + c2 > 4 for its constriction factor, got {phi}")
    return 2.0 / abs(2.0 - phi - math.sqrt(phi * phi - 4.0 * phi))


def expected_normal_norm(n: int) -> float:
    """``E||N(0, I_n)|| ~ sqrt(n) (1 - 1/(4n) + 1/(21 n^2))``."""
    return math.sqrt(n) * (1 - 1 / (4 * n) + 1 / (21 * n * n))


def ipso_init(problem: SwarmProblem, cfg: IPSOCfg, q_init, *, generator: torch.Generator) -> IPSOState:
    x, v = init_particles(problem, cfg.particles, q_init, cfg.init, generator=generator)
    if cfg.v_max is not None:
        v = v.clamp(-cfg.v_max, cfg.v_max)
    f = problem.fitness(x)
    pbest_x, pbest_f, gbest_x, gbest_f = best_update(x, f, x, f)
    B, n = problem.batch, problem.n
    sigma = torch.full((B,), cfg.sigma0, dtype=x.dtype, device=x.device)
    p_sigma = torch.zeros(B, n, dtype=x.dtype, device=x.device)
    return IPSOState(x, v, f, pbest_x, pbest_f, gbest_x, gbest_f, sigma, p_sigma, 0)


def ipso_step(state: IPSOState, problem: SwarmProblem, cfg: IPSOCfg, *, generator: torch.Generator) -> IPSOState:
    """One improved-PSO iteration (pure)."""
    B, P, n = state.x.shape
    dtype, device = state.x.dtype, state.x.device
    mu = cfg.w_min + (cfg.w_max - cfg.w_min) * torch.rand(B, P, 1, generator=generator, dtype=dtype, device=device)
    r3 = torch.randn(B, P, 1, generator=generator, dtype=dtype, device=device)
    w = mu + state.sigma[:, None, None] * r3
    gamma = constriction(cfg.c1, cfg.c2)
    base = PSOState(state.x, state.v, state.f, state.pbest_x, state.pbest_f, state.gbest_x, state.gbest_f, state.t)
    x, v = move(
        base,
        problem,
        inertia=w,
        c1=cfg.c1,
        c2=cfg.c2,
        v_max=cfg.v_max,
        boundary=cfg.boundary,
        gamma=gamma,
        generator=generator,
    )
    f = problem.fitness(x)
    pbest_x, pbest_f, gbest_x, gbest_f = best_update(x, f, state.pbest_x, state.pbest_f)

    # CMA-ES cumulative step-size adaptation on the swarm's mean displacement
    mu_eff = float(cfg.mu_eff if cfg.mu_eff is not None else P)
    cs = (mu_eff + 2) / (n + mu_eff + 5)
    ds = 1 + 2 * max(0.0, math.sqrt((mu_eff - 1) / (n + 1)) - 1) + cs
    disp = angle_diff(x, state.x, problem.wrap).mean(dim=1)  # (B, n)
    p_sigma = (1 - cs) * state.p_sigma + math.sqrt(cs * (2 - cs) * mu_eff) * disp / state.sigma[:, None]
    ratio = torch.linalg.vector_norm(p_sigma, dim=-1) / expected_normal_norm(n)
    sigma = (state.sigma * torch.exp((cs / ds) * (ratio - 1))).clamp(cfg.sigma_min, cfg.sigma_max)
    return IPSOState(x, v, f, pbest_x, pbest_f, gbest_x, gbest_f, sigma, p_sigma, state.t + 1)
