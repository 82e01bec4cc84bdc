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
grows by ``lambda_up``. One iteration costs one FK + Jacobian per row.

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
from dataclasses import dataclass
from functools import partial

import torch

from nik.costs.pose import DEAD_ZONE, bounded_residual
from nik.costs.pose import dead_zone as _dead_zone
from nik.kinematics import chain_jacobian
from nik.poses import matrix_to_quaternion, rotation_modes, tool_error
from nik.robots.joints import wrap_into, wrap_mask
from nik.robots.model import Robot
from nik.robots.reach import within_reach
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["DEAD_ZONE", "LMCfg", "LMRun", "bounded_residual", "lm_run", "lm_solve", "so3_log"]


@dataclass
class LMCfg:
    """Levenberg-Marquardt settings (``method="lm"``, ``polish=True`` and the solver's default refinement)."""

    iters: int = 25  # iteration limit of one start (each iteration: one FK + Jacobian per start)
    starts: int = 32  # kept for compatibility (the old number of uniform starts); see first_starts / restarts
    first_starts: int = 16  # without guesses: the first start is the best of this many uniform configurations
    restarts: int = 2  # fresh uniform starts a failing target draws in the first pass (one when its start is spent)
    tail_starts: int = 16  # then the targets still failing (0.3 % on panda): this many uniform starts side by side...
    tail_restarts: int = 16  # ...and this many more fresh starts per target
    stall_iters: int = 4  # a start stops after this many iterations in a row without progress...
    stall_rel: float = 1e-3  # ...progress meaning |e|^2 lowered by at least this fraction
    rot_weight: float = 0.5  # m/rad, weight of the rotation error rows
    lambda0: float = 1e-3  # initial damping (relative to diag(J^T J))
    lambda_up: float = 5.0  # damping factor after a rejected step
    lambda_down: float = 0.3  # damping factor after an accepted step
    lambda_min: float = 1e-9
    lambda_max: float = 1e6
    eps: float = 1e-9  # added to diag(J^T J), m^2
    max_step: float = 0.5  # rad, largest change of any joint in one step
    compiled: bool = False  # FK + Jacobian + error through torch.compile (needs a C compiler; eager fallback).
    #   Measured (panda, one thread): 2.3x faster per evaluation at a fixed 10,000 rows, but end to end
    #   slower (10,000 targets: 0.018 vs 0.011 ms per target from guesses, 0.19 vs 0.13 multistart; the
    #   batch shrinks as targets finish, and guards/recompiles cost more than they save), plus a
    #   one-off compile of 15-25 s. Hence off by default.


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


@dataclass
class LMRun:
    """Result of :func:`lm_run` for B targets with K starts each.

    Attributes:
        q: (B, dof) answer per target (converged start with the lowest error, else the lowest error).
        E: (B,) squared weighted error of ``q`` (m^2).
        converged: (B,) bool, within tolerance.
        iterations: (B,) long, iterations spent.
    """

    q: torch.Tensor
    E: torch.Tensor
    converged: torch.Tensor
    iterations: torch.Tensor


def lm_run(
    T_target: torch.Tensor,
    q0: torch.Tensor,
    G: torch.Tensor,
    offsets: torch.Tensor,
    lo: torch.Tensor,
    hi: torch.Tensor,
    wrap: torch.Tensor,
    *,
    cfg: LMCfg,
    tol_pos: float,
    tol_rot: float,
    iters: int,
    restarts: int = 0,
    first_iters: int | None = None,
    sampler=None,
    reachable: torch.Tensor | None = None,
    prismatic: torch.Tensor | None = None,
    bounds: torch.Tensor | None = None,
) -> LMRun:
    """Levenberg-Marquardt from ``q0: (B, K, dof)`` towards ``T_target: (B, 3|4, 4)``, restarting in place.

    Each of the ``B x K`` rows is one start. A row that stalls (``cfg.stall_iters`` iterations without
    progress) or runs ``iters`` iterations without converging is, while its target has restarts left
    (``restarts`` per target) and is ``reachable``, replaced in the same batch by a fresh start
    ``sampler(m) -> (m, dof)``; it costs no extra evaluation (the new start is evaluated where the
    candidate step would be); the starts of ``q0`` run ``first_iters`` iterations at most (default
    ``iters``). A target leaves the batch as soon as one of its rows converges, or when
    none of its rows can go on. Only failing targets ever draw restarts.

    ``G, offsets`` are the normal form (:mod:`nik.kinematics`) in the dtype/device of ``T_target``;
    ``lo, hi: (dof,)`` limits, ``wrap: (dof,)`` bool; ``prismatic`` (None: all revolute) is passed to
    the kernel when some joint is prismatic. ``bounds: (B, 6)`` (None: the tolerances): tolerant goals
    (:func:`bounded_residual`; ``tol_pos, tol_rot`` then unused).
    """
    B, K, n = q0.shape
    dtype, device = T_target.dtype, T_target.device
    rw = cfg.rot_weight
    row_w = torch.tensor([1.0, 1.0, 1.0, rw, rw, rw], dtype=dtype, device=device)[:, None]
    any_wrap = bool(wrap.any())
    kw = {"prismatic": prismatic} if prismatic is not None and bool(prismatic.any()) else {}
    eye_eps = cfg.eps * torch.eye(n, dtype=dtype, device=device)
    if sampler is None:
        restarts = 0

    def clamp(q):
        if any_wrap:
            q = torch.where(wrap, wrap_into(q, lo, hi), q)
        return torch.minimum(torch.maximum(q, lo), hi)

    kernel = _evaluator(cfg.compiled and not kw)
    tolerant = bounds is not None
    bnd = bounds.to(dtype=dtype, device=device)[:, None, :] if tolerant else torch.zeros(B, 1, 0, device=device)

    def evaluate(q, Tt, bnd):
        if tolerant:
            return _evaluate_bounded(q, Tt, bnd, G, offsets, rw, **kw)
        if kw:
            e, J, E, pos, rot = _evaluate_eager(q, Tt, G, offsets, row_w, rw, **kw)
        else:
            e, J, E, pos, rot = kernel(q, Tt, G, offsets, row_w, rw)
        return e, J, E, pos, rot, (pos <= tol_pos) & (rot <= tol_rot)

    Tt = T_target[:, None, :3, :]
    q = clamp(q0)
    e, J, E, pos, rot, ok = evaluate(q, Tt, bnd)
    lam = torch.full((B, K), cfg.lambda0, dtype=dtype, device=device)
    stall = torch.zeros((B, K), dtype=torch.int32, device=device)
    # the starts given run first_iters iterations at most, fresh ones iters
    first = iters if first_iters is None else int(first_iters)
    age = torch.full((B, K), iters - first, dtype=torch.int32, device=device)
    left = torch.full((B,), int(restarts), dtype=torch.int32, device=device)
    if reachable is not None:
        left = torch.where(reachable.to(device), left, torch.zeros_like(left))
    best_q, best_E = q.clone(), E.clone()  # per row, over its restarts
    out_q = q[:, 0].clone()
    out_E = E[:, 0].clone()
    out_conv = torch.zeros(B, dtype=torch.bool, device=device)
    out_it = torch.zeros(B, dtype=torch.long, device=device)
    active = torch.arange(B, device=device)
    total = max(first, 0) + int(restarts) * iters  # hard per-target budget

    def finish(rows):
        """Write the answers of the targets ``rows`` (indices into the active batch)."""
        q_, E_, conv_ = q[rows], E[rows], ok[rows]
        bq, bE = best_q[rows], best_E[rows]
        better = (E_ < bE) | conv_
        q_ = torch.where(better[..., None], q_, bq)
        E_ = torch.where(better, E_, bE)
        score = torch.where(conv_, E_, E_ + float("inf"))
        anyc = conv_.any(1)
        score = torch.where(anyc[:, None], score, E_)
        i = score.argmin(dim=1)
        tgt = active[rows]
        out_q[tgt] = torch.gather(q_, 1, i[:, None, None].expand(-1, 1, n)).squeeze(1)
        out_E[tgt] = torch.gather(E_, 1, i[:, None]).squeeze(1)
        out_conv[tgt] = anyc

    for it in range(total + 1):
        conv = ok
        spent = (stall >= cfg.stall_iters) | (age >= iters)
        # rows to restart: spent, target not converged, restarts left (drawn in row order)
        want = spent & ~conv.any(1, keepdim=True)
        if restarts:
            rank = torch.cumsum(want.to(torch.int32), dim=1)
            restart = want & (rank <= left[:, None])
        else:
            restart = torch.zeros_like(want)
        done = conv.any(1) | (spent & ~restart).all(1)
        if it == total:
            done = torch.ones_like(done)
        if bool(done.any()):
            rows = done.nonzero().squeeze(1)
            finish(rows)
            if bool(done.all()):
                break
            keep = (~done).nonzero().squeeze(1)
            active, q, e, J, E, pos, rot, ok, lam, stall, age, left, best_q, best_E, restart, Tt, bnd = (
                t.index_select(0, keep)
                for t in (active, q, e, J, E, pos, rot, ok, lam, stall, age, left, best_q, best_E, restart, Tt, bnd)
            )
        A = (J[..., :, :, None] * J[..., :, None, :]).sum(-3)  # J^T J by broadcasting: faster than bmm here
        g = (J * e[..., :, None]).sum(-2).unsqueeze(-1)
        # active set (nik.kernels.lm_step.hold): a joint on a limit that the descent direction pushes further out is
        # left out, and so is one that the step solved without it pushes out (the step is solved once more)
        dq, info = _held_step(A, g, q, lo, hi, torch.zeros_like(q), lam, cfg.eps, eye_eps)
        out = ((q <= lo) & (dq < 0)) | ((q >= hi) & (dq > 0))
        if bool(out.any()):
            dq, info = _held_step(A, g, q, lo, hi, dq, lam, cfg.eps, eye_eps)
        big = dq.abs().amax(dim=-1, keepdim=True)
        dq = dq * torch.clamp(cfg.max_step / big.clamp_min(1e-30), max=1.0)
        dq = torch.where((info == 0)[..., None] & torch.isfinite(dq), dq, torch.zeros_like(dq))
        qc = clamp(q + dq)
        n_restart = int(restart.sum())
        if n_restart:
            # remember the best of the spent start, then put a fresh start in its place
            better = restart & (E < best_E)
            best_q = torch.where(better[..., None], q, best_q)
            best_E = torch.where(better, E, best_E)
            fresh = torch.zeros_like(qc)
            fresh[restart] = sampler(n_restart).to(dtype=dtype, device=device)
            qc = torch.where(restart[..., None], fresh, qc)
            left = left - restart.sum(1, dtype=torch.int32)
        ec, Jc, Ec, posc, rotc, okc = evaluate(qc, Tt, bnd)
        good = info == 0
        acc = ((Ec < E) & good) | restart
        if tolerant:  # a step that reaches every bound is kept (the compiled kernel's rule)
            acc = acc | (okc & good)
        gain = torch.where(acc, E - Ec, torch.zeros_like(E))
        stall = torch.where((gain >= cfg.stall_rel * E) | restart, torch.zeros_like(stall), stall + 1)
        age = torch.where(restart, torch.zeros_like(age), age + 1)
        a3 = acc[..., None]
        q = torch.where(a3, qc, q)
        e = torch.where(a3, ec, e)
        J = torch.where(a3[..., None], Jc, J)
        E = torch.where(acc, Ec, E)
        pos = torch.where(acc, posc, pos)
        rot = torch.where(acc, rotc, rot)
        ok = torch.where(acc, okc, ok)
        lam = torch.where(acc, lam * cfg.lambda_down, lam * cfg.lambda_up).clamp(cfg.lambda_min, cfg.lambda_max)
        if n_restart:
            lam = torch.where(restart, torch.full_like(lam, cfg.lambda0), lam)
        out_it[active] += 1
    return LMRun(out_q, out_E, out_conv, out_it)


def _held_step(A, g, q, lo, hi, prev, lam, eps, eye_eps):
    """``(dq (..., n), info)``: the damped step of ``A (..., n, n) dq = g (..., n, 1)`` with the joints on a limit
    that ``g`` or ``prev`` (the step before, zeros at first) pushes further out held
    (:func:`nik.kernels.lm_step.hold`)."""
    gs = g.squeeze(-1)
    held = ((q <= lo) & ((gs < 0) | (prev < 0))) | ((q >= hi) & ((gs > 0) | (prev > 0)))
    if bool(held.any()):
        f = (~held).to(A.dtype)
        A = A * (f[..., :, None] * f[..., None, :]) + (1.0 - f).diag_embed()
        g = g * f[..., None]
    A = A + (lam[..., None] * (torch.diagonal(A, dim1=-2, dim2=-1) + eps)).diag_embed() + eye_eps
    L, info = torch.linalg.cholesky_ex(A)
    return torch.cholesky_solve(g, L).squeeze(-1), info


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
    G, off = robot._params(T_target)
    lo, hi = robot.limits_as(T_target)
    wraps = wrap_mask(robot.limits, prismatic=robot.prismatic).to(device) & wrap
    prismatic = robot.prismatic.to(device)
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
        G=G,
        offsets=off,
        lo=lo,
        hi=hi,
        wrap=wraps,
        cfg=cfg,
        tol_pos=tol_pos,
        tol_rot=tol_rot,
        iters=iters,
        sampler=lambda m: robot.sample(m, generator=generator, dtype=dtype, device=device),
        prismatic=prismatic,
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
