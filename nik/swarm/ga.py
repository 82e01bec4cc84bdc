"""Paper D's genetic-algorithm baseline, real-coded and batched over targets.

One generation, for a population ``(B, S, n)``:

1. **selection**: binary tournament (scale-free, so any objective's units work);
2. **crossover**: consecutive parents pair up; with probability ``p_c = 0.9`` a pair is
   replaced by two arithmetic (blend) children ``a p1 + (1 - a) p2`` and ``(1 - a) p1 + a p2``,
   ``a ~ U(0, 1)`` per pair;
3. **mutation**: each gene is redrawn uniformly inside the limits with probability
   ``p_m(i) = 0.1 - i * 0.01 / S``, ``i = 1..S`` the rank of the child's first parent from
   worst (i = 1) to best (i = S): the classic MATLAB listing paper D follows
   (``pm = 0.10 - [1:Size] * 0.01 / Size``, "bigger fitness, smaller pm");
4. **elitism**: the best individual so far replaces the worst child.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch

from nik.swarm.init import init_particles
from nik.swarm.problem import SwarmProblem
from nik.swarm.pso import SwarmCfg

__all__ = ["GACfg", "GAState", "ga_init", "ga_step"]


@dataclass
class GACfg(SwarmCfg):
    """Paper D's GA: population 500, crossover 0.9, mutation 0.1 - i * 0.01 / Size, 100 generations."""

    particles: int = 500  # population size S
    iters: int = 100  # generations
    crossover: float = 0.9  # probability p_c that a parent pair is crossed
    mutation_max: float = 0.1  # p_m(i) = mutation_max - i * mutation_drop / S
    mutation_drop: float = 0.01


class GAState(NamedTuple):
    x: torch.Tensor  # (B, S, n) population
    f: torch.Tensor  # (B, S) fitness
    gbest_x: torch.Tensor  # (B, n) best individual so far
    gbest_f: torch.Tensor  # (B,)
    t: int

    @property
    def memory(self) -> tuple[torch.Tensor, torch.Tensor]:
        return self.x, self.f


def ga_init(problem: SwarmProblem, cfg: GACfg, q_init, *, generator: torch.Generator) -> GAState:
    x, _ = init_particles(problem, cfg.particles, q_init, cfg.init, generator=generator)
    f = problem.fitness(x)
    gbest_f, i = f.min(dim=1)
    gbest_x = torch.gather(x, 1, i[:, None, None].expand(-1, 1, x.shape[-1])).squeeze(1)
    return GAState(x, f, gbest_x, gbest_f, 0)


def ga_step(state: GAState, problem: SwarmProblem, cfg: GACfg, *, generator: torch.Generator) -> GAState:
    """One generation (pure)."""
    x, f = state.x, state.f
    B, S, n = x.shape
    dtype, device = x.dtype, x.device
    # 1. binary tournament
    cand = torch.randint(0, S, (B, S, 2), generator=generator, device=device)
    fc = torch.gather(f, 1, cand.reshape(B, 2 * S)).reshape(B, S, 2)
    winner = torch.gather(cand, 2, fc.argmin(dim=2, keepdim=True)).squeeze(2)  # (B, S)
    parents = torch.gather(x, 1, winner[..., None].expand(-1, -1, n))
    # 2. arithmetic crossover of consecutive pairs
    half = S // 2
    p1, p2 = parents[:, 0 : 2 * half : 2], parents[:, 1 : 2 * half : 2]
    a = torch.rand(B, half, 1, generator=generator, dtype=dtype, device=device)
    cross = torch.rand(B, half, 1, generator=generator, device=device) < cfg.crossover
    c1 = torch.where(cross, a * p1 + (1 - a) * p2, p1)
    c2 = torch.where(cross, (1 - a) * p1 + a * p2, p2)
    children = torch.stack([c1, c2], dim=2).reshape(B, 2 * half, n)
    if S % 2:
        children = torch.cat([children, parents[:, -1:]], dim=1)
    # 3. rank-dependent uniform mutation: worst-ranked parents mutate most
    rank = torch.empty_like(winner)
    order = f.argsort(dim=1, descending=True)  # worst first -> i = 1
    rank.scatter_(1, order, torch.arange(1, S + 1, device=device).expand(B, S))
    parent_rank = torch.gather(rank, 1, winner[:, : children.shape[1]])
    p_m = (cfg.mutation_max - parent_rank.to(dtype) * cfg.mutation_drop / S)[..., None]
    mutate = torch.rand(B, S, n, generator=generator, dtype=dtype, device=device) < p_m
    u = torch.rand(B, S, n, generator=generator, dtype=dtype, device=device)
    fresh = problem.lo + u * (problem.hi - problem.lo)
    children = torch.where(mutate, fresh, children)
    children = torch.minimum(torch.maximum(children, problem.lo), problem.hi)
    fch = problem.fitness(children)
    # 4. elitism: the best so far replaces the worst child
    worst = fch.argmax(dim=1)
    bidx = torch.arange(B, device=device)
    children[bidx, worst] = state.gbest_x
    fch[bidx, worst] = state.gbest_f
    gbest_f, i = fch.min(dim=1)
    gbest_x = torch.gather(children, 1, i[:, None, None].expand(-1, 1, n)).squeeze(1)
    return GAState(children, fch, gbest_x, gbest_f, state.t + 1)
