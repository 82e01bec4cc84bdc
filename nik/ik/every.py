"""``IKSolver.solve_all(..., costs=)``: the solutions of one pose under the user's cost terms.

The solutions come from :func:`nik.ik.collide.solve_all` (the closed form's, or LM from every hypothesis and
uniform starts; with a world and a posture as that function says). With ``costs=``, each is solved again under
the call's problem (:mod:`nik.ik.costs`: the pose or bounds, the limits, the posture, collisions where a check is
active, the user's terms) from where it stands; the ones that meet every constraint are kept in their order,
de-duplicated again (two solutions may meet at the same answer), then only the collision-free ones by the
solver's verdict (:func:`nik.ik.collide.free_solutions`, the call's world).
"""

from __future__ import annotations

import torch

__all__ = ["with_costs"]


def with_costs(solver, plan, T: torch.Tensor, world, costs, Q: torch.Tensor, dedupe_tol: float = 1e-3):
    """``(K', dof)``: the rows of the solutions ``Q: (K, dof)`` of the one pose ``T: (1, 4, 4)`` solved again under
    the call's terms and kept where every constraint is met (module docstring); ``Q`` itself without ``costs``."""
    from nik.ik.costs import call_terms, check_costs

    costs = check_costs(costs)
    if not costs or Q.shape[0] == 0:
        return Q
    from nik.ik.guesses import dedupe
    from nik.lm.problem import Problem, solve_problem

    TK = T.to(torch.float64).expand(Q.shape[0], 4, 4)
    terms, limits, s = call_terms(solver, plan, TK, world, costs)
    out = solve_problem(Problem(terms, limits), Q.to(torch.float64))
    q = dedupe(out.x[out.ok], tol=dedupe_tol, prismatic=solver.robot.prismatic)
    if s is not None and q.shape[0]:  # the solver's verdict (the meshes with mesh_verdict)
        q = q[torch.from_numpy(~s.colliding(solver.robot, q.cpu().numpy())).to(q.device)]
    return q.to(Q)
