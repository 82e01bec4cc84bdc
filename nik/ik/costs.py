"""A user's cost terms in a call (``solve(T, costs=[...])``, ``solve_all(..., costs=)``): the problem of the call.

After the usual pipeline (guess, refine, the goal and collision stages) gives a pose solution, the call's terms
are assembled into one problem (:class:`nik.lm.problem.Problem`) and solved by :func:`nik.lm.problem.solve_problem`
from that answer (its choices: :mod:`nik.lm.problem`):

- the pose: :func:`nik.costs.pose` (the classic tolerances) or, with ``bounds=``, :func:`nik.costs.bounded_pose`;
- the joint limits (:func:`nik.costs.limits`: the box of every step, and a verdict);
- with ``q_rest``: :func:`nik.costs.posture` weighted by ``rest_weight`` (a preference);
- where a collision check is active (a world, or self-collision: :func:`nik.ik.collide.setup`'s rule):
  :func:`nik.costs.collision` (margin 5 mm, the collision stage's);
- the user's terms (:func:`nik.costs.custom`, or any :class:`nik.costs.Term`).

The targets whose constraints still fail are solved again from the other starts the collision stage uses (the
closed form's branches or the network's hypotheses, :func:`nik.ik.collide._starts`; at most :data:`HYPOTHESES`),
then from :data:`UNIFORM_STARTS` uniform configurations (seeded by the call's ``seed``), until one start meets them
all.
Where none does, the pipeline's answer stands (it reaches the pose where the pipeline succeeded), so what a failed
answer misses is the user's term that cannot be met, not a compromise of every term.

**Success** requires every constraint's check on the returned joints: the pose within tolerance (or the bounds),
the limits, collision-free (the solver's verdict: the spheres, or the meshes with ``mesh_verdict``) and each
user's term with a finite ``tol`` (``|r| <= tol``). ``res.unmet`` names, per target, what a failed answer misses
(``["above_plane: residual above 1e-06"]``; None where nothing is missed), and a ``UserWarning`` says how many
targets fail a term and names the first.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

__all__ = ["HYPOTHESES", "UNIFORM_STARTS", "apply", "call_terms", "check_costs", "solve"]

#: Uniform starts a target whose terms are still unmet draws after the pipeline's other starts.
UNIFORM_STARTS = 4
#: Most of the other branches or hypotheses a target whose terms are unmet is solved again from.
HYPOTHESES = 8


def check_costs(costs) -> list:
    """``costs`` as a list of :class:`nik.costs.Term` (one term alone is accepted); a one-line ``ValueError``
    naming the first item that is not one."""
    from nik.costs import Term

    if costs is None:
        return []
    items = [costs] if isinstance(costs, Term) else costs
    if not isinstance(items, list | tuple):
        raise ValueError(f"costs: expected a list of cost terms (nik.costs.custom(...)), got {type(costs).__name__}")
    for i, t in enumerate(items):
        if not isinstance(t, Term):
            raise ValueError(f"costs[{i}]: expected a cost term (nik.costs.custom(fn, ...)), got {type(t).__name__}")
        if t.path:
            raise ValueError(f"costs[{i}] ({t.name!r}) is a path term: give it to solve_path")
    return list(items)


def call_terms(solver, plan, T: torch.Tensor, world, costs: list, *, q_rest=None, rest_weight=None):
    """``(terms, limits, setup)``: the call's terms for targets ``T: (B, 4, 4)`` float64 (module docstring), the
    limits term and the collision check (:class:`nik.ik.collide.Setup` or None)."""
    from nik import costs as C
    from nik.costs.pose import ROT_WEIGHT
    from nik.ik import collide

    robot, B = solver.robot, T.shape[0]
    rw = plan.lm_cfg.rot_weight if plan.lm_cfg is not None else ROT_WEIGHT
    if plan.bounds is None:
        terms = [C.pose(robot, T, tol_pos=plan.tol_pos, tol_rot=plan.tol_rot, rot_weight=rw)]
    else:
        terms = [C.bounded_pose(robot, T, plan.bounds.as_tensor(B, T), rot_weight=rw)]
    q_rest = plan.q_rest if q_rest is None else q_rest
    if q_rest is not None:
        terms.append(C.posture(robot, q_rest, weight=plan.rest_weight if rest_weight is None else rest_weight))
    s = collide.setup(robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is not None:
        terms.append(C.collision(robot, s.world, self_collision=s.self_on, model=s.model))
    return terms + costs, C.limits(robot), s


def _extra_starts(solver, plan, T: torch.Tensor, q: torch.Tensor, seed: int) -> list[torch.Tensor]:
    """The other starts of the targets (module docstring), each ``(B, dof)``; a target without its own k-th start
    gets its answer again (it is not active then)."""
    from nik.ik.collide import _starts

    starts, count = _starts(solver.robot, plan, T.cpu().numpy(), q.cpu().numpy())
    out = []
    for k in range(1, min(starts.shape[1], 1 + HYPOTHESES)):
        sk = torch.from_numpy(starts[:, k]).to(q)
        out.append(torch.where(torch.from_numpy(count > k).to(q.device)[:, None], sk, q))
    g = torch.Generator().manual_seed(int(seed))
    for _ in range(UNIFORM_STARTS):
        out.append(solver.robot.sample(q.shape[0], generator=g, dtype=q.dtype).to(q.device))
    return out


def apply(solver, plan, T: torch.Tensor, q: torch.Tensor, terms, limits, *, seed: int = 0, reachable=None):
    """``(q, iterations, checks)``: the problem of ``terms`` solved from ``q: (B, dof)`` (float64), then from the
    other starts for the targets still failing (module docstring); ``checks``: per term name ``(B,)`` bool."""
    from nik.lm.problem import Problem, solve_problem

    problem = Problem(terms, limits)
    out = solve_problem(problem, q)
    x, its, ok = out.x, out.iterations, out.ok
    reach = torch.ones_like(ok) if reachable is None else torch.as_tensor(np.asarray(reachable)).to(ok.device)
    if bool((~ok & reach).any()):
        for start in _extra_starts(solver, plan, T, x, seed):
            todo = ~ok & reach
            if not bool(todo.any()):
                break
            alt = solve_problem(problem, torch.where(todo[:, None], start, x), active=todo)
            won = todo & alt.ok
            x, its, ok = torch.where(won[:, None], alt.x, x), its + torch.where(todo, alt.iterations, 0), ok | won
    x = torch.where(ok[:, None], x, q)  # no start meets every constraint: the pipeline's answer stands
    return x, its, problem.checks(x)


def _unmet(terms, limits, checks: dict) -> list:
    why = {t.name: t.why() for t in [limits, *terms]}
    names = list(checks)
    fails = torch.stack([checks[n] for n in names]).cpu().numpy()
    return [None if fails[:, b].all() else [why[n] for n, f in zip(names, fails[:, b], strict=True) if not f]
            for b in range(fails.shape[1])]  # fmt: skip


def warn_unmet(unmet: list, what: str = "targets") -> None:
    """One ``UserWarning`` line: how many ``what`` miss a term, and the first with what it misses."""
    bad = [i for i, u in enumerate(unmet) if u]
    if bad:
        first = bad[0]
        msg = (f"{len(bad)} of {len(unmet)} {what} miss a cost term (first: {what[:-1]} {first}: "
               f"{'; '.join(unmet[first])}); success is False there")  # fmt: skip
        warnings.warn(msg, UserWarning, stacklevel=4)


def solve(solver, backend, plan, T_target, q_near, representation, world, costs):
    """:meth:`nik.IKSolver.solve`: the pipeline (:func:`nik.ik.collide.after_solve`), then the problem of the call's
    terms where ``costs`` are given (module docstring); the result keeps the input's kind (numpy or tensors)."""
    from nik.ik import collide

    costs = check_costs(costs)
    res = collide.after_solve(solver, backend, plan, T_target, q_near, representation, world)
    if not costs:
        return res
    from nik.costs.collision import CollisionTerm
    from nik.ik.targets import as_poses
    from nik.poses import pose_error, rotation_modes, tool_error

    T = as_poses(T_target, representation)
    dtype, device = T.dtype, T.device
    T = T.to(torch.float64)
    q0 = torch.as_tensor(np.asarray(res.q) if isinstance(res.q, np.ndarray) else res.q).to(T)
    terms, limits, s = call_terms(solver, plan, T, world, costs)
    reach = None if res.reachable is None else np.asarray(torch.as_tensor(res.reachable).cpu())
    q, its, checks = apply(solver, plan, T, q0, terms, limits, seed=plan.seed, reachable=reach)
    out = type(res)(**{**res.__dict__})
    Tq = solver.robot.fk(q)
    pos, rot = pose_error(T, Tq)
    if s is not None:  # the solver's verdict (spheres, or meshes with mesh_verdict) judges collisions
        names = [t.name for t in terms if isinstance(t, CollisionTerm)]
        hit = s.colliding(solver.robot, q.cpu().numpy())
        for n in names:
            checks[n] = torch.from_numpy(~hit).to(q.device)
        out.collision_free = torch.from_numpy(~hit)
        out.collisions = [None] * len(hit)
        for i, nm in zip(np.nonzero(hit)[0], s.names(solver.robot, q.cpu().numpy()[hit]), strict=True):
            out.collisions[i] = nm or []
    if plan.bounds is not None:
        out.axis_err = tool_error(T, Tq, rotation_modes(plan.bounds.as_tensor(T.shape[0], T)))
    ok = torch.stack(list(checks.values())).all(0)
    out.unmet = _unmet(terms, limits, checks)
    warn_unmet([u if reach is None or reach[i] else None for i, u in enumerate(out.unmet)])  # out of reach: warned
    out.q, out.pos_err, out.rot_err = q.to(dtype), pos.to(dtype), rot.to(dtype)
    out.success = ok if res.reachable is None else ok & torch.as_tensor(res.reachable).to(ok.device)
    out.iterations = torch.as_tensor(np.asarray(res.iterations) if isinstance(res.iterations, np.ndarray)
                                     else res.iterations).cpu() + its.cpu()  # fmt: skip
    out = out.to(device) if isinstance(res.q, torch.Tensor) else out.numpy()
    return out
