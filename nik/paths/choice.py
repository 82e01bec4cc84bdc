"""The choice over the whole path: among ``K`` candidates per waypoint, the sequence whose largest step is the
smallest, then the least squared motion (:func:`nik.paths.kernels.path_dp`), a closed loop's end pinned to its
start; and the cost by which two answers of one path are compared."""

from __future__ import annotations

import math

import numpy as np

from nik.paths.run import _closure
from nik.paths.settings import PATH_CLOSED_STARTS, PATH_DEDUPE


def _choose(cand, valid, wraps, q0, closed: bool, close_within: float = PATH_DEDUPE, tries: int = PATH_CLOSED_STARTS):
    """``choice (N,)``: :func:`nik.paths.kernels.path_dp` over the candidates; on a closed path, the choice that
    ends on its start's branch (the last waypoint's candidate nearest the first's, modulo whole turns on the joints
    that wrap): when the free choice does not, each distinct start candidate (at most ``tries``) is tried
    with the end pinned to its match, and the least-motion sequence (largest step, then sum of squared steps) is
    kept (with ``q0``, the step from it counted)."""
    from nik.paths.kernels import path_dp

    N = cand.shape[0]
    choice = np.empty(N, dtype=np.int64)
    start = np.zeros(cand.shape[2]) if q0 is None else q0
    path_dp(cand, valid, wraps, start, q0 is not None, 1e-9, choice)
    if not closed or choice[0] < 0 or choice[-1] < 0:
        return choice
    if _closure(cand[[0, -1], choice[[0, -1]]], wraps) <= PATH_DEDUPE:
        return choice
    first = [int(choice[0])] + [int(k) for k in np.nonzero(valid[0])[0] if k != choice[0]]
    tried: list[int] = []  # distinct start candidates only (tracks from q_start start alike)
    for k in first:
        if len(tried) < tries and all(np.abs(cand[0, k] - cand[0, t]).max() > PATH_DEDUPE for t in tried):
            tried.append(k)
    best, best_cost = choice, (math.inf, math.inf)
    for k in tried:
        d = np.abs(cand[-1] - cand[0, k])  # _closure of each last candidate against start k
        d[:, wraps] = np.abs(np.remainder(d[:, wraps] + math.pi, 2 * math.pi) - math.pi)
        gap = d.max(axis=1)
        gap[~valid[-1]] = math.inf
        end = int(np.argmin(gap))
        if gap[end] > close_within:
            continue
        pinned = valid.copy()
        pinned[0], pinned[-1] = False, False
        pinned[0, k], pinned[-1, end] = True, True
        c = np.empty(N, dtype=np.int64)
        path_dp(cand, pinned, wraps, start, q0 is not None, 1e-9, c)
        if (c < 0).any() and not ((c < 0) == (choice < 0)).all():
            continue
        seq = cand[np.nonzero(c >= 0)[0], c[c >= 0]]
        if q0 is not None:  # the step from q_start counts: a start on another branch is a jump
            seq = np.concatenate([q0[None], seq])
        d = np.abs(np.diff(seq, axis=0))
        d[:, wraps] = np.abs(np.remainder(d[:, wraps] + math.pi, 2 * math.pi) - math.pi)
        steps = d.max(axis=1) if d.size else np.zeros(1)
        cost = (float(steps.max()), float((steps**2).sum()))
        if cost < best_cost:
            best, best_cost = c, cost
    return best


def _path_cost(q: np.ndarray, ok: np.ndarray, q0: np.ndarray | None, wraps=None, within: float = 0.0) -> tuple:
    """``(waypoints missed, open, largest step)`` of a path ``q: (N, dof)`` (the first step from ``q0`` where given;
    ``open``: with ``wraps``, a closed path whose last row is more than ``within`` from its first, else 0): the order
    in which the search and the plain chain are compared."""
    full = q if q0 is None else np.concatenate([q0[None], q])
    step = float(np.abs(np.diff(full, axis=0)).max()) if full.shape[0] > 1 else 0.0
    gap = 0 if wraps is None else int(_closure(q, wraps) > within)
    return int((~ok).sum()), gap, round(step, 9)
