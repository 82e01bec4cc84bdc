"""nik.kernels.lm_loop: the one compiled LM loop, with a problem and a configuration given as arguments (a linear
least-squares problem against numpy's lstsq; the stop and accept rules), and the shape of the compiled solvers (one
loop, short signatures) read from their source."""

import ast
import math
from collections import namedtuple
from pathlib import Path

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from nik.kernels.chain import LOWER, UPPER  # noqa: E402
from nik.kernels.lm_loop import ACCEPT_ANY, ACCEPT_LOWER, _lm_loop, _loop_cfg, problem_kind  # noqa: E402
from nik.kernels.lm_step import _dense_step  # noqa: E402

KERNELS = Path(__file__).resolve().parents[1] / "nik" / "kernels"
Lin = namedtuple("Lin", ["A", "b", "joints", "work"])
State = namedtuple("State", ["q", "J", "e"])


@numba.njit
def _measure(prob, s, bar):
    """|b - A q|^2, the rows J = A and e = b - A q; never done (every row counts: ``bar`` unused)."""
    m, n = prob.A.shape
    E = 0.0
    for k in range(m):
        v = prob.b[k]
        for i in range(n):
            v -= prob.A[k, i] * s.q[i]
            s.J[k, i] = prob.A[k, i]
        s.e[k] = v
        E += v * v
    return E, False


@numba.njit
def _propose(prob, s, lam, c):
    good = _dense_step(s.J, s.e, None, None, s.q, prob.joints, lam, 1e-12, 1e3, prob.work)
    for i in range(s.q.shape[0]):
        c.q[i] = s.q[i] + prob.work[2][i]
    return good, math.inf


problem_kind(Lin, _measure, _propose)


@numba.njit
def _run(A, b, joints, q0, limit, lam0, accept):
    m, n = A.shape
    prob = Lin(A, b, joints, (np.empty((n, n)), np.empty(n), np.empty(n)))
    cur, other = State(q0.copy(), np.empty((m, n)), np.empty(m)), State(np.empty(n), np.empty((m, n)), np.empty(m))
    cfg = _loop_cfg(limit, lam0, (0.3, 5.0, 0.0, 1e6), math.inf, (1e-3, 4), (-math.inf, 0.0), accept)
    E, done = _measure(prob, cur, math.inf)
    it, E, done, cur, other = _lm_loop(prob, cfg, cur, other, E, done)
    return it, E, cur.q.copy()


def _problem(seed, m=9, n=4):
    rng = np.random.default_rng(seed)
    joints = np.zeros((n, 5))
    joints[:, LOWER], joints[:, UPPER] = -1e6, 1e6
    return rng.normal(size=(m, n)), rng.normal(size=m), joints


def test_the_loop_solves_a_given_least_squares_problem_as_numpy_does():
    A, b, joints = _problem(0)
    it, E, q = _run(A, b, joints, np.zeros(4), 50, 1e-3, ACCEPT_LOWER)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    np.testing.assert_allclose(q, x, atol=1e-8)
    assert E == pytest.approx(float(np.sum((b - A @ x) ** 2)), rel=1e-10)
    assert 0 < it < 50  # stopped by the stall rule: 4 kept steps in a row that gain less than 0.1 %


def test_one_undamped_step_with_every_step_kept_is_the_gauss_newton_step():
    A, b, joints = _problem(1)
    q0 = np.full(4, 0.3)
    it, _, q = _run(A, b, joints, q0, 1, 0.0, ACCEPT_ANY)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)  # a linear problem: one Gauss-Newton step lands on the minimum
    assert it == 1
    np.testing.assert_allclose(q, x, atol=1e-9)


def test_no_iteration_leaves_the_start_as_it_is():
    A, b, joints = _problem(2)
    q0 = np.full(4, -0.2)
    it, E, q = _run(A, b, joints, q0, 0, 1e-3, ACCEPT_LOWER)
    assert it == 0
    np.testing.assert_array_equal(q, q0)
    assert E == pytest.approx(float(np.sum((b - A @ q0) ** 2)))


def _solve_loops(path):
    """Names of the functions of ``path`` with a for/while whose body calls a linear solve of normal equations."""
    solves = {"_dense_step", "_held_step", "_cholesky_solve", "band_solve", "band_cholesky"}
    found = []
    for fn in ast.walk(ast.parse(path.read_text())):
        if isinstance(fn, ast.FunctionDef):
            for loop in (n for n in ast.walk(fn) if isinstance(n, (ast.For, ast.While))):
                called = {c.func.id for c in ast.walk(loop) if isinstance(c, ast.Call) and isinstance(c.func, ast.Name)}
                if called & solves and fn.name != "_held_step":  # the step's own second pass (a held joint)
                    found.append(fn.name)
                    break
    return found


def test_the_pose_the_walk_the_posture_the_collision_and_the_path_solvers_have_no_loop_of_their_own():
    for name in ("lm.py", "driver.py", "trajopt.py", "lm_step.py", "lm_loop.py", "collision_lm.py"):
        assert _solve_loops(KERNELS / name) == [], name


def test_the_solver_kernels_take_at_most_twelve_parameters():
    for name in ("lm.py", "driver.py", "trajopt.py", "lm_step.py", "lm_loop.py", "manipulability.py"):
        for fn in ast.walk(ast.parse((KERNELS / name).read_text())):
            if isinstance(fn, ast.FunctionDef):
                a = fn.args
                count = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
                assert count <= 12, f"{name}: {fn.name} takes {count}"
