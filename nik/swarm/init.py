"""Initial particles: uniform inside the limits (the papers' behaviour), or around joint guesses."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.swarm.bounds import apply_bounds
from nik.swarm.problem import SwarmProblem

__all__ = ["InitCfg", "init_particles"]


@dataclass
class InitCfg:
    """How particles start.

    With no guesses every particle is uniform inside the limits. With guesses ``(B, K, dof)``,
    ``round(uniform_fraction * P)`` particles are uniform and the rest are spread around the
    K guesses in turn (guess ``k`` gets particles ``k, k + K, ...``).
    """

    spread: float = 0.05  # rad, std of the Gaussian cloud around a guess
    uniform_fraction: float = 0.1  # share of uniform particles when guesses are given, in [0, 1]
    keep_guess: bool = True  # the first particle of each guess sits exactly on it (never worse than the guess)
    velocity_fraction: float = 0.1  # uniform particles: |v0| <= this * (hi - lo); seeded ones: |v0| <= spread


def init_particles(
    problem: SwarmProblem,
    n_particles: int,
    q_init: torch.Tensor | None,
    cfg: InitCfg,
    *,
    generator: torch.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Initial positions and velocities, each ``(B, P, n)`` over the problem's free joints.

    Args:
        q_init: None, or full joint guesses ``(B, dof)`` / ``(B, K, dof)``, radians.
    """
    B, n, P = problem.batch, problem.n, int(n_particles)
    lo, hi = problem.lo, problem.hi
    dtype, device = lo.dtype, lo.device
    span = hi - lo
    x = lo + torch.rand(B, P, n, generator=generator, dtype=dtype, device=device) * span
    v = (2 * torch.rand(B, P, n, generator=generator, dtype=dtype, device=device) - 1) * (cfg.velocity_fraction * span)
    if q_init is None:
        return x, v
    guesses = q_init if q_init.ndim == 3 else q_init.unsqueeze(1)
    guesses = guesses.to(dtype=dtype, device=device)[..., problem.free]  # (B, K, n)
    K = guesses.shape[1]
    n_seeded = P - int(round(cfg.uniform_fraction * P))
    if n_seeded <= 0:
        return x, v
    which = torch.arange(n_seeded, device=device) % K
    centre = guesses[:, which]  # (B, S, n)
    noise = torch.randn(B, n_seeded, n, generator=generator, dtype=dtype, device=device) * cfg.spread
    if cfg.keep_guess:
        noise[:, : min(K, n_seeded)] = 0
    xs, _ = apply_bounds(centre + noise, None, lo, hi, problem.wrap, "clamp")
    vs = (2 * torch.rand(B, n_seeded, n, generator=generator, dtype=dtype, device=device) - 1) * cfg.spread
    x = torch.cat([xs, x[:, n_seeded:]], dim=1)
    v = torch.cat([vs, v[:, n_seeded:]], dim=1)
    return x, v
