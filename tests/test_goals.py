"""Preferred postures (``q_rest``, :mod:`nik.ik.goals`): the answer is the candidate nearest the posture that meets the
goal, then moved in the null space (issue 49 item 8)."""

from __future__ import annotations

import warnings

import numpy as np
import torch

import nik
from nik.ik.goals import rest_target
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT


def test_q_rest_mid_on_xarm7_lands_within_15_percent_of_the_nearest_solution_solve_all_finds():
    """xarm7, 24 targets from FK of random configurations (seed 3): the mean joint distance (Euclidean, radians) of
    ``solve(q_rest="mid")``'s answers to the middle of the ranges is at most 1.15 x the mean over the targets of the
    nearest solution ``solve_all`` finds (main: 1.4 x, the answer stayed on the stretch of the null space its guess
    found); every answer still reaches its target by FK, inside the limits, and success is that of the plain solve."""
    robot = nik.load_robot("xarm7")
    g = torch.Generator().manual_seed(3)
    T = robot.fk(robot.sample(24, generator=g, dtype=torch.float64))
    solver = nik.IKSolver(robot)
    mid = rest_target(robot, "mid", 1)[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = solver.solve(T)
        res = solver.solve(T, q_rest="mid")
        nearest = np.array([np.linalg.norm(solver.solve_all(T[i : i + 1]).numpy() - mid, axis=1).min() for i in
                            range(T.shape[0])])  # fmt: skip
    assert torch.equal(res.success, plain.success) and bool(res.success.all())
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    assert float(pos.max()) <= DEFAULT_TOL_POS and float(rot.max()) <= DEFAULT_TOL_ROT
    assert bool(robot.within_limits(res.q).all())
    dist = np.linalg.norm(res.q.numpy() - mid, axis=1)
    assert dist.mean() <= 1.15 * nearest.mean(), (dist.mean(), nearest.mean())
    # never farther than the plain answer moved along its own stretch of the null space
    assert (dist <= np.linalg.norm(plain.q.numpy() - mid, axis=1) + 1e-9).all()


def test_q_rest_mid_on_the_torch_backend_takes_the_nearest_candidate_too():
    """The torch stages (``backend="torch"``) choose among the same candidates: xarm7, 12 targets (seed 4), the mean
    distance to the middle well below that of the plain answer moved along its own stretch (main: 1.4 x the nearest
    of solve_all on the compiled backend, the torch stages alike), every answer reached by FK."""
    robot = nik.load_robot("xarm7")
    g = torch.Generator().manual_seed(4)
    T = robot.fk(robot.sample(12, generator=g, dtype=torch.float64))
    solver = nik.IKSolver(robot, backend="torch")
    mid = rest_target(robot, "mid", 1)[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = solver.solve(T)
        res = solver.solve(T, q_rest="mid")
        nearest = np.array([np.linalg.norm(nik.IKSolver(robot).solve_all(T[i : i + 1]).numpy() - mid, axis=1).min()
                            for i in range(T.shape[0])])  # fmt: skip
    assert torch.equal(res.success, plain.success) and bool(res.success.all())
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    assert float(pos.max()) <= DEFAULT_TOL_POS and float(rot.max()) <= DEFAULT_TOL_ROT
    dist = np.linalg.norm(res.q.numpy() - mid, axis=1)
    assert dist.mean() <= 1.15 * nearest.mean(), (dist.mean(), nearest.mean())
