"""The stages of :meth:`nik.IKSolver.solve`, one small function each, composed in this order:

1. :func:`guess`: the initial guess (network, closed form, or none: the refiner starts from uniform
   configurations itself) with its errors by FK;
2. :func:`refine`: the targets the guess leaves outside tolerance, refined from it (never worse than it);
3. :func:`near`: with ``q_near`` (arms without a closed form), a second refinement from ``q_near`` itself;
   per target the successful answer nearest ``q_near`` is kept;
4. :func:`more_hypotheses`: targets still failing get LM from the other hypotheses of a multi-solution network;
5. :func:`fallback`: targets still failing and within reach get a second chance (closed form or multistart LM);
6. :func:`final_check`: the :class:`~nik.ik.result.IKResult`, success measured against the tolerances.

:meth:`IKSolver.solve_all` reuses the same parts in :func:`all_solutions`: every closed-form solution, or
LM from every network hypothesis and uniform starts, kept where within tolerance, de-duplicated.

Every stage has the signature ``stage(solver, job, answers) -> answers``: ``solver`` is the
:class:`~nik.ik.solver.IKSolver` whose configuration (robot, network, refine method, fallback) it reads,
``job`` the targets and tolerances of one call (:class:`Job`), ``answers`` the best answers so far
(:class:`Answers`, joints inside the limits with their errors measured by FK). A stage replaces an answer
only by a better one.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.ik.guesses import analytic_guess, dedupe, multistart_guess, network_guess
from nik.ik.refiners import RefineResult, lm_refine, swarm_refine
from nik.ik.result import IKResult
from nik.poses import pose_error

__all__ = [
    "Answers",
    "Job",
    "all_solutions",
    "fallback",
    "final_check",
    "first_guess",
    "guess",
    "more_hypotheses",
    "near",
    "refine",
    "refine_from",
]


@dataclass
class Job:
    """One call of :meth:`IKSolver.solve`: B targets and what their answers must meet.

    Attributes:
        T: (B, 4, 4) target poses, metres.
        reachable: (B,) bool, False where the reach bound proves a target out of reach.
        q_near: (B, dof) radians or None, the configuration to stay near.
        tol_pos: metres; tol_rot: radians (geodesic).
        seed: seeds every random choice.
        max_iters: iteration limit of the refinement (None: the method's config).
    """

    T: torch.Tensor
    reachable: torch.Tensor
    q_near: torch.Tensor | None
    tol_pos: float
    tol_rot: float
    seed: int = 0
    max_iters: int | None = None


@dataclass
class Answers:
    """The best answers so far: ``q (B, dof)``, ``pos_err``, ``rot_err`` ``(B,)`` by FK, ``iterations (B,)`` long."""

    q: torch.Tensor
    pos_err: torch.Tensor
    rot_err: torch.Tensor
    iterations: torch.Tensor

    def ok(self, job: Job) -> torch.Tensor:
        """``(B,)`` bool: within both tolerances."""
        return (self.pos_err <= job.tol_pos) & (self.rot_err <= job.tol_rot)

    def score(self) -> torch.Tensor:
        """``(B,)``: the error used to compare two answers (metres + 0.1 x radians)."""
        return self.pos_err + 0.1 * self.rot_err

    def take(self, idx: torch.Tensor, other: RefineResult | Answers, mask: torch.Tensor) -> Answers:
        """A copy with target ``idx[i]`` replaced by row ``i`` of ``other`` where ``mask[i]`` (``idx, mask: (b,)``)."""
        keep = idx[mask]
        q, pos, rot = self.q.clone(), self.pos_err.clone(), self.rot_err.clone()
        q[keep] = other.q[mask].to(q.dtype)
        pos[keep] = other.pos_err[mask].to(pos.dtype)
        rot[keep] = other.rot_err[mask].to(rot.dtype)
        return Answers(q, pos, rot, self.iterations)

    def add_iterations(self, idx: torch.Tensor, it: torch.Tensor) -> Answers:
        """A copy with ``it: (b,)`` added to the iterations of targets ``idx: (b,)``."""
        iterations = self.iterations.clone()
        iterations[idx] += it.to(torch.long)
        return Answers(self.q, self.pos_err, self.rot_err, iterations)


def first_guess(solver, T: torch.Tensor, *, q_near: torch.Tensor | None, seed: int) -> torch.Tensor:
    """``(B, dof)`` the raw initial guess for ``T: (B, 4, 4)``: the network's, the closed form's (the solution
    nearest ``q_near``, or the one farthest inside the limits), else the best of 64 uniform configurations."""
    if solver.uses_network(T):
        return network_guess(solver.net, solver.robot, T)
    if solver.closed_form:
        return analytic_guess(solver.robot, T, q_near=q_near)
    return multistart_guess(solver.robot, T, seed=seed)


def guess(solver, job: Job) -> Answers | None:
    """Stage 1: the initial guess with its FK errors; None where the refiner starts from uniform
    configurations itself (no network, no closed form, a refinement to follow)."""
    if solver.source_for(job.T) == "multistart" and solver.refine != "none":
        return None
    q0 = first_guess(solver, job.T, q_near=job.q_near, seed=job.seed)
    pos, rot = pose_error(job.T, solver.robot.fk(q0))
    return Answers(q0, pos, rot, torch.zeros(q0.shape[0], dtype=torch.long, device=q0.device))


def refine_from(solver, job: Job, idx: torch.Tensor, q0: torch.Tensor | None) -> RefineResult:
    """The solver's refiner on targets ``idx: (b,)`` from ``q0: (b, dof)`` (None: uniform starts)."""
    T, reachable = job.T[idx], job.reachable[idx]
    kw = {"tol_pos": job.tol_pos, "tol_rot": job.tol_rot, "seed": job.seed, "max_iters": job.max_iters}
    if solver.refine == "lm":
        # LM restarts its failing targets itself when the multistart is the fallback, or without a guess
        restarts = solver.fallback == "multistart" or q0 is None
        return lm_refine(solver.robot, T, q0, cfg=solver.swarm_cfg, restarts=restarts, reachable=reachable, **kw)
    return swarm_refine(solver.robot, T, q0, method=solver.refine, cfg=solver.swarm_cfg, polish=solver.polish, **kw)


def refine(solver, job: Job, answers: Answers | None) -> Answers:
    """Stage 2: refine the targets outside tolerance from their guess (all targets, from uniform starts,
    when there is no guess); the refined answer is kept unless the guess was better. Out-of-reach targets of
    the closed form keep its clamped solution (the best effort)."""
    T = job.T
    if answers is None:
        res = refine_from(solver, job, torch.arange(T.shape[0], device=T.device), None)
        return Answers(res.q.to(T.dtype), res.pos_err.to(T.dtype), res.rot_err.to(T.dtype), res.iterations.long())
    todo = ~answers.ok(job)
    if solver.source_for(T) == "analytic":
        todo &= job.reachable
    idx = todo.nonzero().squeeze(1)
    if idx.numel() == 0:
        return answers
    res = refine_from(solver, job, idx, answers.q[idx])
    better = (res.pos_err + 0.1 * res.rot_err) <= answers.score()[idx]
    return answers.take(idx, res, better).add_iterations(idx, res.iterations)


def near(solver, job: Job, answers: Answers) -> Answers:
    """Stage 3 (``q_near`` given, no closed form): refine every target from ``q_near`` too; per target a
    successful answer first, then the one nearer ``q_near``; where neither succeeded, the smaller error."""
    if job.q_near is None or solver.closed_form:
        return answers
    idx = torch.arange(job.T.shape[0], device=job.T.device)
    res = refine_from(solver, job, idx, job.q_near)
    ok_a = answers.ok(job)
    ok_b = (res.pos_err <= job.tol_pos) & (res.rot_err <= job.tol_rot)
    dist_a = torch.linalg.vector_norm(answers.q - job.q_near, dim=-1)
    dist_b = torch.linalg.vector_norm(res.q - job.q_near, dim=-1)
    worse_a = answers.score() > (res.pos_err + 0.1 * res.rot_err)
    take_b = (ok_b & (~ok_a | (dist_b < dist_a))) | (~ok_a & ~ok_b & worse_a)
    return answers.take(idx, res, take_b).add_iterations(idx, res.iterations)


def more_hypotheses(solver, job: Job, answers: Answers) -> Answers:
    """Stage 4: targets still outside tolerance after refining the best hypothesis of a multi-solution
    network get LM from its other ``K - 1`` hypotheses, in one batch (no uniform restarts); the answer is
    kept where it improves on the current one."""
    from nik.lm import lm_solve

    failing = ~answers.ok(job)
    if not solver.uses_network(job.T) or getattr(solver.net, "n_hypotheses", 1) <= 1 or not bool(failing.any()):
        return answers
    robot, idx = solver.robot, failing.nonzero().squeeze(1)
    T = job.T[idx]
    hyp = solver.net.ranked_hypotheses(T)[0][:, 1:]  # (b, K - 1, dof): the best one was refined already
    g = torch.Generator(device=T.device).manual_seed(int(job.seed))
    hq, it = lm_solve(
        robot, T, hyp, tol_pos=job.tol_pos, tol_rot=job.tol_rot, max_iters=job.max_iters, restarts=0, generator=g
    )
    hq = robot.clamp(hq).to(answers.q.dtype)
    hpos, hrot = pose_error(T, robot.fk(hq))
    res = RefineResult(hq, hpos, hrot, it)
    better = (hpos + 0.1 * hrot) < answers.score()[idx]
    return answers.take(idx, res, better).add_iterations(idx, it)


def fallback(solver, job: Job, answers: Answers) -> Answers:
    """Stage 5: targets still outside tolerance and within reach get a second chance, kept where better:
    ``analytic``, the closed-form solution nearest the answer so far (or ``q_near``); ``multistart``, LM
    from uniform starts. Skipped where it would repeat the first pass (the closed form without a network;
    LM whose restarts are the multistart already) and with ``fallback="none"``."""
    first_pass_is_fallback = (not solver.uses_network(job.T) and solver.closed_form) or (
        solver.refine == "lm" and solver.fallback == "multistart"
    )
    todo = ~answers.ok(job) & job.reachable
    if solver.fallback == "none" or first_pass_is_fallback or not bool(todo.any()):
        return answers
    robot, idx = solver.robot, todo.nonzero().squeeze(1)
    T = job.T[idx]
    if solver.fallback == "analytic":
        start = job.q_near[idx] if job.q_near is not None else answers.q[idx]
        fq = analytic_guess(robot, T, q_near=start)
        fpos, frot = pose_error(T, robot.fk(fq))
        res = RefineResult(fq, fpos, frot, torch.zeros_like(idx))
    else:
        res = lm_refine(robot, T, None, tol_pos=job.tol_pos, tol_rot=job.tol_rot, seed=job.seed)
    better = (res.pos_err + 0.1 * res.rot_err) < answers.score()[idx]
    return answers.take(idx, res, better).add_iterations(idx, res.iterations)


def final_check(solver, job: Job, answers: Answers) -> IKResult:
    """Stage 6: the result, with success measured against the tolerances and reachability attached."""
    return IKResult(
        answers.q,
        answers.pos_err,
        answers.rot_err,
        answers.ok(job),
        answers.iterations,
        solver.source_for(job.T),
        reachable=job.reachable,
    )


def all_solutions(solver, job: Job, *, n_starts: int = 256, dedupe_tol: float = 1e-3) -> torch.Tensor:
    """``(K, dof)`` every distinct solution found for the one pose of ``job`` (see :meth:`IKSolver.solve_all`):
    the valid closed-form solutions, or LM (100 iterations, no restarts) from every hypothesis of the network
    and ``n_starts`` uniform starts, kept where within tolerance, polished to rounding level (:func:`_polish`),
    best first, de-duplicated at ``dedupe_tol``."""
    from nik.lm import lm_solve

    robot, T = solver.robot, job.T
    if solver.closed_form:
        from nik.analytic import solve

        sols, valid = solve(robot, T[0])
        return dedupe(sols[valid], tol=dedupe_tol)
    g = torch.Generator(device=T.device).manual_seed(int(job.seed))
    starts = robot.sample(n_starts, generator=g, dtype=T.dtype, device=T.device)
    if solver.net is not None:  # every hypothesis of the network first (one for a plain IKNet)
        hyp = solver.net.hypotheses(T)[0] if hasattr(solver.net, "hypotheses") else solver.net.predict(T)
        starts = torch.cat([robot.clamp(hyp), starts])
    Tk = T.expand(starts.shape[0], 4, 4)
    q, it = lm_solve(robot, Tk, starts, tol_pos=job.tol_pos, tol_rot=job.tol_rot, max_iters=100, restarts=0)
    q = robot.clamp(q)
    pos, rot = pose_error(Tk, robot.fk(q))
    found = Answers(q, pos, rot, it)
    ok = found.ok(job)
    q, score = q[ok], found.score()[ok]
    q = dedupe(q[score.argsort()], tol=dedupe_tol, prismatic=robot.prismatic)  # fewer to polish
    pos, rot = pose_error(T.expand(q.shape[0], 4, 4), robot.fk(q))
    found = _polish(robot, T, Answers(q, pos, rot, torch.zeros(q.shape[0], dtype=torch.long, device=q.device)))
    return dedupe(found.q[found.score().argsort()], tol=dedupe_tol, prismatic=robot.prismatic)


def _polish(robot, T: torch.Tensor, found: Answers, *, iters: int = 30) -> Answers:
    """LM from each of ``found`` (K solutions of the one pose ``T: (1, 4, 4)``) to rounding level.

    The solver's tolerance (0.1 mm / 0.1 deg) leaves the starts that reached one IK branch up to about 0.1 deg
    apart in each joint; driven on to ``eps ** 0.75`` of the dtype (about 2e-12 in float64) they meet, so the
    de-duplication sees one solution per branch. A polished answer replaces its start only where its error is
    not larger.
    """
    from nik.lm import lm_solve

    if found.q.shape[0] <= 1:
        return found
    tol = torch.finfo(T.dtype).eps ** 0.75
    Tk = T.expand(found.q.shape[0], 4, 4)
    q, _ = lm_solve(robot, Tk, found.q, tol_pos=tol, tol_rot=tol, max_iters=iters, restarts=0)
    q = robot.clamp(q)
    pos, rot = pose_error(Tk, robot.fk(q))
    polished = Answers(q, pos, rot, found.iterations)
    better = polished.score() <= found.score()
    return Answers(
        torch.where(better[:, None], q, found.q),
        torch.where(better, pos, found.pos_err),
        torch.where(better, rot, found.rot_err),
        found.iterations,
    )
