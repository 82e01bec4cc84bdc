"""A user's cost terms in a call (``solve(T, costs=[...])``, ``solve_all(..., costs=)``): the problem of the call.

**Built-in terms take the compiled route of their keyword** (:func:`route`): a term of :mod:`nik.costs` given via
``costs=`` becomes the keyword it equals before anything runs, so it costs what that keyword costs:

- :func:`nik.costs.posture` -> ``q_rest=`` its posture, ``rest_weight=`` its weight (in (0, 1]; 0 drops it);
- :func:`nik.costs.bounded_pose` -> ``bounds=`` its bounds; :func:`nik.costs.pose` -> the goal itself, its
  ``tol_pos`` / ``tol_rot`` the call's (both must be of the call's targets);
- :func:`nik.costs.limits` -> nothing (the limits always hold);
- :func:`nik.costs.collision` -> ``world=`` its world, the collision stage with its ``self_collision`` and margin;
- :func:`nik.costs.manipulability` -> the plan's ``manipulability`` (:mod:`nik.ik.goals`: the null-space step, the
  closed form's branch of the highest measure).

A term given twice, or beside the keyword it equals with another value (a posture and ``q_rest=``), is a one-line
``ValueError``. Only the other terms (:func:`nik.costs.custom`, a user's :class:`nik.costs.Term`) run the torch
problem below, beside the call's own terms.

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

import copy
import warnings
from dataclasses import dataclass, field

import numpy as np
import torch

__all__ = ["HYPOTHESES", "UNIFORM_STARTS", "Route", "apply", "call_terms", "check_costs", "route", "solve",
           "solve_routed"]  # fmt: skip

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


@dataclass
class Route:
    """The keywords of a call after its built-in terms were turned into them (:func:`route`); ``costs`` the terms
    left for the torch problem (None: none), ``solver`` the solver to run (a copy where a collision term changes its
    self-collision check or margin)."""

    solver: object
    tol_pos: float
    tol_rot: float
    world: object = None
    bounds: object = None
    q_rest: object = None
    rest_weight: float = 0.1
    manipulability: float = 0.0
    costs: list | None = field(default=None)

    def plain(self, solver) -> bool:
        """Nothing but the pose asked, on ``solver`` itself (the one-pose path may answer)."""
        plain = self.world is self.bounds is self.q_rest is self.costs is None
        return plain and self.manipulability == 0.0 and self.solver is solver

    def goal(self, plan):
        """``plan`` with this call's goal and preferences (:func:`nik.ik.plan.with_goal`, the manipulability)."""
        from dataclasses import replace

        from nik.ik.plan import with_goal

        plan = with_goal(plan, self.bounds, self.q_rest, self.rest_weight)
        return replace(plan, manipulability=self.manipulability) if self.manipulability else plan


def _same_targets(term, T, name: str) -> None:
    Tt = term.T.to(torch.float64)
    T = T.to(device="cpu", dtype=torch.float64)
    if Tt.shape[-3] not in (1, T.shape[0]) or not torch.allclose(Tt.cpu().expand_as(T), T, atol=1e-9, rtol=0):
        raise ValueError(f"costs: the {name} term's targets are not the call's (give the goal as the call's targets)")


def route(solver, costs, T, *, tol_pos, tol_rot, world=None, bounds=None, q_rest=None, rest_weight=0.1) -> Route:
    """The call's keywords with the built-in terms of ``costs`` turned into them (module docstring); ``T``: the
    call's targets ``(B, 4, 4)`` (a callable giving them: read only where a pose term needs them). One-line
    ``ValueError`` on a term given twice or beside its keyword with another value."""
    from nik.costs.collision import MARGIN, CollisionTerm
    from nik.costs.limits import LimitsTerm
    from nik.costs.manipulability import ManipulabilityTerm
    from nik.costs.pose import BoundedPoseTerm, PoseTerm
    from nik.costs.posture import PostureTerm
    from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

    out = Route(solver, tol_pos, tol_rot, world, bounds, q_rest, rest_weight)
    if costs is None:
        return out
    items = check_costs(costs)
    seen, rest = set(), []
    for t in items:
        kind = type(t)
        if kind in (PostureTerm, PoseTerm, BoundedPoseTerm, CollisionTerm, ManipulabilityTerm):
            if kind in seen:
                raise ValueError(f"costs: two {t.name!r} terms of the same kind; give one")
            seen.add(kind)
        if kind is LimitsTerm:
            continue
        if kind is PostureTerm:
            if q_rest is not None:
                raise ValueError("costs: a posture term and q_rest= both given; give one")
            if t.weight == 0.0:
                continue
            if not 0.0 < t.weight <= 1.0:
                raise ValueError(f"costs: the posture term's weight is the share of the way each step asks, in (0, 1]; "
                                 f"got {t.weight!r}")  # fmt: skip
            out.q_rest, out.rest_weight = t.q_rest, t.weight
        elif kind is BoundedPoseTerm:
            if bounds is not None:
                raise ValueError("costs: a bounded_pose term and bounds= both given; give one")
            _same_targets(t, T() if callable(T) else T, "bounded_pose")
            out.bounds = t.bounds
        elif kind is PoseTerm:
            _same_targets(t, T() if callable(T) else T, "pose")
            given = (tol_pos, tol_rot) != (DEFAULT_TOL_POS, DEFAULT_TOL_ROT)
            if given and (t.tol_pos, t.tol_rot) != (tol_pos, tol_rot):
                raise ValueError("costs: the pose term's tolerances differ from tol_pos= / tol_rot=; give one")
            out.tol_pos, out.tol_rot = t.tol_pos, t.tol_rot
        elif kind is CollisionTerm:
            if world is not None and t.world is not None and t.world is not world:
                raise ValueError("costs: a collision term's world and world= differ; give one")
            out.world = t.world if t.world is not None else world
            cfg = getattr(solver, "collide_cfg", None)
            margin = cfg.margin if cfg is not None else MARGIN
            own = solver.self_collision if solver.self_collision is not None else True  # None: on where checked
            if t.self_collision != own or t.margin != margin:
                from dataclasses import replace

                from nik.ik.collide import CollideCfg

                out.solver = copy.copy(out.solver)
                out.solver.self_collision = t.self_collision
                out.solver.collide_cfg = replace(cfg or CollideCfg(), margin=t.margin)
        elif kind is ManipulabilityTerm:
            out.manipulability = t.weight
        else:
            rest.append(t)
    out.costs = rest or None
    return out


def solve_routed(solver, T_target, costs, call: dict):
    """:meth:`nik.IKSolver.solve` with ``costs`` given: the built-in terms turned into keywords (:func:`route`), then
    the call as :meth:`~nik.IKSolver.solve` makes it (the torch problem only for the terms left); ``call``: the other
    arguments of :meth:`~nik.IKSolver.solve` by name."""
    from nik.ik import backends
    from nik.ik.targets import as_poses, check_tolerances

    rep = call["representation"]
    keys = ("tol_pos", "tol_rot", "world", "bounds", "q_rest", "rest_weight")
    r = route(solver, costs, lambda: as_poses(T_target, rep), **{k: call[k] for k in keys})
    check_tolerances(r.tol_pos, r.tol_rot)
    be = backends.choose(r.solver, T_target)
    plan = call["plan"]
    if plan is None:
        plan = r.solver.plan(backend=be.name, tol_pos=r.tol_pos, tol_rot=r.tol_rot, seed=call["seed"],
                             max_iters=call["max_iters"])  # fmt: skip
    return solve(r.solver, be, r.goal(plan), T_target, call["q_near"], rep, r.world, r.costs)


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
    if getattr(plan, "manipulability", 0.0) > 0.0:
        terms.append(C.manipulability(robot, weight=plan.manipulability))
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
