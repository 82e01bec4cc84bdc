"""The compiled interpreter of a solve plan: every stage of one call in one kernel call.

The stages are those of ``nik.ik.stages`` (guess, refine, near, more hypotheses, fallback, final check), in the same
order and on the same kernels (:func:`nik.kernels.poses.reach_flags`, :func:`nik.kernels.seeded.ranked_hypotheses`,
:func:`nik.kernels.closed.guess`, :func:`nik.kernels.lm.lm_solve`, :func:`nik.kernels.seeded.lm_starts`,
:func:`nik.kernels.seeded.merge`): the targets a stage takes up are gathered into compact arrays as the staged
backend gathers them (``np.flatnonzero``), so that each LM call sees the same targets in the same order and draws
the same random streams; the answers equal those of the staged compiled backend. Only the Python between the
kernels is gone.

The plan arrives as numbers (``SOURCE_*``, ``FALLBACK_*`` codes and flags); a stage that does not apply gets empty
arrays of the right kinds (no network: ``heads = 0``; no closed form: ``closed`` empty), so one compiled version
serves every arm and plan.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER, WRAPS, _chain, _chain_jacobian
from nik.kernels.closed import guess as closed_guess
from nik.kernels.lm import (
    _STREAM,
    CLASSIC,
    MANIPULABILITY,
    MAX_STEP,
    ROT_WEIGHT,
    TOL_POS,
    TOL_ROT,
    PoseProblem,
    PoseState,
    _bounded_check,
    _bounds,
    _copy,
    _eval_goal,
    _lm_one_bounded,
    _measure_pose,
    _tool_error,
    _work_size,
    lm_solve,
    turns_toward,
)
from nik.kernels.lm_loop import ACCEPT_ANY, ACCEPT_LOWER, NEVER, _lm_loop, _loop_cfg, problem_kind
from nik.kernels.lm_step import _dense_step
from nik.kernels.manipulability import EPS as MANIP_EPS
from nik.kernels.manipulability import _manipulability
from nik.kernels.poses import reach_flags
from nik.kernels.seeded import lm_starts, merge, ranked_hypotheses
from nik.tolerances import NEAR_FAR, NEAR_PRIOR, NEAR_PRIOR_STEPS

__all__ = ["FALLBACK_ANALYTIC", "FALLBACK_MULTISTART", "FALLBACK_NONE", "SOURCE_ANALYTIC", "SOURCE_MULTISTART",
           "SOURCE_NETWORK", "rest_posture", "solve", "solve_bounded"]  # fmt: skip

#: The manipulability's null-space step stops after a kept step that lowers its cost by less than this share of it.
MANIP_STALL = 0.02
#: Codes of the plan's guess source and fallback.
SOURCE_NETWORK, SOURCE_ANALYTIC, SOURCE_MULTISTART = 0, 1, 2
FALLBACK_NONE, FALLBACK_ANALYTIC, FALLBACK_MULTISTART = 0, 1, 2


@kernel
def _pose_state(n):
    """A :data:`nik.kernels.lm.PoseState` of ``n`` joints without extra rows, on arrays of its own."""
    return PoseState(np.empty(n), np.empty((3, 4)), np.empty((6, n)), np.empty(6), np.empty(3), None)


@kernel
def near_prior(G, joints, T, q_near, rw, max_step, q):
    """``q: (B, n)`` out: from ``q_near: (B, n)``, Gauss-Newton steps on ``|e|^2 + w^2 |q - q_near|^2`` (``e``: the
    pose error of ``T: (B, 4, 4)``, rotation rows times ``rw``) with ``w`` over :data:`NEAR_PRIOR`, each
    :data:`NEAR_PRIOR_STEPS` times: ``(J^T J + w^2 I) dq = J^T e - w^2 (q - q_near)``. Each weight is one run of the
    one LM loop (:func:`nik.kernels.lm_loop._lm_loop`) on the pose rows with that prior row, ``lam = 0``, every good
    step kept, stop on a failed step: the joints on a limit that a step pushes out held
    (:func:`nik.kernels.lm_step.hold`), scaled to ``max_step``, clamped into the limits (``joints``; pass them
    without wrapping). Not exact (``w`` ends above 0): a start for LM that stays on the side of ``q_near``."""
    B, n = q.shape
    cur, other = _pose_state(n), _pose_state(n)
    d, work = np.empty(6), (np.empty((n, n)), np.empty(n), np.empty(n))
    cfg = _loop_cfg(NEAR_PRIOR_STEPS, 0.0, (1.0, 1.0, 0.0, 0.0), -1.0, (0.0, NEVER), (-math.inf, 0.0), ACCEPT_ANY)
    for b in range(B):
        _copy(q_near[b], cur.q)
        for w in NEAR_PRIOR:  # the goal's tolerances -1: never done, every step taken
            prob = PoseProblem(G, joints, (T[b], rw, d, CLASSIC, -1.0, -1.0), (q_near[b], w * w), 1e-9, max_step, d,
                               work)  # fmt: skip
            E, done = _measure_pose(prob, cur, math.inf)
            _, _, _, cur, other = _lm_loop(prob, cfg, cur, other, E, done)
        _copy(cur.q, q[b])


@kernel
def _gather(mask, want):
    """Indices ``b`` with ``mask[b] == want`` (as ``np.flatnonzero``)."""
    m = 0
    for b in range(mask.shape[0]):
        if mask[b] == want:
            m += 1
    idx = np.empty(m, dtype=np.int64)
    m = 0
    for b in range(mask.shape[0]):
        if mask[b] == want:
            idx[m] = b
            m += 1
    return idx


@kernel
def _rows(x, idx):
    out = np.empty((idx.shape[0],) + x.shape[1:], dtype=x.dtype)
    for i in range(idx.shape[0]):
        out[i] = x[idx[i]]
    return out


@kernel
def _budgets(reachable, budget):
    out = np.empty(reachable.shape[0], dtype=np.int64)
    for b in range(reachable.shape[0]):
        out[b] = budget if reachable[b] else 0
    return out


@kernel
def _lm(G, joints, T, q0, opts, iopts, budget, seed):
    """:func:`nik.kernels.lm.lm_solve` with its outputs allocated here: ``(q, iterations, pos, rot)``."""
    B, n = T.shape[0], joints.shape[0]
    q, it = np.empty((B, n)), np.empty(B, dtype=np.int64)
    conv, pos, rot = np.empty(B, dtype=np.bool_), np.empty(B), np.empty(B)
    lm_solve(G, joints, T, q0, opts, iopts, budget, seed, (q, it, conv, pos, rot))
    return q, it, pos, rot


@kernel
def solve(model, T, guess, Tin, closed_form, q_near, use_near, stages, out):
    """One call of the plan on ``T: (B, 4, 4)`` float64 targets.

    Args:
        model: ``(G, joints)``, the chain model.
        guess: ``(center, radius, slack, source, flat, layout, activation, in_mean, in_std, out_center, out_half,
            prismatic, heads)``: the reach bound (:func:`nik.kernels.poses.reach_flags`), ``SOURCE_*`` and the packed
            network (:func:`nik.kernels.seeded.ranked_hypotheses`); ``Tin``: its input poses.
        closed_form: ``(closed, check_tol, limit_rounding)``, the closed form (:func:`nik.kernels.closed.guess`).
        q_near: (B, n), read when ``use_near``.
        stages: ``(opts, iopts, iopts_multi, budget, seed, restarts, hypotheses, near, fallback, tol_pos, tol_rot)``:
            LM options from given starts and from the best uniform configurations (no guess); the restarts a target
            within reach may draw; seed (1,) uint64; the plan's flags; ``FALLBACK_*``; the stages' tolerances.
        out: ``(q (B, n), pos, rot (B,), ok (B,) bool, iterations (B,) int64, reachable (B,) bool)``, written here.

    Returns whether every target is within reach. The tuples are those of
    :meth:`nik.ik.backends.compiled.CompiledBackend.driver_args` (gathered once per plan).
    """
    G, joints = model
    center, radius, slack, source, flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, heads = (
        guess
    )
    closed, check_tol, limit_rounding = closed_form
    opts, iopts, iopts_multi, budget, seed, restarts, hypotheses, near, fallback, tol_pos, tol_rot = stages
    q, pos, rot, ok, iterations, reachable = out
    B, n = T.shape[0], joints.shape[0]
    every = reach_flags(T, center, radius, slack, reachable)
    for b in range(B):
        iterations[b] = 0
    has_hyp = False
    hyp = np.empty((0, 0, n))
    guessed = True
    if source == SOURCE_NETWORK:
        net = (flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, heads)
        hyp, p, r, o, _ = ranked_hypotheses(net, G, joints, Tin, T, tol_pos, tol_rot)
        for b in range(B):
            q[b] = hyp[b, 0]
            pos[b], rot[b], ok[b] = p[b], r[b], o[b]
        has_hyp = hyp.shape[1] > 1 and hypotheses
    elif source == SOURCE_ANALYTIC:
        closed_guess(
            closed, G, joints, check_tol, T, q_near if use_near else q, use_near, limit_rounding, tol_pos, tol_rot,
            reachable, (q, pos, rot, ok),
        )  # fmt: skip
    else:
        guessed = False
    restarts_first = restarts and not has_hyp
    # refine
    if not guessed:
        b_all = _budgets(reachable, budget if restarts_first else 0)
        rq, rit, rpos, rrot = _lm(G, joints, T, np.zeros((B, n)), opts, iopts_multi, b_all, seed)
        for b in range(B):
            q[b] = rq[b]
            pos[b], rot[b], iterations[b] = rpos[b], rrot[b], rit[b]
            ok[b] = pos[b] <= tol_pos and rot[b] <= tol_rot
    else:
        todo = np.empty(B, dtype=np.bool_)
        for b in range(B):
            todo[b] = not ok[b] and (reachable[b] or source != SOURCE_ANALYTIC)
        idx = _gather(todo, True)
        if idx.shape[0] > 0:
            reach = _rows(reachable, idx)
            rq, rit, rpos, rrot = _lm(
                G, joints, _rows(T, idx), _rows(q, idx), opts, iopts,
                _budgets(reach, budget if restarts_first else 0), seed,
            )  # fmt: skip
            merge((q, pos, rot, iterations, ok), idx, (rq, rpos, rrot, rit), False, tol_pos, tol_rot)
    # near
    if use_near and near:
        b_all = _budgets(reachable, budget if restarts and fallback != FALLBACK_NONE else 0)
        local = joints.copy()  # from q_near no joint wraps: a turn across a limit lands a full turn away
        for j in range(n):
            local[j, WRAPS] = 0.0
        rq, rit, rpos, rrot = _lm(G, local, T, q_near, opts, iopts, b_all, seed)
        turns_toward(joints, q, q_near)
        turns_toward(joints, rq, q_near)
        for b in range(B):
            ok_b = rpos[b] <= tol_pos and rrot[b] <= tol_rot
            da, db = 0.0, 0.0
            for j in range(n):
                da += (q[b, j] - q_near[b, j]) ** 2
                db += (rq[b, j] - q_near[b, j]) ** 2
            worse_a = pos[b] + 0.1 * rot[b] > rpos[b] + 0.1 * rrot[b]
            if (ok_b and (not ok[b] or math.sqrt(db) < math.sqrt(da))) or (not ok[b] and not ok_b and worse_a):
                q[b] = rq[b]
                pos[b], rot[b] = rpos[b], rrot[b]
            iterations[b] += rit[b]
            ok[b] = pos[b] <= tol_pos and rot[b] <= tol_rot
        if n > 6:  # a redundant arm's answer drifts along its self-motion: LM again from a walk out of q_near
            far = np.empty(B, dtype=np.bool_)
            for b in range(B):
                d = 0.0
                for j in range(n):
                    d = max(d, abs(q[b, j] - q_near[b, j]))
                far[b] = d > NEAR_FAR
            idx = _gather(far, True)
            m = idx.shape[0]
            if m > 0:
                Ti, qn = _rows(T, idx), _rows(q_near, idx)
                start = np.empty((m, n))
                near_prior(G, local, Ti, qn, opts[ROT_WEIGHT], opts[MAX_STEP], start)
                rq, rit, rpos, rrot = _lm(G, local, Ti, start, opts, iopts, _budgets(_rows(reachable, idx), 0), seed)
                for i in range(m):
                    b = idx[i]
                    da, db = 0.0, 0.0
                    for j in range(n):
                        da += (q[b, j] - q_near[b, j]) ** 2
                        db += (rq[i, j] - q_near[b, j]) ** 2
                    if rpos[i] <= tol_pos and rrot[i] <= tol_rot and (not ok[b] or db < da):
                        q[b] = rq[i]
                        pos[b], rot[b], ok[b] = rpos[i], rrot[i], True
                    iterations[b] += rit[i]
    # more hypotheses
    if has_hyp:
        idx = _gather(ok, False)
        if idx.shape[0] > 0:
            m, K = idx.shape[0], hyp.shape[1]
            starts = np.empty((m, K - 1, n))
            for i in range(m):
                for k in range(1, K):
                    starts[i, k - 1] = hyp[idx[i], k]
            rq, rit = np.empty((m, n)), np.empty(m, dtype=np.int64)
            conv, rpos, rrot = np.empty(m, dtype=np.bool_), np.empty(m), np.empty(m)
            lm_starts(G, joints, _rows(T, idx), starts, opts, iopts, seed, rq, rit, conv, rpos, rrot)
            merge((q, pos, rot, iterations, ok), idx, (rq, rpos, rrot, rit), True, tol_pos, tol_rot)
    # fallback
    skip = fallback == FALLBACK_NONE
    skip = skip or (fallback == FALLBACK_ANALYTIC and source == SOURCE_ANALYTIC)
    skip = skip or (fallback == FALLBACK_MULTISTART and restarts_first)
    if not skip:
        todo = np.empty(B, dtype=np.bool_)
        for b in range(B):
            todo[b] = not ok[b] and reachable[b]
        idx = _gather(todo, True)
        m = idx.shape[0]
        if m > 0:
            Ti = _rows(T, idx)
            if fallback == FALLBACK_ANALYTIC:
                start = _rows(q_near, idx) if use_near else _rows(q, idx)
                rq, rpos, rrot = np.empty((m, n)), np.empty(m), np.empty(m)
                rok = np.empty(m, dtype=np.bool_)
                closed_guess(
                    closed, G, joints, check_tol, Ti, start, True, limit_rounding, tol_pos, tol_rot,
                    _rows(reachable, idx), (rq, rpos, rrot, rok),
                )  # fmt: skip
                rit = np.zeros(m, dtype=np.int64)
            else:
                rq, rit, rpos, rrot = _lm(
                    G, joints, Ti, np.zeros((m, n)), opts, iopts_multi, _budgets(_rows(reachable, idx), budget), seed
                )
            merge((q, pos, rot, iterations, ok), idx, (rq, rpos, rrot, rit), True, tol_pos, tol_rot)
    return every


@kernel
def solve_bounded(model, T, starts, goal, lm, out):
    """One call towards tolerant goals (:mod:`nik.ik.bounds`) on ``T: (B, 4, 4)`` float64 targets.

    Per target ``b``: its starts ``starts[b]: (K, n)`` (the network's hypotheses, the closed-form solutions, ``q_near``;
    rows with a NaN are skipped) are brought inside the limits and ranked by the bounded error
    (:func:`nik.kernels.lm._bounded_check`), then LM towards the bounds (:func:`nik.kernels.lm._lm_one_bounded`, no
    restarts) runs from each in that order until one lands inside every bound; a target still outside (or without
    starts) gets LM from the best of the uniform configurations of ``iopts_multi`` with ``budget[b]`` restarts (0 for
    a target proven out of reach). The answer is the first inside, else the smallest bounded error.

    Args:
        model: ``(G, joints)``, the chain model.
        goal: ``(half, modes)``: ``half (B, 6)`` half-widths (m, rad, ``inf`` = free), ``modes (B,)`` rotation modes
            (:func:`nik.kernels.lm.rotation_modes`).
        lm: ``(opts, iopts, iopts_multi, budget, seed)``: LM options (:func:`nik.kernels.lm.lm_options`), ``budget
            (B,)`` int64, ``seed (1,)`` uint64 (target ``b`` draws from its own stream).
        out: ``(q, ok, iterations, pos, rot, d)``, written here: ``q (B, n)`` inside the limits, ``ok (B,)`` (FK of
            ``q`` inside every bound), ``iterations (B,)``, ``pos, rot (B,)`` the classic errors (m, geodesic rad)
            and ``d (B, 6)`` the error per tool axis (:func:`nik.kernels.lm.bounded_errors`; 0 on the entry of a free
            rotation axis).
    """
    G, joints = model
    half, modes = goal
    opts, iopts, iopts_multi, budget, seed = lm
    q, ok, iterations, pos, rot, d = out
    B, K, n = starts.shape
    rw = opts[ROT_WEIGHT]
    rng = np.empty(1, dtype=np.uint64)
    work = np.empty(_work_size(n))
    cand = np.empty(n)
    Tc = np.empty((3, 4))
    e = np.empty(6)
    ds = np.empty(6)
    score = np.empty(max(K, 1))
    for b in range(B):
        rng[0] = seed[0] ^ (np.uint64(b) * _STREAM)
        for k in range(K):
            score[k] = math.inf
            if math.isfinite(starts[b, k, 0]):
                _bounds(joints, starts[b, k])
                _chain(G, joints, starts[b, k], Tc)
                score[k], _, _, _ = _bounded_check(T[b], Tc, half[b], modes[b], rw, e, ds)
        best = math.inf
        total = 0
        done = False
        for _ in range(K):
            k = 0
            for j in range(1, K):
                if score[j] < score[k]:
                    k = j
            if score[k] == math.inf:
                break
            score[k] = math.inf
            it, conv, _, _ = _lm_one_bounded(
                G, joints, T[b], starts[b, k], half[b], modes[b], opts, iopts, 0, rng, cand, work
            )
            total += it
            _chain(G, joints, cand, Tc)
            E, _, _, _ = _bounded_check(T[b], Tc, half[b], modes[b], rw, e, ds)
            if conv or E < best:
                best = E
                _copy(cand, q[b])
            if conv:
                done = True
                break
        if not done and (best == math.inf or budget[b] > 0):
            it, conv, _, _ = _lm_one_bounded(
                G, joints, T[b], cand, half[b], modes[b], opts, iopts_multi, budget[b], rng, cand, work
            )
            total += it
            _chain(G, joints, cand, Tc)
            E, _, _, _ = _bounded_check(T[b], Tc, half[b], modes[b], rw, e, ds)
            if conv or E < best:
                _copy(cand, q[b])
        iterations[b] = total
        _chain(G, joints, q[b], Tc)
        pos[b], rot[b] = _tool_error(T[b], Tc, modes[b], d[b])
        inside = True
        for r in range(6):
            if not abs(d[b, r]) <= half[b, r]:
                inside = False
        ok[b] = inside


@kernel
def _geometric(G, joints, q, J, rw, mode, T6, J6):
    """``J6 (6, n)``: the geometric Jacobian at ``q``, from the task's ``J`` where that is it (the classic error:
    rotation rows times ``rw``), else by :func:`nik.kernels.chain._chain_jacobian` (scratch ``T6``)."""
    if mode == CLASSIC and rw != 0.0:
        for r in range(6):
            f = 1.0 if r < 3 else 1.0 / rw
            for i in range(q.shape[0]):
                J6[r, i] = J[r, i] * f
    else:
        _chain_jacobian(G, joints, q, T6, J6)


@kernel
def _preference(joints, q, q_rest, weight, mw, J6, A6, M6, grad):
    """``(cost, w)`` of the null-space step's preferences at ``q (n,)``: ``|q - q_rest|^2`` where ``mw == 0`` (the
    posture alone), else ``weight^2 |q - q_rest|^2 / 2 + (mw / (w + EPS))^2 / 2`` with ``w`` the manipulability of
    the geometric Jacobian ``J6`` (:mod:`nik.kernels.manipulability`), ``grad (n,)`` then the gradient of ``log w``."""
    n = q.shape[0]
    dist = 0.0
    for i in range(n):
        dist += (q[i] - q_rest[i]) ** 2
    if mw == 0.0:
        return dist, 0.0
    w = _manipulability(J6, joints, A6, M6, grad)
    return 0.5 * weight * weight * dist + 0.5 * (mw / (w + MANIP_EPS)) ** 2, w


#: The null-space posture problem of one answer for :func:`nik.kernels.lm_loop._lm_loop`: the model ``G, joints``
#: and ``free`` (the limits open: no joint held), the goal of :func:`nik.kernels.lm._eval_goal`, the posture
#: ``q_rest (n,)`` and its ``weight``, the manipulability weight ``mw``, the prior's weight ``damping``, the largest
#: step ``max_step``; scratch ``d (6,)``, ``geo = (T6, J6, A6, M6)``, ``qp (n,)``, ``work = (A, g, dq)``.
RestProblem = namedtuple(
    "RestProblem", ["G", "joints", "free", "goal", "q_rest", "weight", "mw", "damping", "max_step", "d", "geo", "qp",
                    "work"]
)  # fmt: skip
#: Its state: ``q (n,)``, ``T (3, 4)``, the task rows ``J (6, n)``, ``e (6,)``, ``info (4,)`` = (unused, position
#: error m, rotation angle rad, manipulability ``w``) and ``grad (n,)``, the gradient of ``log w``.
RestState = namedtuple("RestState", ["q", "T", "J", "e", "info", "grad"])


@kernel
def _measure_rest(prob, s, bar):
    """The loop's measure of the posture problem: the task at ``s.q`` and the preference's cost (:func:`_preference`);
    returns ``(cost, False)``, the cost ``inf`` where ``s.q`` has left the task (its tolerances or bounds; ``bar``
    unused)."""
    Tt, rw, bnd, mode, tol_pos, tol_rot = prob.goal
    _, p, r, done = _eval_goal(prob.G, prob.joints, s.q, (Tt, rw, bnd, mode, tol_pos, tol_rot), s.T, s.J, s.e, prob.d)
    T6, J6, A6, M6 = prob.geo
    if prob.mw > 0.0:
        _geometric(prob.G, prob.joints, s.q, s.J, rw, mode, T6, J6)
    dist, w = _preference(prob.joints, s.q, prob.q_rest, prob.weight, prob.mw, J6, A6, M6, s.grad)
    s.info[1], s.info[2], s.info[3] = p, r, w
    return (dist if done else math.inf), False


@kernel
def _propose_rest(prob, s, lam, c):
    """The loop's proposal of the posture problem: the null-space step of :func:`rest_posture` with ``s = 1 / lam``
    (the dense step with the prior ``q + z``, no Marquardt damping, no joint held), refused above ``max_step``, then
    brought inside the limits; returns ``(good, its largest entry)``."""
    n = s.q.shape[0]
    sc = 1.0 / lam
    gm = 0.0  # the manipulability's share: s mw (w + EPS) grad(w) / |grad(w)|^2, grad(w) = w grad(log w)
    w = s.info[3]
    if prob.mw > 0.0 and w > 0.0:
        g2 = 0.0
        for i in range(n):
            g2 += s.grad[i] * s.grad[i]
        if g2 > 0.0:
            gm = sc * prob.mw * (w + MANIP_EPS) / (w * g2)
    qp = prob.qp
    for i in range(n):
        qp[i] = s.q[i] + sc * prob.weight * (prob.q_rest[i] - s.q[i]) + gm * s.grad[i]
    good = _dense_step(s.J, s.e, None, (qp, prob.damping), s.q, prob.free, 0.0, 0.0, math.inf, prob.work)
    dq = prob.work[2]
    big = 0.0
    if good:
        for i in range(n):
            big = max(big, abs(dq[i]))
            c.q[i] = s.q[i] + dq[i]
        good = big <= prob.max_step
    if good:
        _bounds(prob.joints, c.q)
    return good, big


problem_kind(RestProblem, _measure_rest, _propose_rest)


@kernel
def rest_posture(model, T, q, goal, opts, posture, ok, fit):
    """In place: the answers ``q: (B, n)`` where ``ok[b]`` moved towards ``q_rest: (B, n)`` in the null space of the
    task, never leaving it (see :mod:`nik.ik.goals`). ``model = (G, joints)``; ``goal = (half, modes)`` as
    :func:`solve_bounded`'s; ``posture = (q_rest, weight, iters, damping)``; ``fit = (pos, rot, d)``, updated.

    Each iteration takes the step ``dq = z + J^T (J J^T + damping I)^-1 (e - J z)`` with ``z = s * weight * (q_rest -
    q)``: the task residual ``e`` (and its Jacobian ``J``: the classic error where ``modes[b] == CLASSIC``, else the
    bounded one of ``half[b]``, whose free rows vanish and so leave more room) is held (to first order) while the rest
    of the motion goes to ``q_rest``. That step is the one of ``|e - J dq|^2 + damping |dq - z|^2`` (the push-through
    identity): the one LM loop (:func:`nik.kernels.lm_loop._lm_loop`) with the prior row ``q + z`` (weight
    ``damping``, no Marquardt damping, no joint held at a limit: a joint held would leave a 7-joint arm no null space
    to move in; the clamp into the limits follows the step). The step is kept only where FK of the result is still
    within tolerance (the tolerances of ``opts``, or inside every bound) and nearer ``q_rest``; else ``s`` is halved
    (from 1; doubled after a kept one; stop below 1/64: the loop's damping ``lam = 1 / s``). ``pos, rot, d`` are
    updated for the kept answers (as :func:`solve_bounded`'s).
    A target whose task has as many live rows as the arm has joints (a 6-joint arm, no free axis) has no null space
    and is left as it is.

    With ``opts[MANIPULABILITY] = mw > 0`` (:func:`nik.costs.manipulability`) the step also asks ``s * mw`` times the
    Gauss-Newton step of the residual ``1 / (w + EPS)``, ``(w + EPS) grad(w) / |grad(w)|^2`` (the step that would
    double Yoshikawa's ``w`` to first order), and a step is kept where the cost of :func:`_preference` falls
    (``weight = 0`` with ``q_rest`` anything: the manipulability alone); it stops after a kept step that lowers that
    cost by less than :data:`MANIP_STALL` of it (the measure has no target to reach).
    """
    G, joints = model
    half, modes = goal
    q_rest, weight, iters, damping = posture
    pos, rot, d = fit
    B, n = q.shape
    rw, tol_pos, tol_rot, max_step = opts[ROT_WEIGHT], opts[TOL_POS], opts[TOL_ROT], opts[MAX_STEP]
    mw = opts[MANIPULABILITY]
    Tc, dd = np.empty((3, 4)), np.empty(6)
    geo = (np.empty((3, 4)), np.empty((6, n)), np.empty((6, 6)), np.empty((6, n)))
    work, qp = (np.empty((n, n)), np.empty(n), np.empty(n)), np.empty(n)
    # grad stays 0 without the manipulability (the step reads it as 0 * grad: no garbage may enter)
    cur = RestState(np.empty(n), np.empty((3, 4)), np.empty((6, n)), np.empty(6), np.zeros(4), np.zeros(n))
    other = RestState(np.empty(n), np.empty((3, 4)), np.empty((6, n)), np.empty(6), np.zeros(4), np.zeros(n))
    free = joints.copy()  # no joint held at a limit: the step slides along it and the clamp follows
    for i in range(n):
        free[i, LOWER], free[i, UPPER] = -math.inf, math.inf
    conv = MANIP_STALL if mw > 0.0 else -math.inf  # the manipulability has no target: stop on a small gain
    cfg = _loop_cfg(iters, 1.0, (0.5, 2.0, 1.0, math.inf), 64.0, (0.0, NEVER), (conv, 1e-9), ACCEPT_LOWER)
    for b in range(B):
        mode = modes[b]
        bnd = half[b]
        live = 6
        if mode != CLASSIC:
            live = 3 if mode == 3 else (5 if mode >= 0 else 6)
            for r in range(3):
                if not bnd[r] < math.inf:
                    live -= 1
        if not ok[b] or n <= live:  # no null space: nothing to move
            continue
        prob = RestProblem(G, joints, free, (T[b], rw, bnd, mode, tol_pos, tol_rot), q_rest[b], weight, mw, damping,
                           max_step, dd, geo, qp, work)  # fmt: skip
        _copy(q[b], cur.q)
        E, _ = _measure_rest(prob, cur, math.inf)
        if E == math.inf:  # not within the task: nothing to hold
            continue
        _, _, _, cur, other = _lm_loop(prob, cfg, cur, other, E, False)
        _copy(cur.q, q[b])
        pos[b], rot[b] = cur.info[1], cur.info[2]
        if mode != CLASSIC:
            _chain(G, joints, q[b], Tc)
            _tool_error(T[b], Tc, mode, d[b])
