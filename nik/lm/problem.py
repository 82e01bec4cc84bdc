"""Levenberg-Marquardt over a problem of cost terms (:mod:`nik.costs`), torch: one pose, a batch, or a whole path.

A problem is a list of terms and the joint limits' box. Each iteration stacks the weighted residuals and
Jacobians of the terms (``r: (B, M)``, ``J: (B, M, n)``, ``weight * r`` per term) and takes the step of the
one torch LM (:func:`nik.lm.loop.lm_loop`, the compiled LM's step, :mod:`nik.kernels.lm`)::

    dq = -(J^T J + lambda (diag(J^T J) + eps) + eps I)^-1 J^T r        (Marquardt scaling)

with the joints held at a limit that the descent pushes further out left out of the step (the active set),
the step scaled so that no joint moves more than ``max_step``, then brought inside the box
(:meth:`nik.costs.limits.LimitsTerm.project`). A step is kept only where it lowers the total cost ``|r|^2``;
lambda then shrinks by ``lambda_down``, else grows by ``lambda_up``. A row stops after ``stall_iters`` steps in a
row that lower the cost by less than the fraction ``stall_rel``, at a cost of ``cost_tol`` or less, or after
``iters``. Without preferences, rows that start meeting every constraint are not touched.

:func:`solve_problem` runs two passes (the choice where a preference and a constraint disagree): first every
term (preferences such as a rest posture pull the answer, and may pull a constraint slightly out of its check),
then, for the rows whose checks fail, the constraints alone (``hard`` terms) from there, so a preference never
costs the goal: the second pass lands on the constraints nearest the first pass's answer (damped steps are the
least-norm ones); where that fails too, from the start itself (a start that met the constraints before the
preferences pulled it keeps meeting them). A start that met every constraint is returned as it was where the answer's
preference cost is no lower than the start's (a preference never makes an answer worse). Every row of the batch
stays in the batch (rows that stopped are masked, not dropped), so a user's term sees the rows in their order every
time and may hold per-target data.

:class:`Problem` has one configuration per row (``x: (B, dof)``); :class:`PathProblem` one path per problem
(``x: (1, N * dof)``, the waypoints side by side): its per-waypoint terms give a block-diagonal Jacobian, the path
terms (:mod:`nik.costs.smoothness`) couple neighbours (banded), and the normal equations are solved dense
(``N * dof`` unknowns: 350 for a 7-joint path of 50 waypoints).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.lm.loop import Box, Eval, LMCfg, lm_loop

__all__ = ["PathProblem", "Problem", "ProblemCfg", "ProblemResult", "lm_minimise", "problem_evaluator", "solve_problem"]


#: The settings of :func:`solve_problem`: :class:`nik.lm.LMCfg`, the one set of LM defaults (the name is kept).
ProblemCfg = LMCfg
#: What :func:`solve_problem` runs by default: :class:`LMCfg` with three fields changed for problems of several
#: terms, whose rows pull against each other: the active set of the descent's joints only (``hold="once"``), up to
#: 50 iterations a pass, and progress counted down to a fraction of 1e-4 (measured: with the pose LM's values, 2 of
#: 6 panda posture problems of ``tests/test_costs.py`` end on a pose solution farther from the rest posture).
PROBLEM_CFG = LMCfg(iters=50, stall_rel=1e-4, hold="once")


@dataclass
class ProblemResult:
    """What :func:`solve_problem` returns: ``x`` the answer (the problem's variables), ``iterations (B,)`` long,
    ``checks``: per term name its check ``(R,)`` bool (R: the problem's rows, targets or waypoints), ``ok (R,)``:
    every constraint met."""

    x: torch.Tensor
    iterations: torch.Tensor
    checks: dict
    ok: torch.Tensor


def _stack(parts, B: int, like: torch.Tensor):
    if not parts:
        return like.new_zeros(B, 0), like.new_zeros(B, 0, like.shape[-1])
    return torch.cat([p[0] for p in parts], 1), torch.cat([p[1] for p in parts], 1)


class Problem:
    """Terms over configurations ``x: (B, dof)``: ``terms`` (:class:`nik.costs.term.Term`, per row) and
    ``limits`` (:class:`nik.costs.limits.LimitsTerm`: the box, and its verdict)."""

    def __init__(self, terms, limits):
        self.terms, self.limits = list(terms), limits

    def evaluate(self, x: torch.Tensor, hard_only: bool = False):
        """``(r (B, M), J (B, M, n))``: the weighted residuals and Jacobians stacked."""
        parts = []
        for t in self.terms:
            if hard_only and not t.hard:
                continue
            r, J = t.evaluate(x)
            parts.append((t.weight * r.to(x), t.weight * J.to(x)))
        return _stack(parts, x.shape[0], x)

    def box(self, x: torch.Tensor):
        """``(lo, hi, wrap)``: ``(n,)`` each, for the variables ``x``."""
        return self.limits.bounds(x)

    def project(self, x: torch.Tensor) -> torch.Tensor:
        return self.limits.project(x)

    def checks(self, x: torch.Tensor) -> dict:
        """Per constraint term name, ``(B,)`` bool (the limits' verdict included)."""
        out = {self.limits.name: self.limits.check(x)}
        for t in self.terms:
            if t.hard:
                out[t.name] = out[t.name] & t.check(x) if t.name in out else t.check(x)
        return out

    def row_ok(self, checks: dict) -> torch.Tensor:
        """``(B,)`` bool: every check of ``checks`` passes, per LM row."""
        return torch.stack(list(checks.values())).all(0)


class PathProblem(Problem):
    """One path ``x: (1, N * dof)`` (module docstring): ``terms`` per waypoint and ``path_terms`` on the whole path."""

    def __init__(self, terms, limits, N: int, dof: int):
        super().__init__(terms, limits)
        self.N, self.dof = N, dof

    def _q(self, x: torch.Tensor) -> torch.Tensor:
        return x.reshape(self.N, self.dof)

    def evaluate(self, x: torch.Tensor, hard_only: bool = False):
        q, N, n = self._q(x), self.N, self.dof
        parts = []
        for t in self.terms:
            if hard_only and not t.hard:
                continue
            r, J = t.evaluate(q)
            if t.path:
                parts.append((t.weight * r.to(x), t.weight * J.to(x)))
                continue
            m = r.shape[1]
            full = x.new_zeros(N, m, N, n)
            idx = torch.arange(N, device=x.device)
            full[idx, :, idx, :] = J.to(x)
            parts.append((t.weight * r.to(x).reshape(1, N * m), t.weight * full.reshape(1, N * m, N * n)))
        return _stack(parts, 1, x)

    def box(self, x: torch.Tensor):
        lo, hi, wrap = self.limits.bounds(x)
        return lo.repeat(self.N), hi.repeat(self.N), wrap.repeat(self.N) & False  # a path's joints never wrap

    def project(self, x: torch.Tensor) -> torch.Tensor:
        lo, hi, _ = self.limits.bounds(x)
        return torch.minimum(torch.maximum(self._q(x), lo), hi).reshape(x.shape)

    def checks(self, x: torch.Tensor) -> dict:
        """Per constraint term name, ``(N,)`` bool per waypoint."""
        return super().checks(self._q(x))

    def row_ok(self, checks: dict) -> torch.Tensor:
        return torch.stack(list(checks.values())).all().reshape(1)


def problem_evaluator(problem: Problem, hard_only: bool = False):
    """``evaluate(x (B, 1, n), rows) -> Eval`` of :func:`nik.lm.loop.lm_loop` for ``problem`` (its weighted rows
    stacked; ``hard_only``: the constraint terms alone); no row is done before its cost reaches ``cost_tol``."""

    def evaluate(x, rows):
        r, J = problem.evaluate(x[:, 0], hard_only)
        E = (r * r).sum(-1)
        return Eval(-r[:, None], J[:, None], E[:, None], torch.zeros_like(E, dtype=torch.bool)[:, None])

    return evaluate


def lm_minimise(problem: Problem, x0: torch.Tensor, active: torch.Tensor, *, hard_only: bool = False,
                cfg: LMCfg | None = None) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """``(x, iterations (B,))``: the one LM (:func:`nik.lm.loop.lm_loop`, module docstring) on the rows
    ``active: (B,) bool`` of ``x0: (B, n)``, the others returned inside the box as they are; ``hard_only``: the
    constraint terms alone. Every row stays in the batch (masked), in its order."""
    cfg = cfg or PROBLEM_CFG
    lo, hi, wrap = problem.box(x0)
    box = Box(lo, hi, wrap, problem.project)
    run = lm_loop(problem_evaluator(problem, hard_only), x0[:, None], box, cfg, active=active, compact=False)
    return run.q, run.iterations


def solve_problem(problem: Problem, x0: torch.Tensor, *, active: torch.Tensor | None = None,
                  cfg: LMCfg | None = None) -> ProblemResult:  # fmt: skip
    """The two passes of the module docstring from ``x0: (B, n)`` on the rows ``active`` (default all), with the
    thread count of :func:`nik.threads.threads_for` (one thread for small batches: the ops are small)."""
    from nik.threads import threads_for

    active = torch.ones(x0.shape[0], dtype=torch.bool, device=x0.device) if active is None else active
    with threads_for(x0.shape[0]):
        return _solve(problem, x0, active, cfg)


def _preference_cost(problem: Problem, x: torch.Tensor) -> torch.Tensor:
    """``(B,)``: the weighted preference terms' ``|r|^2`` of ``x`` (every term's cost less the constraints')."""
    r, _ = problem.evaluate(x)
    rh, _ = problem.evaluate(x, True)
    return (r * r).sum(-1) - (rh * rh).sum(-1)


def _solve(problem: Problem, x0: torch.Tensor, active: torch.Tensor, cfg: LMCfg | None) -> ProblemResult:
    if all(t.hard for t in problem.terms):  # no preference: rows that already meet every constraint stay as they are
        active = active & ~problem.row_ok(problem.checks(x0))
    x, its = lm_minimise(problem, x0, active, cfg=cfg)
    checks = problem.checks(x)
    fail = active & ~problem.row_ok(checks)
    if all(t.hard for t in problem.terms):  # no preference: the first pass was the constraints alone already
        fail = fail & False
    for start in (x, x0):  # the constraints alone: from the first pass's answer, then from the start itself
        if not bool(fail.any()):
            break
        x2, its2 = lm_minimise(problem, start, fail, hard_only=True, cfg=cfg)
        x, its = torch.where(fail[:, None], x2, x), its + its2
        checks = problem.checks(x)
        fail = active & ~problem.row_ok(checks)
    if not all(t.hard for t in problem.terms):  # a start that met the constraints is kept where the answer's
        start_ok = active & problem.row_ok(problem.checks(x0))  # preferences came out no better
        if bool(start_ok.any()):
            worse = start_ok & (_preference_cost(problem, x) > _preference_cost(problem, x0))
            if bool(worse.any()):
                x = torch.where(worse[:, None], problem.project(x0), x)
                checks = problem.checks(x)
    return ProblemResult(x, its, checks, torch.stack(list(checks.values())).all(0))
