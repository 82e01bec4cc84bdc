"""The candidates at each waypoint and the paths made of them alone: the closed form's branches (sampled about a free
tool axis), LM chains from ``q_start``, from the network's hypotheses or from uniform starts, and the closed-form
path (branches chosen over the whole path, then refined, gaps filled)."""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.paths.choice import _choose
from nik.paths.run import _errors, _Run
from nik.paths.settings import PATH_DEDUPE, PATH_DP_CELLS, PATH_FOLLOW_STEP, PATH_PULL, PATH_STARTS
from nik.tolerances import score


def _chain_from_start(run: _Run) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q (N, dof), iterations (N,), ok (N,))``: the LM chain from ``q0``, each waypoint seeded by the answer before
    (no restarts: a restart could only jump); ``ok`` where it reaches the waypoint inside the limits."""
    q, its, ok = run.chains(run.T, run.q0[None], run.reachable, pull=0.0, restarts=0)
    inside = ((q[0] >= run.model.lo - 1e-9) & (q[0] <= run.model.hi + 1e-9)).all(axis=1)
    return q[0], its[0], ok[0] & inside


def _follows(run: _Run, chain, max_step: float):
    """``(q (N, dof), iterations (N,))`` of the chain from ``q0`` (:func:`_chain_from_start`) when it follows the whole
    path smoothly (:data:`PATH_FOLLOW_STEP`), else None."""
    q, its, ok = chain
    steps = np.abs(np.diff(np.concatenate([run.q0[None], q]), axis=0)).max()
    return (q, its) if ok.all() and steps <= min(PATH_FOLLOW_STEP, max_step) else None


def _closed_form_path(run: _Run, closed: bool = False, chain=None, max_step: float = math.inf):
    """``(q (N, 6), iterations (N,), reasons, source)`` of a closed-form arm: the guess stage (every branch of every
    waypoint; with a free tool axis, every branch of every sampled angle: :func:`_branches`; with ``q_start``, the LM
    chain from it as one more candidate on an approximate closed form, ``chain`` of :func:`_chain_from_start`: its
    branches may miss the posture ``q_start`` is in, and the chain keeps it; the first waypoint's candidates within
    ``max_step`` of ``q_start`` only, where there are any: a jump the path cannot avoid comes where it must, not at
    the start), the choice over the whole path (a closed path ends on its start's branch: :func:`_choose`), then the
    refine stage (LM from the chosen branch where it misses the tolerance: an approximate closed form,
    :mod:`nik.ik.model`; LM from the neighbour's answer where no branch serves)."""
    model, Tn, q0 = run.model, run.T, run.q0
    N = Tn.shape[0]
    cand, valid = _branches(run)
    if chain is not None and model.approximate:
        cand = np.ascontiguousarray(np.concatenate([cand, chain[0][:, None]], axis=1))
        valid = np.ascontiguousarray(np.concatenate([valid, chain[2][:, None]], axis=1))
    if q0 is not None:
        d = np.abs(cand[0] - q0)
        d[:, model.wraps] = np.abs(np.remainder(d[:, model.wraps] + math.pi, 2 * math.pi) - math.pi)
        near = valid[0] & (d.max(axis=1) <= max_step)
        if near.any():
            valid = valid.copy()
            valid[0] = near
    wraps = model.wraps
    choice = _choose(cand, valid, wraps, q0, closed)
    have = choice >= 0
    its = np.zeros(N, dtype=np.int64)
    if not have.any() and run.refine:  # no waypoint has a valid branch: LM along the path from q_start or a start
        first = _first_answer(run)
        q, its, _ = run.chains(Tn, first[None], run.reachable, pull=0.0, restarts=0)
        q, its = q[0], its[0]
    elif not have.any():  # refine="none": the clamped branch nearest each pose (nik.kernels.closed.pick)
        q = _nearest_clamped(model, Tn, cand)
    else:
        q = cand[np.arange(N), np.maximum(choice, 0)]
        if wraps.any():
            q, fits = _unwrap(q, have, wraps, q0, model.lo, model.hi)
            if not fits:  # some run cannot stay inside its limits: choose the whole turns with the branches
                q = _with_turns(cand, valid, have, wraps, q0, model.lo, model.hi)
        if run.refine:
            q, its = _polish(run, q, have)
            if not have.all():
                q, its = _fill_gaps(run, q, its, have)
        elif not have.all():
            gaps = np.nonzero(~have)[0]
            q[gaps] = _nearest_clamped(model, Tn[gaps], cand[gaps])
    reasons = [""] * N
    for i in np.nonzero(~have)[0]:
        reasons[i] = _closed_form_reason(run, i, cand[i])
    return q, its, reasons, "analytic"


def _branches(run: _Run) -> tuple[np.ndarray, np.ndarray]:
    """``(cand (N, K, 6), valid (N, K))``: the closed form's branches of every waypoint, valid where inside the limits
    and within the call's tolerance by FK (an approximate closed form: within the model's check, the one policy of
    :mod:`nik.ik.model`; LM then polishes what misses the call's tolerance). With one free tool axis (a tolerant
    goal, :mod:`nik.ik.bounds`) the branches of every sampled angle about it (:mod:`nik.ik.free_axis`'s sampling:
    evenly from 0, :func:`_free_samples` of them), checked at the goal's tightest half-widths, the valid ones first
    (K: the most any waypoint has)."""
    model, Tn = run.model, run.T
    tol = () if model.approximate else (run.tol_pos, run.tol_rot)
    if run.half is None or not set(run.modes.tolist()) <= {0, 1, 2}:
        return model.closed_solutions(Tn, *tol)
    N, S = Tn.shape[0], _free_samples(Tn.shape[0])
    gamma = 2.0 * math.pi * np.arange(S) / S
    gamma = np.where(gamma > math.pi, gamma - 2.0 * math.pi, gamma)
    c, s = np.cos(gamma), np.sin(gamma)
    R = np.zeros((N, S, 4, 4))
    R[..., 3, 3] = 1.0
    for k in range(3):  # the rotation about each waypoint's free axis k
        at = run.modes == k
        i, j = (k + 1) % 3, (k + 2) % 3
        R[at, :, k, k] = 1.0
        R[at, :, i, i], R[at, :, i, j], R[at, :, j, i], R[at, :, j, j] = c, -s, s, c
    Tm = np.ascontiguousarray((Tn[:, None] @ R).reshape(N * S, 4, 4))
    if not model.approximate:
        rot = run.half[:, 3:]
        tol = (float(run.half[:, :3].min()), float(rot[np.isfinite(rot)].min()))
    cand, valid = model.closed_solutions(Tm, *tol)
    cand, valid = cand.reshape(N, S * 8, -1), valid.reshape(N, S * 8)
    order = np.argsort(~valid, axis=1, kind="stable")[:, : max(int(valid.sum(axis=1).max()), 1)]
    cand = np.ascontiguousarray(np.take_along_axis(cand, order[..., None], axis=1))
    return cand, np.ascontiguousarray(np.take_along_axis(valid, order, axis=1))


def _free_samples(N: int) -> int:
    """Angles sampled about a free tool axis on a path of ``N`` waypoints: 36 (every 10 degrees, as
    :func:`nik.ik.free_axis.closed_form_free_axis`), fewer on long paths so that the dynamic programming's
    ``(N, K, K)`` tables (``K = 8`` per angle) stay within :data:`PATH_DP_CELLS` (at least 4)."""
    return int(np.clip(math.isqrt(PATH_DP_CELLS // N) // 8, 4, 36))


def _nearest_clamped(model, T: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """``(B, 6)``: per pose of ``T: (B, 4, 4)``, the branch of ``cand: (B, 8, 6)`` that comes nearest it once clamped
    into the limits (the closed form's one rule for a pose no branch reaches: :func:`nik.kernels.closed.pick`)."""
    from nik.ik.guesses import LIMIT_ROUNDING
    from nik.kernels.closed import pick

    out = np.empty((T.shape[0], cand.shape[2]))
    none = np.zeros((T.shape[0], 8), dtype=bool)
    T, near = np.ascontiguousarray(T), np.zeros_like(out)
    pick(np.ascontiguousarray(cand), none, model.G, model.joints, T, near, False, LIMIT_ROUNDING, out)
    return out


def _polish(run: _Run, q: np.ndarray, have: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The refine stage on the chosen branches: LM (no restarts) from each one that misses the call's tolerance (an
    approximate closed form's branch, checked at :data:`nik.ik.model.APPROXIMATE_CHECK_TOL`), kept where better."""
    its = np.zeros(q.shape[0], dtype=np.int64)
    if not run.model.approximate or run.half is not None:  # a tolerant goal: its branches are checked as they are
        return q, its
    pos, rot = _errors(run.model, run.T, q)
    idx = np.nonzero(have & ((pos > run.tol_pos) | (rot > run.tol_rot)))[0]
    if idx.size:
        res = run.model.lm.solve(
            run.T[idx], q[idx], tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, restarts=False
        )
        better = score(res.pos_err, res.rot_err) <= score(pos[idx], rot[idx])
        q = q.copy()
        q[idx[better]] = res.q[better]
        its[idx] = res.iterations
    return q, its


def _closed_form_reason(run: _Run, i: int, cand_i: np.ndarray) -> str:
    """Why no branch serves waypoint ``i``: some reaches the pose outside the limits, or none reaches it at all."""
    if not run.reachable[i]:
        return "out of reach"
    Ti = np.repeat(run.T[i][None], cand_i.shape[0], axis=0)
    pos, rot = _errors(run.model, Ti, cand_i)  # the branches before the limits
    near = bool(((pos <= run.tol_pos) & (rot <= run.tol_rot)).any())
    return "beyond a joint limit on every branch" if near else "out of reach"


def _unwrap(q, have, wraps, q0, lo, hi) -> tuple[np.ndarray, bool]:
    """Joints of ``q: (N, dof)`` that may turn past +-pi made continuous along the path (whole turns added), the
    whole run then shifted by whole turns to fit the limits, starting nearest ``q0`` when given. Also returns
    whether every run fits (False: some joint would have to turn back, see :func:`_with_turns`)."""
    q = q.copy()
    fits = True
    idx = np.nonzero(have)[0]
    for j in np.nonzero(wraps)[0]:
        x = q[idx, j]
        d = np.remainder(np.diff(x) + math.pi, 2 * math.pi) - math.pi
        x = x[0] + np.concatenate([[0.0], np.cumsum(d)])
        if q0 is not None:
            x += 2 * math.pi * np.round((q0[j] - x[0]) / (2 * math.pi))
        shifts = sorted(range(-3, 4), key=abs)
        for k in shifts:  # the nearest whole-turn shift that keeps the run inside the limits
            y = x + 2 * math.pi * k
            if y.min() >= lo[j] - 1e-12 and y.max() <= hi[j] + 1e-12:
                x = y
                break
        else:
            fits = False
        q[idx, j] = x
    return q, fits


def _with_turns(cand, valid, have, wraps, q0, lo, hi) -> np.ndarray:
    """The choice over the whole path when the whole turns matter: every branch of every waypoint with each of
    its turning joints at every value inside the limits (``+-2 pi`` copies), and real (not modulo 2 pi) motion
    between them. ``cand: (N, 8, dof)``; returns ``q: (N, dof)``."""
    from itertools import product

    from nik.paths.kernels import path_dp

    N, K, n = cand.shape
    turns = np.zeros((3 ** int(wraps.sum()), n))
    turns[:, wraps] = 2 * math.pi * np.array(list(product((0.0, -1.0, 1.0), repeat=int(wraps.sum()))))
    big = (cand[:, :, None, :] + turns[None, None]).reshape(N, -1, n)  # (N, 8 x 3^w, dof)
    ok = np.repeat(valid, turns.shape[0], axis=1) & ((big >= lo) & (big <= hi)).all(axis=-1)
    order = np.argsort(~ok, axis=1, kind="stable")[:, : max(int(ok.sum(axis=1).max()), 1)]  # the valid ones first
    big = np.ascontiguousarray(np.take_along_axis(big, order[..., None], axis=1))
    ok = np.ascontiguousarray(np.take_along_axis(ok, order, axis=1))
    choice = np.empty(N, dtype=np.int64)
    path_dp(big, ok, np.zeros(n, dtype=bool), np.zeros(n) if q0 is None else q0, q0 is not None, 1e-9, choice)
    return big[np.arange(N), np.maximum(choice, 0)]


def _fill_gaps(run: _Run, q: np.ndarray, its: np.ndarray, have: np.ndarray):
    """Waypoints without a valid branch: LM seeded by the answer next to them (the previous one; for a leading
    gap, the first waypoint that has a branch, walking back), uniform restarts only with ``fallback="multistart"``
    (the closed form found no solution there: a restart could only jump). Their best effort, flagged by the final
    check."""
    N, Tn, reachable = q.shape[0], run.T, run.reachable
    kw = {"pull": 0.0, "restarts": run.restarts}
    its = its.copy()
    first = int(np.argmax(have))
    for i in range(first - 1, -1, -1):  # a leading gap, walking back from the first solved waypoint
        qi, it, _ = run.chains(Tn[i : i + 1], q[i + 1][None], reachable[i : i + 1], offset=i, **kw)
        q[i], its[i] = qi[0, 0], it[0, 0]
    i = first + 1
    while i < N:  # the other gaps, each run of missing waypoints in one compiled chain
        if have[i]:
            i += 1
            continue
        j = i
        while j < N and not have[j]:
            j += 1
        qi, it, _ = run.chains(Tn[i:j], q[i - 1][None], reachable[i:j], seed=run.seed + i, offset=i, **kw)
        q[i:j], its[i:j] = qi[0], it[0]
        i = j
    return q, its


def _first_answer(run: _Run) -> np.ndarray:
    """A start for a single chain: ``q0``, else LM from uniform starts at the first waypoint."""
    if run.q0 is not None:
        return run.q0
    res = run.model.lm.solve(
        run.T[:1], None, tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, reachable=run.reachable[:1]
    )
    return res.q[0]


def _chain_path(run: _Run):
    """``(q (N, dof), iterations (N,), source)`` of an arm without a closed form: chains of LM from the start
    postures (candidates at every waypoint: each chain's answer), the choice over the whole path by
    :func:`nik.paths.kernels.path_dp` over those candidates."""
    from nik.paths.kernels import path_dp

    pull = PATH_PULL if run.model.dof > 6 else 0.0
    kw = {"pull": pull, "restarts": run.restarts}
    if run.q0 is not None:
        q, its, _ = run.chains(run.T, run.q0[None], run.reachable, **kw)
        return q[0], its[0], "q_start"
    starts, sources = _start_postures(run)
    if run.rest is not None:  # the start nearest q_rest first
        order = np.argsort(np.abs(starts - run.rest).max(axis=1), kind="stable")
        starts, sources = starts[order], [sources[i] for i in order]
    q, its, ok = run.chains(run.T, starts, run.reachable, **kw)
    if q.shape[0] == 1:
        return q[0], its[0], sources[0]
    N = run.T.shape[0]
    cand = np.ascontiguousarray(q.transpose(1, 0, 2))  # (N, K, dof): every chain's answer at every waypoint
    choice = np.empty(N, dtype=np.int64)
    path_dp(cand, np.ascontiguousarray(ok.T), run.model.wraps, np.zeros(run.model.dof), False, 1e-9, choice)
    if (choice < 0).all():  # no chain reaches any waypoint: the chain with the least largest step
        steps = np.abs(np.diff(q, axis=1)).max(axis=(1, 2))
        best = int(np.argmin(steps))
        return q[best], its[best], sources[best]
    chosen = np.nonzero(choice >= 0)[0]
    for i in np.nonzero(choice < 0)[0]:  # a waypoint no chain reaches: the chain chosen before it continues
        before = chosen[chosen < i]
        choice[i] = choice[before[-1]] if before.size else choice[chosen[0]]
    rows = np.arange(N)
    return q[choice, rows], its[choice, rows], sources[int(choice[0])]


def _start_postures(run: _Run) -> tuple[np.ndarray, list[str]]:
    """Distinct solutions of the first waypoint: ``(K, dof)`` and where each came from (``network`` for the
    network's hypotheses, the guess stage's packed network, polished by LM; ``multistart`` for LM from uniform
    starts)."""
    lm, T0, tol = run.model.lm, run.T[:1], {"tol_pos": run.tol_pos, "tol_rot": run.tol_rot, "seed": run.seed}
    seeds, sources = [], []
    hyp = _hypotheses(run)
    if hyp is not None:
        hyp = hyp[0]
        seeds.append(hyp)
        sources += ["network"] * hyp.shape[0]
    uni = lm.solve(np.repeat(T0, PATH_STARTS, axis=0), None, restarts=False, **tol)
    seeds.append(uni.q)
    sources += ["multistart"] * PATH_STARTS
    seeds = np.concatenate(seeds)
    res = lm.solve(np.repeat(T0, seeds.shape[0], axis=0), seeds, restarts=False, **tol)
    order = np.argsort(~res.converged, kind="stable")  # reached ones first, network before uniform
    q = res.q[order]
    close = np.abs(q[:, None] - q[None]).max(axis=-1) <= PATH_DEDUPE  # (K, K)
    kept = order[~np.triu(close, k=1).any(axis=0)]  # drop each answer close to an earlier one
    return res.q[kept], [sources[i] for i in kept]


def _hypotheses(run: _Run, rows=None) -> np.ndarray | None:
    """``(len(rows), K, dof)`` the plan's network's hypotheses for the waypoints ``rows`` (default the first), ranked
    by FK: the compiled backend's guess stage (the packed network, targets in the arm's frame where the network was
    made for the bare arm), or None where the plan has no network."""
    if run.plan.net is None:
        return None
    from nik.ik.backends import Job, compiled_backend

    rows = np.array([0]) if rows is None else rows
    be, m, T = compiled_backend(), run.model, np.ascontiguousarray(run.T[rows])
    job = Job(be, m.robot, T, run.reachable[rows], None, run.tol_pos, run.tol_rot, torch.float64, model=m)
    return np.ascontiguousarray(be.network(run.plan, job)[0])
