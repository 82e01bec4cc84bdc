"""The one torch Levenberg-Marquardt loop: every torch solver of nik (the pose LM, a problem of cost terms, the
near prior, the rest posture, the closed form's polish) is :func:`lm_loop` with an evaluation and a configuration.

Rows: ``q: (B, K, n)``, B targets (problems) with K starts each; a path is one row whose variables are all its
waypoints (``n = N * dof``, :class:`nik.lm.problem.PathProblem`). Each iteration asks ``evaluate(q, rows)`` for the
stacked rows of the problem (:class:`Eval`: the error ``e = -r``, its Jacobian, the cost ``E`` a step must lower and
the rows that are done) and takes the damped step::

    dq = (J^T J + D + eps I)^-1 J^T (e - J z) + z

- damping ``D`` (``cfg.damping``): ``"marquardt"``: ``lambda (diag(J^T J) + eps)``, lambda shrinking by
  ``lambda_down`` after a kept step and growing by ``lambda_up`` after a refused one; ``"fixed"``: none (``eps I``
  only; a prior row of the problem, or ``eps``, keeps it regular), lambda then scaling the preference step;
- ``z``: a preference direction of the evaluation (``Eval.z``, the null-space step of a posture:
  :func:`nik.ik.goals.rest_torch`) scaled by ``1 / lambda``, zero without one;
- the linear solver (``cfg.linear_solver``): ``"cholesky"`` (``cholesky_ex``; a failed factorisation refuses the
  step) or ``"lu"`` (``solve_ex``);
- the joints on a limit that the descent (``cfg.hold="twice"``: or the first solve's step, solved once more) pushes
  further out are held (the active set of the compiled LM), the step scaled so that no joint moves more than
  ``max_step``, then brought inside the box;
- the acceptance (``cfg.accept``): ``"decrease"``: a step that lowers ``E``; ``"decrease_or_done"``: or that lands
  done (tolerant goals); ``"feasible"``: a step that lowers ``E`` and lands on a feasible row (``Eval.feasible``:
  a posture that must not leave its goal); ``"always"``: every finite step (Gauss-Newton: the polish, the prior walk).

The stop rule: a target stops when one of its rows is done (``Eval.done``, or ``E <= cost_tol``), or when each of
its rows is *spent* (``stall_iters`` iterations in a row lowering ``E`` by less than the fraction ``stall_rel``,
``iters`` iterations, or lambda above ``lambda_max``) and has no restart left. With :class:`Restarts`, a spent row of
a target that has restarts left is replaced in place by a fresh start (the answer of a target is then its done row of
lowest ``E``, else its lowest ``E`` seen). ``compact=True`` drops finished targets from the batch; ``False`` keeps
every row in place (masked), so an evaluation sees the rows in their order every call (user terms with per-target
data).

The settings are one dataclass, :class:`LMCfg` (the defaults of every caller); a caller changes a field with
``dataclasses.replace``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch

from nik.robots.joints import wrap_into

__all__ = ["Box", "Eval", "LMCfg", "LMRun", "Restarts", "lm_loop", "with_prior"]

DAMPINGS = ("marquardt", "fixed")
LINEAR_SOLVERS = ("cholesky", "lu")
ACCEPTS = ("decrease", "decrease_or_done", "feasible", "always")
HOLDS = ("twice", "once")


@dataclass
class LMCfg:
    """Levenberg-Marquardt settings, the one set of defaults of every LM of nik (module docstring): ``method="lm"``,
    ``polish=True``, the solver's default refinement, problems of cost terms, the near prior, the rest posture and
    the closed form's polish (these change a field or two with ``dataclasses.replace``)."""

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
    lambda_max: float = 1e6  # a row whose damping grows past this is spent
    eps: float = 1e-9  # added to diag(J^T J), m^2
    max_step: float = 0.5  # rad, largest change of any joint in one step
    compiled: bool = False  # FK + Jacobian + error through torch.compile (needs a C compiler; eager fallback).
    #   Measured (panda, one thread): 2.3x faster per evaluation at a fixed 10,000 rows, but end to end
    #   slower (10,000 targets: 0.018 vs 0.011 ms per target from guesses, 0.19 vs 0.13 multistart; the
    #   batch shrinks as targets finish, and guards/recompiles cost more than they save), plus a
    #   one-off compile of 15-25 s. Hence off by default.
    cost_tol: float = 1e-24  # a row whose cost E is at most this is done
    damping: str = "marquardt"  # "marquardt" | "fixed" (module docstring)
    linear_solver: str = "cholesky"  # "cholesky" | "lu"
    accept: str = "decrease"  # "decrease" | "decrease_or_done" | "feasible" | "always"
    hold: str = "twice"  # the active set: "twice" (the compiled LM's), or "once" (the descent's joints only)

    def __post_init__(self):
        for name, value, allowed in (("damping", self.damping, DAMPINGS),
                                     ("linear_solver", self.linear_solver, LINEAR_SOLVERS),
                                     ("accept", self.accept, ACCEPTS), ("hold", self.hold, HOLDS)):  # fmt: skip
            if value not in allowed:
                raise ValueError(f"LMCfg.{name}: expected one of {list(allowed)}, got {value!r}")


class Eval(NamedTuple):
    """An evaluation of rows ``q: (b, K, n)``: ``e (b, K, M)`` the error (minus the weighted residual), ``J (b, K,
    M, n)`` the residual's Jacobian, ``E (b, K)`` the cost a step must lower (``|e|^2`` for an LM), ``done (b, K)``
    bool (converged: the target stops); optional ``feasible (b, K)`` bool (``accept="feasible"``) and ``z (b, K, n)``
    the preference direction of a null-space step."""

    e: torch.Tensor
    J: torch.Tensor
    E: torch.Tensor
    done: torch.Tensor
    feasible: torch.Tensor | None = None
    z: torch.Tensor | None = None


class Box(NamedTuple):
    """The variables' box: ``lo, hi: (n,)`` (``inf`` = unbounded), ``wrap: (n,)`` bool (moved by whole turns into the
    range instead of clamped, never held); ``project: q -> q`` replaces the default projection when given."""

    lo: torch.Tensor
    hi: torch.Tensor
    wrap: torch.Tensor
    project: Callable | None = None


class Restarts(NamedTuple):
    """Fresh starts of failing targets: ``count`` per target, drawn by ``sampler(m) -> (m, n)``; ``reachable (B,)``
    bool (None: all) the targets allowed to draw them; the given starts run ``first_iters`` iterations (None:
    ``cfg.iters``), the fresh ones ``cfg.iters``."""

    count: int = 0
    sampler: Callable | None = None
    reachable: torch.Tensor | None = None
    first_iters: int | None = None


@dataclass
class LMRun:
    """Result of :func:`lm_loop` (and :func:`nik.lm.lm_run`) for B targets with K starts each.

    Attributes:
        q: (B, n) answer per target (done start with the lowest cost, else the lowest cost).
        E: (B,) its cost.
        converged: (B,) bool, done.
        iterations: (B,) long, iterations spent.
    """

    q: torch.Tensor
    E: torch.Tensor
    converged: torch.Tensor
    iterations: torch.Tensor


def with_prior(evaluate: Callable, q_prior: torch.Tensor, weight: float) -> Callable:
    """``evaluate`` with the prior rows ``weight * (q - q_prior)`` appended (``q_prior: (B, n)``, one per target):
    a pull towards ``q_prior`` as rows of the problem, traded against its other rows by the normal equations."""

    def evaluate_with_prior(q, rows):
        base = evaluate(q, rows)
        r = weight * (q - q_prior.index_select(0, rows)[:, None])
        eye = torch.eye(q.shape[-1], dtype=q.dtype, device=q.device) * weight
        J = torch.cat([base.J, eye.expand(*q.shape[:-1], -1, -1)], -2)
        return base._replace(e=torch.cat([base.e, -r], -1), J=J, E=base.E + (r * r).sum(-1))

    return evaluate_with_prior


def _projection(box: Box) -> Callable:
    """``q -> q`` inside ``box``: its own ``project``, or wrapping joints by whole turns and the others clamped."""
    if box.project is not None:
        return box.project
    if bool(box.wrap.any()):
        return lambda q: torch.minimum(torch.maximum(torch.where(box.wrap, wrap_into(q, box.lo, box.hi), q), box.lo),
                                       box.hi)  # fmt: skip
    return lambda q: torch.minimum(torch.maximum(q, box.lo), box.hi)


def _held_step(A, g, q, box: Box, prev, lam, cfg: LMCfg, eye_eps):
    """``(dq (..., n), info)``: the damped step of ``A (..., n, n) dq = g (..., n, 1)`` (module docstring) with the
    joints on a limit that ``g`` or ``prev`` (the step before, zeros at first) pushes further out held
    (:func:`nik.kernels.lm_step.hold`)."""
    gs = g.squeeze(-1)
    lo, hi = box.lo, box.hi
    held = ~box.wrap & (((q <= lo) & ((gs < 0) | (prev < 0))) | ((q >= hi) & ((gs > 0) | (prev > 0))))
    if bool(held.any()):
        f = (~held).to(A.dtype)
        A = A * (f[..., :, None] * f[..., None, :]) + (1.0 - f).diag_embed()
        g = g * f[..., None]
    if cfg.damping == "marquardt":
        A = A + (lam[..., None] * (torch.diagonal(A, dim1=-2, dim2=-1) + cfg.eps)).diag_embed()
    A = A + eye_eps
    if cfg.linear_solver == "lu":
        dq, info = torch.linalg.solve_ex(A, g)
        return dq.squeeze(-1), info
    L, info = torch.linalg.cholesky_ex(A)
    return torch.cholesky_solve(g, L).squeeze(-1), info


def _step(ev: Eval, q: torch.Tensor, box: Box, lam: torch.Tensor, cfg: LMCfg, eye_eps: torch.Tensor):
    """``(dq (b, K, n), good (b, K))``: one damped step with the active set (two solves where the first pushes a
    joint out), scaled to ``max_step``; zero and not good where the solve failed or is not finite."""
    J, e = ev.J, ev.e
    A = (J[..., :, :, None] * J[..., :, None, :]).sum(-3)  # J^T J by broadcasting: faster than bmm here
    z = None if ev.z is None else ev.z / lam[..., None]
    r = e if z is None else e - (J @ z[..., None])[..., 0]
    g = (J * r[..., :, None]).sum(-2).unsqueeze(-1)
    dq, info = _held_step(A, g, q, box, torch.zeros_like(q), lam, cfg, eye_eps)
    if z is not None:
        dq = dq + z
    out = ((q <= box.lo) & (dq < 0)) | ((q >= box.hi) & (dq > 0))
    if cfg.hold == "twice" and bool((out & ~box.wrap).any()):
        dq2, info = _held_step(A, g, q, box, dq, lam, cfg, eye_eps)
        dq = dq2 if z is None else dq2 + z
    big = dq.abs().amax(dim=-1, keepdim=True)
    dq = dq * torch.clamp(cfg.max_step / big.clamp_min(1e-30), max=1.0)
    good = (info == 0) & torch.isfinite(dq).all(-1)
    return torch.where(good[..., None], dq, torch.zeros_like(dq)), good


def _accepted(cfg: LMCfg, good, new: Eval, E):
    if cfg.accept == "always":
        return good
    acc = good & (new.E < E)
    if cfg.accept == "decrease_or_done":
        return acc | (good & new.done)
    if cfg.accept == "feasible":
        return acc & new.feasible
    return acc


def _select(ev: Eval, keep) -> Eval:
    return Eval(*[None if t is None else t.index_select(0, keep) for t in ev])


def _where(acc, a: Eval, b: Eval) -> Eval:
    """``a`` where ``acc (b, K)``, else ``b`` (the fields that ``b`` lacks are ``a``'s; ``done`` is kept apart)."""
    out = []
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        if x is None or y is None or i == 3:
            out.append(x)
            continue
        out.append(torch.where(acc.reshape(*acc.shape, *([1] * (x.dim() - acc.dim()))), x, y))
    return Eval(*out)


def lm_loop(evaluate: Callable, q0: torch.Tensor, box: Box, cfg: LMCfg, *, restarts: Restarts | None = None,
            active: torch.Tensor | None = None, compact: bool = True) -> LMRun:  # fmt: skip
    """The loop of the module docstring from ``q0: (B, K, n)`` (brought inside ``box`` first).

    ``evaluate(q (b, K, n), rows (b,) long) -> Eval``: ``rows`` are the targets of ``q`` (indices into B).
    ``active: (B,)`` bool (default all): the other targets are returned at their first start, untouched.
    Returns :class:`LMRun` (``iterations``: the loop's passes each target took part in).
    """
    B, K, n = q0.shape
    device = q0.device
    rs = restarts or Restarts()
    n_restarts = int(rs.count) if rs.sampler is not None else 0
    iters = int(cfg.iters)
    first = iters if rs.first_iters is None else int(rs.first_iters)
    rows = torch.arange(B, device=device)
    project = _projection(box)
    eye_eps = cfg.eps * torch.eye(n, dtype=q0.dtype, device=device)
    q = project(q0)
    ev = evaluate(q, rows)
    E = ev.E
    done = ev.done | (E <= cfg.cost_tol)
    lam = torch.full((B, K), cfg.lambda0, dtype=q.dtype, device=device)
    stall = torch.zeros((B, K), dtype=torch.int32, device=device)
    age = torch.full((B, K), iters - first, dtype=torch.int32, device=device)  # the given starts run `first`
    left = torch.full((B,), n_restarts, dtype=torch.int32, device=device)
    if rs.reachable is not None:
        left = torch.where(rs.reachable.to(device), left, torch.zeros_like(left))
    best_q, best_E = q.clone(), torch.full_like(E, float("inf"))  # per row, over its spent starts
    out_q, out_E = q[:, 0].clone(), E[:, 0].clone()
    out_conv = torch.zeros(B, dtype=torch.bool, device=device)
    out_it = torch.zeros(B, dtype=torch.long, device=device)
    live = torch.ones(B, dtype=torch.bool, device=device) if active is None else active.to(device).clone()
    total = max(first, 0) + n_restarts * iters  # hard per-target budget

    def finish(sel):
        """Write the answers of the targets ``sel`` (indices into the batch)."""
        q_, E_, conv_ = q[sel], E[sel], done[sel]
        better = (E_ < best_E[sel]) | conv_
        q_ = torch.where(better[..., None], q_, best_q[sel])
        E_ = torch.where(better, E_, best_E[sel])
        anyc = conv_.any(1)
        score = torch.where(anyc[:, None], torch.where(conv_, E_, E_ + float("inf")), E_)
        i = score.argmin(dim=1)
        tgt = rows[sel]
        out_q[tgt] = torch.gather(q_, 1, i[:, None, None].expand(-1, 1, n)).squeeze(1)
        out_E[tgt] = torch.gather(E_, 1, i[:, None]).squeeze(1)
        out_conv[tgt] = anyc

    if active is not None and not bool(live.all()):  # the inactive targets: their first start as it is
        finish((~live).nonzero().squeeze(1))
        if compact:
            keep = live.nonzero().squeeze(1)
            rows, q, E, done, lam, stall, age, left, best_q, best_E, live = (
                t.index_select(0, keep) for t in (rows, q, E, done, lam, stall, age, left, best_q, best_E, live)
            )
            ev = _select(ev, keep)
    for it in range(total + 1):
        spent = (stall >= cfg.stall_iters) | (age >= iters) | (lam > cfg.lambda_max)
        want = spent & ~done.any(1, keepdim=True)  # rows to restart: spent, target not done, restarts left
        if n_restarts:
            rank = torch.cumsum(want.to(torch.int32), dim=1)
            restart = want & (rank <= left[:, None]) & live[:, None]
        else:
            restart = torch.zeros_like(want)
        stop = live & (done.any(1) | (spent & ~restart).all(1))
        if it == total:
            stop = live.clone()
        if bool(stop.any()):
            finish(stop.nonzero().squeeze(1))
            live = live & ~stop
            if not bool(live.any()):
                break
            if compact:
                keep = live.nonzero().squeeze(1)
                rows, q, E, done, lam, stall, age, left, best_q, best_E, restart, live = (
                    t.index_select(0, keep)
                    for t in (rows, q, E, done, lam, stall, age, left, best_q, best_E, restart, live)
                )
                ev = _select(ev, keep)
        dq, good = _step(ev, q, box, lam, cfg, eye_eps)
        moving = None if compact else live[:, None].expand_as(good)  # compact: every row in the batch moves
        qc = project(q + (dq if compact else torch.where(moving[..., None], dq, torch.zeros_like(dq))))
        n_restart = int(restart.sum())
        if n_restart:  # remember the best of the spent start, then put a fresh start in its place
            better = restart & (E < best_E)
            best_q = torch.where(better[..., None], q, best_q)
            best_E = torch.where(better, E, best_E)
            fresh = torch.zeros_like(qc)
            fresh[restart] = rs.sampler(n_restart).to(dtype=qc.dtype, device=device)
            qc = torch.where(restart[..., None], project(fresh), qc)
            left = left - restart.sum(1, dtype=torch.int32)
        new = evaluate(qc, rows)
        acc = _accepted(cfg, good, new, E) | restart
        step = 1
        if not compact:
            acc, step = acc & moving, moving.int()
        gain = torch.where(acc, E - new.E, torch.zeros_like(E))
        stall = torch.where((gain >= cfg.stall_rel * E) | restart, torch.zeros_like(stall), stall + step)
        age = torch.where(restart, torch.zeros_like(age), age + step)
        q = torch.where(acc[..., None], qc, q)
        ev = _where(acc, new, ev)
        E = ev.E
        done = torch.where(acc, new.done | (new.E <= cfg.cost_tol), done)
        up = lam * cfg.lambda_up if compact else torch.where(moving, lam * cfg.lambda_up, lam)
        lam = torch.where(acc, lam * cfg.lambda_down, up).clamp(cfg.lambda_min, cfg.lambda_max * cfg.lambda_up)
        if n_restart:
            lam = torch.where(restart, torch.full_like(lam, cfg.lambda0), lam)
        out_it[rows if compact else rows[live]] += 1
    return LMRun(out_q, out_E, out_conv, out_it)
