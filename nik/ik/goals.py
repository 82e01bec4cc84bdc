"""The goal stages of a call: tolerant goals (``bounds=``) and preferred postures (``q_rest=``), both backends.

**Tolerant goals** (:mod:`nik.ik.bounds`; the plan's ``bounds``). Success means every axis of the error in the
target's tool frame inside its bound, measured by FK of the returned joints (:func:`nik.poses.within_bounds`,
:func:`nik.kernels.lm.bounded_errors`: the same numbers). The result's ``pos_err`` / ``rot_err`` stay the classic
errors (position norm, geodesic angle: a free axis shows there); ``axis_err: (B, 6)`` is the error per tool axis
(m, rad; 0 on the entry of a free rotation axis, whose twist is not measured). The starts, ranked by the bounded
error:

- a network: all its hypotheses;
- an arm with a closed form: its solutions of the pose as given (they meet any goal where they exist), and with one
  rotation axis free, for the targets none of those reach, the closed form at the free angle of
  :func:`nik.ik.free_axis.closed_form_free_axis` (36 angles searched; compiled: the same search on the numba closed
  form); with the orientation free (``"position"``) the closed form has no angle to search: LM does the rest from
  those starts and uniform ones;
- ``q_near`` when given (an extra start; no second refinement).

Then LM towards the bounds from each start in turn until one lands inside (compiled:
:func:`nik.kernels.driver.solve_bounded`; torch: :func:`nik.lm.lm_solve` with ``bounds``, the starts side by side),
and for the targets still outside, LM from uniform starts with the restart budget (none for a target proven out of
reach, a free position axis lifting the reach test; none at all where the plan has neither restarts nor a
fallback). Float32 targets are refined to the plan's float32 margin of the bounds and measured again after rounding.

**Preferred postures** (``q_rest``, ``rest_weight``; the plan's). After the answer is found, on a redundant arm (more
joints than the task's 6 rows) each target that succeeded first takes the candidate nearest ``q_rest`` that meets the
goal: the answer, LM from ``q_rest`` and LM from the network's :data:`REST_HYPOTHESES` hypotheses nearest it (without
a network, :data:`REST_UNIFORM` uniform starts), a short refinement each (:func:`nearest_candidates`; torch:
:func:`nearest_candidates_torch`); its cost is those LM runs (xarm7 and panda, one thread: 0.36-0.38 ms a target,
1.6-1.8x ``q_rest`` without them; the mean distance to the middle 1.01x that of the nearest solution ``solve_all``
finds, was 1.25-1.42x: ``benchmarks/results/goals_rest.md``). Then it moves towards ``q_rest`` in the null space of its
task: steps ``dq = z + J^T (J J^T + mu I)^-1 (e - J z)``,
``z = s * rest_weight * (q_rest - q)`` (``e, J``: the task's residual and Jacobian, classic or bounded, the rows of
free axes zero, so a free axis adds a direction of the null space), kept only where FK of the result is still within
tolerance (the stages' tolerance: nothing is lost) and nearer ``q_rest``; a refused step halves ``s``,
a kept one doubles it (at most 1)
(:func:`nik.kernels.driver.rest_posture`; torch: :func:`rest_torch`, the same steps batched). ``q_rest="mid"`` is
the middle of the joint ranges (distance from the limits). A 6-joint arm without a free axis has no null space: its
answers do not move (to rounding; the residual step only polishes them). :data:`REST_ITERS` steps at most.
Where a collision check is active the posture is applied by the collision stage instead, after its re-solve and
before its verdict, never ending in a collision (:func:`nik.ik.collide.rest_free`).

**Manipulability** (``plan.manipulability``: :func:`nik.costs.manipulability` given via ``costs=``) takes the same
route: the same null-space step, its preference step raising Yoshikawa's measure as well (:func:`preference`;
:func:`nik.kernels.driver.rest_posture`), and on an arm with a closed form, before it, the closed-form branch of the
highest measure among those that meet the goal (:func:`most_manipulable`; not under a collision check).
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

from nik.ik.result import IKResult

__all__ = ["REST_CANDIDATE_ITERS", "REST_DAMPING", "REST_HYPOTHESES", "REST_ITERS", "REST_UNIFORM",
           "all_solutions_bounded", "most_manipulable", "nearest_candidates", "nearest_candidates_torch", "preference",
           "prefers", "rest_target", "rest_torch", "solve_compiled", "solve_torch"]  # fmt: skip

#: Most null-space steps towards ``q_rest`` per target.
REST_ITERS = 50
#: Damping of ``J J^T`` in the null-space step (m^2): keeps the step finite at singular configurations.
REST_DAMPING = 1e-8
#: Most LM iterations of each candidate start of :func:`nearest_candidates` (a short refinement: a start that needs
#: more is no near candidate).
REST_CANDIDATE_ITERS = 30
#: Uniform starts of :func:`nearest_candidates` where the plan has no network.
REST_UNIFORM = 8
#: The network's hypotheses that :func:`nearest_candidates` refines: those nearest ``q_rest`` before refinement.
REST_HYPOTHESES = 4


def rest_target(robot, q_rest, batch: int) -> np.ndarray:
    """``q_rest`` (``"mid"``, ``(dof,)`` or ``(B, dof)`` radians) as ``(batch, dof)`` float64; ``"mid"``: the middle
    of each joint's range (a joint without finite limits: 0). Raises ``ValueError`` (one line) on a bad one."""
    dof = robot.dof
    if isinstance(q_rest, str):
        if q_rest != "mid":
            raise ValueError(f"q_rest: expected 'mid' or joint angles, got {q_rest!r}")
        lim = robot.limits.detach().double().cpu().numpy()
        mid = np.where(np.isfinite(lim).all(1), lim.mean(1), 0.0)
        return np.broadcast_to(mid, (batch, dof)).copy()
    if isinstance(q_rest, torch.Tensor):
        q_rest = q_rest.detach().double().cpu().numpy()
    try:
        q = np.asarray(q_rest, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"q_rest: expected 'mid' or ({dof},) / ({batch}, {dof}) radians, got {q_rest!r:.60}") from None
    if q.shape not in ((dof,), (batch, dof), (1, dof)):
        raise ValueError(f"q_rest: expected shape ({dof},) or ({batch}, {dof}), got {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError("q_rest: NaN or infinite joint angle")
    return np.broadcast_to(q.reshape(-1, dof), (batch, dof)).copy()


def prefers(plan) -> bool:
    """Whether the plan asks the null-space step for anything: a posture (``q_rest``) or the manipulability."""
    return plan.q_rest is not None or plan.manipulability > 0.0


def preference(robot, plan, B: int, opts: np.ndarray | None) -> tuple[np.ndarray, float, np.ndarray | None]:
    """``(q_rest (B, dof), rest_weight, opts)`` of :func:`nik.kernels.driver.rest_posture` for the plan's
    preferences: without ``q_rest`` zeros and weight 0 (the manipulability alone); ``opts`` a copy with
    ``plan.manipulability`` in its ``MANIPULABILITY`` entry where that is set (``opts`` itself otherwise)."""
    from nik.kernels.lm import MANIPULABILITY

    if plan.q_rest is None:
        qr, weight = np.zeros((B, robot.dof)), 0.0
    else:
        qr, weight = rest_target(robot, plan.q_rest, B), float(plan.rest_weight)
    if plan.manipulability > 0.0 and opts is not None:
        opts = opts.copy()
        opts[MANIPULABILITY] = plan.manipulability
    return qr, weight, opts


def most_manipulable(robot, model, T: np.ndarray, q: np.ndarray, ok: np.ndarray, check) -> np.ndarray:
    """``(B,)`` bool, which rows changed: ``q: (B, dof)`` in place, where ``ok``, replaced by the closed form's
    solution of ``T: (B, 4, 4)`` of the highest manipulability among those ``check(rows, q_rows) -> (k,) bool``
    accepts (the goal of targets ``rows`` by FK), where that is higher than the answer's own; nothing on an arm
    without a closed form."""
    from nik.costs.manipulability import manipulability

    changed = np.zeros(q.shape[0], dtype=bool)
    idx = np.flatnonzero(ok)
    if model.closed is None or idx.size == 0:
        return changed
    Tk = np.ascontiguousarray(T[idx])
    sols, valid = model.closed_solutions(Tk)  # (k, 8, n), (k, 8)
    k, m, n = sols.shape
    flat = np.ascontiguousarray(np.where(valid[..., None], sols, 0.0).reshape(k * m, n))
    good = valid.reshape(-1).copy()
    if good.any():
        good[good] = check(np.repeat(idx, m)[good], np.ascontiguousarray(flat[good]))
    term = manipulability(robot)
    r = np.where(good, term.compiled(flat)[0][:, 0], np.inf).reshape(k, m)  # 1 / (w + eps): lowest is best
    own = term.compiled(np.ascontiguousarray(q[idx]))[0][:, 0]
    best = r.argmin(1)
    better = r[np.arange(k), best] < own
    q[idx[better]] = sols[better, best[better]]
    changed[idx[better]] = True
    return changed


def _modes_half(plan, B: int, margin: float):
    """``(half (B, 6), modes (B,))`` of the plan's goal for the stages (bounds times ``margin``), or the classic
    placeholder (``modes == CLASSIC``) without one."""
    from nik.kernels.lm import CLASSIC

    if plan.bounds is None:
        return np.zeros((B, 6)), np.full(B, CLASSIC, dtype=np.int64)
    return plan.bounds.expand(B) * margin, plan.bounds.modes(B)


# -- compiled ------------------------------------------------------------------------------------------------------
def _closed_starts(robot, model, plan, T: np.ndarray) -> list[np.ndarray]:
    """The closed form's starts ``[(B, k, 6)]`` (NaN rows where there is none; module docstring)."""
    out = []
    q, valid = model.closed_solutions(T)
    out.append(np.where(valid[..., None], q, np.nan))
    modes = plan.bounds.modes(T.shape[0])
    if ((modes >= 0) & (modes <= 2)).all() and len(set(modes.tolist())) == 1:
        todo = np.flatnonzero(~valid.any(1))  # a valid solution of the pose as given meets the goal already
        extra = np.full((T.shape[0], 1, q.shape[-1]), np.nan)
        if todo.size:
            extra[todo, 0] = _free_axis_start(model, T[todo], int(modes[0]))
        out.insert(0, extra)
    return out


def _free_axis_start(model, T: np.ndarray, k: int, samples: int = 36) -> np.ndarray:
    """``(m, 6)``: the compiled closed form's valid solution of ``T Rk(gamma)`` (``T: (m, 4, 4)``) of the smallest
    ``|gamma|`` over ``samples`` angles, NaN where none (the search of
    :func:`nik.ik.free_axis.closed_form_free_axis`, on the numba closed form instead of torch's)."""
    from nik.ik.free_axis import _about

    m = T.shape[0]
    gamma = 2.0 * np.pi * np.arange(samples) / samples
    gamma = np.where(gamma > np.pi, gamma - 2.0 * np.pi, gamma)
    Tm = T[:, None] @ _about(k, torch.from_numpy(gamma)).numpy()  # (m, S, 4, 4)
    q, valid = model.closed_solutions(Tm.reshape(-1, 4, 4))
    q, valid = q.reshape(m, samples * 8, -1), valid.reshape(m, samples * 8)
    score = np.where(valid, np.repeat(np.abs(gamma), 8), np.inf)
    best = score.argmin(1)
    return np.where(valid.any(1)[:, None], q[np.arange(m), best], np.nan)


def solve_compiled(backend, robot, plan, T_target, q_near, representation) -> IKResult:
    """``plan.bounds`` on the compiled backend (module docstring): one :func:`nik.kernels.driver.solve_bounded` call."""
    from nik.kernels import driver, lm

    job = backend.job(robot, plan, T_target, q_near, representation, reach=False)
    model, B, n = job.model, job.size, job.model.dof
    reachable, every = model.reach(job.T)
    free_pos = np.isinf(plan.bounds.expand(B)[:, :3]).any(1)
    reachable = reachable | free_pos
    if not reachable.all():
        warnings.warn(model.unreachable_message(job.T, reachable), UserWarning, stacklevel=4)
    job.reachable = reachable
    starts = []
    if plan.source == "network":
        hyp = backend.network(plan, job)[0]
        starts.append(np.asarray(hyp, dtype=np.float64))
    elif plan.source == "analytic":
        starts += _closed_starts(robot, model, plan, job.T)
    if job.q_near is not None:
        starts.append(job.q_near[:, None])
    starts = np.ascontiguousarray(np.concatenate(starts, 1) if starts else np.zeros((B, 0, n)))
    float32 = job.dtype == torch.float32
    half, modes = _modes_half(plan, B, plan.float32_margin if float32 else 1.0)
    lmod = model.lm
    opts, iopts = lmod.options(job.tol_pos, job.tol_rot, plan.max_iters)
    _, iopts_multi = lmod.options(job.tol_pos, job.tol_rot, plan.max_iters, multistart=True)
    budget = np.where(reachable, lmod.budget if plan.restarts or plan.fallback != "none" else 0, 0)
    q, ok, it = np.empty((B, n)), np.empty(B, dtype=bool), np.empty(B, dtype=np.int64)
    pos, rot, d = np.empty(B), np.empty(B), np.empty((B, 6))
    seed = lm.seed_state(plan.seed)
    lm_args = (opts, iopts, iopts_multi, budget.astype(np.int64), seed)
    driver.solve_bounded((model.G, model.joints), job.T, starts, (half, modes), lm_args, (q, ok, it, pos, rot, d))
    if prefers(plan):
        if plan.manipulability > 0.0:
            most_manipulable(robot, model, job.T, q, ok, lambda rows, qk: _inside(model, job.T, rows, qk, modes, half))
        qr, weight, popts = preference(robot, plan, B, opts)
        driver.rest_posture((model.G, model.joints), job.T, q, (half, modes), popts, (qr, weight, REST_ITERS,
                            REST_DAMPING), ok, (pos, rot, d))  # fmt: skip
    if float32:  # rounded, clamped into the float32 limits, measured again against the asked bounds
        q = np.clip(q.astype(np.float32), model.lo32, model.hi32)
        full, _ = _modes_half(plan, B, 1.0)
        lm.bounded_errors(model.G, model.joints, job.T, q.astype(np.float64), modes, d)
        lm.pose_errors(model.G, model.joints, job.T, q.astype(np.float64), pos, rot)
        ok = (np.abs(d) <= full).all(1)
        pos, rot, d = pos.astype(np.float32), rot.astype(np.float32), d.astype(np.float32)
    res = IKResult(q, pos, rot, ok, it, plan.source, reachable=reachable, axis_err=d)
    return res if job.numpy_out else res.to("cpu")


def rest_compiled(plan, job, answers) -> None:
    """In place: the successful answers (classic tolerances) replaced by the candidate nearest ``plan.q_rest``
    (:func:`nearest_candidates`), then moved towards it and a higher manipulability in the null space (module
    docstring; compiled)."""
    from nik.kernels import driver, lm

    model, B = job.model, job.size
    opts, _ = model.lm.options(job.tol_pos, job.tol_rot, plan.max_iters)
    half, modes = _modes_half(plan, B, 1.0)
    ok = answers.ok(job)
    if plan.manipulability > 0.0:

        def within(rows, qk):
            pos, rot = np.empty(len(qk)), np.empty(len(qk))
            lm.pose_errors(model.G, model.joints, np.ascontiguousarray(job.T[rows]), qk, pos, rot)
            return (pos <= job.tol_pos) & (rot <= job.tol_rot)

        if most_manipulable(job.robot, model, job.T, answers.q, ok, within).any():
            lm.pose_errors(model.G, model.joints, job.T, answers.q, answers.pos_err, answers.rot_err)
    qr, weight, popts = preference(job.robot, plan, B, opts)
    if plan.q_rest is not None:
        nearest_candidates(plan, job, answers, qr)
        ok = answers.ok(job)
    driver.rest_posture((model.G, model.joints), job.T, answers.q, (half, modes), popts, (qr, weight, REST_ITERS,
                        REST_DAMPING), ok, (answers.pos_err, answers.rot_err, np.empty((B, 6))))  # fmt: skip


def _inside(model, T: np.ndarray, rows: np.ndarray, q: np.ndarray, modes: np.ndarray, half: np.ndarray) -> np.ndarray:
    """``(k,)`` bool: ``q: (k, n)`` inside the bounds ``half[rows]`` of targets ``T[rows]`` (modes ``modes[rows]``)."""
    from nik.kernels import lm

    d = np.empty((len(q), 6))
    lm.bounded_errors(model.G, model.joints, np.ascontiguousarray(T[rows]), q, np.ascontiguousarray(modes[rows]), d)
    return (np.abs(d) <= half[rows]).all(1)


def nearest_candidates(plan, job, answers, qr: np.ndarray) -> None:
    """In place (compiled): each successful answer of a redundant arm (more joints than the task's 6 rows: the null
    space that :func:`nik.kernels.driver.rest_posture` moves in) replaced by the candidate nearest ``qr: (B, dof)``
    (Euclidean joint distance) among those that meet the goal. The candidates: the answer, LM from ``qr`` itself, and
    LM from the network's :data:`REST_HYPOTHESES` hypotheses nearest ``qr`` (``answers.hypotheses``, else the
    backend's guess stage anew; without a network, :data:`REST_UNIFORM` uniform starts): LM without restarts, at most
    :data:`REST_CANDIDATE_ITERS` iterations, kept where it converges within the stage tolerances (inside the limits:
    the kernels clamp). The null space is a continuum and the guess lands on one stretch of it; moving along it from
    there ends near that guess (xarm7, 200 targets: 1.42x the distance of the nearest solution ``solve_all`` finds;
    with the candidates 1.015x, ``benchmarks/goals.py --rest``). A 6-joint arm has no null space: its answers stay
    (the closed form's branch is the plan's choice, ``q_near`` picks among them)."""
    model, n = job.model, job.model.dof
    ok = np.asarray(answers.ok(job))
    if n <= 6 or not ok.any():
        return
    idx = np.flatnonzero(ok)
    starts = [qr[idx, None]]
    if plan.net is not None:
        hyp = answers.hypotheses
        if hyp is None:
            hyp = job.backend.network(plan, job)[0]
        hyp = np.asarray(hyp, dtype=np.float64)[idx]
        near = np.argsort(np.linalg.norm(hyp - qr[idx, None], axis=-1), axis=1, kind="stable")[:, :REST_HYPOTHESES]
        starts.append(np.take_along_axis(hyp, near[..., None], axis=1))
    else:
        g = np.random.default_rng(int(plan.seed))
        starts.append(g.uniform(model.lo, model.hi, (idx.size, REST_UNIFORM, n)))
    S = np.clip(np.concatenate(starts, 1), model.lo, model.hi)
    m, K = S.shape[:2]
    T = np.ascontiguousarray(np.repeat(job.T[idx], K, axis=0))
    run = model.lm.solve(T, S.reshape(m * K, n), tol_pos=job.tol_pos, tol_rot=job.tol_rot, seed=plan.seed,
                         max_iters=REST_CANDIDATE_ITERS, restarts=False)  # fmt: skip
    q = run.q.reshape(m, K, n)
    good = run.converged.reshape(m, K) & (run.pos_err.reshape(m, K) <= job.tol_pos)
    good &= run.rot_err.reshape(m, K) <= job.tol_rot
    dist = np.where(good, np.linalg.norm(q - qr[idx, None], axis=-1), np.inf)
    best = dist.argmin(1)
    rows = np.arange(m)
    now = np.linalg.norm(np.asarray(answers.q)[idx] - qr[idx], axis=-1)
    take = dist[rows, best] < now
    at = idx[take]
    pick = (rows[take], best[take])
    answers.q[at] = q[pick]
    answers.pos_err[at] = run.pos_err.reshape(m, K)[pick]
    answers.rot_err[at] = run.rot_err.reshape(m, K)[pick]
    answers.iterations[idx] += run.iterations.reshape(m, K).sum(1)
    answers._ok = None


# -- torch ---------------------------------------------------------------------------------------------------------
def solve_torch(backend, robot, plan, T_target, q_near, representation) -> IKResult:
    """``plan.bounds`` on the torch backend (module docstring): :func:`nik.lm.lm_solve` with ``bounds`` from the
    starts side by side, then from uniform starts for the targets left."""
    from nik.lm import lm_solve
    from nik.poses import pose_error, tool_error, within_bounds

    job = backend.job(robot, plan, T_target, q_near, representation, stacklevel=5)
    T, B = job.T, job.size
    float32 = T.dtype == torch.float32
    half = torch.from_numpy(plan.bounds.expand(B)).to(T)
    stage_half = half * (plan.float32_margin if float32 else 1.0)
    reachable = job.reachable | torch.isinf(half[:, :3]).any(1)
    starts = []
    if plan.source == "network":
        starts.append(backend.network(plan, job)[0].to(T))
    elif plan.source == "analytic":
        starts += [torch.from_numpy(s).to(T) for s in _closed_starts(robot, _model(robot, plan), plan,
                                                                     T.detach().double().cpu().numpy())]  # fmt: skip
    if job.q_near is not None:
        starts.append(job.q_near[:, None])
    g = torch.Generator(device=T.device).manual_seed(int(plan.seed))
    if starts:
        q0 = torch.cat(starts, 1)
        bad = torch.isnan(q0).any(-1, keepdim=True)
        fill = robot.sample(B * q0.shape[1], generator=g, dtype=T.dtype, device=T.device).reshape(q0.shape)
        q0 = torch.where(bad, fill, q0)
    else:
        q0 = None
    q, it = lm_solve(
        robot,
        T,
        q0,
        cfg=plan.lm_cfg,
        max_iters=plan.max_iters,
        generator=g,
        reachable=reachable,
        bounds=stage_half,
        restarts=None if plan.restarts or plan.fallback != "none" else 0,
    )
    q = robot.clamp(q).to(T.dtype)
    if prefers(plan):
        ok = within_bounds(T, robot.fk(q), stage_half)
        q = rest_torch(robot, T, q, ok, plan, stage_half, job.tol_pos, job.tol_rot)
    Tq = robot.fk(q)
    pos, rot = pose_error(T, Tq)
    d = tool_error(T, Tq, torch.from_numpy(plan.bounds.modes(B)).to(T.device))
    ok = (d.abs() <= half).all(-1)
    res = IKResult(q, pos, rot, ok, it.long(), plan.source, reachable=reachable, axis_err=d)
    return res.numpy() if job.numpy_out else res


def _model(robot, plan):
    from nik.ik.model import model_of

    return model_of(robot, plan.lm_cfg)


def rest_torch(robot, T, q, ok, plan, half, tol_pos: float, tol_rot: float) -> torch.Tensor:
    """``q: (B, dof)`` with the answers where ``ok`` moved towards ``plan.q_rest`` in the null space of the task
    (classic where ``half`` is None, else towards the bounds ``half: (B, 6)``): the steps of
    :func:`nik.kernels.driver.rest_posture`, batched, as the one torch LM (:func:`nik.lm.loop.lm_loop`) in its
    null-space mode: the preference step ``z = s (rest_weight (q_rest - q) + up)`` (``s = 1 / lambda``: doubled after
    a kept step up to 1, halved after a refused one, stopping below 1/64) plus the least-squares correction of the
    task rows, kept only where the task still holds and the preference cost fell. Returns a new tensor."""
    from dataclasses import replace

    from nik.lm.batched import LMCfg, chain_of, pose_evaluator
    from nik.lm.loop import Box, lm_loop

    base = plan.lm_cfg if plan.lm_cfg is not None else LMCfg()
    cfg = replace(base, iters=REST_ITERS, stall_iters=REST_ITERS + 1, damping="fixed", eps=REST_DAMPING,
                  lambda0=1.0, lambda_down=0.5, lambda_up=2.0, lambda_min=1.0, lambda_max=64.0, cost_tol=0.0,
                  accept="feasible", compiled=False)  # fmt: skip
    qr, weight, _ = preference(robot, plan, q.shape[0], None)
    qr = torch.from_numpy(qr).to(q).expand(q.shape[0], -1)
    T = T.to(q)
    chain = chain_of(robot, q, wrap=False)
    task = pose_evaluator(T, chain, cfg, (tol_pos, tol_rot), half)

    def evaluate(qq, rows):
        ev = task(qq, rows)
        qr_ = qr.index_select(0, rows)
        cost, up = _preference_torch(robot, qq[:, 0], qr_, weight, plan.manipulability)
        z = weight * (qr_ - qq[:, 0]) + up
        return ev._replace(E=cost[:, None], done=torch.zeros_like(ev.done), feasible=ev.done, z=z[:, None])

    if half is None:
        live = torch.full((q.shape[0],), 6.0, dtype=q.dtype, device=q.device)
    else:
        live = torch.isfinite(half[:, :3]).sum(-1).to(q) + torch.isfinite(half[:, 3:]).any(-1).to(q) * (
            3 - torch.isinf(half[:, 3:]).sum(-1).to(q).clamp(max=1)
        )
    active = ok & (live < q.shape[1])  # no null space: nothing to move
    box = Box(chain.lo, chain.hi, chain.wrap, robot.clamp)
    return lm_loop(evaluate, q[:, None], box, cfg, active=active).q


def _preference_torch(robot, q: torch.Tensor, qr: torch.Tensor, weight: float, mw: float):
    """``(cost (B,), up (B, dof))``: :func:`nik.kernels.driver.rest_posture`'s preference cost of ``q`` and the
    manipulability's step ``mw (w + EPS) grad(w) / |grad(w)|^2`` (zeros without it), in torch."""
    dist = (q - qr).square().sum(-1)
    if mw <= 0.0:
        return dist, torch.zeros_like(q)
    from nik.costs.manipulability import EPS, measure

    with torch.enable_grad():
        x = q.detach().clone().requires_grad_(True)
        w = measure(robot, x)
        (gw,) = torch.autograd.grad(w.sum(), x)
    w = w.detach()
    g2 = gw.square().sum(-1, keepdim=True)
    up = torch.where(g2 > 0, mw * (w + EPS)[:, None] * gw / torch.where(g2 > 0, g2, torch.ones_like(g2)), 0.0)
    return 0.5 * weight * weight * dist + 0.5 * (mw / (w + EPS)) ** 2, up


def rest_stage(plan, job, answers):
    """The stages' posture step (classic tolerances, torch): the successful answers moved towards ``plan.q_rest``
    (and a higher manipulability)."""
    from nik.poses import pose_error

    if plan.q_rest is not None:
        nearest_candidates_torch(plan, job, answers)
    ok = answers.ok(job)
    q = rest_torch(job.robot, job.T, answers.q, ok, plan, None, job.tol_pos, job.tol_rot)
    pos, rot = pose_error(job.T, job.robot.fk(q))
    answers.q, answers.pos_err, answers.rot_err, answers._ok = q, pos, rot, None
    return answers


def nearest_candidates_torch(plan, job, answers) -> None:
    """In place (torch): :func:`nearest_candidates` on the torch backend: the successful answers of a redundant arm
    replaced by the candidate nearest ``plan.q_rest`` that meets the goal, among the answer, LM from ``q_rest`` and
    LM from the :data:`REST_HYPOTHESES` network hypotheses nearest it (``answers.hypotheses``; without them
    :data:`REST_UNIFORM` uniform starts), batched (:func:`nik.lm.lm_solve`, no restarts, at most
    :data:`REST_CANDIDATE_ITERS` iterations)."""
    from nik.lm import lm_solve
    from nik.poses import pose_error

    robot, T = job.robot, job.T
    n = robot.dof
    ok = answers.ok(job)
    if n <= 6 or not bool(ok.any()):
        return
    idx = torch.nonzero(ok).flatten()
    qr = torch.from_numpy(rest_target(robot, plan.q_rest, T.shape[0])).to(answers.q)[idx]
    starts = [qr[:, None]]
    if answers.hypotheses is not None:
        hyp = answers.hypotheses[idx].to(answers.q)
        near = (hyp - qr[:, None]).norm(dim=-1).argsort(dim=1, stable=True)[:, :REST_HYPOTHESES]
        starts.append(torch.gather(hyp, 1, near[..., None].expand(-1, -1, n)))
    else:
        g = torch.Generator(device=T.device).manual_seed(int(plan.seed))
        starts.append(robot.sample(idx.numel() * REST_UNIFORM, generator=g, dtype=T.dtype, device=T.device)
                      .reshape(idx.numel(), REST_UNIFORM, n))  # fmt: skip
    S = robot.clamp(torch.cat(starts, 1))
    m, K = S.shape[:2]
    Tk = T[idx].repeat_interleave(K, dim=0)
    q, it = lm_solve(robot, Tk, S.reshape(m * K, n), cfg=plan.lm_cfg, tol_pos=job.tol_pos, tol_rot=job.tol_rot,
                     max_iters=REST_CANDIDATE_ITERS, restarts=0)  # fmt: skip
    q = robot.clamp(q).to(T.dtype)
    pos, rot = pose_error(Tk, robot.fk(q))
    good = ((pos <= job.tol_pos) & (rot <= job.tol_rot)).reshape(m, K)
    q, pos, rot = q.reshape(m, K, n), pos.reshape(m, K), rot.reshape(m, K)
    dist = torch.where(good, (q - qr[:, None]).norm(dim=-1), torch.full_like(pos, float("inf")))
    best = dist.argmin(1)
    rows = torch.arange(m, device=T.device)
    take = dist[rows, best] < (answers.q[idx] - qr).norm(dim=-1)
    at, pick = idx[take], (rows[take], best[take])
    answers.q, answers.pos_err, answers.rot_err = answers.q.clone(), answers.pos_err.clone(), answers.rot_err.clone()
    answers.q[at] = q[pick].to(answers.q.dtype)
    answers.pos_err[at] = pos[pick].to(answers.pos_err.dtype)
    answers.rot_err[at] = rot[pick].to(answers.rot_err.dtype)
    answers.iterations[idx] += it.reshape(m, K).sum(1).to(answers.iterations.dtype)
    answers._ok = None


# -- solve_all -----------------------------------------------------------------------------------------------------
def all_solutions_bounded(plan, job, *, closed_form: bool, n_starts: int = 256, dedupe_tol: float = 1e-3):
    """``(K, dof)`` distinct solutions of the one pose of ``job`` inside ``plan.bounds``: on a closed-form arm with
    one free rotation axis, every valid sampled closed-form solution (:func:`nik.ik.free_axis.closed_form_free_axis`,
    36 angles) that meets the goal; else LM towards the bounds (100 iterations, no restarts) from the network's
    hypotheses and ``n_starts`` uniform starts, kept where inside, de-duplicated at ``dedupe_tol`` (a free axis makes
    a continuum: K counts the samples found)."""
    from nik.ik.guesses import dedupe
    from nik.lm import lm_solve
    from nik.poses import bounded_error, within_bounds

    robot, T = job.robot, job.T
    half = torch.from_numpy(plan.bounds.expand(1)).to(T)
    modes = plan.bounds.modes(1)
    if closed_form and 0 <= int(modes[0]) <= 2:
        from nik.ik.free_axis import closed_form_free_axis

        fa = closed_form_free_axis(robot, T, bounds=plan.bounds, refine=False)
        q = fa.solutions[0][fa.valid[0]]
    else:
        g = torch.Generator(device=T.device).manual_seed(int(plan.seed))
        starts = robot.sample(n_starts, generator=g, dtype=T.dtype, device=T.device)
        if plan.net is not None:
            Tn = T
            if plan.net_in_arm_frame:  # the bare arm's frame: base^-1 @ T @ tool^-1
                Tn = Tn if robot.base is None else torch.linalg.inv(robot.base.to(T)) @ Tn
                Tn = Tn if robot.tool is None else Tn @ torch.linalg.inv(robot.tool.to(T))
            hyp = plan.net.hypotheses(Tn)[0] if hasattr(plan.net, "hypotheses") else plan.net.predict(Tn)
            starts = torch.cat([robot.clamp(hyp).to(T), starts])
        Tk = T.expand(starts.shape[0], 4, 4)
        q, _ = lm_solve(robot, Tk, starts, cfg=plan.lm_cfg, max_iters=100, restarts=0, generator=g,
                        bounds=half.expand(starts.shape[0], 6))  # fmt: skip
        q = robot.clamp(q).to(T.dtype)
    if q.shape[0] == 0:
        return q
    Tq = robot.fk(q)
    keep = within_bounds(T.expand(q.shape[0], 4, 4), Tq, half.expand(q.shape[0], 6))
    q = q[keep]
    err = bounded_error(T.expand(q.shape[0], 4, 4), robot.fk(q), half.expand(q.shape[0], 6)).square().sum(-1)
    return dedupe(q[err.argsort()], tol=dedupe_tol, prismatic=robot.prismatic)
