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

import contextlib
import warnings

import numpy as np
import torch

from nik.paths.solve import PATH_MAX_STEP, PathOptions
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
    ``costs`` are given. The built-in terms take their keyword's route first (:func:`nik.ik.costs.route`; a posture
    term's ``q_rest``, its weight unused: the path's own pulls serve it), the manipulability the path's null-space
    step (:func:`_manipulable`); only the other terms make the problem."""
    if costs is None:
        return search_path(
            solver, T_path, q_start, PathOptions(timing=timing, vel_limits=vel_limits, acc_limits=acc_limits, **kw)
        )
    from nik.ik.costs import route
    from nik.paths.solve import _poses

    per, path_terms = _split(costs)
    keys = ("tol_pos", "tol_rot", "world", "bounds", "q_rest")
    r = route(solver, per or None, lambda: torch.from_numpy(_poses(T_path, kw.get("representation"))[0]),
              **{k: kw.get(k) for k in keys})  # fmt: skip
    q_rest = r.q_rest[0] if isinstance(r.q_rest, torch.Tensor) and r.q_rest.shape[0] == 1 else r.q_rest
    kw.update(tol_pos=r.tol_pos, tol_rot=r.tol_rot, world=r.world, bounds=r.bounds, q_rest=q_rest)
    solver, per = r.solver, r.costs or []
    if not per and not path_terms and not r.manipulability:
        return search_path(
            solver, T_path, q_start, PathOptions(timing=timing, vel_limits=vel_limits, acc_limits=acc_limits, **kw)
        )
    more = bool(per or path_terms)
    with warnings.catch_warnings(record=True) if more else contextlib.nullcontext():  # folded into the report's
        if more:
            warnings.simplefilter("always")
        res = search_path(solver, T_path, q_start, PathOptions(vel_limits=vel_limits, acc_limits=acc_limits, **kw))
    if r.manipulability:
        res = _manipulable(solver, T_path, q_start, res, r.manipulability, None if more else timing,
                           (vel_limits, acc_limits), kw)  # fmt: skip
    if not more:
        return res
    return _refine(solver, T_path, q_start, res, (per, path_terms), (timing, vel_limits, acc_limits), kw)


def _manipulable(solver, T_path, q_start, res, weight: float, timing, limits: tuple, kw: dict):
    """``res`` with the reached waypoints moved in the null space of their poses towards a higher manipulability (the
    null-space step of :func:`nik.kernels.driver.rest_posture`, as a pose's), all at once, one step a sweep (at most
    :data:`nik.ik.goals.REST_ITERS` sweeps), stopping before a sweep that makes a step larger than ``max_step`` (or the
    path's largest step before) or a waypoint collide that did not; kept where every waypoint is still within its goal
    by FK (a closed path's ``closure`` measured again), else ``res`` as it was. ``timing``
    (None: not timed here), ``limits``: ``(vel_limits, acc_limits)`` of :func:`nik.paths.solve._time`."""
    from dataclasses import replace

    from nik.ik import collide
    from nik.ik.goals import REST_DAMPING, REST_ITERS
    from nik.ik.model import model_of
    from nik.kernels import driver
    from nik.kernels.lm import CLASSIC, MANIPULABILITY
    from nik.paths.solve import _closure, _poses, _report, _time

    robot = solver.robot
    Tn, dtype, device = _poses(T_path, kw.get("representation"))
    N, n = Tn.shape[0], robot.dof
    q = np.ascontiguousarray(res.q.detach().cpu().numpy(), dtype=np.float64)
    ok = res.success.cpu().numpy().astype(bool)
    if kw.get("bounds") is None:
        half, modes = np.zeros((N, 6)), np.full(N, CLASSIC, dtype=np.int64)
    else:
        from nik.ik.bounds import parse_bounds

        goal = parse_bounds(kw["bounds"], batch=N, tol_pos=kw["tol_pos"], tol_rot=kw["tol_rot"])
        half, modes = np.ascontiguousarray(goal.expand(N)), np.ascontiguousarray(goal.modes(N))
    model = model_of(robot, None)
    opts = model.lm.options(kw["tol_pos"], kw["tol_rot"])[0].copy()
    opts[MANIPULABILITY] = weight
    q0 = None if q_start is None else np.asarray(torch.as_tensor(q_start).cpu(), dtype=np.float64).reshape(n)

    def largest(x):
        prev = np.concatenate([(x[:1] if q0 is None else q0[None]), x[:-1]])
        return np.abs(x - prev).max()

    bound = max(res.path.max_step, largest(q))
    s = collide.setup(robot, solver.world if kw.get("world") is None else kw["world"], solver.self_collision)
    hit = None if s is None else s.colliding(robot, q)
    qm, scratch = q.copy(), (np.empty(N), np.empty(N), np.empty((N, 6)))
    for _ in range(REST_ITERS):  # one step per waypoint a sweep: the path moves as one, its steps watched
        qn = qm.copy()
        driver.rest_posture((model.G, model.joints), Tn, qn, (half, modes), opts, (np.zeros((N, n)), 0.0, 1,
                            REST_DAMPING), ok, scratch)  # fmt: skip
        if largest(qn) > bound or (s is not None and (s.colliding(robot, qn) & ~hit).any()):
            break
        qm, moved = qn, np.abs(qn - qm).max()
        if moved < 1e-9:
            break
    keep = bool((qm != q).any())
    if keep:  # every moved waypoint is still within its goal (the step's own test); checked again by FK
        Tq = robot.fk(torch.from_numpy(qm))
        from nik.poses import pose_error, tool_error, within_bounds

        T = torch.from_numpy(Tn)
        p, rt = pose_error(T, Tq)
        if kw.get("bounds") is None:
            within = ((p <= kw["tol_pos"]) & (rt <= kw["tol_rot"])).numpy()
        else:
            within = within_bounds(T, Tq, torch.from_numpy(half)).numpy()
        keep = bool((within | ~ok).all())
    if not keep:
        if timing:
            _time(res.path, robot, q, timing, *limits)
        return res
    report = _report(robot, qm, q0, ok, res.path.reasons, res.path.max_step)
    report.closed, report.warning = res.path.closed, res.path.warning
    report.closure = _closure(qm, model.wraps) if report.closed else None
    if timing:
        _time(report, robot, qm, timing, *limits)
    like = dict(dtype=dtype, device=device)
    out = replace(res, q=torch.from_numpy(qm).to(**like), pos_err=p.to(**like), rot_err=rt.to(**like), path=report)
    if kw.get("bounds") is not None and res.axis_err is not None:
        out.axis_err = tool_error(T, Tq, torch.from_numpy(modes)).to(**like)
    return out


def _refine(solver, T_path, q_start, res, terms: tuple[list, list], timed: tuple, kw: dict):
    """The path problem of the module docstring from the search's answer ``res``, solved by the one torch LM
    (:func:`nik.lm.problem.solve_problem` over :class:`nik.lm.problem.PathProblem`); ``terms``: ``(per-configuration
    terms, path terms)`` of the user; ``timed``: ``(timing, vel_limits, acc_limits)``; ``kw``: the search's keywords
    (``tol_pos``, ``tol_rot``, ``seed``, ``representation``, ``max_step``, ``world``, ``bounds``, ``q_rest``)."""
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

    per, path_terms = terms
    timing, vel_limits, acc_limits = timed
    tol_pos, tol_rot, bounds, q_rest = kw["tol_pos"], kw["tol_rot"], kw.get("bounds"), kw.get("q_rest")
    seed, world, max_step = kw.get("seed", 0), kw.get("world"), kw.get("max_step", PATH_MAX_STEP)
    robot = solver.robot
    Tn, dtype, device = _poses(T_path, kw.get("representation"))
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
