"""The collision stage itself: :func:`after_solve` (the pipeline, then the stage where a check is active) and
:func:`resolve` (the order of its steps: the check, the re-solve from the answer, the blocked-pose proof, the
starts and restarts, the meshes' verdict, the posture, the verdict of every term); :mod:`nik.ik.collide` says
the rules."""

from __future__ import annotations

import numpy as np
import torch

from nik.ik.collide.choice import CollideCfg, Setup, _like, _numpy, setup
from nik.ik.collide.mesh_step import MeshStep, mesh_step
from nik.ik.collide.resolver import _collision_solve, _goal, _judge, _pusher, _solve_free, rest_free
from nik.ik.collide.starts import _starts
from nik.ik.collide.verdict import _meshes_judge
from nik.ik.goals import preference, prefers


def after_solve(solver, backend, plan, T_target, q_near, representation, world):
    """:meth:`nik.IKSolver.solve` on ``backend``, then :func:`resolve` where a check is active (the call's
    ``world``, else the solver's); without one the backend's result itself (``collision_free`` None). With a check,
    the posture (``plan.q_rest``) is left to :func:`resolve` (after the collision re-solve, before the verdict)."""
    s = setup(solver.robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None:
        return backend.solve(solver.robot, plan, T_target, q_near, representation)
    from dataclasses import replace

    from nik.ik.targets import as_poses

    first = plan if plan.q_rest is None and not plan.manipulability else replace(plan, q_rest=None, manipulability=0.0)
    res = backend.solve(solver.robot, first, T_target, q_near, representation)
    return resolve(solver.robot, plan, as_poses(T_target, representation), res, s, getattr(solver, "collide_cfg", None))


def resolve(robot, plan, T: torch.Tensor, res, s: Setup, cfg: CollideCfg | None = None):
    """``res`` with colliding answers solved again and ``collision_free`` set (module docstring); ``T: (B, 4, 4)``
    the validated targets, ``res`` of either kind (numpy or tensors: the result keeps its kind).

    Every term of the call composes: the re-solve keeps the call's goal (``plan.bounds``: the bounded residual with
    its dead zones in the collision LM's pose rows, else the classic one); with ``plan.q_rest`` every successful
    answer then moves towards the posture by :func:`rest_free` (inside the goal, never into a collision); an
    answer that changed is judged again on its final ``q`` (as returned: float32 answers rounded and clamped into
    the float32 limits) by each term's check: the goal (``pos_err``/``rot_err``, or ``axis_err`` inside the
    bounds), the joint limits (kept by the kernels) and the collision verdict."""
    cfg = cfg or CollideCfg()
    q = np.ascontiguousarray(_numpy(res.q), dtype=np.float64)
    B = q.shape[0]
    Tnp = np.ascontiguousarray(_numpy(T), dtype=np.float64)
    float32 = _numpy(res.q).dtype == np.float32
    goal = _goal(robot, plan, B, float32)
    model, half, modes, opts, iopts = goal
    hit = s.steering(robot, q)  # the spheres, unless the meshes judge without their cover (today's flow)
    reach = np.ones(B, dtype=bool) if res.reachable is None else _numpy(res.reachable).astype(bool)
    idx = np.nonzero(hit & reach)[0]
    success = _numpy(res.success).astype(bool).copy()
    q_own, own_ok, done = q.copy(), success.copy(), np.zeros(0, dtype=bool)  # the call's own answers
    pos, rot, it = (_numpy(x).copy() for x in (res.pos_err, res.rot_err, res.iterations))
    axis = None if res.axis_err is None else _numpy(res.axis_err).copy()
    changed = np.zeros(B, dtype=bool)
    if idx.size:
        Tn = np.ascontiguousarray(Tnp[idx])
        k = idx.size
        kgoal = (model, half[idx], modes[idx], opts, iopts)
        first = q[idx]
        if prefers(plan):  # the first start moved towards q_rest first (the re-solve lands nearer it)
            qr, weight, _ = preference(robot, plan, B, None)
            rest_free(robot, None, kgoal, Tn, first, success[idx], qr[idx], weight)
        # from the answer alone first: it ends most targets (44 of 55 on the panda's scene), without the
        # hypotheses, the blocked-pose proof or the restarts, which only the rest get
        # (the margin-0 pass of :func:`_solve_free` waits for the second pass: measured, it costs more there than
        # it saves)
        qk, done, itk = _collision_solve(
            robot, s, plan, cfg, kgoal, Tn, first[:, None], np.ones(k), np.zeros(k), cfg.margin
        )
        miss = np.flatnonzero(~done)
        if miss.size and (s.mesh is None or s.covered) and getattr(plan, "bounds", None) is None:
            # a pose whose own rows collide has no free answer: not solved on (a tolerant goal fixes no pose)
            from nik.collision.compiled import blocked_targets

            T_miss = _numpy(T)[idx[miss]]
            miss = miss[
                ~blocked_targets(robot, s.model, s.world, T_miss, plan.tol_pos, plan.tol_rot, self_collision=s.self_on)
            ]
        if miss.size:  # from the first pass's answer, the hypotheses or branches, the uniform restarts
            Tm = np.ascontiguousarray(Tn[miss])
            starts, n_starts = _starts(robot, plan, Tm, qk[miss])
            mgoal = (model, half[idx[miss]], modes[idx[miss]], opts, iopts)
            qm, dm, itm = _solve_free(
                robot, s, plan, cfg, mgoal, Tm, starts, n_starts, np.full(miss.size, cfg.restarts)
            )
            qk[miss], done[miss], itk[miss] = qm, dm, itk[miss] + itm
        q[idx], it[idx] = qk, it[idx] + itk
        hit[idx] = s.steering(robot, qk)  # the check of the new answers (the others' stands)
        success[idx] = done & ~hit[idx]
        changed[idx] = True
    if s.mesh is not None and s.covered:  # the meshes judge what the spheres still call colliding
        _meshes_judge(robot, s, q, hit, success, changed, idx, done, q_own, own_ok)
    if s.mesh is not None and cfg.mesh_steer and idx.size:  # the meshes steer where the spheres found nothing
        rows = idx[~success[idx]]
        if rows.size:
            step = MeshStep(plan, s, cfg, float32, model.lo32, model.hi32)
            qm, okm = mesh_step(robot, step, np.ascontiguousarray(Tnp[rows]), q[rows], q_own[rows])
            won = rows[okm]
            q[won], hit[won], success[won], changed[won] = qm[okm], False, True, True
    if prefers(plan):
        ok = success & ~hit
        (qr, weight, _), push = preference(robot, plan, B, None), _pusher(robot, s, plan, cfg, goal, Tnp)
        changed |= rest_free(robot, s, goal, Tnp, q, ok, qr, weight, push)
    if changed.any():
        if float32:  # rounded and clamped into the float32 limits, as the answer is returned, then judged
            q[changed] = np.clip(q[changed].astype(np.float32), model.lo32, model.hi32)
        ok, pk, rk, dk = _judge(model, plan, np.ascontiguousarray(Tnp[changed]), np.ascontiguousarray(q[changed]))
        pos[changed], rot[changed], success[changed] = pk, rk, ok
        if axis is not None and dk is not None:
            axis[changed] = dk
    free = ~hit
    out = type(res)(**{**res.__dict__})
    out.q, out.pos_err, out.rot_err = _like(q, res.q), _like(pos, res.pos_err), _like(rot, res.rot_err)
    out.iterations, out.success = _like(it, res.iterations), _like(success & free, res.success)
    if axis is not None:
        out.axis_err = _like(axis, res.axis_err)
    out.collision_free = _like(free, res.success)
    out.collisions = [None] * B
    for i, names in zip(np.nonzero(hit)[0], s.names(robot, q[hit]), strict=True):
        out.collisions[i] = names or []  # [] only where the verdict's margin 0 and the names' rounding differ
    return out
