"""The stages of :meth:`nik.IKSolver.solve`, one small function each, written once for both backends:

1. :func:`guess`: the initial guess with its errors by FK: the network's hypotheses ranked by FK (the best is the
   guess), the closed form, or none (the refiner starts from uniform configurations itself);
2. :func:`refine`: the targets the guess leaves outside tolerance, refined from it (never worse than it);
3. :func:`near`: with ``q_near`` (arms without a closed form), a second refinement from ``q_near`` itself;
   per target the successful answer nearest ``q_near`` is kept; on a redundant arm a far one gets LM from a walk out
   of ``q_near`` too;
4. :func:`more_hypotheses`: targets still failing get LM from the network's next hypotheses, in turn;
5. :func:`fallback`: targets still failing and within reach get a second chance (the closed form, or LM from
   uniform starts with the restart budget);
6. :func:`final_check`: the :class:`~nik.ik.result.IKResult`, success measured against the tolerances.

Every stage has the signature ``stage(plan, job, answers) -> answers``: ``plan`` says how the call is solved
(:class:`~nik.ik.plan.Plan`: guess source and network, LM settings and caps, restarts, fallback, tolerances, seed),
``job`` the robot, targets and tolerances of one call (:class:`~nik.ik.backends.Job`, whose ``backend`` computes:
:mod:`nik.ik.backends`, compiled kernels on numpy or torch), ``answers`` the best answers so far
(:class:`Answers`, joints inside the limits with their errors measured by FK). A stage replaces an answer only
by a better one. Arrays are the backend's (numpy or torch); the stages use only what both have (masks, indexing)
and the backend's few helpers. :func:`run` is the torch backend's interpreter of a plan (a Python loop over the
stages); the compiled backend runs the same stages in one kernel call (:mod:`nik.kernels.driver`), tested to give
the answers of these stages run one by one over its kernels.

:meth:`IKSolver.solve_all` uses :func:`all_solutions`: every closed-form solution, or LM (compiled on the CPU) from
every network hypothesis and uniform starts, kept where within tolerance, de-duplicated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from nik.ik.backends.base import Job, Refined
from nik.ik.guesses import analytic_guess, dedupe, multistart_guess, network_guess
from nik.ik.plan import Plan
from nik.ik.result import IKResult
from nik.poses import pose_error
from nik.tolerances import NEAR_FAR, NEAR_PRIOR, NEAR_PRIOR_STEPS, score

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
    "run",
]


@dataclass
class Answers:
    """The best answers so far: ``q (B, dof)``, ``pos_err``, ``rot_err`` ``(B,)`` by FK, ``iterations (B,)``;
    ``hypotheses``: the network's ranked hypotheses ``(B, K, dof)`` when it guessed (the next ones are the
    :func:`more_hypotheses` stage's starts), else None."""

    q: Any
    pos_err: Any
    rot_err: Any
    iterations: Any
    hypotheses: Any = None
    _ok: Any = None
    _failing: int | None = None

    def ok(self, job: Job):
        """``(B,)`` bool: within both tolerances (computed once)."""
        if self._ok is None:
            self._ok = (self.pos_err <= job.tol_pos) & (self.rot_err <= job.tol_rot)
        return self._ok

    def failing(self, job: Job) -> int:
        """How many targets are outside tolerance (kept up to date by :meth:`merge`)."""
        if self._failing is None:
            self._failing = int((~self.ok(job)).sum())
        return self._failing

    def score(self):
        """``(B,)``: the error used to compare two answers (metres + 0.1 x radians)."""
        return score(self.pos_err, self.rot_err)

    def merge(self, job: Job, idx, other: Refined, *, strict: bool) -> Answers:
        """In place: target ``idx[i]`` takes row ``i`` of ``other`` where that is better (``strict``: a lower
        :meth:`score`, else one not higher), and ``other``'s iterations are added to targets ``idx``."""
        self._failing = job.backend.merge(self, job, idx, other, strict)
        return self

    def take(self, job: Job, idx, other: Refined, mask, it=None) -> Answers:
        """A copy with target ``idx[i]`` replaced by row ``i`` of ``other`` where ``mask[i]`` (``idx, mask: (b,)``),
        and the iterations ``it: (b,)`` (default ``other.iterations``) added to targets ``idx``."""
        be = job.backend
        keep = idx[mask]
        q, pos, rot, iters = be.copy(self.q), be.copy(self.pos_err), be.copy(self.rot_err), be.copy(self.iterations)
        be.put(q, keep, other.q[mask])
        be.put(pos, keep, other.pos_err[mask])
        be.put(rot, keep, other.rot_err[mask])
        iters[idx] += other.iterations if it is None else it
        return Answers(q, pos, rot, iters, self.hypotheses)


def run(plan: Plan, job: Job) -> IKResult:
    """The stages on one job, in order, as ``plan`` says (the torch backend's interpreter of the plan; the compiled
    backend runs the same stages over its kernels)."""
    answers = guess(plan, job)
    if plan.refine != "none":
        answers = refine(plan, job, answers)
        answers = near(plan, job, answers)
        answers = more_hypotheses(plan, job, answers)
        answers = fallback(plan, job, answers)
    return final_check(plan, job, answers)


def first_guess(plan: Plan, robot, T: torch.Tensor, *, q_near: torch.Tensor | None) -> torch.Tensor:
    """``(B, dof)`` the raw initial guess for ``T: (B, 4, 4)`` (torch): the network's, the closed form's (the
    solution nearest ``q_near``, or the one farthest inside the limits), else the best of 64 uniform configurations."""
    if plan.source == "network":
        return network_guess(plan.net, robot, _arm_targets(robot, T) if plan.net_in_arm_frame else T)
    if plan.source == "analytic":
        return analytic_guess(robot, T, q_near=q_near)
    return multistart_guess(robot, T, seed=plan.seed)


def _arm_targets(robot, T: torch.Tensor) -> torch.Tensor:
    """``T: (B, 4, 4)`` in the bare arm's frame, ``base^-1 @ T @ tool^-1`` (:attr:`nik.Robot.arm`)."""
    if robot.base is not None:
        T = torch.linalg.inv(robot.base.to(T)) @ T
    if robot.tool is not None:
        T = T @ torch.linalg.inv(robot.tool.to(T))
    return T


def guess(plan: Plan, job: Job) -> Answers | None:
    """Stage 1: the initial guess with its FK errors; None where the refiner starts from uniform
    configurations itself (no network, no closed form, a refinement to follow)."""
    be, src = job.backend, plan.source
    hyp, checked = None, None
    if src == "network":
        hyp, pos, rot, checked = be.network(plan, job)
        q = hyp[:, 0]
        if hyp.shape[1] == 1 or not plan.hypotheses:
            hyp = None
    elif src == "analytic":
        q, pos, rot = be.closed_form(plan, job, None, job.q_near)
    elif plan.refine == "none":
        q = be.uniform_guess(plan, job)
        pos, rot = pose_error(job.T, job.robot.fk(q))
    else:
        return None
    answers = Answers(q, pos, rot, be.zeros_long(job.size, job.T), hyp)
    if checked is not None:
        answers._ok, answers._failing = checked
    return answers


def _restarts_first(plan: Plan, answers: Answers | None) -> bool:
    """Whether the refine stage's LM restarts its failing targets from uniform starts itself: the plan allows
    restarts and no other network hypotheses come first."""
    return plan.restarts and (answers is None or answers.hypotheses is None)


def refine(plan: Plan, job: Job, answers: Answers | None) -> Answers:
    """Stage 2: refine the targets outside tolerance from their guess (all targets, from uniform starts,
    when there is no guess); the refined answer is kept unless the guess was better. Out-of-reach targets of
    the closed form keep its clamped solution (the best effort)."""
    be = job.backend
    restarts = _restarts_first(plan, answers)
    if answers is None:
        res = be.refine(plan, job, None, None, restarts)
        return Answers(res.q, res.pos_err, res.rot_err, res.iterations)
    if answers.failing(job) == 0:
        return answers
    todo = ~answers.ok(job)
    if plan.source == "analytic":
        todo &= job.reachable
    idx = be.nonzero(todo)
    if idx.shape[0] == 0:
        return answers
    res = be.refine(plan, job, idx, be.rows(answers.q, idx), restarts)
    return answers.merge(job, idx, res, strict=False)


def near(plan: Plan, job: Job, answers: Answers) -> Answers:
    """Stage 3 (``q_near`` given, ``plan.near``: no closed form): refine every target from ``q_near`` too (no joint
    wrapping: ``local``); both answers' wrapping joints moved by whole turns towards ``q_near``; per target a
    successful answer first, then the one nearer ``q_near``; where neither succeeded, the smaller error.

    On an arm of more than 6 joints LM from ``q_near`` can end on a pose solution that drifted along the self-motion
    manifold, 0.5 rad and more away where an exact one lies within 0.3 rad (issue 37): the answers farther than
    :data:`NEAR_FAR` (some joint) get LM (no restarts) from :func:`_near_prior`'s walk out of ``q_near``, taken
    where successful and nearer. (A pull towards ``q_near`` in the null space after it, the ``q_rest`` step, found
    no more and cost 2.5x the stage.)"""
    if job.q_near is None or not plan.near:
        return answers
    be = job.backend
    idx = be.arange(job.size, job.T)
    res = be.refine(plan, job, None, job.q_near, plan.restarts and plan.fallback != "none", local=True)
    answers.q, res.q = be.turns_toward(job, answers.q), be.turns_toward(job, res.q)
    ok_a = answers.ok(job)
    ok_b = (res.pos_err <= job.tol_pos) & (res.rot_err <= job.tol_rot)
    dist_a = be.norm(answers.q - job.q_near)
    dist_b = be.norm(res.q - job.q_near)
    worse_a = answers.score() > score(res.pos_err, res.rot_err)
    take_b = (ok_b & (~ok_a | (dist_b < dist_a))) | (~ok_a & ~ok_b & worse_a)
    answers = answers.take(job, idx, res, take_b)
    if job.robot.dof <= 6:
        return answers
    # a redundant arm's answer drifts along its self-motion: the answers still far from q_near get LM from a walk
    # out of q_near (nik.kernels.driver.near_prior), kept where successful and nearer
    idx = be.nonzero(_max_abs(answers.q - job.q_near) > NEAR_FAR)
    if idx.shape[0] > 0:
        qn = be.rows(job.q_near, idx)
        res = be.refine(plan, job, idx, _near_prior(plan, job, idx, qn), False, local=True)
        ok_b = (res.pos_err <= job.tol_pos) & (res.rot_err <= job.tol_rot)
        ok_a = be.rows(answers.ok(job), idx)
        closer = be.norm(res.q - qn) < be.norm(be.rows(answers.q, idx) - qn)
        answers = answers.take(job, idx, res, ok_b & (~ok_a | closer))
    return answers


def _max_abs(x):
    """``(B,)`` the largest entry of ``|x|: (B, n)`` per row (numpy or torch)."""
    return abs(x).max(1) if isinstance(x, np.ndarray) else x.abs().amax(1)


def _near_prior(plan: Plan, job: Job, idx, q_near):
    """``(b, n)`` starts: :func:`nik.kernels.driver.near_prior` on the targets ``idx`` (compiled), or the same walk
    batched in torch (the torch backend): the one torch LM (:func:`nik.lm.loop.lm_loop`) on the pose rows and the
    prior rows ``w (q - q_near)`` (:func:`nik.lm.loop.with_prior`), Gauss-Newton steps (no damping beyond the prior,
    every step taken), ``NEAR_PRIOR_STEPS`` for each weight ``w`` of ``NEAR_PRIOR``."""
    if job.model is not None:
        from nik.kernels import driver
        from nik.kernels.chain import WRAPS
        from nik.kernels.lm import MAX_STEP, ROT_WEIGHT

        opts, _ = job.model.lm.options(job.tol_pos, job.tol_rot, plan.max_iters)
        local = job.model.joints.copy()
        local[:, WRAPS] = 0.0
        q = np.empty(q_near.shape)
        driver.near_prior(job.model.G, local, job.backend.rows(job.T, idx), q_near, opts[ROT_WEIGHT], opts[MAX_STEP],
                          q)  # fmt: skip
        return q
    from dataclasses import replace

    from nik.lm.batched import LMCfg, chain_of, pose_evaluator
    from nik.lm.loop import Box, lm_loop, with_prior

    robot, T = job.robot, job.backend.rows(job.T, idx)
    chain = chain_of(robot, q_near, wrap=False)
    base = plan.lm_cfg if plan.lm_cfg is not None else LMCfg()
    # Gauss-Newton with the prior rows (no damping beyond them, every step taken), NEAR_PRIOR_STEPS steps a weight
    cfg = replace(base, iters=NEAR_PRIOR_STEPS, stall_iters=NEAR_PRIOR_STEPS + 1, damping="fixed", eps=1e-9,
                  linear_solver="lu", accept="always", compiled=False)  # fmt: skip
    pose = pose_evaluator(T.to(q_near), chain, cfg, (0.0, 0.0))
    box = Box(chain.lo, chain.hi, chain.wrap)
    q = q_near.clone()
    for w in NEAR_PRIOR:  # a schedule of prior weights, each the one LM
        q = lm_loop(with_prior(pose, q_near, w), q[:, None], box, cfg).q
    return q


def more_hypotheses(plan: Plan, job: Job, answers: Answers) -> Answers:
    """Stage 4: targets still outside tolerance after refining the best hypothesis of a multi-solution network
    get LM from its other ``K - 1`` hypotheses (no uniform restarts); the answer is kept where it improves on the
    current one."""
    if answers.hypotheses is None or answers.failing(job) == 0:
        return answers
    be = job.backend
    idx = be.nonzero(~answers.ok(job))
    if idx.shape[0] == 0:
        return answers
    res = be.lm_starts(plan, job, idx, be.rows(answers.hypotheses, idx)[:, 1:])
    return answers.merge(job, idx, res, strict=True)


def fallback(plan: Plan, job: Job, answers: Answers) -> Answers:
    """Stage 5: targets still outside tolerance and within reach get a second chance, kept where better:
    ``analytic``, the closed-form solution nearest the answer so far (or ``q_near``); ``multistart``, LM
    from uniform starts with the restart budget. Skipped where it would repeat the first pass (the closed form as
    the guess; LM that restarted from uniform starts already) and with ``fallback="none"``."""
    if plan.fallback == "none":
        return answers
    if plan.fallback == "analytic" and plan.source == "analytic":
        return answers  # the closed form was the guess
    if plan.fallback == "multistart" and plan.refine == "lm" and _restarts_first(plan, answers):
        return answers  # LM restarted from uniform starts in the refine stage
    if answers.failing(job) == 0:
        return answers
    be = job.backend
    idx = be.nonzero(~answers.ok(job) & job.reachable)
    if idx.shape[0] == 0:
        return answers
    if plan.fallback == "analytic":
        start = be.rows(job.q_near if job.q_near is not None else answers.q, idx)
        q, pos, rot = be.closed_form(plan, job, idx, start)
        res = Refined(q, pos, rot, be.zeros_long(idx.shape[0], job.T))
    else:
        res = be.lm(plan, job, idx, None, True)
    return answers.merge(job, idx, res, strict=True)


def final_check(plan: Plan, job: Job, answers: Answers) -> IKResult:
    """Stage 6: the result, with success measured against the asked tolerances and reachability attached; with
    ``plan.q_rest`` (or ``plan.manipulability``) the successful answers first moved towards it in the null space
    (:mod:`nik.ik.goals`)."""
    if plan.q_rest is not None or plan.manipulability > 0.0:
        from nik.ik import goals

        if job.model is not None:
            goals.rest_compiled(plan, job, answers)
        else:
            answers = goals.rest_stage(plan, job, answers)
    return job.backend.result(job, answers, plan.source)


def all_solutions(
    plan: Plan, job: Job, *, closed_form: bool, n_starts: int = 256, dedupe_tol: float = 1e-3
) -> torch.Tensor:
    """``(K, dof)`` every distinct solution found for the one pose of ``job`` (see :meth:`IKSolver.solve_all`):
    the valid closed-form solutions, or LM (100 iterations, no restarts) from every hypothesis of the network
    and ``n_starts`` uniform starts (compiled on the CPU, the batched torch LM on a GPU), kept where within tolerance,
    best first, de-duplicated at ``dedupe_tol``.

    Before the last de-duplication the survivors are driven by LM (30 iterations) to ``eps ** 0.75`` of the dtype
    (about 2e-12 in float64): the solver's tolerance (0.1 mm / 0.1 deg) leaves the starts that reached one IK
    branch up to about 0.1 deg apart in each joint; polished, they meet, so the de-duplication sees one solution
    per branch. A polished answer replaces its start only where its error is not larger. Cost on the CPU (one
    thread, panda, 256 starts): tens of milliseconds (``python benchmarks/solve_all.py``)."""

    robot, T = job.robot, job.T
    if plan.bounds is not None:
        from nik.ik.goals import all_solutions_bounded

        return all_solutions_bounded(plan, job, closed_form=closed_form, n_starts=n_starts, dedupe_tol=dedupe_tol)
    if closed_form:
        from nik.analytic import solve

        sols, valid = solve(robot, T[0])
        return dedupe(sols[valid], tol=dedupe_tol)
    g = torch.Generator(device=T.device).manual_seed(int(plan.seed))
    starts = robot.sample(n_starts, generator=g, dtype=T.dtype, device=T.device)
    if plan.net is not None:  # every hypothesis of the network first (one for a plain IKNet)
        Tn = _arm_targets(robot, T) if plan.net_in_arm_frame else T
        hyp = plan.net.hypotheses(Tn)[0] if hasattr(plan.net, "hypotheses") else plan.net.predict(Tn)
        starts = torch.cat([robot.clamp(hyp), starts])
    lm = _each_start_compiled if T.device.type == "cpu" else _each_start_torch
    q, pos, rot, it = lm(plan, robot, T, starts, job.tol_pos, job.tol_rot, 100)
    found = Answers(q, pos, rot, it)
    ok = found.ok(job)
    q, score = q[ok], found.score()[ok]
    q = dedupe(q[score.argsort()], tol=dedupe_tol, prismatic=robot.prismatic)  # fewer to polish
    if q.shape[0] > 1:  # LM to rounding level: starts that reached one branch meet (docstring)
        tol = torch.finfo(T.dtype).eps ** 0.75
        pos0, rot0 = pose_error(T.expand(q.shape[0], 4, 4), robot.fk(q))
        q1, pos1, rot1, _ = lm(plan, robot, T, q, tol, tol, 30)
        s0, s1 = pos0 + 0.1 * rot0, pos1 + 0.1 * rot1
        better = s1 <= s0
        q = torch.where(better[:, None], q1, q)[torch.where(better, s1, s0).argsort()]
    return dedupe(q, tol=dedupe_tol, prismatic=robot.prismatic)


def _each_start_compiled(plan: Plan, robot, T: torch.Tensor, starts: torch.Tensor, tol_pos, tol_rot, iters):
    """LM (compiled, :class:`nik.lm.compiled.CompiledLM`, no restarts) from each of ``starts: (K, dof)`` towards the
    one pose ``T: (1, 4, 4)``: ``(q (K, dof), pos (K,), rot (K,), iterations (K,))`` as tensors of ``T``'s dtype."""
    from nik.ik.model import model_of

    Tk = np.ascontiguousarray(np.broadcast_to(T[0].detach().double().numpy(), (starts.shape[0], 4, 4)))
    q0 = np.ascontiguousarray(starts.detach().double().numpy())
    run = model_of(robot, plan.lm_cfg).lm.solve(
        Tk, q0, tol_pos=tol_pos, tol_rot=tol_rot, seed=plan.seed, max_iters=iters, restarts=False
    )
    dt = T.dtype
    return (torch.from_numpy(run.q).to(dt), torch.from_numpy(run.pos_err).to(dt), torch.from_numpy(run.rot_err).to(dt),
            torch.from_numpy(run.iterations))  # fmt: skip


def _each_start_torch(plan: Plan, robot, T: torch.Tensor, starts: torch.Tensor, tol_pos, tol_rot, iters):
    """:func:`_each_start_compiled` with the batched torch LM (targets on a GPU)."""
    from nik.lm import lm_solve

    Tk = T.expand(starts.shape[0], 4, 4)
    q, it = lm_solve(robot, Tk, starts, cfg=plan.lm_cfg, tol_pos=tol_pos, tol_rot=tol_rot, max_iters=iters, restarts=0)
    q = robot.clamp(q)
    pos, rot = pose_error(Tk, robot.fk(q))
    return q, pos, rot, it
