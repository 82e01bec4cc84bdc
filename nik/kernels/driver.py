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

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.closed import guess as closed_guess
from nik.kernels.lm import lm_solve
from nik.kernels.poses import reach_flags
from nik.kernels.seeded import lm_starts, merge, ranked_hypotheses

__all__ = ["FALLBACK_ANALYTIC", "FALLBACK_MULTISTART", "FALLBACK_NONE", "SOURCE_ANALYTIC", "SOURCE_MULTISTART",
           "SOURCE_NETWORK", "solve"]  # fmt: skip

#: Codes of the plan's guess source and fallback.
SOURCE_NETWORK, SOURCE_ANALYTIC, SOURCE_MULTISTART = 0, 1, 2
FALLBACK_NONE, FALLBACK_ANALYTIC, FALLBACK_MULTISTART = 0, 1, 2


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
    lm_solve(G, joints, T, q0, opts, iopts, budget, seed, q, it, conv, pos, rot)
    return q, it, pos, rot


@kernel
def solve(
    G,
    joints,
    T,
    center,
    radius,
    slack,
    source,
    flat,
    layout,
    activation,
    in_mean,
    in_std,
    out_center,
    out_half,
    prismatic,
    heads,
    Tin,
    closed,
    check_tol,
    limit_rounding,
    q_near,
    use_near,
    opts,
    iopts,
    iopts_multi,
    budget,
    seed,
    restarts,
    hypotheses,
    near,
    fallback,
    tol_pos,
    tol_rot,
    q,
    pos,
    rot,
    ok,
    iterations,
    reachable,
):
    """One call of the plan on ``T: (B, 4, 4)`` float64 targets.

    Args:
        G, joints: the model; center, radius, slack: the reach bound (:func:`nik.kernels.poses.reach_flags`).
        source: ``SOURCE_*``; flat ... heads, Tin: the packed network (:func:`nik.kernels.seeded.ranked_hypotheses`;
            ``Tin`` its input poses); closed, check_tol, limit_rounding: the closed form
            (:func:`nik.kernels.closed.guess`).
        q_near: (B, n), read when ``use_near``.
        opts, iopts: LM options from given starts; iopts_multi: from the best uniform configurations (no guess);
        budget: the restarts a target within reach may draw; seed: (1,) uint64.
        restarts, hypotheses, near: the plan's flags; fallback: ``FALLBACK_*``; tol_pos, tol_rot: the stages'.

    Outputs ``q (B, n), pos, rot (B,), ok (B,) bool, iterations (B,) int64, reachable (B,) bool``; returns
    whether every target is within reach.
    """
    B, n = T.shape[0], joints.shape[0]
    every = reach_flags(T, center, radius, slack, reachable)
    for b in range(B):
        iterations[b] = 0
    has_hyp = False
    hyp = np.empty((0, 0, n))
    guessed = True
    if source == SOURCE_NETWORK:
        hyp, p, r, o, _ = ranked_hypotheses(
            flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, heads, G, joints, Tin, T,
            tol_pos, tol_rot,
        )  # fmt: skip
        for b in range(B):
            q[b] = hyp[b, 0]
            pos[b], rot[b], ok[b] = p[b], r[b], o[b]
        has_hyp = hyp.shape[1] > 1 and hypotheses
    elif source == SOURCE_ANALYTIC:
        closed_guess(
            closed, G, joints, check_tol, T, q_near if use_near else q, use_near, limit_rounding, tol_pos, tol_rot,
            reachable, q, pos, rot, ok,
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
            merge(q, pos, rot, iterations, ok, idx, rq, rpos, rrot, rit, False, tol_pos, tol_rot)
    # near
    if use_near and near:
        b_all = _budgets(reachable, budget if restarts and fallback != FALLBACK_NONE else 0)
        rq, rit, rpos, rrot = _lm(G, joints, T, q_near, opts, iopts, b_all, seed)
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
            merge(q, pos, rot, iterations, ok, idx, rq, rpos, rrot, rit, True, tol_pos, tol_rot)
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
                    _rows(reachable, idx), rq, rpos, rrot, rok,
                )  # fmt: skip
                rit = np.zeros(m, dtype=np.int64)
            else:
                rq, rit, rpos, rrot = _lm(
                    G, joints, Ti, np.zeros((m, n)), opts, iopts_multi, _budgets(_rows(reachable, idx), budget), seed
                )
            merge(q, pos, rot, iterations, ok, idx, rq, rpos, rrot, rit, True, tol_pos, tol_rot)
    return every
