"""The verdict of the collision stage: the meshes judging what the spheres call colliding, with the call's
own answer kept where a re-solve fails (:func:`_meshes_judge`), and the check of given configurations
(:func:`path_waypoints`, :func:`free_solutions`)."""

from __future__ import annotations

import numpy as np
import torch

from nik.ik.collide.choice import Setup, _numpy, setup


def _meshes_judge(robot, s: Setup, q, hit, success, changed, idx, done, q_own, own_ok) -> None:
    """:func:`resolve`'s verdict where the spheres cover the meshes (:attr:`Setup.covered`), in place: the meshes
    judge the answers ``q`` the spheres call colliding (``hit``: the others are free on the meshes); a re-solved
    answer (rows ``idx``, ``done`` where it met the goal) that fails, where the call's own answer ``q_own`` met the
    goal (``own_ok``) and is free on the meshes, gives way to it, unchanged (``changed`` off: its errors stand): a
    conservative sphere model must never turn a free answer into a failure. The re-solve steered by the spheres
    (the answers they call colliding solved again, the blocked-pose proof sparing the restarts), so both the
    re-solved answers still colliding and the own answers asked about are ones the spheres call colliding: coal is
    asked about nothing else."""
    hit[:] = s.judge(robot, q, hit)
    if not idx.size:
        return
    success[idx] = done & ~hit[idx]
    back = idx[~success[idx] & own_ok[idx]]
    if back.size:
        own = back[~s.mesh.collides(q_own[back], s.world, self_collision=s.self_on)]
        q[own], hit[own], success[own], changed[own] = q_own[own], False, True, False


def path_waypoints(solver, q: np.ndarray, world, success: np.ndarray):
    """For :func:`nik.paths.solve.solve_path`: ``(success & free, free, reasons)`` for the trajectory ``q: (N, dof)``
    under the call's check (``world``, else the solver's; the rule of :func:`setup`): ``free (N,)`` bool and
    ``reasons`` (N strings, ``"colliding"`` where the answer collides, else ``""``); without a check
    ``(success, None, ["", ...])``."""
    s = setup(solver.robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None:
        return success, None, [""] * len(success)
    hit = s.colliding(solver.robot, q)
    return success & ~hit, ~hit, ["colliding" if h else "" for h in hit]


def free_solutions(solver, Q: torch.Tensor) -> torch.Tensor:
    """The rows of ``Q: (K, dof)`` that are collision-free under the solver's check (all without one)."""
    robot = solver.robot
    s = setup(robot, solver.world, solver.self_collision, solver.mesh_verdict)
    if s is None or Q.shape[0] == 0:
        return Q
    hit = s.colliding(robot, _numpy(Q))
    return Q[torch.from_numpy(~hit).to(Q.device)]
