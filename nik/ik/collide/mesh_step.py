"""The meshes steer where the spheres refuse: the collision stage's last step for the targets it found no free
answer for, where coal and the robot's collision meshes are there (the check that judges, :attr:`Setup.mesh`).

A sphere model overreaches its meshes by centimetres, so a target whose free answers all look colliding to the
spheres (a hand that must pass within a few centimetres of an obstacle, a tight self-collision pose) is refused by
the sphere re-solve. For those targets :func:`mesh_step` solves the problem of the call's pose term (the classic
pose or ``bounds=``) and the mesh rows (:func:`nik.costs.mesh.mesh_collision`: coal's distances and nearest points
of each near link pair, ``max(0, margin - d)`` with its Jacobian) with the torch LM of
:func:`nik.lm.loop.lm_loop` (:func:`_descend`), from the sphere re-solve's answer, the call's own answer, then the
closed form's branches or the network's hypotheses (:func:`nik.ik.collide.starts._starts`). From each start: where
the start is free on the meshes (the sphere re-solve's answer usually is: a compromise held off the goal by the
spheres' overreach), the rows at margin 0 first (a few iterations reach the goal); then the rows at the stage's
margin, then once more at margin 0 from where that ended (a goal nearer an obstacle than the margin). Each descent
stops at its first iterate within the goal's tolerance and free on the meshes (the same coal queries as its rows),
as the compiled collision LM does. An answer is kept only where the meshes call it free at margin 0 and the goal's
check passes, on the answer as it is returned (float32 answers rounded and clamped first). Cost: one coal collision
query per pair whose bounding spheres are near and one distance query per pair within the margin, per LM
iteration (:class:`nik.collision.mesh_distance.MeshDistance`): about 5 ms a refused target on the panda and the
xarm7 in ``benchmarks/collision_feasible.py``'s scenes, up to 0.2-0.4 s where most starts must be tried (only
those targets pay it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nik.ik.collide.choice import CollideCfg, Setup

__all__ = ["MeshStep", "mesh_step"]

#: Starts taken from the closed form's branches or the network's hypotheses, after the two answers.
HYPOTHESES = 4


@dataclass(frozen=True)
class MeshStep:
    """What :func:`mesh_step` needs of the call: ``plan`` (its goal and seed), ``s`` the check, ``cfg`` the stage's
    settings, ``float32``: the answers are returned as float32 (rounded and clamped into ``lo32``/``hi32`` first),
    ``lo32``/``hi32`` ``(n,)`` the limits of that rounding."""

    plan: object
    s: Setup
    cfg: CollideCfg
    float32: bool
    lo32: np.ndarray
    hi32: np.ndarray


def _distance(s: Setup):
    """The :class:`nik.collision.mesh_distance.MeshDistance` of ``s``, kept on its mesh check per world version."""
    from nik.collision.mesh_distance import MeshDistance

    memo = s.mesh.__dict__.setdefault("_distances", {})
    key = (id(s.world), None if s.world is None else s.world.version, bool(s.self_on))
    got = memo.get(key)
    if got is None or got[0] is not s.world:
        got = memo[key] = (s.world, MeshDistance(s.mesh, s.world, self_collision=s.self_on))
    return got[1]


class _CompiledGoal:
    """The call's pose term ``goal`` (:class:`nik.costs.pose.PoseTerm` or ``BoundedPoseTerm``) with its rows and
    Jacobian from its compiled kernel (``goal.compiled``: the same residual, float64 CPU, several times faster than
    its torch twin for one target), judged by its own check; a :class:`nik.costs.term.Term` by its interface (the
    costs room is imported only when the step runs)."""

    hard, path = True, False

    def __init__(self, goal):
        self.goal, self.name, self.weight = goal, goal.name, goal.weight

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        return self.goal.residual(q)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        r, J = self.goal.compiled(q.detach().cpu().numpy())
        return torch.from_numpy(r).to(q), torch.from_numpy(J).to(q)

    def check(self, q: torch.Tensor) -> torch.Tensor:
        return self.goal.check(q)

    def why(self) -> str:
        return self.goal.why()


def _problem(robot, plan, T: torch.Tensor, term):
    """The problem of the call's pose term for ``T: (k, 4, 4)`` and the mesh rows ``term``."""
    from nik import costs as C
    from nik.costs.pose import ROT_WEIGHT
    from nik.lm.problem import Problem

    rw = plan.lm_cfg.rot_weight if plan.lm_cfg is not None else ROT_WEIGHT
    if plan.bounds is None:
        goal = C.pose(robot, T, tol_pos=plan.tol_pos, tol_rot=plan.tol_rot, rot_weight=rw)
    else:
        goal = C.bounded_pose(robot, T, plan.bounds.as_tensor(T.shape[0], T), rot_weight=rw)
    return Problem([_CompiledGoal(goal), term], C.limits(robot))


def mesh_step(robot, step: MeshStep, T: np.ndarray, first: np.ndarray, own: np.ndarray):
    """``(q (k, n), ok (k,))`` for the targets ``T: (k, 4, 4)`` (module docstring): the answer found from the
    sphere re-solve's answers ``first: (k, n)``, the call's own ``own: (k, n)``, then the branches or hypotheses;
    ``ok`` where it meets the goal and the meshes call it free (margin 0), as returned (``q`` is ``first`` where
    not)."""
    from nik.costs.mesh import MeshCollisionTerm
    from nik.ik.collide.starts import _starts
    from nik.lm.problem import ProblemCfg

    plan, s, cfg = step.plan, step.s, step.cfg
    k = T.shape[0]
    Tt = torch.from_numpy(np.ascontiguousarray(T, dtype=np.float64))
    distance = _distance(s)
    term = MeshCollisionTerm(distance, s.world, s.self_on, cfg.margin, cfg.weight)
    flush = MeshCollisionTerm(distance, s.world, s.self_on, 0.0, cfg.weight)
    margin_p, flush_p = _problem(robot, plan, Tt, term), _problem(robot, plan, Tt, flush)
    lm = ProblemCfg(iters=cfg.iters, accept="decrease_or_done")
    hyp, count = _starts(robot, plan, T, first)
    starts = [first, own] + [np.where((count > h)[:, None], hyp[:, h], first) for h in range(1, 1 + HYPOTHESES)
                             if h < hyp.shape[1]]  # fmt: skip
    q, ok = first.copy(), np.zeros(k, dtype=bool)
    for start in starts:
        todo = ~ok
        if not todo.any():
            break
        x0 = torch.from_numpy(np.ascontiguousarray(start, dtype=np.float64))
        x = x0
        free = todo.copy()  # margin 0 first from a start free on the meshes (off the goal: a few iterations reach it)
        free[todo] = ~s.mesh.collides(start[todo], s.world, self_collision=s.self_on)
        # then the margin's rows from the start, then margin 0 from where they ended (a goal nearer an obstacle than
        # the margin)
        for problem, origin, rows in ((flush_p, True, free), (margin_p, True, None), (flush_p, False, None)):
            rows = todo if rows is None else rows & todo
            if not rows.any():
                continue
            x = _descend(problem, x0 if origin else x, torch.from_numpy(rows), lm)
            qx = _returned(step, x.numpy())
            won = todo & _accepted(robot, step, margin_p, Tt, qx)
            q[won], ok[won], todo = qx[won], True, todo & ~won
            if not todo.any():
                break
    return q, ok


def _descend(problem, x0: torch.Tensor, active: torch.Tensor, cfg) -> torch.Tensor:
    """``(k, n)``: the LM of :func:`nik.lm.loop.lm_loop` on ``problem`` (the goal term, then the mesh rows) from
    ``x0: (k, n)`` on the rows ``active``, each ending at its first iterate that is **done**: within the goal's
    tolerance and free on the meshes (every distance above 0, from the same coal queries as its rows), as the
    compiled collision LM does (the margin rows pull on past that point where the goal lies nearer an obstacle than
    the margin, to a compromise off the goal). The rows that start done stay where they are."""
    from nik.lm.loop import Box, Eval, lm_loop
    from nik.threads import threads_for

    goal, mesh = problem.terms
    lo, hi, wrap = problem.box(x0)

    def evaluate(xq, rows):
        xv = xq[:, 0]
        rg, Jg = goal.evaluate(xv)
        rm, Jm, d = mesh.distance.rows_at(xv.detach().cpu().numpy(), mesh.margin)
        r = torch.cat([goal.weight * rg, mesh.weight * torch.from_numpy(rm).to(xv)], 1)
        J = torch.cat([goal.weight * Jg, mesh.weight * torch.from_numpy(Jm).to(xv)], 1)
        free = torch.from_numpy((d > 1e-9).all(1) if d.shape[1] else np.ones(len(d), dtype=bool))
        done = goal.check(xv) & free.to(xv.device)
        return Eval(-r[:, None], J[:, None], (r * r).sum(-1)[:, None], done[:, None])

    with threads_for(x0.shape[0]):  # one thread for a few targets (the ops are small), as solve_problem
        run = lm_loop(evaluate, x0[:, None], Box(lo, hi, wrap, problem.project), cfg, active=active, compact=False)
    return run.q


def _returned(step: MeshStep, q: np.ndarray) -> np.ndarray:
    """``q`` as the call returns it (float32 answers rounded and clamped into the float32 limits)."""
    if not step.float32:
        return np.array(q, dtype=np.float64)
    return np.clip(q.astype(np.float32), step.lo32, step.hi32).astype(np.float64)


def _accepted(robot, step: MeshStep, problem, T: torch.Tensor, q: np.ndarray) -> np.ndarray:
    """``(k,)`` bool: ``q`` meets the goal term's check and the joint limits, and the meshes call it free."""
    x = torch.from_numpy(np.ascontiguousarray(q))
    ok = problem.terms[0].check(x).cpu().numpy() & problem.limits.check(x).cpu().numpy()
    if ok.any():
        s = step.s
        ok[ok] = ~s.mesh.collides(q[ok], s.world, self_collision=s.self_on)
    return ok
