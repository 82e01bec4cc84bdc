"""Levenberg-Marquardt IK, batched, with restarts only for the targets that fail.

Error of a configuration (6-vector, base frame)::

    e = [p* - p ;  rot_weight * log(R* R^T)]          (metres; rot_weight metres per radian)

with ``log`` the rotation vector (axis times angle; its norm is the geodesic angle, computed as
``atan2(|sin|, cos)`` so it is exact at every angle) and the geometric Jacobian of
:func:`nik.kinematics.chain_jacobian` (rotation rows scaled alike). Step::

    dq = (J^T J + lambda (diag(J^T J) + eps) + eps I)^-1 J^T e        (Marquardt scaling)

solved by a Cholesky factorisation (``torch.linalg.cholesky_ex`` + ``cholesky_solve``; the matrix is
symmetric positive definite; a failed factorisation counts as a rejected step), limited to ``max_step``
radians per joint, then brought inside the limits (wrapping joints wrap, the others are clamped).
A step is kept only if it lowers ``|e|^2``; lambda then shrinks by ``lambda_down``, otherwise it
grows by ``lambda_up``. One iteration costs one FK + Jacobian per row. The iteration is the one torch LM
(:func:`nik.lm.loop.lm_loop`) with the pose rows of :func:`pose_evaluator`.

Per-target work (:func:`lm_solve`, :func:`lm_run`):

1. every target starts from its guesses ``(B, K, dof)`` (or, without guesses, from the best of
   ``first_starts`` uniform configurations by pose error);
2. a target leaves the batch as soon as one of its starts is within tolerance;
3. a start is *spent* when it stalls (``stall_iters`` iterations in a row that lower ``|e|^2`` by
   less than the fraction ``stall_rel``) or after ``iters`` iterations; a spent start of a target
   that is not provably out of reach (:func:`nik.robots.reach.within_reach`) and has restarts left is
   replaced, in the same batch, by a fresh uniform start (at most ``restarts`` per target). So
   only failing targets draw restarts, the batch stays large, and a provably unreachable target
   costs one start (stopped early by the stall test).

The answer of a target is its converged start with the lowest error, or else the start with the
lowest error it saw (best effort). Random starts come from one ``torch.Generator``: same seed,
same result.

Tolerant goals (``bounds=``: ``(B, 6)`` half-widths per target along the target's tool axes, ``inf`` = free;
:mod:`nik.ik.bounds`): the error is :func:`bounded_residual`, the compiled kernel's
(:mod:`nik.kernels.lm`, module docstring): TRAC-IK's error in the target's tool frame (the swing of a free
tool axis), a dead-zone residual at half of each bound, the exact Jacobian of the error with the rows of free
axes zero; a target converges when every axis lies inside its bound, and a step that gets there is kept even if
the dead-zone error grew.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from functools import partial
from typing import NamedTuple

import torch

from nik.costs.pose import DEAD_ZONE, bounded_residual
from nik.costs.pose import dead_zone as _dead_zone
from nik.kinematics import chain_jacobian
from nik.lm.loop import Box, Eval, LMCfg, LMRun, Restarts, lm_loop
from nik.poses import matrix_to_quaternion, rotation_modes, tool_error
from nik.robots.joints import wrap_mask
from nik.robots.model import Robot
from nik.robots.reach import within_reach
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["DEAD_ZONE", "Chain", "LMCfg", "LMRun", "bounded_residual", "chain_of", "lm_run", "lm_solve",
           "pose_evaluator", "so3_log"]  # fmt: skip


def so3_log(R: torch.Tensor) -> torch.Tensor:
    """Rotation vector ``(..., 3)`` of ``R: (..., 3, 3)`` (angle in [0, pi] times the unit axis).

    Through the unit quaternion (Shepperd's method, ``w >= 0``): ``2 atan2(|v|, w) v / |v|``,
    with the limit ``2 v / w`` near the identity; robust at every angle, including pi.
    """
    quat = matrix_to_quaternion(R)
    w, v = quat[..., :1], quat[..., 1:]
    nv = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    small = nv < 1e-7
    scale = torch.where(small, 2.0 / w.clamp_min(1e-12), 2.0 * torch.atan2(nv, w) / nv.clamp_min(1e-30))
    return v * scale


def _residual(Tt: torch.Tensor, T: torch.Tensor, rw: float):
    """Weighted error ``e (..., 6)``, ``E = |e|^2``, position error and angle for ``(..., 3, 4)`` poses.

    The rotation part is ``theta * axis`` of ``R* R^T``: ``s = vee(asym(M)) = sin(theta) axis``,
    ``cos(theta) = (trace M - 1) / 2``, ``theta = atan2(|s|, cos)`` (exact at every angle).
    """
    dp = Tt[..., :, 3] - T[..., :, 3]
    M = Tt[..., :, :3] @ T[..., :, :3].transpose(-1, -2)
    s = 0.5 * torch.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1)
    c = 0.5 * (M[..., 0, 0] + M[..., 1, 1] + M[..., 2, 2] - 1.0)
    sn = torch.linalg.vector_norm(s, dim=-1)
    theta = torch.atan2(sn, c)
    scale = torch.where(sn > 1e-12, theta / sn.clamp_min(1e-300), torch.ones_like(sn))
    w = s * (rw * scale)[..., None]
    pos2 = (dp * dp).sum(-1)
    E = pos2 + (rw * theta) ** 2
    return torch.cat([dp, w], dim=-1), E, pos2.sqrt(), theta


def _evaluate_bounded(q, Tt, bounds, G, offsets, rw: float, **kw):
    """FK, Jacobian and bounded error of ``q: (B, K, n)`` against ``Tt: (B, 1, 3, 4)``, ``bounds: (B, 1, 6)``:
    ``e (B, K, 6)``, ``J (B, K, 6, n)``, ``E, pos, rot, inside (B, K)``."""
    B, K, n = q.shape
    T, J = chain_jacobian(q.reshape(-1, n), G, offsets, **kw)
    return bounded_residual(Tt, T.reshape(B, K, 3, 4), J.reshape(B, K, 6, n), bounds, rw)


def _evaluate_eager(q, Tt, G, offsets, row_w, rw: float, **kw):
    """FK, weighted Jacobian and error of ``q: (B, K, n)`` against ``Tt: (B, 1, 3, 4)``:
    ``e (B, K, 6)``, ``J (B, K, 6, n)``, ``E, pos, rot (B, K)``."""
    B, K, n = q.shape
    T, J = chain_jacobian(q.reshape(-1, n), G, offsets, **kw)
    e, E, pos, rot = _residual(Tt, T.reshape(B, K, 3, 4), rw)
    return e, J.reshape(B, K, 6, n) * row_w, E, pos, rot


_compiled_evaluate = None
_compile_failed = False


def _evaluator(compiled: bool):
    """:func:`_evaluate_eager`, or its ``torch.compile`` (dynamic shapes) with an eager fallback: when
    compiling or running fails, a warning is given once and the eager version is used from then on."""
    if not compiled or _compile_failed:
        return _evaluate_eager

    def run(*args):
        global _compiled_evaluate, _compile_failed
        if not _compile_failed:
            try:
                if _compiled_evaluate is None:
                    _compiled_evaluate = torch.compile(_evaluate_eager, dynamic=True)
                return _compiled_evaluate(*args)
            except Exception as err:  # pragma: no cover - depends on the platform's compiler
                _compile_failed = True
                warnings.warn(f"compiled LM kernel failed ({type(err).__name__}: {err}); using eager", stacklevel=2)
        return _evaluate_eager(*args)

    return run


class Chain(NamedTuple):
    """The arm as :func:`lm_run` takes it: the normal form ``G, offsets`` (:mod:`nik.kinematics`) in the dtype/device
    of the targets, ``lo, hi: (dof,)`` limits, ``wrap: (dof,)`` bool, ``prismatic: (dof,)`` bool or None (all
    revolute)."""

    G: torch.Tensor
    offsets: torch.Tensor
    lo: torch.Tensor
    hi: torch.Tensor
    wrap: torch.Tensor
    prismatic: torch.Tensor | None = None


def chain_of(robot: Robot, like: torch.Tensor, wrap: bool = True) -> Chain:
    """:class:`Chain` of ``robot`` in the dtype/device of ``like``; ``wrap=False``: no joint wraps (all clamped)."""
    G, off = robot._params(like)
    lo, hi = robot.limits_as(like)
    wraps = wrap_mask(robot.limits, prismatic=robot.prismatic).to(like.device) & wrap
    return Chain(G, off, lo, hi, wraps, robot.prismatic.to(like.device))


def pose_evaluator(T_target: torch.Tensor, chain: Chain, cfg: LMCfg, tol: tuple[float, float], bounds=None):
    """``evaluate(q (b, K, n), rows) -> Eval`` of :func:`nik.lm.loop.lm_loop` for the pose rows towards
    ``T_target: (B, 3|4, 4)`` (module docstring): done within ``tol = (tol_pos, tol_rot)`` (m, rad), or with
    ``bounds: (B, 6)`` inside every bound (the bounded error)."""
    dtype, device = T_target.dtype, T_target.device
    rw = cfg.rot_weight
    row_w = torch.tensor([1.0, 1.0, 1.0, rw, rw, rw], dtype=dtype, device=device)[:, None]
    prismatic = chain.prismatic
    kw = {"prismatic": prismatic} if prismatic is not None and bool(prismatic.any()) else {}
    kernel = _evaluator(cfg.compiled and not kw)
    Tt = T_target[:, None, :3, :]
    bnd = None if bounds is None else bounds.to(dtype=dtype, device=device)[:, None, :]
    G, off = chain.G, chain.offsets
    last = [None, Tt, bnd]  # the rows of the last call and their targets (the loop changes rows when it compacts)

    def evaluate(q, rows):
        if rows is not last[0]:
            full = rows.shape[0] == Tt.shape[0]
            last[:] = rows, (Tt if full else Tt[rows]), (bnd if full or bnd is None else bnd[rows])
        T, b = last[1], last[2]
        if b is not None:
            e, J, E, _, _, inside = _evaluate_bounded(q, T, b, G, off, rw, **kw)
            return Eval(e, J, E, inside)
        if kw:
            e, J, E, pos, rot = _evaluate_eager(q, T, G, off, row_w, rw, **kw)
        else:
            e, J, E, pos, rot = kernel(q, T, G, off, row_w, rw)
        return Eval(e, J, E, (pos <= tol[0]) & (rot <= tol[1]))

    return evaluate


def lm_run(
    T_target: torch.Tensor,
    q0: torch.Tensor,
    chain: Chain,
    *,
    cfg: LMCfg,
    tol_pos: float,
    tol_rot: float,
    iters: int,
    restarts: int = 0,
    first_iters: int | None = None,
    sampler=None,
    reachable: torch.Tensor | None = None,
    bounds: torch.Tensor | None = None,
) -> LMRun:
    """Levenberg-Marquardt from ``q0: (B, K, dof)`` towards ``T_target: (B, 3|4, 4)``, restarting in place: the one
    loop (:func:`nik.lm.loop.lm_loop`) on the pose rows (:func:`pose_evaluator`).

    Each of the ``B x K`` rows is one start. A row that stalls (``cfg.stall_iters`` iterations without
    progress) or runs ``iters`` iterations without converging is, while its target has restarts left
    (``restarts`` per target) and is ``reachable``, replaced in the same batch by a fresh start
    ``sampler(m) -> (m, dof)``; it costs no extra evaluation (the new start is evaluated where the
    candidate step would be); the starts of ``q0`` run ``first_iters`` iterations at most (default
    ``iters``). A target leaves the batch as soon as one of its rows converges, or when
    none of its rows can go on. Only failing targets ever draw restarts.

    ``chain``: the arm (:class:`Chain`). ``bounds: (B, 6)`` (None: the tolerances): tolerant goals
    (:func:`bounded_residual`; ``tol_pos, tol_rot`` then unused; a step that lands inside every bound is kept).
    """
    cfg = replace(cfg, iters=int(iters), accept="decrease" if bounds is None else "decrease_or_done")
    evaluate = pose_evaluator(T_target, chain, cfg, (tol_pos, tol_rot), bounds)
    box = Box(chain.lo, chain.hi, chain.wrap)
    rs = Restarts(int(restarts), sampler, reachable, first_iters)
    return lm_loop(evaluate, q0, box, cfg, restarts=rs)


def lm_solve(
    robot: Robot,
    T_target: torch.Tensor,
    q0: torch.Tensor | None,
    *,
    cfg: LMCfg | None = None,
    tol_pos: float = DEFAULT_TOL_POS,
    tol_rot: float = DEFAULT_TOL_ROT,
    max_iters: int | None = None,
    restarts: int | None = None,
    generator: torch.Generator | None = None,
    reachable: torch.Tensor | None = None,
    bounds: torch.Tensor | None = None,
    wrap: bool = True,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Levenberg-Marquardt from guesses, with restarts only for the targets that fail.

    Args:
        T_target: (B, 4, 4) (or (B, 3, 4)) wanted poses, metres.
        q0: (B, dof) or (B, K, dof) starts, radians (brought inside the limits first); None: the best
            of ``cfg.first_starts`` uniform configurations per target.
        tol_pos, tol_rot: stop a target when a start is within both (metres, radians).
        max_iters: iteration limit of the given starts (default ``cfg.iters``; restarts run ``cfg.iters``).
        restarts: fresh uniform starts a failing target may draw (default ``cfg.restarts``; 0: none).
        generator: source of the random starts (default: a generator seeded with 0).
        reachable: (B,) bool, targets allowed to restart (default :func:`nik.robots.reach.within_reach`):
            a provably unreachable target gets its first start only (best effort, success False).
        bounds: (B, 6) tolerant goals per target (half-widths along the target's tool axes, metres then
            radians, ``inf`` = free; :meth:`nik.ik.bounds.Bounds.expand`), or None for ``tol_pos, tol_rot``.
            Targets stop when inside every bound; the reach test (a bound on the position only, never looser) is
            skipped when a position axis is free.
        wrap: joints of a range of ``2 pi`` or more wrap (a step across a limit moves a whole turn); False: they are
            clamped like the others (the answer stays near the start, as ``q_near`` asks).

    Returns:
        ``q: (B, dof)`` inside the limits, and ``iterations: (B,)`` long.
    """
    cfg = cfg or LMCfg()
    first_iters = cfg.iters if max_iters is None else int(max_iters)
    iters = cfg.iters
    n_restarts = cfg.restarts if restarts is None else int(restarts)
    dtype, device = T_target.dtype, T_target.device
    if generator is None:
        generator = torch.Generator(device=device).manual_seed(0)
    chain = chain_of(robot, T_target, wrap)
    if bounds is not None:
        bounds = torch.as_tensor(bounds, dtype=dtype, device=device).expand(T_target.shape[0], 6)
    if q0 is None:
        q0 = _best_of_uniform(robot, T_target, cfg.first_starts, generator, bounds)
    q0 = (q0 if q0.ndim == 3 else q0.unsqueeze(1)).to(dtype=dtype, device=device)
    if n_restarts > 0 and reachable is None:
        reachable = within_reach(robot, T_target) if T_target.shape[-2] == 4 else None
        if reachable is not None and bounds is not None:  # a free position axis widens the reach
            reachable = reachable | torch.isinf(bounds[:, :3]).any(-1)
    run_from = partial(
        lm_run,
        chain=chain,
        cfg=cfg,
        tol_pos=tol_pos,
        tol_rot=tol_rot,
        iters=iters,
        sampler=lambda m: robot.sample(m, generator=generator, dtype=dtype, device=device),
    )
    run = run_from(
        T_target[..., :3, :], q0, first_iters=first_iters, restarts=n_restarts, reachable=reachable, bounds=bounds
    )
    q, it = run.q, run.iterations
    todo = ~run.converged
    if reachable is not None:
        todo &= reachable
    todo = todo.nonzero().squeeze(1)
    if n_restarts > 0 and cfg.tail_starts > 0 and todo.numel():
        # the few hard targets left: many starts side by side (few sequential iterations)
        S = cfg.tail_starts
        starts = robot.sample(todo.numel() * S, generator=generator, dtype=dtype, device=device)
        tail = run_from(
            T_target[todo][..., :3, :],
            starts.reshape(-1, S, robot.dof),
            restarts=cfg.tail_restarts,
            bounds=None if bounds is None else bounds[todo],
        )
        better = tail.converged | (tail.E < run.E[todo])
        q[todo[better]] = tail.q[better]
        it[todo] += tail.iterations
    return q, it


def _best_of_uniform(
    robot: Robot, T_target: torch.Tensor, m: int, generator: torch.Generator, bounds: torch.Tensor | None = None
) -> torch.Tensor:
    """``(B, 1, dof)``: per target, the one of ``m`` uniform configurations with the lowest pose error (the
    bounded error with ``bounds: (B, 6)``)."""
    B, n = T_target.shape[0], robot.dof
    q = robot.sample(B * m, generator=generator, dtype=T_target.dtype, device=T_target.device)
    if m == 1:
        return q.reshape(B, 1, n)
    q = q.reshape(B, m, n)
    T = robot.fk(q.reshape(-1, n), check=False).reshape(B, m, 4, 4)
    if bounds is None:
        _, E, _, _ = _residual(T_target[:, None, :3, :], T[..., :3, :], LMCfg.rot_weight)
    else:
        e = _dead_zone(tool_error(T_target[:, None], T, rotation_modes(bounds[:, None])), bounds[:, None])
        w = torch.tensor([1.0, 1.0, 1.0] + [LMCfg.rot_weight] * 3, dtype=e.dtype, device=e.device)
        E = ((e * w) ** 2).sum(-1)
    i = E.argmin(dim=1)
    return torch.gather(q, 1, i[:, None, None].expand(-1, 1, n))
