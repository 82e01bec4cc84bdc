"""The collision re-solve: the call's pose term for the compiled kernels (:func:`_goal`), the collision LM
(:func:`_collision_solve`, :func:`_solve_free`: :mod:`nik.kernels.collision_lm`), the verdict of the goal
(:func:`_judge`) and the posture steps that never leave free (:func:`rest_free`)."""

from __future__ import annotations

import numpy as np

from nik.ik.collide.choice import CollideCfg, Setup


def _goal(robot, plan, B: int, float32: bool):
    """``(model, half (B, 6), modes (B,), opts, iopts)`` of the call's pose term for the compiled kernels: the
    bounded goal (bounds times the float32 margin for float32 targets) or the classic one (``modes == CLASSIC``,
    the stage tolerances in ``opts``)."""
    from nik.ik.goals import _modes_half
    from nik.ik.model import model_of

    model = model_of(robot, plan.lm_cfg)
    half, modes = _modes_half(plan, B, plan.float32_margin if float32 else 1.0)
    opts, iopts = model.lm.options(*plan.stage_tolerances(float32))
    if plan.manipulability > 0.0:  # read by the posture step only (nik.ik.goals.preference)
        from nik.kernels.lm import MANIPULABILITY

        opts = opts.copy()
        opts[MANIPULABILITY] = plan.manipulability
    return model, np.ascontiguousarray(half), np.ascontiguousarray(modes), opts, iopts


def _judge(model, plan, T: np.ndarray, q: np.ndarray):
    """``(ok, pos, rot, d)`` of ``q: (k, n)`` against ``T: (k, 4, 4)`` by FK: the pose within the asked tolerances,
    or (with ``plan.bounds``) every axis of ``d (k, 6)`` (:func:`nik.kernels.lm.bounded_errors`) inside the asked
    bounds; ``d`` None without bounds."""
    from nik.kernels import lm

    k = q.shape[0]
    pos, rot = np.empty(k), np.empty(k)
    lm.pose_errors(model.G, model.joints, T, q, pos, rot)
    if plan.bounds is None:
        return (pos <= plan.tol_pos) & (rot <= plan.tol_rot), pos, rot, None
    half, modes = plan.bounds.expand(k), plan.bounds.modes(k)
    d = np.empty((k, 6))
    lm.bounded_errors(model.G, model.joints, T, q, modes, d)
    return (np.abs(d) <= half).all(1), pos, rot, d


def rest_free(robot, s: Setup | None, goal, T: np.ndarray, q: np.ndarray, ok, q_rest, weight: float, push=None):
    """``(k,)`` bool, which rows moved: ``q: (k, n)`` in place, where ``ok (k,)``, moved towards ``q_rest: (k, n)`` in
    the null space of the pose term ``goal`` (:func:`_goal`; :func:`nik.kernels.driver.rest_posture`: never leaving
    the goal) **without leaving collision-free** under ``s`` (None: no check). An answer whose posture steps end
    colliding takes the nearer ``q_rest`` of: the longest collision-free prefix of the same steps
    (:data:`nik.ik.goals.REST_ITERS` steps, then half as many, ... down to one; the steps are deterministic, so ``i``
    steps are the first ``i`` of the longer run), and ``push(rows, q_end)`` (the collision LM from the colliding end:
    ``(q, done)``; :func:`_pusher`), moved on towards ``q_rest`` the same way, where that is done, free and nearer
    ``q_rest`` than the answer was; else it stays where it was."""
    from nik.ik.goals import REST_DAMPING, REST_ITERS
    from nik.kernels import driver

    model, half, modes, opts, _ = goal
    q0 = q.copy()  # s None: no collision check (the posture alone)
    todo = np.flatnonzero(ok)
    iters = REST_ITERS
    pushed, q_push = np.zeros(0, dtype=np.int64), None
    while todo.size and iters >= 1:
        qt = np.ascontiguousarray(q0[todo])
        k = todo.size
        driver.rest_posture((model.G, model.joints), np.ascontiguousarray(T[todo]), qt, (half[todo], modes[todo]),
                            opts, (np.ascontiguousarray(q_rest[todo]), float(weight), iters, REST_DAMPING),
                            np.ones(k, dtype=bool), (np.empty(k), np.empty(k), np.empty((k, 6))))  # fmt: skip
        moved = (qt != q0[todo]).any(1)
        hit = np.zeros(k, dtype=bool)
        if s is not None and moved.any():
            hit[moved] = s.colliding(robot, qt[moved])
        keep = ~hit
        q[todo[keep]] = qt[keep]
        if iters == REST_ITERS and push is not None and hit.any():
            pushed = todo[hit]
            q_push, done = push(pushed, np.ascontiguousarray(qt[hit]))
            done &= ~s.colliding(robot, q_push)
            pushed, q_push = pushed[done], q_push[done]
        todo, iters = todo[hit], iters // 2
    if pushed.size:  # the pushed end, moved on towards q_rest, where nearer it than the prefix (and the answer)
        mask = np.zeros(q.shape[0], dtype=bool)
        mask[pushed] = True
        qp = q.copy()
        qp[pushed] = q_push
        rest_free(robot, s, goal, T, qp, mask, q_rest, weight)
        near = ((qp[pushed] - q_rest[pushed]) ** 2).sum(1) < ((q[pushed] - q_rest[pushed]) ** 2).sum(1)
        q[pushed[near]] = qp[pushed[near]]
    return (q != q0).any(1)


def _pusher(robot, s: Setup, plan, cfg: CollideCfg, goal, T: np.ndarray):
    """``push(rows, q) -> (q', done)`` for :func:`rest_free`: the collision LM (:func:`_solve_free`) for targets
    ``T[rows]`` under rows ``rows`` of ``goal`` from ``q: (m, n)``, no restarts."""

    def push(rows, q):
        model, half, modes, opts, iopts = goal
        m = rows.size
        g = (model, half[rows], modes[rows], opts, iopts)
        qp, done, _ = _solve_free(robot, s, plan, cfg, g, T[rows], q[:, None], np.ones(m), np.zeros(m))
        return qp, done

    return push


def _collision_solve(robot, s: Setup, plan, cfg: CollideCfg, goal, T, starts, n_starts, restarts, margin: float):
    """:func:`nik.kernels.collision_lm.collision_lm` for targets ``T: (k, 4, 4)`` with the call's pose term ``goal``
    (:func:`_goal`; rows ``k`` of it) from ``starts: (k, H, n)`` (``n_starts (k,)`` of them) and ``restarts (k,)``
    uniform ones, the collision rows' reach ``margin``; returns ``(q (k, n), done (k,), iterations (k,))``."""
    from nik.kernels.collision_lm import Answers, CollideOpts, Starts, Targets, collision_lm
    from nik.kernels.lm import ITERS, STALL_ITERS, seed_state

    _, half, modes, opts, iopts = goal
    (G, joints), rest = s.arguments(robot)
    iopts = iopts.copy()
    iopts[ITERS], iopts[STALL_ITERS] = cfg.iters, cfg.stall_iters
    k, n = starts.shape[0], starts.shape[2]
    q, free, done = np.empty((k, n)), np.empty(k, dtype=bool), np.empty(k, dtype=bool)
    it, pos, rot = np.empty(k, dtype=np.int64), np.empty(k), np.empty(k)
    targets = Targets(np.ascontiguousarray(T), np.ascontiguousarray(half[:k]), np.ascontiguousarray(modes[:k]))
    given = Starts(np.ascontiguousarray(starts), np.asarray(n_starts, dtype=np.int64),
                   np.asarray(restarts, dtype=np.int64))  # fmt: skip
    settings = CollideOpts(float(margin), float(cfg.weight), int(cfg.tries), int(cfg.patience), int(cfg.finish),
                           int(cfg.descents), float(cfg.converged), float(cfg.converged_given))  # fmt: skip
    collision_lm(G, joints, targets, given, *rest, opts, iopts, settings, seed_state(plan.seed),
                 Answers(q, free, done, it, pos, rot))  # fmt: skip
    return q, done, it


def _solve_free(robot, s: Setup, plan, cfg: CollideCfg, goal, T, starts, n_starts, restarts):
    """:func:`_collision_solve` with :attr:`CollideCfg.margin`, then, where that is not done, LM once more from its
    answer with the rows pushing only where spheres overlap (margin 0, the verdict's): the margin rows may hold an
    answer off a goal that lies nearer an obstacle than the margin (a free compromise millimetres off the pose;
    measured: 2 of 300 panda targets from free configurations in a clutter, 1 of 300 xarm7). Returns
    ``(q (k, n), done (k,), iterations (k,))``."""
    q, done, it = _collision_solve(robot, s, plan, cfg, goal, T, starts, n_starts, restarts, cfg.margin)
    miss = np.flatnonzero(~done)
    if miss.size:
        model, half, modes, opts, iopts = goal
        mgoal = (model, half[miss], modes[miss], opts, iopts)
        qm, dm, itm = _collision_solve(robot, s, plan, cfg, mgoal, T[miss], q[miss, None], np.ones(miss.size),
                                       np.zeros(miss.size), 0.0)  # fmt: skip
        q[miss[dm]], done[miss[dm]] = qm[dm], True
        it[miss] += itm
    return q, done, it
