"""``IKSolver.solve_all``: every distinct solution found for one pose (see :meth:`nik.IKSolver.solve_all`).

The solutions come from :func:`nik.ik.stages.all_solutions` (the closed form's, or LM from every hypothesis and
uniform starts), then, with ``costs=``, each is solved again under the call's problem (:mod:`nik.ik.costs`: the
pose or bounds, the limits, collisions where a check is active, the user's terms) from where it stands; the ones
that meet every constraint are kept, de-duplicated again (two solutions may meet at the same answer), best
first as before. Last, only the collision-free ones where a check is active (:func:`nik.ik.collide.free_solutions`).
"""

from __future__ import annotations

import torch

__all__ = ["solve_all"]


def solve_all(solver, T_target, *, tol_pos, tol_rot, seed, n_starts, dedupe_tol, representation, bounds, costs=None):
    """``(K, dof)``: the solutions of one pose ``T_target`` (module docstring; the arguments of
    :meth:`nik.IKSolver.solve_all`)."""
    from nik.ik import backends, collide, stages
    from nik.ik.costs import call_terms, check_costs
    from nik.ik.guesses import dedupe
    from nik.ik.plan import with_goal
    from nik.ik.targets import as_poses, check_tolerances
    from nik.robots.reach import within_reach

    T = as_poses(T_target, representation)
    if T.shape[0] != 1:
        raise ValueError(f"solve_all: expected one pose, got {T.shape[0]}")
    check_tolerances(tol_pos, tol_rot)
    costs = check_costs(costs)
    plan = with_goal(solver.plan(backend="torch", tol_pos=tol_pos, tol_rot=tol_rot, seed=seed), bounds)
    job = stages.Job(backends.torch_backend(), solver.robot, T, within_reach(solver.robot, T), None, plan.tol_pos,
                     plan.tol_rot, T.dtype, plan.tol_pos, plan.tol_rot)  # fmt: skip
    Q = stages.all_solutions(plan, job, closed_form=solver.closed_form, n_starts=n_starts, dedupe_tol=dedupe_tol)
    if costs and Q.shape[0]:
        from nik.lm.problem import Problem, solve_problem

        TK = T.to(torch.float64).expand(Q.shape[0], 4, 4)
        terms, limits, _ = call_terms(solver, plan, TK, None, costs)
        out = solve_problem(Problem(terms, limits), Q.to(torch.float64))
        Q = dedupe(out.x[out.ok], tol=dedupe_tol, prismatic=solver.robot.prismatic).to(Q.dtype)
    return collide.free_solutions(solver, Q)
