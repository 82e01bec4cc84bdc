"""Differential evolution: a state and pure ``ask`` / ``tell`` / ``step`` functions.

Paper C trains the network's flattened weights and biases with DE/rand/1/bin (NP = 220,
F = 0.6, CR = 0.5, 500 generations). For target ``i`` of the population ``x: (NP, D)``:

- ``rand1bin``: mutant ``v = x_r1 + F (x_r2 - x_r3)`` with ``r1, r2, r3`` distinct and ``!= i``;
- ``current_to_best1bin`` (stronger option): ``v = x_i + F (x_best - x_i) + F (x_r1 - x_r2)``,
  greedier: it pulls every individual towards the best, converging faster on smooth,
  single-basin problems at the cost of diversity;
- binomial crossover: trial coordinate ``j`` is ``v_j`` with probability ``CR`` (and for one
  random ``j_rand`` always), else ``x_ij``;
- greedy selection: the trial replaces its target when its fitness is not worse.

``jde=True`` (stronger option, Brest et al. 2006, "self-adapting control parameters"): every
individual carries its own ``F_i, CR_i``; before each generation, with probability ``tau`` each is
redrawn (``F ~ U(0.1, 1.0)``, ``CR ~ U(0, 1)``), and a redrawn value survives only with a trial that
wins selection. It removes the need to tune F and CR for the problem at hand.

Bounds (``lower``/``upper``, optional): a mutant coordinate outside the box is replaced by a
uniform draw between its target's value and the bound it crossed, so every individual stays inside.

Everything is batched over the population; there is no Python loop over individuals. Randomness
comes only from the ``generator`` argument. Fitness is minimised.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch

__all__ = ["DECfg", "DEState", "STRATEGIES", "de_init", "de_ask", "de_tell", "de_step", "de_minimize"]

STRATEGIES = ("rand1bin", "current_to_best1bin")


@dataclass
class DECfg:
    """Differential evolution settings (paper C's values by default)."""

    pop_size: int = 220  # NP, individuals
    F: float = 0.6  # mutation (differential weight), dimensionless
    CR: float = 0.5  # crossover probability, in [0, 1]
    strategy: str = "rand1bin"  # rand1bin | current_to_best1bin
    jde: bool = False  # self-adaptive F_i, CR_i per individual (jDE)
    jde_tau: float = 0.1  # jDE: probability of redrawing F_i (and, independently, CR_i) each generation
    jde_F_min: float = 0.1  # jDE: F_i ~ U(F_min, F_max) when redrawn
    jde_F_max: float = 1.0

    def __post_init__(self):
        if self.strategy not in STRATEGIES:
            raise ValueError(f"unknown DE strategy {self.strategy!r}; expected one of {STRATEGIES}")
        if self.pop_size < 4:
            raise ValueError(f"DE needs a population of at least 4 (3 distinct partners), got {self.pop_size}")
        if not 0.0 <= self.CR <= 1.0:
            raise ValueError(f"DE crossover rate CR must be in [0, 1], got {self.CR}")
        if self.F <= 0:
            raise ValueError(f"DE mutation factor F must be > 0, got {self.F}")


class DEState(NamedTuple):
    """Population and bookkeeping. ``x: (NP, D)``, ``fitness, F, CR: (NP,)``, bounds ``(D,)`` or None."""

    x: torch.Tensor
    fitness: torch.Tensor
    F: torch.Tensor
    CR: torch.Tensor
    lower: torch.Tensor | None
    upper: torch.Tensor | None
    generation: int = 0
    evals: int = 0  # fitness evaluations of single individuals so far

    @property
    def best_index(self) -> int:
        return int(torch.argmin(self.fitness))

    @property
    def best_x(self) -> torch.Tensor:
        """(D,) the best individual."""
        return self.x[self.best_index]

    @property
    def best_fitness(self) -> float:
        return float(self.fitness.min())


def _rand(shape, generator: torch.Generator | None, like: torch.Tensor) -> torch.Tensor:
    """Uniform [0, 1) draws from ``generator`` (on its own device), moved to ``like``'s device/dtype."""
    device = generator.device if generator is not None else like.device
    return torch.rand(shape, generator=generator, device=device, dtype=torch.float64).to(like.device, like.dtype)


def de_init(
    x: torch.Tensor,
    fitness: torch.Tensor,
    cfg: DECfg,
    *,
    lower: torch.Tensor | None = None,
    upper: torch.Tensor | None = None,
) -> DEState:
    """A state from an evaluated initial population ``x: (NP, D)`` with ``fitness: (NP,)``."""
    if x.ndim != 2 or x.shape[0] != cfg.pop_size:
        raise ValueError(f"de_init: expected a population of shape ({cfg.pop_size}, D), got {tuple(x.shape)}")
    if fitness.shape != (x.shape[0],):
        raise ValueError(f"de_init: expected fitness of shape ({x.shape[0]},), got {tuple(fitness.shape)}")
    if lower is not None:
        lower = torch.as_tensor(lower, dtype=x.dtype, device=x.device).expand(x.shape[1])
        upper = torch.as_tensor(upper, dtype=x.dtype, device=x.device).expand(x.shape[1])
        if bool(((x < lower) | (x > upper)).any()):
            raise ValueError("de_init: the initial population lies partly outside the bounds")
    n = x.shape[0]
    F = torch.full((n,), float(cfg.F), dtype=x.dtype, device=x.device)
    CR = torch.full((n,), float(cfg.CR), dtype=x.dtype, device=x.device)
    return DEState(x, fitness.to(x.dtype), F, CR, lower, upper, 0, n)


def de_ask(state: DEState, cfg: DECfg, *, generator: torch.Generator | None = None):
    """Make one trial per individual.

    Returns:
        ``(trials (NP, D), F (NP,), CR (NP,))``: the trial vectors and the control parameters used
        (equal to ``cfg.F``/``cfg.CR`` unless ``cfg.jde``).
    """
    x = state.x
    n, d = x.shape
    F, CR = state.F, state.CR
    if cfg.jde:
        u = _rand((4, n), generator, x)
        F = torch.where(u[0] < cfg.jde_tau, cfg.jde_F_min + u[1] * (cfg.jde_F_max - cfg.jde_F_min), F)
        CR = torch.where(u[2] < cfg.jde_tau, u[3], CR)
    # three distinct partners per target, none equal to the target: smallest 3 of a random row
    keys = _rand((n, n), generator, x)
    keys.fill_diagonal_(2.0)
    r = keys.topk(3, dim=1, largest=False).indices  # (NP, 3)
    Fc = F[:, None]
    if cfg.strategy == "rand1bin":
        v = x[r[:, 0]] + Fc * (x[r[:, 1]] - x[r[:, 2]])
    else:  # current_to_best1bin
        best = x[torch.argmin(state.fitness)]
        v = x + Fc * (best - x) + Fc * (x[r[:, 0]] - x[r[:, 1]])
    u = _rand((n, d), generator, x)
    j_rand = (_rand((n,), generator, x) * d).long().clamp_max(d - 1)
    cross = u < CR[:, None]
    cross[torch.arange(n, device=x.device), j_rand] = True
    trials = torch.where(cross, v, x)
    if state.lower is not None:
        lo, hi = state.lower, state.upper
        w = _rand((n, d), generator, x)
        trials = torch.where(trials < lo, x + w * (lo - x), trials)
        trials = torch.where(trials > hi, x + w * (hi - x), trials)
    return trials, F, CR


def de_tell(
    state: DEState,
    trials: torch.Tensor,
    trial_fitness: torch.Tensor,
    F: torch.Tensor,
    CR: torch.Tensor,
    *,
    parent_fitness: torch.Tensor | None = None,
) -> DEState:
    """Greedy selection. ``parent_fitness: (NP,)`` replaces the stored parent fitness first (when the
    fitness was re-evaluated on this generation's mini-batch, so both sides see the same samples)."""
    fit = state.fitness if parent_fitness is None else parent_fitness.to(state.fitness.dtype)
    # a NaN fitness counts as +inf: a NaN trial never wins, a NaN parent always loses
    fit = torch.nan_to_num(fit, nan=float("inf"))
    trial_fitness = torch.nan_to_num(trial_fitness.to(fit.dtype), nan=float("inf"))
    win = trial_fitness <= fit
    x = torch.where(win[:, None], trials, state.x)
    fitness = torch.where(win, trial_fitness, fit)
    evals = state.evals + trials.shape[0] + (0 if parent_fitness is None else parent_fitness.shape[0])
    return DEState(
        x,
        fitness,
        torch.where(win, F, state.F),
        torch.where(win, CR, state.CR),
        state.lower,
        state.upper,
        state.generation + 1,
        evals,
    )


def de_step(
    state: DEState,
    fitness_fn: Callable[[torch.Tensor], torch.Tensor],
    cfg: DECfg,
    *,
    generator: torch.Generator | None = None,
    reevaluate: bool = False,
) -> DEState:
    """One generation: ask, evaluate all trials in one call of ``fitness_fn((M, D)) -> (M,)``, tell.

    ``reevaluate=True`` evaluates parents and trials together (one call on ``2 NP`` vectors), for a
    fitness that changes between generations (a random mini-batch of samples).
    """
    trials, F, CR = de_ask(state, cfg, generator=generator)
    if reevaluate:
        both = fitness_fn(torch.cat([state.x, trials]))
        n = state.x.shape[0]
        return de_tell(state, trials, both[n:], F, CR, parent_fitness=both[:n])
    return de_tell(state, trials, fitness_fn(trials), F, CR)


def de_minimize(
    fitness_fn: Callable[[torch.Tensor], torch.Tensor],
    x0: torch.Tensor,
    cfg: DECfg,
    generations: int,
    *,
    generator: torch.Generator | None = None,
    lower: torch.Tensor | None = None,
    upper: torch.Tensor | None = None,
) -> DEState:
    """Run ``generations`` generations from the initial population ``x0: (NP, D)``; return the final state."""
    state = de_init(x0, fitness_fn(x0), cfg, lower=lower, upper=upper)
    for _ in range(int(generations)):
        state = de_step(state, fitness_fn, cfg, generator=generator)
    return state
