"""The compiled loops of :mod:`nik.paths.solve`: the whole-path choice over candidates, and LM chains along a path.

Both loops run over waypoints, one after the other (each waypoint's answer depends on the one before), so they
are compiled: a Python loop would spend more time in its own overhead than in the arithmetic (one LM solve
seeded by the previous waypoint costs one or two microseconds here).

- :func:`path_dp`: among ``K`` candidates per waypoint, the sequence whose largest step is the smallest, and
  among those the one with the least sum of squared steps, then the least total joint motion (dynamic
  programming, two passes: the bottleneck value, then the cheapest sequence whose steps all stay within it; a pair
  that cannot beat the best so far is not measured, and a step's measure stops at the joint that settles it: no
  ``(N, K, K)`` table, a few times faster with the hundred candidates of a search among obstacles).
  Squared steps rather than plain motion: where one large step is unavoidable (a joint limit ahead), a plain
  sum would accept more medium-sized jumps elsewhere under that bound; squares keep every other step small.
- :func:`path_chains`: ``K`` chains of Levenberg-Marquardt (:mod:`nik.kernels.lm`) along the path, each waypoint
  seeded by the chain's answer at the previous one, moved slightly towards the middle of the joint ranges.

The step between two configurations is the largest joint motion, ``max_j |a_j - b_j|``; on joints that may turn
freely past a full turn (``wraps``: their range exceeds 2 pi) the motion is taken modulo 2 pi, shortest way.
Imported only when a path is solved (it imports numba through :mod:`nik.kernels`).
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER
from nik.kernels.lm import _STREAM, _lm_one, _lm_one_bounded, _work_size

__all__ = ["path_chains", "path_chains_bounded", "path_chains_bounded_toward", "path_chains_toward", "path_dp"]

_TWO_PI = 2.0 * math.pi
#: Weight of the total joint motion (radians) beside the sum of squared steps (radians^2) in the second pass:
#: a tie-break among sequences whose steps are alike.
_TIE = 1e-6


@kernel
def _motion(x, y, wraps):
    """One joint's motion from ``x`` to ``y``: the shorter way round where the joint ``wraps``."""
    d = abs(x - y)
    if wraps:
        d = d % _TWO_PI
        if d > math.pi:
            d = _TWO_PI - d
    return d


@kernel
def _step(a, b, wraps):
    """``(largest joint motion, total joint motion)`` from ``a (n,)`` to ``b (n,)``."""
    m = 0.0
    s = 0.0
    for j in range(a.shape[0]):
        d = _motion(a[j], b[j], wraps[j])
        if d > m:
            m = d
        s += d
    return m, s


@kernel
def _largest(a, b, wraps, stop):
    """The largest joint motion from ``a (n,)`` to ``b (n,)``, or a value at least ``stop`` as soon as one joint's
    motion reaches it (the caller has no use for more)."""
    m = 0.0
    for j in range(a.shape[0]):
        d = _motion(a[j], b[j], wraps[j])
        if d > m:
            m = d
            if m >= stop:
                return m
    return m


@kernel
def path_dp(cand, valid, wraps, q_start, use_start, slack, choice):
    """The candidate chosen at each waypoint: the sequence with the smallest largest step, then the least sum of
    squared steps (ties: the least total motion).

    Args:
        cand: (N, K, n) candidates per waypoint.
        valid: (N, K) bool; a waypoint without a valid candidate is skipped (the step is taken across it).
        wraps: (n,) bool, joints whose motion counts modulo 2 pi.
        q_start: (n,) the configuration before the path (used when ``use_start``: the first step starts there).
        slack: how far above the smallest largest step a step of the second pass may go (rounding).
        choice: (N,) int64 out: the candidate chosen at each waypoint, -1 where none is valid.

    Returns:
        the smallest achievable largest step (inf when no waypoint has a valid candidate).
    """
    N, K = valid.shape
    inf = math.inf
    V = np.full((N, K), inf)
    S = np.full((N, K), inf)
    M0 = np.full(K, inf)  # the first layer's step from q_start, and its cost in pass 2: step^2 + _TIE x motion
    C0 = np.full(K, inf)
    parent = np.full((N, K), -1, dtype=np.int64)
    prev = -1
    for i in range(N):  # pass 1: the bottleneck value of the best sequence ending at each candidate
        seen = False
        for k in range(K):
            if not valid[i, k]:
                continue
            seen = True
            if prev < 0:
                m, s = _step(q_start, cand[i, k], wraps)
                V[i, k] = m if use_start else 0.0
                M0[k], C0[k] = (m, m * m + _TIE * s) if use_start else (0.0, 0.0)
                continue
            best = inf
            for a in range(K):
                if valid[prev, a] and V[prev, a] < best:  # else no step from a can do better
                    m = _largest(cand[prev, a], cand[i, k], wraps, best)
                    if max(V[prev, a], m) < best:
                        best = max(V[prev, a], m)
            V[i, k] = best
        if seen:
            prev = i
    if prev < 0:
        choice[:] = -1
        return inf
    last = prev
    bound = inf
    for k in range(K):
        if V[last, k] < bound:
            bound = V[last, k]
    best_max = bound
    bound += slack
    prev = -1
    for i in range(N):  # pass 2: the least cost over sequences whose steps stay within the bound
        seen = False
        for k in range(K):
            if not valid[i, k]:
                continue
            seen = True
            if prev < 0:
                S[i, k] = C0[k] if M0[k] <= bound else inf
                continue
            best, arg = inf, -1
            for a in range(K):
                if S[prev, a] < best and _largest(cand[prev, a], cand[i, k], wraps, bound) <= bound:
                    m, s = _step(cand[prev, a], cand[i, k], wraps)  # a reached within the bound, cheaper so far
                    c = S[prev, a] + (m * m + _TIE * s)
                    if m <= bound and c < best:
                        best, arg = c, a
            S[i, k] = best
            parent[i, k] = arg
        if seen:
            prev = i
    k = 0
    for a in range(K):
        if S[last, a] < S[last, k]:
            k = a
    for i in range(N - 1, -1, -1):
        if i > last:
            choice[i] = -1
            continue
        seen = False
        for a in range(K):
            if valid[i, a]:
                seen = True
                break
        if not seen:
            choice[i] = -1
            continue
        choice[i] = k
        k = parent[i, k]
    return best_max


@kernel
def path_chains(G, joints, T, starts, lm, pull, pull_cap, out):
    """``K`` chains of LM along the path ``T: (N, 4, 4)``, one from each start ``starts: (K, n)``.

    Waypoint 0 of chain ``c`` is solved from ``starts[c]``; waypoint ``i`` from the chain's answer at ``i - 1``
    moved towards the middle of each joint's range by ``pull`` times its distance from there (at most
    ``pull_cap`` radians or metres). On a redundant arm the LM step from that seed undoes the part of the move
    that would shift the tool, so what remains is self-motion away from the limits. A waypoint not reached
    from that seed is tried from the previous answer itself, then from up to ``restarts[i]`` uniform starts.

    Args:
        G, joints: the model (:func:`nik.kernels.chain.chain_model`).
        lm: ``(opts, iopts, restarts, seed)``: opts, iopts: :func:`nik.kernels.lm.lm_options` (first starts 0: the
            seed is the first start); restarts: (N,) int64, uniform restarts a waypoint may draw (0 where it is out
            of reach); seed: (1,) uint64 (:func:`nik.kernels.lm.seed_state`): waypoint ``i`` of chain ``c`` draws
            from its stream.
        out: ``(q, iterations, ok, pos, rot)``, written in place: q: (K, N, n) the answers; iterations: (K, N)
            int64; ok: (K, N) bool, within both tolerances; pos, rot: (K, N), metres and radians (the LM scratch is
            allocated here: threads never share it).
    """
    K, n = starts.shape
    targets = np.empty((K, n))
    for c in range(K):
        for j in range(n):
            targets[c, j] = 0.5 * (joints[j, LOWER] + joints[j, UPPER])
    path_chains_toward(G, joints, T, starts, (targets, np.full(K, pull), np.full(K, pull_cap)), lm, out)


@kernel
def path_chains_toward(G, joints, T, starts, drift, lm, out):
    """:func:`path_chains` with a posture of its own per chain: ``drift = (targets, pull, pull_cap)``; waypoint ``i``
    of chain ``c`` is seeded by the chain's answer at ``i - 1`` moved towards ``targets[c] (n,)`` by ``pull[c]``
    times its distance from there (at most ``pull_cap[c]`` per joint). On a redundant arm each chain drifts along the
    self-motion towards its own posture (the global search's tracks: :mod:`nik.paths.search`). ``targets: (K, n)``,
    ``pull, pull_cap: (K,)``; the other arguments and outputs as :func:`path_chains`."""
    targets, pull, pull_cap = drift
    opts, iopts, restarts, seed = lm
    q, iterations, ok, pos, rot = out
    K, n = starts.shape
    N = T.shape[0]
    x = np.empty(n)
    work = np.empty(_work_size(n))
    rng = np.empty(1, dtype=np.uint64)
    for c in range(K):
        for i in range(N):
            rng[0] = seed[0] ^ (np.uint64(c * N + i + 1) * _STREAM)
            if i == 0:
                for j in range(n):
                    x[j] = starts[c, j]
            else:
                for j in range(n):
                    d = -pull[c] * (q[c, i - 1, j] - targets[c, j])
                    x[j] = q[c, i - 1, j] + min(max(d, -pull_cap[c]), pull_cap[c])
            it, good, p, r = _lm_one(G, joints, T[i], x, opts, iopts, 0, rng, q[c, i], work)
            if not good and i > 0:
                total = it
                it, good, p, r = _lm_one(G, joints, T[i], q[c, i - 1], opts, iopts, restarts[i], rng, q[c, i], work)
                it += total
            elif not good and restarts[i] > 0:
                total = it
                it, good, p, r = _lm_one(G, joints, T[i], x, opts, iopts, restarts[i], rng, q[c, i], work)
                it += total
            iterations[c, i], ok[c, i], pos[c, i], rot[c, i] = it, good, p, r


@kernel
def path_chains_bounded(G, joints, T, starts, goal, lm, pull, pull_cap, out):
    """:func:`path_chains` towards tolerant goals (:mod:`nik.ik.bounds`), ``goal = (half, modes)``: waypoint ``i`` is
    reached when its error in the target's tool frame lies inside ``half[i] (6,)`` (rotation mode ``modes[i]``); LM is
    :func:`nik.kernels.lm._lm_one_bounded`. Arguments and outputs otherwise as :func:`path_chains` (``pos, rot``:
    position error m, geodesic angle rad to the pose as given)."""
    K, n = starts.shape
    targets = np.empty((K, n))
    for c in range(K):
        for j in range(n):
            targets[c, j] = 0.5 * (joints[j, LOWER] + joints[j, UPPER])
    path_chains_bounded_toward(G, joints, T, starts, (targets, np.full(K, pull), np.full(K, pull_cap)), goal, lm, out)


@kernel
def path_chains_bounded_toward(G, joints, T, starts, drift, goal, lm, out):
    """:func:`path_chains_bounded` with a posture of its own per chain (``drift = (targets, pull, pull_cap)``:
    ``targets: (K, n)``, ``pull, pull_cap: (K,)``, as :func:`path_chains_toward`)."""
    targets, pull, pull_cap = drift
    half, modes = goal
    opts, iopts, restarts, seed = lm
    q, iterations, ok, pos, rot = out
    K, n = starts.shape
    N = T.shape[0]
    x = np.empty(n)
    work = np.empty(_work_size(n))
    rng = np.empty(1, dtype=np.uint64)
    for c in range(K):
        for i in range(N):
            rng[0] = seed[0] ^ (np.uint64(c * N + i + 1) * _STREAM)
            if i == 0:
                for j in range(n):
                    x[j] = starts[c, j]
            else:
                for j in range(n):
                    d = -pull[c] * (q[c, i - 1, j] - targets[c, j])
                    x[j] = q[c, i - 1, j] + min(max(d, -pull_cap[c]), pull_cap[c])
            h, m = half[i], modes[i]
            it, good, p, r = _lm_one_bounded(G, joints, T[i], x, h, m, opts, iopts, 0, rng, q[c, i], work)
            if not good and (i > 0 or restarts[i] > 0):
                total = it
                if i > 0:
                    for j in range(n):
                        x[j] = q[c, i - 1, j]
                it, good, p, r = _lm_one_bounded(G, joints, T[i], x, h, m, opts, iopts, restarts[i], rng, q[c, i], work)
                it += total
            iterations[c, i], ok[c, i], pos[c, i], rot[c, i] = it, good, p, r
