"""``solve_path(..., costs=[...])``: a path under the user's cost terms, one problem over the whole path.

The path's own search (:func:`nik.paths.solve.solve_path`: branches, chains, trajectory optimisation, obstacle
avoidance) gives a continuous joint path first. Where the user's terms are given, that path is the start of one
problem over every waypoint at once (:class:`nik.lm.problem.PathProblem`, solved by
:func:`nik.lm.problem.solve_problem`): per waypoint the pose (or the bounds), the limits, collisions where a check is
active (:mod:`nik.ik.costs`, :func:`nik.ik.collide.setup`'s rule), the posture with ``q_rest`` (a preference) and
the user's per-configuration terms; over the
path :func:`nik.costs.smoothness` from ``q_start`` (velocity and acceleration rows, a preference) and
:func:`nik.costs.step_cap` (``max_step``, a constraint) and any path terms the user gives (``path = True``). The
problem is solved only where the search's path misses a constraint or a user's term is a preference (a path that
already meets everything is returned as the search made it).

Each waypoint's success requires every constraint's check there (the step cap included: the step into it), the
collision verdict of the waypoint and of the motion into it (samples inside the step, as the search's check), and
reachability. ``res.unmet`` names what each failed waypoint misses, ``res.path.reasons`` says it too, and the
report's warning is given once (the search's own warnings are folded into it). A closed path is not held closed
by the problem: ``res.path.closure`` is measured again.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

from nik.paths.solve import PATH_MAX_STEP
from nik.paths.solve import solve_path as search_path

__all__ = ["PATH_MAX_STEP", "solve_path"]


def _split(costs) -> tuple[list, list]:
    """``(per-configuration terms, path terms)`` of the user's ``costs`` (one line where an item is not a term)."""
    from nik.costs import Term
    from nik.ik.costs import check_costs

    items = [costs] if isinstance(costs, Term) else costs
    if not isinstance(items, list | tuple):
        raise ValueError(f"costs: expected a list of cost terms (nik.costs.custom(...)), got {type(costs).__name__}")
    per = check_costs([t for t in items if not (isinstance(t, Term) and t.path)])
    return per, [t for t in items if isinstance(t, Term) and t.path]


def solve_path(solver, T_path, q_start=None, *, costs=None, timing=False, vel_limits=None, acc_limits=None,
               **kw):  # fmt: skip
    """:func:`nik.paths.solve.solve_path` (same arguments), then the problem of the module docstring where
    ``costs`` are given."""
    if costs is None:
        return search_path(solver, T_path, q_start, timing=timing, vel_limits=vel_limits, acc_limits=acc_limits, **kw)
    per, path_terms = _split(costs)
    with warnings.catch_warnings(record=True):  # folded into the final report's warning
        warnings.simplefilter("always")
        res = search_path(solver, T_path, q_start, vel_limits=vel_limits, acc_limits=acc_limits, **kw)
    return _refine(solver, T_path, q_start, res, per, path_terms, timing, vel_limits, acc_limits, **kw)


def _refine(solver, T_path, q_start, res, per, path_terms, timing, vel_limits, acc_limits, *, tol_pos, tol_rot,
            seed=0, representation=None, max_step=PATH_MAX_STEP, world=None, closed=None, bounds=None,
            q_rest=None):  # fmt: skip
    from nik import costs as C
    from nik.costs.collision import CollisionTerm
    from nik.ik.costs import _unmet, call_terms, warn_unmet
    from nik.ik.model import model_of
    from nik.ik.plan import with_goal
    from nik.ik.result import IKResult
    from nik.lm.problem import PathProblem, solve_problem
    from nik.paths.solve import JUMP_REASON, _closure, _poses, _report, _time, jumps, open_note
    from nik.paths.trajopt import path_collisions
    from nik.poses import pose_error

    robot = solver.robot
    Tn, dtype, device = _poses(T_path, representation)
    N, n = Tn.shape[0], robot.dof
    plan = with_goal(solver.plan(backend="compiled", tol_pos=tol_pos, tol_rot=tol_rot, seed=seed), bounds, q_rest,
                     batch=N)  # fmt: skip
    T = torch.from_numpy(Tn)
    terms, limits, s = call_terms(solver, plan, T, world, per)
    q0 = None if q_start is None else torch.as_tensor(np.asarray(torch.as_tensor(q_start).cpu()), dtype=torch.float64)
    terms = terms + [C.smoothness(q0), C.step_cap(q0, max_step=max_step)] + path_terms
    problem = PathProblem(terms, limits, N, n)
    x = res.q.detach().cpu().to(torch.float64).reshape(1, N * n)
    its = res.iterations.cpu().clone()
    checks = problem.checks(x)
    if not bool(torch.stack(list(checks.values())).all()) or any(not t.hard for t in per + path_terms):
        out = solve_problem(problem, x)
        x, checks, its = out.x, out.checks, its + out.iterations
    q = x.reshape(N, n)
    qn = q.numpy()
    model = model_of(robot, plan.lm_cfg)
    reachable = res.reachable.cpu().numpy()
    free = None
    names = [t.name for t in terms if isinstance(t, CollisionTerm)]
    if s is not None:  # the verdict of the waypoints and of the motion into each
        hit = s.colliding(robot, qn)
        _, between = path_collisions(model, qn, None if q0 is None else q0.numpy(), s.arguments(robot)[1], 8)
        free = ~hit
        for nm in names:
            checks[nm] = torch.from_numpy(~hit & ~between)
    unmet = _unmet(terms, limits, checks)
    ok = torch.stack(list(checks.values())).all(0).numpy() & reachable
    reasons = ["" if ok[i] else "out of reach" if not reachable[i] else "; ".join(unmet[i] or ["not reached"])
               for i in range(N)]  # fmt: skip
    jump = jumps(qn, ok, max_step)  # reached only by a step above max_step: not reached (nik.paths.solve.jumps)
    for i in np.nonzero(jump)[0]:
        reasons[i] = JUMP_REASON
    ok &= ~jump
    reach_note = None if reachable.all() else model.unreachable_message(Tn, reachable)
    report = _report(robot, qn, None if q0 is None else q0.numpy(), ok, reasons, max_step, reach_note)
    report.closed = bool(res.path.closed)
    report.closure = None if res.path.closure is None else _closure(qn, model.wraps)
    if report.closure is not None and not report.closed:  # a loop left open (nik.paths.solve.open_note)
        note = open_note(report.closure, max_step)
        report.warning = f"{report.warning}; {note}" if report.warning else f"solve_path on {robot.name}: {note}"
    if timing is not False:
        _time(report, robot, qn, timing, vel_limits, acc_limits, ok)
    if report.warning is not None:
        warnings.warn(report.warning, UserWarning, stacklevel=4)
    else:
        warn_unmet(unmet, "waypoints")
    pos, rot = pose_error(T, robot.fk(q))
    like = dict(dtype=dtype, device=device)
    free = None if free is None else torch.from_numpy(free).to(device)
    return IKResult(q.to(**like), pos.to(**like), rot.to(**like), torch.from_numpy(ok).to(device), its.to(device),
                    res.source, reachable=res.reachable, path=report, collision_free=free, unmet=unmet)  # fmt: skip
