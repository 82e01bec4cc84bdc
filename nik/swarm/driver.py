"""The thin driver: run a swarm (or LM) over a batch of targets until tolerance or the iteration limit."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import torch

from nik.lm import LMCfg, lm_solve
from nik.poses import pose_error, validate_joints, validate_pose
from nik.robots.model import Robot
from nik.swarm.bounds import BOUNDARY_STRATEGIES
from nik.swarm.ga import GACfg, ga_init, ga_step
from nik.swarm.ipso import IPSOCfg, ipso_init, ipso_step
from nik.swarm.objectives import make_objective
from nik.swarm.problem import SwarmProblem, make_problem
from nik.swarm.pso import PSOCfg, pso_init, pso_step
from nik.swarm.sapso import SAPSOCfg, sapso_init, sapso_step
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["ALGORITHMS", "METHODS", "Polish", "SwarmResult", "SwarmRun", "default_cfg", "refine", "run_swarm"]


class _Algorithm(NamedTuple):
    cfg: type
    init: Any
    step: Any


ALGORITHMS = {
    "pso": _Algorithm(PSOCfg, pso_init, pso_step),
    "sapso": _Algorithm(SAPSOCfg, sapso_init, sapso_step),
    "ipso": _Algorithm(IPSOCfg, ipso_init, ipso_step),
    "ga": _Algorithm(GACfg, ga_init, ga_step),
}
METHODS = (*ALGORITHMS, "lm")


class Polish(NamedTuple):
    """The LM polish of :func:`refine` (``polish=Polish(...)``; ``polish=True`` is ``Polish()``): ``cfg`` the LM's
    settings (None: :class:`nik.lm.LMCfg`'s), ``starts`` the best remembered particles each failing target starts
    from."""

    cfg: LMCfg | None = None
    starts: int = 1


def default_cfg(method: str):
    """The default (paper) configuration of ``method``."""
    if method == "lm":
        return LMCfg()
    if method not in ALGORITHMS:
        raise ValueError(f"unknown refinement method {method!r}; expected one of {list(METHODS)}")
    return ALGORITHMS[method].cfg()


@dataclass
class SwarmResult:
    """Result of :func:`refine` for B targets.

    Attributes:
        q: (B, dof) joint angles, radians, always inside the limits.
        pos_err: (B,) position error of ``q``, metres (measured by FK on the returned q).
        rot_err: (B,) geodesic rotation error of ``q``, radians.
        success: (B,) bool, ``pos_err <= tol_pos`` and ``rot_err <= tol_rot``.
        iterations: (B,) long, swarm iterations (or LM iterations for ``method="lm"``) used.
        polish_iterations: (B,) long, LM iterations spent by ``polish=True`` (zeros otherwise).
        history: (iterations + 1, B) best objective value after each iteration (converged
            targets keep their last value), or None unless ``history=True``.
        method: the method used.
    """

    q: torch.Tensor
    pos_err: torch.Tensor
    rot_err: torch.Tensor
    success: torch.Tensor
    iterations: torch.Tensor
    polish_iterations: torch.Tensor
    history: torch.Tensor | None
    method: str


class SwarmRun(NamedTuple):
    """What :func:`run_swarm` returns."""

    x: torch.Tensor  # (B, n) best position of each target
    f: torch.Tensor  # (B,) its objective value
    iterations: torch.Tensor  # (B,) long
    history: torch.Tensor | None  # (T + 1, B) best objective per iteration
    top_x: torch.Tensor  # (B, k, n) the k best remembered positions (gbest repeated for converged targets)


def _select(state, idx: torch.Tensor):
    return type(state)(*[v[idx] if isinstance(v, torch.Tensor) else v for v in state])


def run_swarm(
    problem: SwarmProblem,
    method: str,
    cfg,
    q_init: torch.Tensor | None,
    *,
    generator: torch.Generator,
    tol_pos: float,
    tol_rot: float,
    history: bool = False,
    top_k: int = 1,
) -> SwarmRun:
    """Iterate ``ALGORITHMS[method]`` for at most ``cfg.iters`` iterations.

    Before each step the global best of every still-active target is checked against the
    tolerances (position metres, rotation radians); targets within both are recorded and
    dropped from the state, so they cost nothing more; the loop ends when none is left.
    Pass negative tolerances to always run ``cfg.iters`` iterations (paper protocols).
    """
    algo = ALGORITHMS[method]
    state = algo.init(problem, cfg, q_init, generator=generator)
    B, n = problem.batch, problem.n
    device = state.gbest_x.device
    best_x, best_f = state.gbest_x.clone(), state.gbest_f.clone()
    top_x = best_x.unsqueeze(1).repeat(1, top_k, 1)
    iterations = torch.zeros(B, dtype=torch.long, device=device)
    hist = [best_f.clone()] if history else None
    active = torch.arange(B, device=device)
    prob = problem
    check = tol_pos >= 0 and tol_rot >= 0
    for _ in range(cfg.iters):
        if check:
            pos, rot = prob.errors(state.gbest_x)
            done = (pos <= tol_pos) & (rot <= tol_rot)
            if bool(done.any()):
                best_x[active[done]] = state.gbest_x[done]
                best_f[active[done]] = state.gbest_f[done]
                keep = (~done).nonzero().squeeze(1)
                active = active[keep]
                state = _select(state, keep)
                prob = prob.subset(keep)
                if active.numel() == 0:
                    break
        state = algo.step(state, prob, cfg, generator=generator)
        iterations[active] += 1
        if history:
            best_f[active] = state.gbest_f
            hist.append(best_f.clone())
    if active.numel():
        best_x[active] = state.gbest_x
        best_f[active] = state.gbest_f
        mem_x, mem_f = state.memory
        k = min(top_k, mem_f.shape[1])
        idx = mem_f.topk(k, dim=1, largest=False).indices
        top_x[active, :k] = torch.gather(mem_x, 1, idx[..., None].expand(-1, -1, n))
    return SwarmRun(best_x, best_f, iterations, torch.stack(hist) if history else None, top_x)


def refine(
    robot: Robot,
    T_target: torch.Tensor,
    *,
    method: str = "ipso",
    q_init: torch.Tensor | None = None,
    cfg=None,
    tol_pos: float = DEFAULT_TOL_POS,
    tol_rot: float = DEFAULT_TOL_ROT,
    max_iters: int | None = None,
    seed: int = 0,
    polish: bool | Polish = False,
    history: bool = False,
    compiled: bool = False,
) -> SwarmResult:
    """Solve IK for a batch of targets by a swarm (or Levenberg-Marquardt), to tolerance.

    Args:
        robot: the arm.
        T_target: (B, 4, 4) wanted tool poses, metres; dtype and device of the computation.
        method: ``ipso`` (paper D's improved PSO), ``pso`` (classic), ``sapso`` (paper A),
            ``ga`` (paper D's baseline) or ``lm`` (no swarm: damped least squares from the guesses,
            or from the best of ``LMCfg.first_starts`` uniform configurations when ``q_init`` is None;
            restarts for the targets that fail, see :func:`nik.lm.lm_solve`).
        q_init: None (uniform particles inside the limits, the papers' behaviour) or guesses
            ``(B, dof)`` / ``(B, K, dof)``, radians: particles start around them (``cfg.init``).
        cfg: the method's config (:class:`PSOCfg`, :class:`SAPSOCfg`, :class:`IPSOCfg`,
            :class:`GACfg`, :class:`LMCfg`); default the paper settings.
        tol_pos, tol_rot: success and stopping tolerances, metres and radians.
        max_iters: overrides ``cfg.iters`` (also the horizon of time schedules).
        seed: seeds a ``torch.Generator`` on ``T_target``'s device: same seed, same result.
        polish: finish targets the swarm left outside tolerance with LM (:func:`nik.lm.lm_solve`, the one torch
            LM) from the best remembered particles: True (:class:`Polish` defaults) or a :class:`Polish` (its
            ``cfg`` and number of ``starts``).
        history: record the best objective value per iteration.
        compiled: use the ``torch.compile``'d FK kernel for the particles (large batches).

    Returns:
        :class:`SwarmResult`; errors and success are measured on the returned ``q``.
    """
    T_target = validate_pose(T_target, name="T_target")
    if T_target.ndim != 3:
        raise ValueError(f"T_target: expected shape (B, 4, 4), got {tuple(T_target.shape)}")
    if method not in METHODS:
        raise ValueError(f"unknown refinement method {method!r}; expected one of {list(METHODS)}")
    B, dof = T_target.shape[0], robot.dof
    dtype, device = T_target.dtype, T_target.device
    if q_init is not None:
        validate_joints(q_init, dof, name="q_init")
        if q_init.ndim not in (2, 3) or q_init.shape[0] != B:
            raise ValueError(f"q_init: expected shape ({B}, {dof}) or ({B}, K, {dof}), got {tuple(q_init.shape)}")
        q_init = q_init.to(dtype=dtype, device=device)
    cfg = cfg if cfg is not None else default_cfg(method)
    expected = LMCfg if method == "lm" else ALGORITHMS[method].cfg
    if not isinstance(cfg, expected):
        raise ValueError(f"cfg for method {method!r} must be a {expected.__name__}, got {type(cfg).__name__}")
    if method != "lm" and cfg.boundary not in BOUNDARY_STRATEGIES:
        raise ValueError(f"unknown boundary strategy {cfg.boundary!r}; expected one of {list(BOUNDARY_STRATEGIES)}")
    if max_iters is not None:
        if int(max_iters) < 0:
            raise ValueError(f"max_iters must be >= 0, got {max_iters}")
        cfg = replace(cfg, iters=int(max_iters))
    generator = torch.Generator(device=device)
    generator.manual_seed(int(seed))
    if polish is not False and not isinstance(polish, bool | Polish):
        got = type(polish).__name__
        raise ValueError(f"polish: expected True, False or nik.swarm.driver.Polish(cfg, starts), got {got}")
    polish_cfg, polish_starts = polish if isinstance(polish, Polish) else Polish()
    polish_it = torch.zeros(B, dtype=torch.long, device=device)
    hist = None

    if method == "lm":
        q, iterations = lm_solve(
            robot, T_target, q_init, cfg=cfg, tol_pos=tol_pos, tol_rot=tol_rot, generator=generator
        )
    else:
        objective = make_objective(cfg.objective, rot_weight=cfg.rot_weight)
        problem = make_problem(robot, T_target, objective, compiled=compiled)
        run = run_swarm(
            problem,
            method,
            cfg,
            q_init,
            generator=generator,
            tol_pos=tol_pos,
            tol_rot=tol_rot,
            history=history,
            top_k=max(1, polish_starts),
        )
        q, iterations, hist = run.x, run.iterations, run.history
        if polish:
            pos, rot = pose_error(T_target, robot.fk(q))
            need = ~((pos <= tol_pos) & (rot <= tol_rot))
            if bool(need.any()):
                idx = need.nonzero().squeeze(1)
                starts = torch.cat([q[idx, None], run.top_x[idx]], dim=1) if polish_starts > 1 else q[idx, None]
                qp, itp = lm_solve(
                    robot, T_target[idx], starts, cfg=polish_cfg, tol_pos=tol_pos, tol_rot=tol_rot, generator=generator
                )
                q = q.clone()
                q[idx] = qp
                polish_it[idx] = itp
    q = robot.clamp(q)
    pos, rot = pose_error(T_target, robot.fk(q))
    success = (pos <= tol_pos) & (rot <= tol_rot)
    return SwarmResult(q, pos, rot, success, iterations, polish_it, hist, method)
