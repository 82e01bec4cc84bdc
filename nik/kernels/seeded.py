"""A network's hypotheses as LM seeds, compiled: its forward pass, the ranking by FK, LM from a list of starts.

The network stage of the compiled pipeline, for the two one-pass multi-solution kinds (one MLP trunk whose last
layer holds ``K`` heads of ``head_dim`` outputs each):

- :func:`hypotheses`: the pose ``T (4, 4)`` -> input features (xyz and the first two rotation columns, the
  ``rot6d`` vector), standardised -> MLP (:func:`nik.kernels.mlp.mlp_forward`) -> per head and joint the angle
  ``atan2(sin, cos)`` taken within ``center +- pi`` (a revolute joint) or ``center + half * y`` (a prismatic one):
  ``q: (B, K, n)``, the decoding of ``nik.nets.multi``;
- :func:`rank`: each target's ``K`` starts brought inside the limits and sorted by FK pose error
  (metres + 0.1 x radians), best first, with the best one's errors;
- :func:`lm_starts`: LM from each target's starts in turn (no uniform restarts), stopping at the first that
  reaches the tolerance; else the best effort of all.

Allocation-free inside the loops; the caller passes the scratch (one set per call, so threads never share it).
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import _chain
from nik.kernels.lm import _bounds, _copy, _lm_one, _residual, _work_size
from nik.kernels.mlp import mlp_forward
from nik.tolerances import SCORE_ROT_WEIGHT

__all__ = ["hypotheses", "lm_starts", "merge", "rank", "ranked_hypotheses"]

_TWO_PI = 2.0 * math.pi


@kernel
def _decode_angle(s, c, center):
    """``atan2(s, c)`` taken within ``center +- pi`` (one arc function; the wrap by arithmetic)."""
    d = math.atan2(s, c) - center
    if d > math.pi:
        d -= _TWO_PI
    elif d < -math.pi:
        d += _TWO_PI
    return center + d


@kernel
def hypotheses(flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, T, x, y, q):
    """Every hypothesis ``q: (B, K, n)`` of the network ``flat, layout, activation`` for ``T: (B, 4, 4)``.

    ``in_mean, in_std: (9,)`` standardise the ``rot6d`` input; ``out_center, out_half: (n,)`` and
    ``prismatic: (n,)`` bool decode each head; scratch ``x: (B, 9)``, ``y: (B, K * head_dim)`` in the dtype of
    ``flat`` (float32 or float64; the MLP's own scratch is allocated by :func:`nik.kernels.mlp.mlp_forward`).
    Unclamped (as ``forward`` of ``nik.nets.multi``).
    """
    B = T.shape[0]
    for b in range(B):
        for r in range(3):
            x[b, r] = (T[b, r, 3] - in_mean[r]) / in_std[r]
            x[b, 3 + r] = (T[b, r, 0] - in_mean[3 + r]) / in_std[3 + r]
            x[b, 6 + r] = (T[b, r, 1] - in_mean[6 + r]) / in_std[6 + r]
    mlp_forward(flat, layout, activation, x, y, None)
    K, n = q.shape[1], q.shape[2]
    head_dim = y.shape[1] // K
    for b in range(B):
        for k in range(K):
            o = k * head_dim
            for j in range(n):
                if prismatic[j]:
                    q[b, k, j] = out_center[j] + out_half[j] * float(y[b, o])
                    o += 1
                else:
                    q[b, k, j] = _decode_angle(float(y[b, o]), float(y[b, o + 1]), out_center[j])
                    o += 2


@kernel
def ranked_hypotheses(net, G, joints, Tin, T, tol_pos, tol_rot):
    """:func:`hypotheses` of the network's input poses ``Tin: (B, 4, 4)`` then :func:`rank` against the targets
    ``T: (B, 4, 4)`` by the FK of ``G, joints`` in one call (``Tin`` is ``T`` unless the network was made for the arm
    without the robot's base/tool frames: then ``base^-1 @ T @ tool^-1``), scratch allocated here: returns
    ``(q (B, K, n) ranked, pos (B,), rot (B,), ok (B,), failing)``: the best hypothesis' errors (metres, radians),
    whether it is within ``tol_pos, tol_rot``, and how many are not. ``net``: the packed network, the tuple
    ``(flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, heads)``
    (:attr:`nik.nets.compiled.PackedNet.arrays`)."""
    flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, heads = net
    B, n = T.shape[0], out_center.shape[0]
    x = np.empty((B, 9), dtype=flat.dtype)
    y = np.empty((B, layout[layout.shape[0] - 1, 0]), dtype=flat.dtype)
    q = np.empty((B, heads, n))
    hypotheses(flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, Tin, x, y, q)
    pos, rot = np.empty(B), np.empty(B)
    rank(G, joints, T, q, pos, rot)
    ok = np.empty(B, dtype=np.bool_)
    failing = 0
    for b in range(B):
        ok[b] = pos[b] <= tol_pos and rot[b] <= tol_rot
        if not ok[b]:
            failing += 1
    return q, pos, rot, ok, failing


@kernel
def rank(G, joints, Tt, starts, pos, rot):
    """Per target ``b``: its starts ``starts[b]: (K, n)`` brought inside the limits and sorted in place by FK pose
    error (metres + 0.1 x radians), best first; ``pos, rot: (B,)`` the errors (m, rad) of the best one."""
    B, K, n = starts.shape
    T = np.empty((3, 4))
    e = np.empty(6)
    score = np.empty(K)
    p = np.empty(K)
    r = np.empty(K)
    row = np.empty(n)
    for b in range(B):
        for k in range(K):
            _bounds(joints, starts[b, k])
            _chain(G, joints, starts[b, k], T)
            _, p[k], r[k] = _residual(Tt[b], T, 1.0, e)
            score[k] = p[k] + SCORE_ROT_WEIGHT * r[k]
        for k in range(1, K):  # insertion sort: K is small
            s, pk, rk = score[k], p[k], r[k]
            _copy(starts[b, k], row)
            i = k - 1
            while i >= 0 and score[i] > s:
                score[i + 1], p[i + 1], r[i + 1] = score[i], p[i], r[i]
                _copy(starts[b, i], starts[b, i + 1])
                i -= 1
            score[i + 1], p[i + 1], r[i + 1] = s, pk, rk
            _copy(row, starts[b, i + 1])
        pos[b], rot[b] = p[0], r[0]


@kernel
def lm_starts(G, joints, Tt, starts, opts, iopts, seed, q, iterations, converged, pos, rot):
    """LM towards each target ``Tt[b]`` from ``starts[b, 0]``, then ``starts[b, 1]``, ... (no uniform restarts;
    ``iopts`` must not ask for first uniform starts), stopping at the first start that reaches the tolerance of
    ``opts``. Outputs as :func:`nik.kernels.lm.lm_solve`: ``q`` the first answer within tolerance, else the one
    with the lowest error (metres + 0.1 x radians); ``iterations`` over all starts."""
    rng = np.empty(1, dtype=np.uint64)
    rng[0] = seed[0]
    n = starts.shape[2]
    cand = np.empty(n)
    work = np.empty(_work_size(n))  # per call: threads never share it
    for b in range(Tt.shape[0]):
        best = math.inf
        total = 0
        converged[b] = False
        for k in range(starts.shape[1]):
            it, ok, p, r = _lm_one(G, joints, Tt[b], starts[b, k], opts, iopts, 0, rng, cand, work)
            total += it
            if ok or p + SCORE_ROT_WEIGHT * r < best:
                best = p + SCORE_ROT_WEIGHT * r
                _copy(cand, q[b])
                pos[b], rot[b] = p, r
            if ok:
                converged[b] = True
                break
        iterations[b] = total


@kernel
def merge(answers, idx, refined, strict, tol_pos, tol_rot):
    """In place: target ``idx[i]`` of the ``answers = (q, pos, rot, iterations, ok)`` takes row ``i`` of the
    ``refined = (rq, rpos, rrot, rit)`` where that is better (metres + 0.1 x radians; ``strict``: lower, else not
    higher), and ``rit[i]`` is added to its iterations; ``ok`` is kept equal to ``pos <= tol_pos and rot <= tol_rot``.
    Returns how many targets still fail."""
    q, pos, rot, iterations, ok = answers
    rq, rpos, rrot, rit = refined
    n = q.shape[1]
    for i in range(idx.shape[0]):
        b = idx[i]
        new, old = rpos[i] + SCORE_ROT_WEIGHT * rrot[i], pos[b] + SCORE_ROT_WEIGHT * rot[b]
        if new < old or (not strict and new == old):
            for j in range(n):
                q[b, j] = rq[i, j]
            pos[b], rot[b] = rpos[i], rrot[i]
            ok[b] = pos[b] <= tol_pos and rot[b] <= tol_rot
        iterations[b] += rit[i]
    failing = 0
    for b in range(ok.shape[0]):
        if not ok[b]:
            failing += 1
    return failing
