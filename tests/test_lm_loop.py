"""The one torch LM loop (nik.lm.loop.lm_loop): a pose, a batch and a path problem, its configuration, and that it is
the only torch loop that solves normal equations."""

from __future__ import annotations

import ast
from dataclasses import replace
from pathlib import Path

import pytest
import torch

import nik
from nik.lm import Box, LMCfg, lm_loop
from nik.lm.batched import chain_of, pose_evaluator
from nik.lm.problem import PathProblem, Problem, lm_minimise


@pytest.fixture(scope="module")
def ur5():
    return nik.load_robot("ur5")


def _configs(robot, n: int, seed: int) -> torch.Tensor:
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


def _near(robot, q: torch.Tensor, seed: int, scale: float = 0.05) -> torch.Tensor:
    noise = torch.randn(q.shape, generator=torch.Generator().manual_seed(seed), dtype=q.dtype) * scale
    return robot.clamp(q + noise)


def _solve_poses(robot, T, q0, cfg=None):
    cfg = cfg or LMCfg()
    chain = chain_of(robot, T)
    evaluate = pose_evaluator(T, chain, cfg, (1e-6, 1e-5))
    return lm_loop(evaluate, q0[:, None], Box(chain.lo, chain.hi, chain.wrap), cfg)


@pytest.mark.parametrize("B", [1, 24])
def test_the_loop_solves_one_pose_and_a_batch_checked_by_fk(ur5, B):
    """One pose and a batch of 24 (ur5, seed 1) from starts 0.05 rad off a solution: every target converges, and FK of
    the answer meets the target within the tolerances."""
    q_true = _configs(ur5, B, 1)
    T = ur5.fk(q_true)
    run = _solve_poses(ur5, T, _near(ur5, q_true, 2))
    assert run.q.shape == (B, ur5.dof) and run.converged.all()
    pos, rot = nik.pose_error(T, ur5.fk(run.q))
    assert (pos <= 1e-6).all() and (rot <= 1e-5).all()
    assert ur5.within_limits(run.q).all()


def test_the_linear_solvers_give_the_same_answer(ur5):
    """``linear_solver="lu"`` and ``"cholesky"`` solve the same normal equations: the same answers to 1e-9."""
    q_true = _configs(ur5, 8, 3)
    T = ur5.fk(q_true)
    q0 = _near(ur5, q_true, 4)
    a = _solve_poses(ur5, T, q0, LMCfg(linear_solver="cholesky"))
    b = _solve_poses(ur5, T, q0, LMCfg(linear_solver="lu"))
    assert a.converged.all() and b.converged.all()
    assert torch.allclose(a.q, b.q, atol=1e-9)


def test_a_path_problem_without_an_active_path_term_equals_the_waypoints_solved_one_by_one(ur5):
    """A path of 6 waypoints (ur5, seed 5) as one problem (its variables all the waypoints, a step cap far above every
    step: a path term that is never active) lands on the answers of the same terms solved waypoint by waypoint (6
    joints: each solution near the start is isolated), to 1e-7 rad, every pose met by FK."""
    q_true = _configs(ur5, 6, 5)
    T = ur5.fk(q_true)
    q0 = _near(ur5, q_true, 6, 0.03)
    limits = nik.costs.limits(ur5)
    N, n = q0.shape
    cfg = replace(LMCfg(), iters=50)
    one = Problem([nik.costs.pose(ur5, T)], limits)
    x1, _ = lm_minimise(one, q0, torch.ones(N, dtype=torch.bool), cfg=cfg)
    terms = [nik.costs.pose(ur5, T), nik.costs.step_cap(None, max_step=100.0)]
    path = PathProblem(terms, limits, N, n)
    xp, its = lm_minimise(path, q0.reshape(1, N * n), torch.ones(1, dtype=torch.bool), cfg=cfg)
    qp = xp.reshape(N, n)
    assert its.shape == (1,) and int(its[0]) > 0
    pos, rot = nik.pose_error(T, ur5.fk(qp))
    assert (pos <= 1e-9).all() and (rot <= 1e-8).all()
    assert torch.allclose(qp, x1, atol=1e-7)


def test_a_prior_row_pulls_towards_its_joints(ur5):
    """With prior rows only (no pose), the loop lands on the prior's joints (a linear problem: one step)."""
    from nik.lm.loop import Eval, with_prior

    q0, qp = _configs(ur5, 4, 7), _configs(ur5, 4, 8)

    def nothing(q, rows):
        z = q.new_zeros(*q.shape[:-1], 0)
        return Eval(z, q.new_zeros(*q.shape[:-1], 0, q.shape[-1]), z.sum(-1), torch.zeros(q.shape[:-1], dtype=bool))

    cfg = LMCfg(damping="fixed", accept="always", max_step=10.0, iters=2)
    inf = torch.full((ur5.dof,), float("inf"), dtype=torch.float64)
    run = lm_loop(with_prior(nothing, qp, 1.0), q0[:, None], Box(-inf, inf, torch.zeros(ur5.dof, dtype=bool)), cfg)
    assert torch.allclose(run.q, qp, atol=1e-6)


@pytest.mark.parametrize("field, value", [("damping", "tr"), ("linear_solver", "qr"), ("accept", "maybe")])
def test_a_bad_setting_is_a_one_line_error(field, value):
    with pytest.raises(ValueError, match=f"LMCfg.{field}") as err:
        LMCfg(**{field: value})
    assert "\n" not in str(err.value)


def test_the_one_loop_is_the_only_torch_loop_that_solves_normal_equations():
    """Every torch solver (the pose LM, problems of terms, the near prior, the rest posture, the closed form's polish)
    runs nik.lm.loop.lm_loop: outside the compiled kernels, no other for/while loop calls a linear solve."""
    solves = {"linalg.solve", "solve_ex", "cholesky", "cholesky_ex", "cholesky_solve", "lstsq", "_held_step", "_step"}

    def called(node):
        for c in ast.walk(node):
            if isinstance(c, ast.Call):
                f = c.func
                if isinstance(f, ast.Attribute):
                    base = f.value.attr if isinstance(f.value, ast.Attribute) else getattr(f.value, "id", "")
                    yield f"{base}.{f.attr}" if f.attr == "solve" else f.attr
                else:
                    yield getattr(f, "id", "")

    root = Path(nik.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if "kernels" in path.parts:  # the compiled solver (numba) is the other one
            continue
        for fn in ast.walk(ast.parse(path.read_text())):
            if not isinstance(fn, ast.FunctionDef) or fn.name in ("canonical_dh", "path_dp"):
                continue  # (a DH fit and the path's dynamic programme are no solver loops)
            if any(isinstance(loop, ast.For | ast.While) and solves & set(called(loop)) for loop in ast.walk(fn)):
                found.append(f"{path.relative_to(root)}:{fn.name}")
    assert found == ["lm/loop.py:lm_loop"]
