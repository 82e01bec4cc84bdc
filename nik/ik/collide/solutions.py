""":meth:`nik.IKSolver.solve_all` under the collision check and the posture: :func:`solve_all` (the search,
then :func:`all_solutions`: colliding solutions solved again, free ones added, moved towards ``q_rest``)."""

from __future__ import annotations

import numpy as np
import torch

from nik.ik.collide.choice import CollideCfg, _numpy, setup
from nik.ik.collide.resolver import _collision_solve, _goal, _judge, _pusher, _solve_free, rest_free
from nik.ik.goals import preference, prefers


def solve_all(solver, plan, T: torch.Tensor, world=None, *, n_starts: int = 256, dedupe_tol: float = 1e-3):
    """:meth:`nik.IKSolver.solve_all` for the one pose ``T: (1, 4, 4)`` (validated) under ``plan`` (its goal and
    posture): the search of :func:`nik.ik.stages.all_solutions`, then :func:`all_solutions` (world and posture)."""
    from nik.ik import stages
    from nik.ik.backends import torch_backend
    from nik.robots.reach import within_reach

    if T.shape[0] != 1:
        raise ValueError(f"solve_all: expected one pose, got {T.shape[0]}")
    robot = solver.robot
    job = stages.Job(torch_backend(), robot, T, within_reach(robot, T), None, plan.tol_pos, plan.tol_rot, T.dtype,
                     plan.tol_pos, plan.tol_rot)  # fmt: skip
    Q = stages.all_solutions(plan, job, closed_form=solver.closed_form, n_starts=n_starts, dedupe_tol=dedupe_tol)
    return all_solutions(solver, plan, T, Q, world, dedupe_tol)


def all_solutions(solver, plan, T: torch.Tensor, Q: torch.Tensor, world=None, dedupe_tol: float = 1e-3):
    """:meth:`nik.IKSolver.solve_all`'s terms after the search: ``Q: (K, dof)`` the solutions found for the one pose
    ``T: (1, 4, 4)`` (within the goal, without a world), returned as ``(K', dof)`` of ``Q``'s kind.

    Where a check is active (the call's ``world``, else the solver's; the rule of :func:`setup`), a colliding solution
    is solved again by the collision LM from itself (the call's goal kept; no restarts: a solution that stays colliding
    is dropped), and one more row from collision-free uniform starts (:attr:`CollideCfg.restarts`) adds a free
    solution where every one found collides; under the classic goal these are then driven to rounding level (the
    collision LM at margin 0, kept where the position error is not larger), as the search's survivors are, so that a
    branch found twice meets in the de-duplication; only the free ones that meet the goal are kept. With ``plan.q_rest``
    each solution moves towards the posture in the null space (:func:`rest_free`: inside the goal, never into a
    collision), and the solutions come nearest ``q_rest`` first. De-duplicated again at ``dedupe_tol``."""
    from nik.ik.guesses import dedupe

    robot = solver.robot
    s = setup(robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None and not prefers(plan):
        return Q
    q = np.ascontiguousarray(_numpy(Q), dtype=np.float64).reshape(-1, robot.dof)
    Tq = np.ascontiguousarray(np.repeat(_numpy(T).astype(np.float64).reshape(1, 4, 4), q.shape[0] + 1, axis=0))
    float32 = Q.dtype == torch.float32
    if s is not None:
        cfg = getattr(solver, "collide_cfg", None) or CollideCfg()
        hit = s.colliding(robot, q) if q.shape[0] else np.zeros(0, dtype=bool)
        k = int(hit.sum()) + 1
        starts = np.zeros((k, 1, robot.dof))
        starts[:-1, 0] = q[hit]
        n_starts, restarts = np.ones(k), np.zeros(k)
        n_starts[-1], restarts[-1] = 0, cfg.restarts
        goal = _goal(robot, plan, k, float32)
        qk = _solve_free(robot, s, plan, cfg, goal, Tq[:k], starts, n_starts, restarts)[0]
        if plan.bounds is None:  # to rounding level, as the search's survivors (the branches meet in dedupe)
            tight = np.finfo(np.float64).eps ** 0.75
            model, half, modes, _, iopts = goal
            polish = (model, half, modes, model.lm.options(tight, tight)[0], iopts)
            qp = _collision_solve(robot, s, plan, cfg, polish, Tq[:k], qk[:, None], np.ones(k), np.zeros(k), 0.0)[0]
            better = _judge(model, plan, Tq[:k], qp)[1] <= _judge(model, plan, Tq[:k], qk)[1]
            qk[better] = qp[better]
        q = np.concatenate([q[~hit], qk])
        q = q[~s.colliding(robot, q)]
    model = _goal(robot, plan, 1, float32)[0]
    if float32:
        q = np.clip(q.astype(np.float32), model.lo32, model.hi32).astype(np.float64)
    Tk = np.ascontiguousarray(Tq[:1].repeat(q.shape[0], axis=0))
    ok = _judge(model, plan, Tk, q)[0]
    q = np.ascontiguousarray(q[ok])
    Tk = np.ascontiguousarray(Tk[ok])
    if prefers(plan) and q.shape[0]:
        qr, weight, _ = preference(robot, plan, q.shape[0], None)
        goal = _goal(robot, plan, q.shape[0], float32)
        push = None if s is None else _pusher(robot, s, plan, cfg, goal, Tk)
        rest_free(robot, s, goal, Tk, q, np.ones(q.shape[0], dtype=bool), qr, weight, push)
        if float32:
            q = np.clip(q.astype(np.float32), model.lo32, model.hi32).astype(np.float64)
        keep = _judge(model, plan, Tk, q)[0]
        q, qr = np.ascontiguousarray(q[keep]), qr[keep]
        if plan.q_rest is not None:  # nearest q_rest first, else the highest manipulability first
            q = q[np.argsort(((q - qr) ** 2).sum(1), kind="stable")]
        else:
            from nik.costs.manipulability import manipulability

            q = q[np.argsort(manipulability(robot).compiled(q)[0][:, 0], kind="stable")]
    out = torch.from_numpy(np.ascontiguousarray(q)).to(dtype=Q.dtype, device=Q.device)
    return dedupe(out, tol=dedupe_tol, prismatic=robot.prismatic)
