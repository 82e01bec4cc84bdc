"""Refiners: ``(robot, T, q0) -> RefineResult`` joint answers brought to tolerance from guesses.

- :func:`lm_refine`: Levenberg-Marquardt (:func:`nik.lm.lm_solve`) with restarts only for the
  targets that fail and are within reach; one pose on the CPU takes the numpy lean path
  (:mod:`nik.lm.single`), where torch's per-op overhead would dominate;
- :func:`swarm_refine`: the swarm methods through :func:`nik.swarm.refine`, answers measured by FK.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.lm import LMCfg, SingleLM, best_of, lm_solve, lm_solve_one
from nik.lm.single import _residual as _residual_one
from nik.poses import pose_error
from nik.robots import Robot

__all__ = ["RefineResult", "lm_refine", "swarm_refine"]


@dataclass
class RefineResult:
    """What a refiner returns for B targets: ``q (B, dof)``, ``pos_err``, ``rot_err`` ``(B,)`` by FK,
    ``iterations (B,)`` long."""

    q: torch.Tensor
    pos_err: torch.Tensor
    rot_err: torch.Tensor
    iterations: torch.Tensor


def lm_refine(
    robot: Robot,
    T: torch.Tensor,
    q0: torch.Tensor | None,
    *,
    tol_pos: float,
    tol_rot: float,
    seed: int = 0,
    max_iters: int | None = None,
    cfg=None,
    restarts: bool = True,
    reachable: torch.Tensor | None = None,
) -> RefineResult:
    """Levenberg-Marquardt from ``q0: (B, dof)`` (None: a multistart guess), restarting only the
    targets that fail and are within reach (``restarts=False``: none). ``T: (B, 4, 4)``."""
    cfg = cfg if isinstance(cfg, LMCfg) else LMCfg()
    g = torch.Generator(device=T.device).manual_seed(int(seed))
    if T.shape[0] == 1 and T.device.type == "cpu":
        return _lm_refine_one(robot, T, q0, tol_pos, tol_rot, max_iters, cfg, restarts, reachable, g)
    q, it = lm_solve(
        robot,
        T,
        q0,
        cfg=cfg,
        tol_pos=tol_pos,
        tol_rot=tol_rot,
        max_iters=max_iters,
        restarts=None if restarts else 0,
        generator=g,
        reachable=reachable,
    )
    q = robot.clamp(q)
    pos, rot = pose_error(T, robot.fk(q, check=False))
    return RefineResult(q, pos, rot, it)


def _lm_refine_one(robot, T, q0, tol_pos, tol_rot, max_iters, cfg, restarts, reachable, g) -> RefineResult:
    """:func:`lm_refine` for one pose on the CPU: the numpy lean path (:mod:`nik.lm.single`)."""
    model = _SINGLE_CACHE.get(id(robot))
    if model is None or model[0] is not robot:
        model = (robot, SingleLM.from_robot(robot))
        _SINGLE_CACHE[id(robot)] = model
    model = model[1]
    Tn = T[0].detach().to(torch.float64).numpy()

    def sample():
        return robot.sample(1, generator=g, dtype=torch.float64)[0].numpy()

    if q0 is None:
        # one vectorised FK of many candidates costs about one LM iteration here: take more than the batch does
        cand = robot.sample(SINGLE_FIRST_STARTS, generator=g, dtype=torch.float64).numpy()
        start = best_of(model, Tn, cand, cfg.rot_weight)
    else:
        start = q0.reshape(-1, robot.dof)[0].detach().to(torch.float64).numpy()
    n_restarts = cfg.restarts + cfg.tail_starts * (1 + cfg.tail_restarts) if restarts else 0
    if reachable is not None and not bool(reachable[0]):
        n_restarts = 0
    q, it = lm_solve_one(
        model,
        Tn,
        start,
        cfg=cfg,
        tol_pos=tol_pos,
        tol_rot=tol_rot,
        first_iters=cfg.iters if max_iters is None else int(max_iters),
        restarts=n_restarts,
        sample=sample,
    )
    _, _, pos, rot = _residual_one(Tn, model.fk_many(q[None])[0], cfg.rot_weight)
    q = torch.as_tensor(q, dtype=T.dtype).reshape(1, -1)
    err = torch.tensor([pos, rot], dtype=T.dtype)
    return RefineResult(q, err[:1], err[1:], torch.tensor([it], dtype=torch.long))


_SINGLE_CACHE: dict = {}

#: Uniform candidates whose best (by pose error) starts the one-pose LM when there is no guess.
SINGLE_FIRST_STARTS = 64


def swarm_refine(
    robot: Robot,
    T: torch.Tensor,
    q0: torch.Tensor | None,
    *,
    method: str,
    tol_pos: float,
    tol_rot: float,
    seed: int = 0,
    max_iters: int | None = None,
    cfg=None,
    polish: bool = True,
) -> RefineResult:
    """A swarm (``method``: ``pso`` | ``sapso`` | ``ipso`` | ``ga``) through :func:`nik.swarm.refine`, seeded
    around ``q0: (B, dof)`` (None: uniform particles), finished by the LM polish unless ``polish=False``.
    ``T: (B, 4, 4)``; the answers are brought inside the limits and measured by FK."""
    from nik.swarm import refine

    res = refine(
        robot,
        T,
        method=method,
        q_init=q0,
        cfg=cfg,
        tol_pos=tol_pos,
        tol_rot=tol_rot,
        max_iters=max_iters,
        seed=seed,
        polish=polish,
    )
    q = robot.clamp(res.q)
    pos, rot = pose_error(T, robot.fk(q))
    return RefineResult(q, pos, rot, res.iterations)
