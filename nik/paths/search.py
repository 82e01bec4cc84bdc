"""The posture search of arms without a closed form: where the chain does not follow the path smoothly, tracks
that each drift towards a posture of their own, every answer a candidate of the whole-path choice (the "global
search" of :mod:`nik.paths.solve`); among obstacles, only free answers and free steps."""

from __future__ import annotations

import numpy as np

from nik.paths.candidates import _hypotheses, _start_postures
from nik.paths.choice import _choose, _path_cost
from nik.paths.report import jumps
from nik.paths.run import _closure, _final_check, _Run
from nik.paths.settings import (
    PATH_PULL,
    PATH_PULL_CAP,
    SEARCH_ANCHORS,
    SEARCH_CLOSED_STARTS,
    SEARCH_DISTINCT,
    SEARCH_FAST_CAP,
    SEARCH_FAST_PULL,
    SEARCH_GAIN,
    SEARCH_HYPOTHESES,
    SEARCH_PULL,
    SEARCH_PULL_CAP,
    SEARCH_RECHOOSE,
    SEARCH_TRIGGER,
)


def _smooth(run: _Run, q: np.ndarray, max_step: float, closed: bool, col=None) -> bool:
    """Whether the chain's answer ``q: (N, dof)`` needs no search: every waypoint reached inside the limits, no step
    (from ``q0`` on) above :data:`SEARCH_TRIGGER` nor ``max_step``, a closed path's last row within ``max_step``
    of its first (:func:`_close_loop` closes the rest) and, with ``col`` (the collision arrays of
    :mod:`nik.ik.collide`), no waypoint colliding."""
    _, _, within = _final_check(run, q)
    if col is not None:
        within &= ~_colliding(run.model, q, col)
    inside = ((q >= run.model.lo - 1e-9) & (q <= run.model.hi + 1e-9)).all()
    _, _, step = _path_cost(q, within, run.q0)
    closes = not closed or _closure(q, run.model.wraps) <= max_step
    return bool(within.all() and inside and closes and step <= min(SEARCH_TRIGGER, max_step))


def _colliding(model, q: np.ndarray, col) -> np.ndarray:
    """``(...)`` bool: configurations of ``q: (..., dof)`` that collide (the sphere check, margin 0)."""
    from nik.kernels.collision import collides_batch

    flat = np.ascontiguousarray(q.reshape(-1, q.shape[-1]), dtype=np.float64)
    hit = np.empty(flat.shape[0], dtype=bool)
    collides_batch(model.G, model.joints, flat, *col, 0.0, hit)
    return hit.reshape(q.shape[:-1])


def _search_path(run: _Run, max_step: float, closed: bool, chain, rest: np.ndarray | None = None, col=None):
    """``(q (N, dof), iterations (N,), source)``: the global search of an arm without a closed form (module
    docstring, "global search"). Tracks: LM chains (:func:`nik.paths.kernels.path_chains_toward`) from ``q0`` (else
    from every distinct start posture, :func:`_start_postures`), each drifting along the self-motion towards a
    posture of its own: the middle of the ranges (the plain chain, :func:`_chain_path`'s), its own start, no
    posture, ``rest`` (``q_rest``), and the network's hypotheses (else uniform LM answers) at the middle and the last
    waypoint. Every track's answer at every waypoint is a candidate (among obstacles, ``col``: the collision arrays of
    :mod:`nik.ik.collide`, one that collides is not); :func:`_choose` picks the sequence with the
    smallest largest step, then the least sum of squared steps (from ``q0``; on a closed path, ending next to its
    first row, within ``max_step``), switching tracks where they meet. Kept over ``chain`` (``(q, iterations, source)``
    of :func:`_chain_path`) and the plain chains unless one of them reaches more waypoints, closes where the search
    does not, or has the smaller largest step (by :data:`SEARCH_GAIN`: the search never answers worse than the
    chain)."""
    model, N = run.model, run.T.shape[0]
    if run.q0 is not None:
        starts, sources = run.q0[None], ["q_start"]
    else:
        starts, sources = _start_postures(run)
    extra = ()
    if col is not None:  # the stretch the chain collides on: its ends are anchors
        hit = np.nonzero(_colliding(model, chain[0], col))[0]
        extra = (int(hit[0]), int(hit[-1])) if hit.size else ()
    postures = _search_postures(run, rest, col, extra)
    mid = 0.5 * (model.lo + model.hi)
    K0 = starts.shape[0]
    plain = mid if rest is None else rest
    tracks = [(k, plain, PATH_PULL, PATH_PULL_CAP) for k in range(K0)]  # track k < K0: start k's plain chain
    for k in range(K0):
        for target, pull in [(starts[k], SEARCH_PULL), (mid, 0.0), *((p, SEARCH_PULL) for p in postures)]:
            tracks.append((k, target, pull, SEARCH_PULL_CAP))
        if col is not None:
            tracks += [(k, p, SEARCH_FAST_PULL, SEARCH_FAST_CAP) for p in postures]
    of = np.array([t[0] for t in tracks])
    q, its, ok = run.tracks(
        run.T, starts[of], np.array([t[1] for t in tracks]), np.array([t[2] for t in tracks]),
        np.array([t[3] for t in tracks]), run.reachable, run.restarts,
    )  # fmt: skip
    # backward tracks, from the last waypoint to the first: from the postures (and, on a closed path, from the start
    # postures, which answer its last pose too), drifting towards the middle of the ranges or their own start
    back = [*(starts if closed else []), *postures]
    if back:
        b_starts = np.repeat(np.array(back), 2, axis=0)
        b_targets = np.stack([x for p in back for x in (mid, p)])
        b_pull = np.tile([PATH_PULL, SEARCH_PULL], len(back))
        b_cap = np.tile([PATH_PULL_CAP, SEARCH_PULL_CAP], len(back))
        if col is not None and closed:  # a loop's way back to its start: fast tracks from it towards the postures
            fast = [(k, p) for k in range(K0) for p in postures]
            b_starts = np.concatenate([b_starts, starts[[k for k, _ in fast]]]) if fast else b_starts
            b_targets = np.concatenate([b_targets, np.array([p for _, p in fast])]) if fast else b_targets
            b_pull = np.concatenate([b_pull, np.full(len(fast), SEARCH_FAST_PULL)])
            b_cap = np.concatenate([b_cap, np.full(len(fast), SEARCH_FAST_CAP)])
        qb, itsb, okb = run.tracks(
            run.T[::-1], b_starts, b_targets, b_pull, b_cap, run.reachable[::-1], run.restarts, backward=True
        )
        q = np.concatenate([q, qb[:, ::-1]])
        its, ok = np.concatenate([its, itsb[:, ::-1]]), np.concatenate([ok, okb[:, ::-1]])
        of = np.concatenate([of, np.full(len(b_starts), -1)])
    inside = ((q >= model.lo - 1e-9) & (q <= model.hi + 1e-9)).all(axis=-1)
    ok = ok & inside
    if col is not None:  # among obstacles: a colliding answer is no candidate
        ok &= ~_colliding(model, q, col)
    cand = np.ascontiguousarray(q.transpose(1, 0, 2))  # (N, K, dof): every track's answer at every waypoint
    valid = np.ascontiguousarray(ok.T)
    if run.q0 is not None:
        near = valid[0] & (np.abs(cand[0] - run.q0).max(axis=1) <= max_step)
        if near.any():
            valid[0] = near
    raw = np.zeros_like(model.wraps)  # real joint motion: tracks are continuous in the joints' own values
    choice = _choose(cand, valid, raw, run.q0, closed, close_within=max_step, tries=SEARCH_CLOSED_STARTS)
    if (choice < 0).all():
        return chain
    if col is not None:
        choice = _free_steps(run, cand, valid, raw, closed, max_step, col, choice)
    chosen = np.nonzero(choice >= 0)[0]
    for i in np.nonzero(choice < 0)[0]:  # a waypoint no track reaches: the track chosen before it continues
        before = chosen[chosen < i]
        choice[i] = choice[before[-1]] if before.size else choice[chosen[0]]
    rows = np.arange(N)
    found, found_its = cand[rows, choice], its.T[rows, choice]
    wraps = raw if closed else None
    c_ok = _final_check(run, chain[0])[2] & ((chain[0] >= model.lo - 1e-9) & (chain[0] <= model.hi + 1e-9)).all(axis=1)
    if col is not None:
        c_ok &= ~_colliding(model, chain[0], col)
    c_ok &= ~jumps(chain[0], c_ok, max_step)  # a waypoint reached only by a jump is missed (the report's rule)
    s_ok = ok.T[rows, choice]
    s_ok &= ~jumps(found, s_ok, max_step)
    c_cost = _path_cost(chain[0], c_ok, run.q0, wraps, max_step)
    s_cost = _path_cost(found, s_ok, run.q0, wraps, max_step)
    if c_cost[:2] < s_cost[:2] or (c_cost[:2] == s_cost[:2] and s_cost[2] > c_cost[2] - SEARCH_GAIN):
        return chain
    return found, found_its, sources[int(of[choice[0]])] if of[choice[0]] >= 0 else "search"


def _free_steps(run: _Run, cand, valid, raw, closed: bool, max_step: float, col, choice: np.ndarray) -> np.ndarray:
    """``choice (N,)`` of the search among obstacles with no step that collides inside (the dynamic programming
    judges the candidates, each one free, not the motion between two of them: a switch between tracks may cross the
    obstacle): up to :data:`SEARCH_RECHOOSE` times, the candidate each colliding step leads to is no candidate and the
    choice is made again; the first choice whose motion is free (else the one with the fewest colliding steps)."""
    from nik.paths.trajopt import TrajCfg, path_collisions

    N = cand.shape[0]
    valid = valid.copy()
    best, fewest = choice, None
    for _ in range(SEARCH_RECHOOSE + 1):
        if (choice < 0).any():
            break
        between = path_collisions(run.model, cand[np.arange(N), choice], run.q0, col, TrajCfg.col_sub)[1]
        n = int(between.sum())
        if fewest is None or n < fewest:
            best, fewest = choice, n
        if n == 0:
            break
        bad = np.nonzero(between)[0]
        valid[bad, choice[bad]] = False
        choice = _choose(cand, valid, raw, run.q0, closed, close_within=max_step, tries=SEARCH_CLOSED_STARTS)
    return best


def _search_postures(run: _Run, rest: np.ndarray | None, col=None, extra=()) -> list[np.ndarray]:
    """The postures the search's tracks drift towards (beside the middle of the ranges and their own start): ``rest``,
    then distinct answers at the middle and the last waypoint: the network's hypotheses there (ranked by FK,
    :data:`SEARCH_HYPOTHESES` per waypoint) where the plan has a network, else LM from uniform starts. Among obstacles
    (``col``: the collision arrays of :mod:`nik.ik.collide`), at the waypoints ``extra`` (where the chain starts and
    stops colliding: the stretch to go round) and at :data:`SEARCH_ANCHORS`: the network's hypotheses and LM's
    answers from uniform starts side by side (:data:`SEARCH_HYPOTHESES` of each: the network adds postures, it
    replaces none), those that collide left out."""
    out = [] if rest is None else [np.asarray(rest, dtype=np.float64)]
    N = run.T.shape[0]
    anchors = {N // 2, N - 1} if col is None else {int(f * (N - 1)) for f in SEARCH_ANCHORS}
    at = np.array([*dict.fromkeys([*extra, *sorted(anchors)])])
    hyp = _hypotheses(run, at)
    if hyp is not None:
        hyp = hyp[:, :SEARCH_HYPOTHESES]
    if hyp is None or col is not None:  # among obstacles the network's and LM's, side by side
        lm = run.model.lm
        T = np.repeat(run.T[at], SEARCH_HYPOTHESES, axis=0)
        res = lm.solve(T, None, tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, restarts=False)
        uni = res.q.reshape(at.size, SEARCH_HYPOTHESES, -1)
        hyp = uni if hyp is None else np.concatenate([hyp, uni], axis=1)
    free = np.ones(hyp.shape[:2], dtype=bool)
    if col is not None:  # the collision check inside the limits
        hyp = np.clip(hyp, run.model.lo, run.model.hi)
        free = ~_colliding(run.model, hyp, col)
    for h, f in zip(hyp, free, strict=True):
        for p in h[f]:
            if all(np.abs(p - o).max() > SEARCH_DISTINCT for o in out):
                out.append(p)
    return out
