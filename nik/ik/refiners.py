"""Refiners: ``(robot, T, q0) -> RefineResult`` joint answers brought to tolerance from guesses.

- :func:`lm_refine`: Levenberg-Marquardt (:func:`nik.lm.lm_solve`) with restarts only for the
  targets that fail and are within reach; one pose on the CPU takes the compiled kernel
  (:mod:`nik.lm.compiled`), where torch's per-op overhead would dominate, except while the kernels compile in the
  background (:data:`nik.kernels.background.BUSY`: the torch LM answers meanwhile);
- :func:`swarm_refine`: the swarm methods through :func:`nik.swarm.refine`, answers measured by FK.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nik.kernels import background
from nik.lm import LMCfg, lm_solve
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
    local: bool = False,
) -> RefineResult:
    """Levenberg-Marquardt from ``q0: (B, dof)`` (None: a multistart guess), restarting only the
    targets that fail and are within reach (``restarts=False``: none). ``T: (B, 4, 4)``. ``local``: no joint
    wraps (:func:`nik.lm.lm_solve`)."""
    cfg = cfg if isinstance(cfg, LMCfg) else LMCfg()
    if T.shape[0] == 1 and T.device.type == "cpu" and not background.BUSY:  # not while kernels compile (background)
        return _lm_refine_one(robot, T, q0, tol_pos, tol_rot, max_iters, cfg, restarts, reachable, int(seed), local)
    g = torch.Generator(device=T.device).manual_seed(int(seed))
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
        wrap=not local,
    )
    q = robot.clamp(q)
    pos, rot = pose_error(T, robot.fk(q, check=False))
    return RefineResult(q, pos, rot, it)


def _lm_refine_one(robot, T, q0, tol_pos, tol_rot, max_iters, cfg, restarts, reachable, seed, local) -> RefineResult:
    """:func:`lm_refine` for one pose on the CPU: the compiled kernel (:mod:`nik.lm.compiled`)."""
    from nik.lm.compiled import CompiledLM

    Tn = np.ascontiguousarray(T.detach().numpy().reshape(1, 4, 4), dtype=np.float64)
    start = None if q0 is None else np.ascontiguousarray(q0.detach().numpy().reshape(1, -1), dtype=np.float64)
    run = CompiledLM.of(robot, cfg).solve(
        Tn,
        start,
        tol_pos=tol_pos,
        tol_rot=tol_rot,
        seed=seed,
        max_iters=max_iters,
        restarts=restarts,
        reachable=None if reachable is None else reachable.numpy(),
        local=local,
    )
    return RefineResult(
        torch.from_numpy(run.q).to(T.dtype),
        torch.from_numpy(run.pos_err).to(T.dtype),
        torch.from_numpy(run.rot_err).to(T.dtype),
        torch.from_numpy(run.iterations),
    )


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
