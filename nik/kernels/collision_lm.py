"""Levenberg-Marquardt with collision rows: joints that reach a pose and keep the arm's spheres apart, compiled.

The residual of a configuration stacks the pose error of :mod:`nik.kernels.lm` (6 rows, classic or a tolerant
goal's dead zone) over the collision rows of :func:`nik.kernels.collision.collision_residual` (``R = P + L``
rows ``max(0, margin - d)``: one per checked link pair and one per link against the world), the latter times
``weight``::

    minimise |e(q)|^2 + weight^2 |r(q)|^2

The step is the damped Gauss-Newton step of :mod:`nik.kernels.lm_step` (Marquardt damping, the active set at the
limits, steps capped at ``max_step`` and brought inside the limits) with the collision rows as extra rows. A
candidate is kept when it lowers the sum, or when it is **done**: within the pose tolerances (or inside the bounds)
and free (every row's distance ``d >= 0``, margin 0). Stopping at the first done candidate matters: the margin rows
still pull when ``0 <= d < margin``, and where the goal needs the arm closer than the margin the minimum of the sum
is a compromise that may miss the tolerance; the path to it passes through done points.

Starts, per target, in order, the first done one ending the target:

1. the ``n_starts[b]`` given ones: the answer that collided (near the caller's ``q_near`` or a path's previous
   waypoint: it keeps the answer on its branch), then the network's other hypotheses or the closed form's other
   branches, ranked once the first is not done (:func:`_rank_starts`: the free ones nearest the pose first, the
   colliding ones dropped);
2. ``restarts[b]`` uniform starts (:func:`_prepare`): each the collision-free draw nearest the pose among ``tries``,
   taken to the pose by the pose LM of :mod:`nik.kernels.lm` without the collision rows, then ranked by the sum the
   collision LM starts from; the collision LM runs from the best ``descents``, from every further one within
   ``weight^2 (2 margin)^2`` of the pose and from every one left free short of the pose (``descents <= 0``: all).

Where no start is done, the answer is the start with the lowest sum. A start that ends free but held off the goal by
the margin rows goes on at once with the rows at margin 0. ``patience > 0`` ends a target's uniform restarts after
that many in a row that do not lower its best sum by 1 %.

The finishing step (``finish > 0`` iterations; classic goals only): a start within the pose tolerances whose
spheres overlap by at most what a pose within them can move a sphere of the last frame is first run with the dead
zone of the tolerant goal (the box inscribed in the tolerances, rotation rows weighted ``tol_pos / tol_rot``) and
collision rows reaching ``FINISH_MARGIN * tol_pos``; it is done by the success judge itself (position, angle, free).

A descent ends when done, after ``stall_iters`` iterations in a row that do not lower its sum by ``stall_rel``, at
its iteration limit, or at a kept step that lowers the sum by less than ``converged`` of it (``converged_given``
for the given starts after the first). A candidate whose pose rows alone are no better than the current sum is
rejected without computing its collision rows. Random numbers: the splitmix64 stream of :mod:`nik.kernels.lm`, one
per target (same seed, same answer). The settings and what they trade: :class:`nik.ik.collide.CollideCfg`.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import NamedTuple

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import _chain
from nik.kernels.collision import _rows_in, collides_in, hand_lever, link_bounds, residual_in, rows_work
from nik.kernels.lm import (
    _STREAM,
    CLASSIC,
    DEAD_ZONE,
    EPS,
    ITERS,
    LAMBDA0,
    LAMBDA_DOWN,
    LAMBDA_MAX,
    LAMBDA_MIN,
    LAMBDA_UP,
    MAX_STEP,
    ROT_WEIGHT,
    STALL_ITERS,
    STALL_REL,
    TOL_POS,
    TOL_ROT,
    PoseState,
    _bounds,
    _copy,
    _draw,
    _eval_goal,
    _lm_one_bounded,
    _propose_dense,
    _score,
    _work_size,
)
from nik.kernels.lm_loop import ACCEPT_DONE, _lm_loop, _loop_cfg, problem_kind

__all__ = ["Answers", "CollideOpts", "Starts", "Targets", "collision_lm"]

#: the finishing step's collision rows reach this fraction of ``tol_pos`` (module docstring)
FINISH_MARGIN = 0.2


class Targets(NamedTuple):
    """The goal of each target of :func:`collision_lm`."""

    T: np.ndarray  #: (B, 4, 4) the target poses
    bounds: np.ndarray  #: (B, 6) the dead zone of a tolerant goal (:func:`nik.kernels.lm._score`)
    modes: np.ndarray  #: (B,) int64 the rotation mode (``CLASSIC``: the tolerances of the options)


class Starts(NamedTuple):
    """The starts of each target of :func:`collision_lm`."""

    q: np.ndarray  #: (B, H, n) given starts
    count: np.ndarray  #: (B,) int64 how many of them target ``b`` uses (>= 0)
    restarts: np.ndarray  #: (B,) int64 the uniform starts target ``b`` may draw at most


class CollideOpts(NamedTuple):
    """The settings of :func:`collision_lm` (:class:`nik.ik.collide.CollideCfg` says what each trades)."""

    margin: float  #: metres, the collision rows' reach
    weight: float  #: the collision rows' weight
    tries: int  #: draws per uniform start
    patience: int  #: uniform restarts in a row that do not lower the best sum by 1 % before giving up (0: never)
    finish: int  #: iteration limit of the finishing step (0: none)
    descents: int  #: the uniform starts the collision LM runs from, at least (<= 0: all)
    converged: float  #: a descent ends at a kept step lowering its sum by less than this fraction (0: off)
    converged_given: float = -1.0  #: the same for the given starts after the first (< 0: ``converged``)


class Answers(NamedTuple):
    """What :func:`collision_lm` writes, per target."""

    q: np.ndarray  #: (B, n) the answer, inside the limits
    free: np.ndarray  #: (B,) bool, collision-free
    done: np.ndarray  #: (B,) bool, reached and free
    iterations: np.ndarray  #: (B,) int64
    pos: np.ndarray  #: (B,) float64, the position error of ``q`` (m)
    rot: np.ndarray  #: (B,) float64, the angle error of ``q`` (rad)


@kernel
def _sum_sq(r):
    s = 0.0
    for k in range(r.shape[0]):
        s += r[k] * r[k]
    return s


@kernel
def _rank_starts(G, joints, tgt, rw, starts, H, arm, scene, lb, order, score, chk):
    """How many of the given starts ``starts[:H] (H, n)`` LM runs from, their indices in ``order``: the first (the
    answer that collided: near the caller's ``q_near`` or the path's previous waypoint, it keeps an answer on its
    branch), then the other free ones (every row >= 0, brought inside the limits) nearest the pose first (the pose
    error of :func:`nik.kernels.lm._score`); the colliding ones are dropped before any iteration (a colliding
    hypothesis mostly lands on a colliding answer). ``tgt = (Tt, bnd, mode)``: the target; ``chk = (Tc, ec, d, r,
    work)``: scratch (a pose, two 6-vectors, the rows, :func:`nik.kernels.collision.rows_work`'s)."""
    Tt, bnd, mode = tgt
    Tc, ec, d, r, work = chk
    n = starts.shape[1]
    q = np.empty(n)
    if H == 0:
        return 0
    order[0] = 0
    m = 1
    for s in range(1, H):
        _copy(starts[s], q)
        _bounds(joints, q)
        if not collides_in(G, joints, q, arm, scene, 0.0, r, lb, work):
            _chain(G, joints, q, Tc)
            e = _score(Tt, Tc, rw, bnd, mode, ec, d)
            k = m  # insertion sort (stable) after the first: a handful of starts
            while k > 1 and score[k - 1] > e:
                score[k], order[k] = score[k - 1], order[k - 1]
                k -= 1
            score[k], order[k] = e, s
            m += 1
    return m


#: The collision LM's problem for :func:`nik.kernels.lm_loop._lm_loop`: :data:`nik.kernels.lm.PoseProblem`'s fields
#: (the dense step reads them) and the collision rows' ``arm, scene`` (:mod:`nik.kernels.collision`), their reach
#: ``margin``, the links' bounds ``lb``, the rows' scratch ``rwork`` and ``norms`` (:func:`_descend`).
CollisionProblem = namedtuple(
    "CollisionProblem",
    ["G", "joints", "goal", "prior", "eps", "max_step", "d", "work", "arm", "scene", "margin", "lb", "rwork", "norms"],
)


@kernel
def _measure_collision(prob, s, bar):
    """The loop's measure of a :data:`CollisionProblem` at ``s.q``: the pose rows (:func:`nik.kernels.lm._eval_goal`)
    and, unless the pose rows alone already lose to ``bar`` (and ``s.q`` is not reached), the collision rows into
    ``s.extra = (Jr, r, w2)``; ``s.info = (S, pos, rot, near)``. Returns ``(S, done)``: ``S = |e|^2 + w2 |r|^2``,
    done where the pose is reached and free of the rows (``near >= 0``)."""
    E, pos, rot, reached = _eval_goal(prob.G, prob.joints, s.q, prob.goal, s.T, s.J, s.e, prob.d)
    reached = reached and (not prob.norms or (pos <= prob.goal[4] and rot <= prob.goal[5]))
    s.info[1], s.info[2] = pos, rot
    if not (reached or E < bar):  # rejected by the pose rows alone (S >= E >= bar): no collision rows
        return math.inf, False
    Jr, r, w2 = s.extra
    near = residual_in(prob.G, prob.joints, s.q, prob.arm, prob.scene, prob.margin, r, Jr, prob.lb, prob.rwork)
    S = E + w2 * _sum_sq(r)
    s.info[0], s.info[3] = S, near
    return S, reached and near >= 0.0


problem_kind(CollisionProblem, _measure_collision, _propose_dense)


@kernel
def _descend(G, joints, tgt, qs, arm, scene, rows, opts, stop, ws, norms):
    """LM with collision rows of reach ``margin`` from ``qs (n,)`` (moved in place) towards ``tgt = (Tt, bnd, mode)``
    until done (the pose within the tolerances and free), stalled or ``limit`` iterations: the one compiled loop
    (:func:`nik.kernels.lm_loop._lm_loop`) on a :data:`CollisionProblem`, Marquardt damping, a candidate that is done
    kept. Returns ``(S, pos, rot, near, done, iterations)``: the sum, the pose errors, the smallest row (exact where
    at most ``margin``). ``rows = (margin, w2, lb)``: the rows' reach, their weight squared, the links' bounds;
    ``stop = (limit, stall_limit, conv_rel)``; ``ws``: the scratch of :func:`collision_lm`. ``norms``: the pose counts
    as reached only where also its position error <= ``opts[TOL_POS]`` and its angle <= ``opts[TOL_ROT]`` (the
    success judge; the finishing step's bounds reach past it). ``conv_rel``: it also ends at a kept step that lowers
    the sum by less than that fraction of it (converged: ``CollideCfg.converged``; 0: never)."""
    Tt, bnd, mode = tgt
    margin, w2, lb = rows
    limit, stall_limit, conv_rel = stop
    T, Tc, e, ec, d, J, Jc, r, rc, Jr, Jrc, A, g, dq, qc, work, info, infoc = ws
    goal = (Tt, opts[ROT_WEIGHT], bnd, mode, opts[TOL_POS], opts[TOL_ROT])
    prob = CollisionProblem(G, joints, goal, None, opts[EPS], opts[MAX_STEP], d, (A, g, dq), arm, scene, margin, lb,
                            work, norms)  # fmt: skip
    cur = PoseState(qs, T, J, e, info, (Jr, r, w2))
    other = PoseState(qc, Tc, Jc, ec, infoc, (Jrc, rc, w2))
    S, done = _measure_collision(prob, cur, math.inf)
    damping = (opts[LAMBDA_DOWN], opts[LAMBDA_UP], opts[LAMBDA_MIN], opts[LAMBDA_MAX])
    cfg = _loop_cfg(limit, opts[LAMBDA0], damping, math.inf, (opts[STALL_REL], stall_limit), (conv_rel, 0.0),
                    ACCEPT_DONE)  # fmt: skip
    total, S, done, cur, _ = _lm_loop(prob, cfg, cur, other, S, done)
    _copy(cur.q, qs)  # the answer may sit in the candidate's buffer (the loop swaps the states)
    return S, cur.info[1], cur.info[2], cur.info[3], done, total


@kernel
def _finish(G, joints, Tt, qs, fgoal, arm, scene, rows, stop, ws, qf):
    """The finishing step from ``qs (n,)`` (module docstring): :func:`_descend` with the pose rows' dead zone the box
    inscribed in the tolerances (``fgoal = (fbnd, fopts)``, rotation weight ``fopts[ROT_WEIGHT] = tol_pos /
    tol_rot``), the rows ``rows = (fmargin, w2, lb)`` of reach ``fmargin``, done by the success judge's norms and
    free at margin 0; ``qs`` moves only where it is done (``qf (n,)``: scratch). Returns ``(done, pos, rot, near,
    iterations)``."""
    fbnd, fopts = fgoal
    _copy(qs, qf)
    _, p_f, r_f, near, done, its = _descend(G, joints, (Tt, fbnd, -1), qf, arm, scene, rows, fopts, stop, ws, True)
    if done:
        _copy(qf, qs)
    return done, p_f, r_f, near, its


@kernel
def _nearest_free(G, joints, tgt, rw, draws, rng, arm, scene, lb, chk, qs):
    """One uniform start's draw (``draws = (tries, drawn, draw_E)``): ``tries`` configurations drawn from ``rng`` into
    ``drawn (tries, n)``, their pose errors (:func:`nik.kernels.lm._score`, towards ``tgt = (Tt, bnd, mode)``) in
    ``draw_E (tries,)``; the free one nearest the pose (the first of equals) copied into ``qs (n,)`` (``chk``: the
    scratch of :func:`_rank_starts`). The draws are checked for collisions nearest the pose first, up to the first
    free one: the same start as checking, in the order drawn, each draw nearer than the nearest free one so far, with
    fewer checks (checking in the order drawn checks every new nearest, free or not). Returns ``(found, checks)``:
    whether a draw is free, the collision checks made; ``draw_E`` is left inf at the draws checked."""
    Tt, bnd, mode = tgt
    tries, drawn, draw_E = draws
    Tc, ec, d, r, work = chk
    for t in range(tries):
        _draw(joints, rng, drawn[t])
        _chain(G, joints, drawn[t], Tc)
        draw_E[t] = _score(Tt, Tc, rw, bnd, mode, ec, d)
    checks = 0
    while True:
        best, t = math.inf, -1
        for k in range(tries):
            if draw_E[k] < best:
                best, t = draw_E[k], k
        if t < 0:
            return False, checks
        draw_E[t] = math.inf
        checks += 1
        if not collides_in(G, joints, drawn[t], arm, scene, 0.0, r, lb, work):
            _copy(drawn[t], qs)
            return True, checks


@kernel
def _prepare(G, joints, tgt, opts, uni, arm, scene, rows, fstep, pools, ws, wp):
    """The uniform starts of one target ``tgt = (Tt, bnd, mode)``, before any collision iteration (``uni = (count,
    tries, rng, iopts)``): ``count`` of them, each the free draw nearest the pose among ``tries``
    (:func:`_nearest_free`; a target none of whose draws is free gets no start), taken to the pose by the pose-only LM
    (``iopts``), judged by the sum :func:`_descend` starts from (pose rows + ``w2`` times the rows at ``margin``,
    ``rows = (margin, w2, lb)``: one rows call without the Jacobian) and put in ``pool (count, n)`` (that sum in
    ``pool_S``, the smallest row in ``pool_near``; ``pools = (pool, pool_S, pool_near, porder)``), ``porder`` their
    indices by that sum, lowest first (stable). A start that is done as it stands (the pose reached and free), or done
    by the finishing step (``fstep = (fin, slack, fbnd, fopts, fmargin, finish, stall_limit, conv_rel)``: ``fin``, at
    the pose, overlapping by at most ``slack``), ends the preparation. ``ws``: the scratch of :func:`collision_lm`,
    ``wp = (qp, work, qf, J0, drawn, draw_E)`` this step's. Returns ``(m, hit, iterations, pos, rot)``: the starts
    kept, the index in ``pool`` of the done one (-1: none; then ``pos, rot`` are inf), the iterations spent (the
    pose-only LM's and the finishing step's)."""
    Tt, bnd, mode = tgt
    count, tries, rng, iopts = uni
    margin, w2, lb = rows
    fin, slack, fbnd, fopts, fmargin, finish, stall_limit, conv_rel = fstep
    pool, pool_S, pool_near, porder = pools
    T, J, e, d, r = ws[0], ws[5], ws[2], ws[4], ws[7]
    qp, lm_work, qf, J0, drawn, draw_E = wp
    chk = (ws[1], ws[3], ws[4], ws[7], ws[15])  # Tc, ec, d, r and the rows' scratch: a draw's check
    rw, tol_pos, tol_rot = opts[ROT_WEIGHT], opts[TOL_POS], opts[TOL_ROT]
    total = 0
    m = 0
    for _ in range(count):
        qs = pool[m]
        found, _ = _nearest_free(G, joints, tgt, rw, (tries, drawn, draw_E), rng, arm, scene, lb, chk, qs)
        if not found:
            continue
        # to the pose by LM without the collision rows (an iteration a small part of the cost of one with them)
        its, _, _, _ = _lm_one_bounded(G, joints, Tt, qs, bnd, mode, opts, iopts, 0, rng, qp, lm_work)
        total += its
        _copy(qp, qs)
        E, p_s, r_s, reached = _eval_goal(G, joints, qs, (Tt, rw, bnd, mode, tol_pos, tol_rot), T, J, e, d)
        _rows_in(G, joints, qs, arm, scene, r, J0, False, margin, lb, False, ws[15])
        near = math.inf
        S = E
        for k in range(r.shape[0]):
            near = min(near, r[k])
            if r[k] < margin:
                S += w2 * (margin - r[k]) * (margin - r[k])
        if reached and near >= 0.0:  # done as it stands (the collision LM would stop before its first iteration)
            return m, m, total, p_s, r_s
        if fin and p_s <= tol_pos and r_s <= tol_rot and -slack <= near < 0.0:
            fdone, p_f, r_f, _, its = _finish(G, joints, Tt, qs, (fbnd, fopts), arm, scene, (fmargin, w2, lb),
                                              (finish, stall_limit, conv_rel), ws, qf)  # fmt: skip
            total += its
            if fdone:
                return m, m, total, p_f, r_f
        k = m  # insertion sort (stable): a handful of starts
        while k > 0 and pool_S[porder[k - 1]] > S:
            porder[k] = porder[k - 1]
            k -= 1
        porder[k] = m
        pool_S[m], pool_near[m] = S, near
        m += 1
    return m, -1, total, math.inf, math.inf


@kernel
def collision_lm(G, joints, targets, given, arm, scene, opts, iopts, settings, seed, out):
    """LM with collision rows for each target ``targets.T[b] (4, 4)`` (module docstring).

    Args:
        G, joints: the chain model; ``arm, scene``: :func:`nik.collision.compiled.kernel_arguments`.
        targets: :class:`Targets` ``(T (B, 4, 4), bounds (B, 6), modes (B,) int64)``: the goal (``modes[b] ==
            CLASSIC``: the tolerances of ``opts``).
        given: :class:`Starts` ``(q (B, H, n), count (B,), restarts (B,))``: the given starts, how many of them
            target ``b`` uses (>= 0), the uniform starts it may draw at most.
        opts, iopts: :func:`nik.kernels.lm.lm_options` (``iters``, ``stall_iters`` per start).
        settings: :class:`CollideOpts` ``(margin, weight, tries, patience, finish, descents, converged,
            converged_given)``: ``descents`` the uniform starts the collision LM runs from, at least, the best by the
            sum it starts from (also every one near the pose or free: module docstring); ``converged`` applies to
            the first given start and the uniform starts, ``converged_given`` to the other given starts (the
            network's hypotheses or the closed form's branches; < 0: ``converged``).
        seed: (1,) uint64.
        out: :class:`Answers` ``(q (B, n), free (B,), done (B,), iterations (B,), pos (B,), rot (B,))`` written:
            the answers inside the limits, collision-free, reached and free, the iterations, the pose errors (m, rad).
    """
    Tt, bounds, modes = targets
    starts, n_starts, restarts = given
    margin, weight, tries, patience, finish, descents, converged, converged_given = settings
    q, free, done_out, iterations, pos, rot = out
    spheres, sphere_frame, body_start, pairs = arm[0], arm[1], arm[2], arm[3]
    B, n = q.shape
    R = pairs.shape[0] + body_start.shape[0] - 1
    rw, tol_pos, tol_rot = opts[ROT_WEIGHT], opts[TOL_POS], opts[TOL_ROT]
    limit, stall_limit = iopts[ITERS], iopts[STALL_ITERS]
    w2 = weight * weight
    conv_given = converged if converged_given < 0.0 else converged_given
    T, Tc = np.empty((3, 4)), np.empty((3, 4))
    e, ec, d = np.empty(6), np.empty(6), np.empty(6)
    J, Jc = np.empty((6, n)), np.empty((6, n))
    r, rc = np.empty(R), np.empty(R)
    Jr, Jrc = np.empty((R, n)), np.empty((R, n))
    A, g, dq = np.empty((n, n)), np.empty(n), np.empty(n)
    qs, qc, qp, best_q = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    rng = np.empty(1, dtype=np.uint64)
    order, score = np.empty(starts.shape[1], dtype=np.int64), np.empty(starts.shape[1])
    lb = np.empty((body_start.shape[0] - 1, 4))  # the links' bounds, once per call (the broad phase)
    link_bounds(spheres, body_start, lb)
    work = rows_work(n, arm, scene)  # the rows' scratch, once per call
    lm_work = np.empty(_work_size(n))  # the pose-only LM's scratch (the uniform starts' first leg)
    # the finishing step's goal: isotropic in the tolerances, its dead zone the box inscribed in them
    fopts = opts.copy()
    fin_on = finish > 0 and tol_pos > 0.0 and tol_rot > 0.0
    fopts[ROT_WEIGHT] = tol_pos / tol_rot if fin_on else rw
    fbnd = np.empty(6)
    for k in range(3):
        fbnd[k] = tol_pos / (math.sqrt(3.0) * DEAD_ZONE)
        fbnd[3 + k] = tol_rot / (math.sqrt(3.0) * DEAD_ZONE)
    fmargin = FINISH_MARGIN * tol_pos
    # the most a pose within the tolerances moves a sphere of the last frame: the overlap the finishing step is tried on
    slack = tol_pos + tol_rot * hand_lever(G, spheres, sphere_frame)
    qf = np.empty(n)
    # the uniform starts of a target, drawn and taken to the pose before any collision iteration, and their order
    most = 1
    for b in range(B):
        most = max(most, restarts[b])
    pool, pool_S, pool_near = np.empty((most, n)), np.empty(most), np.empty(most)
    porder = np.empty(most, dtype=np.int64)
    J0 = np.empty((0, n))  # the rows without their Jacobian
    drawn, draw_E = np.empty((max(tries, 1), n)), np.empty(max(tries, 1))  # a uniform start's draws
    info, infoc = np.empty(4), np.empty(4)  # a descent's state: its sum, pose errors, smallest row
    ws = (T, Tc, e, ec, d, J, Jc, r, rc, Jr, Jrc, A, g, dq, qc, work, info, infoc)  # the descents' scratch
    wp = (qp, lm_work, qf, J0, drawn, draw_E)  # the uniform starts' preparation's
    pools = (pool, pool_S, pool_near, porder)
    for b in range(B):
        rng[0] = seed[0] ^ (np.uint64(b) * _STREAM)
        bnd, mode = bounds[b], modes[b]
        fin = fin_on and mode == CLASSIC
        total = 0
        best_S, best_free, best_done = math.inf, False, False
        best_pos, best_rot = math.inf, math.inf
        stale = 0
        # the first given start runs before the others are ranked (it ends most targets: ranking them costs a
        # collision check each); the others are ranked once it is not done
        H = 1 if n_starts[b] > 0 else 0
        order[0] = 0
        ranked = n_starts[b] <= 1
        nu, prepared = restarts[b], restarts[b] <= 0  # uniform starts left to run; drawn and ranked yet
        s = -1
        while s + 1 < H + nu or not ranked:
            s += 1
            if s == H and not ranked:
                ranked = True
                H = _rank_starts(G, joints, (Tt[b], bnd, mode), rw, starts[b], n_starts[b], arm, scene, lb, order,
                                 score, (Tc, ec, d, r, work))  # fmt: skip
                if s >= H + nu:
                    break
            if s == H and not prepared:
                # every uniform start drawn and taken to the pose first, then the collision LM from the best
                # `descents` by the sum it starts from, lowest first (module docstring)
                prepared = True
                fstep = (fin, slack, fbnd, fopts, fmargin, finish, stall_limit, converged)
                m, hit, its, p_h, r_h = _prepare(G, joints, (Tt[b], bnd, mode), opts, (restarts[b], tries, rng, iopts),
                                                 arm, scene, (margin, w2, lb), fstep, pools, ws, wp)  # fmt: skip
                total += its
                if hit >= 0:
                    best_S, best_free, best_done, best_pos, best_rot = 0.0, True, True, p_h, r_h
                    _copy(pool[hit], best_q)
                    break
                # the best `descents`, every start at most as far off as the pose reached with one sphere the
                # margin deep (a row of 2 margin) and every free one: the starts the collision LM solves from, in
                # their order (module docstring)
                nu = m
                if descents > 0:
                    nu = 0
                    for k in range(m):
                        i = porder[k]
                        if k < descents or pool_S[i] <= w2 * 4.0 * margin * margin or pool_near[i] >= 0.0:
                            porder[nu] = i
                            nu += 1
                if nu == 0:
                    break
            if s < H:
                _copy(starts[b, order[s]], qs)
                _bounds(joints, qs)
            else:
                _copy(pool[porder[s - H]], qs)
            if fin and s < H:
                # at the pose and overlapping by less than the tolerance can move the hand: the finishing step first
                _, p_s, r_s, _ = _eval_goal(G, joints, qs, (Tt[b], rw, bnd, mode, tol_pos, tol_rot), T, J, e, d)
                if p_s <= tol_pos and r_s <= tol_rot:
                    near_s = residual_in(G, joints, qs, arm, scene, 0.0, r, Jr, lb, work)
                    if -slack <= near_s < 0.0:
                        fdone, p_f, r_f, near_f, its = _finish(G, joints, Tt[b], qs, (fbnd, fopts), arm, scene,
                                                               (fmargin, w2, lb), (finish, stall_limit, converged), ws,
                                                               qf)  # fmt: skip
                        total += its
                        if fdone:
                            best_S, best_free, best_done, best_pos, best_rot = 0.0, True, True, p_f, r_f
                            _copy(qs, best_q)
                            break
            # the other given starts (the hypotheses) stop at `conv_given`; the answer and the restarts at `converged`
            conv = conv_given if 0 < s < H else converged
            S, p_e, r_e, near, done, its = _descend(G, joints, (Tt[b], bnd, mode), qs, arm, scene, (margin, w2, lb),
                                                    opts, (limit, stall_limit, conv), ws, False)  # fmt: skip
            total += its
            if not done and margin > 0.0 and near >= 0.0 and S < best_S:
                # free, and held off the goal by the margin rows (a goal nearer an obstacle than the margin): on
                # from here with the rows pushing only where spheres overlap, before any other start
                _copy(qs, qp)
                S0, p0, r0, near0, done0, its = _descend(G, joints, (Tt[b], bnd, mode), qs, arm, scene, (0.0, w2, lb),
                                                         opts, (limit, stall_limit, converged), ws, False)  # fmt: skip
                total += its
                if done0:
                    S, p_e, r_e, near, done = S0, p0, r0, near0, True
                else:
                    _copy(qp, qs)
            if not done and s >= H and patience > 0:
                # the uniform restarts end where earlier starts did: give up after `patience` in a row that do not
                # lower the best sum by 1 % (a goal the spheres block, that no one-joint sweep proves blocked)
                stale = stale + 1 if S >= 0.99 * best_S else 0
                if stale >= patience:
                    if S < best_S:
                        best_S, best_free, best_done, best_pos, best_rot = S, near >= 0.0, done, p_e, r_e
                        _copy(qs, best_q)
                    break
            # the best so far: done, else the lowest sum (a reached pose that collides by millimetres beats a free
            # configuration far from the pose: the best effort a user can look at)
            if done or S < best_S:
                best_S, best_free, best_done, best_pos, best_rot = S, near >= 0.0, done, p_e, r_e
                _copy(qs, best_q)
            if done:
                break
        if best_S == math.inf:  # every start dropped: keep the first given start (or a draw) as it is
            if n_starts[b] > 0:
                _copy(starts[b, 0], best_q)
            else:
                _draw(joints, rng, best_q)
            _bounds(joints, best_q)
            _, best_pos, best_rot, _ = _eval_goal(
                G, joints, best_q, (Tt[b], rw, bnd, mode, tol_pos, tol_rot), T, J, e, d
            )
            best_free = residual_in(G, joints, best_q, arm, scene, 0.0, r, Jr, lb, work) >= 0.0
        _copy(best_q, q[b])
        free[b], done_out[b], iterations[b], pos[b], rot[b] = best_free, best_done, total, best_pos, best_rot
