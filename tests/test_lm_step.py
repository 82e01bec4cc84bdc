"""nik.kernels.lm_step: the one compiled LM step (rows, extra weighted rows, a prior) against dense numpy solves, the
step cap, and the accept/damping rule."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from nik.kernels.chain import LOWER, UPPER  # noqa: E402
from nik.kernels.lm_step import _cap, _dense_step, _judge, _stalled  # noqa: E402

N = 7


def _joints(n=N, lo=-3.0, hi=3.0):
    joints = np.zeros((n, 5))
    joints[:, LOWER], joints[:, UPPER] = lo, hi
    return joints


def _rows(seed, m, n=N):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(m, n)), rng.normal(size=m)


def test_the_step_of_pose_rows_is_the_damped_normal_equations_solved_by_numpy():
    J, e = _rows(0, 6)
    q, lam, eps = np.zeros(N), 1e-2, 1e-9
    A, g, dq = np.empty((N, N)), np.empty(N), np.empty(N)
    assert _dense_step(J, e, None, None, q, _joints(), lam, eps, 10.0, (A, g, dq))
    M = J.T @ J
    ref = np.linalg.solve(M + lam * np.diag(np.diag(M) + eps) + eps * np.eye(N), J.T @ e)
    assert np.allclose(dq, ref, rtol=1e-9, atol=1e-12)


def test_extra_rows_enter_as_stacked_weighted_rows_and_only_where_they_push():
    J, e = _rows(1, 6)
    Jr, r = _rows(2, 9)
    r[[1, 4, 5]] = 0.0  # rows that do not push: their Jacobian must not count
    w2, q, lam, eps = 4.0, np.zeros(N), 1e-3, 1e-9
    A, g, dq = np.empty((N, N)), np.empty(N), np.empty(N)
    assert _dense_step(J, e, (Jr, r, w2), None, q, _joints(), lam, eps, 10.0, (A, g, dq))
    live = r != 0.0
    Js = np.vstack([J, math.sqrt(w2) * Jr[live]])
    es = np.concatenate([e, -math.sqrt(w2) * r[live]])
    M = Js.T @ Js
    ref = np.linalg.solve(M + lam * np.diag(np.diag(M) + eps) + eps * np.eye(N), Js.T @ es)
    assert np.allclose(dq, ref, rtol=1e-9, atol=1e-12)


def test_the_prior_step_is_the_null_space_step_of_the_push_through_identity():
    """rest_posture's step ``z + J^T (J J^T + d I)^-1 (e - J z)`` is the step with the prior ``q + z``, weight d."""
    J, e = _rows(3, 6)
    rng = np.random.default_rng(4)
    q, z, d = rng.uniform(-1, 1, N), rng.normal(size=N), 1e-3
    A, g, dq = np.empty((N, N)), np.empty(N), np.empty(N)
    assert _dense_step(J, e, None, (q + z, d), q, _joints(), 0.0, 0.0, math.inf, (A, g, dq))
    ref = z + J.T @ np.linalg.solve(J @ J.T + d * np.eye(6), e - J @ z)
    assert np.allclose(dq, ref, rtol=1e-8, atol=1e-10)


def test_the_step_cap_scales_the_whole_step_and_refuses_a_non_finite_one():
    dq = np.array([0.1, -2.0, 1.0])
    assert _cap(dq, 0.5)
    assert np.allclose(dq, [0.025, -0.5, 0.25])
    small = np.array([0.1, -0.2])
    assert _cap(small, 0.5) and np.array_equal(small, [0.1, -0.2])
    assert not _cap(np.array([0.1, math.nan]), 0.5)


def test_a_lower_cost_is_kept_and_shrinks_lambda_a_higher_one_grows_it_within_its_range():
    assert _judge(True, 2.0, 1.0, False, 1e-3, 0.3, 5.0, 1e-9, 1e6) == (True, pytest.approx(3e-4))
    assert _judge(True, 2.0, 3.0, False, 1e-3, 0.3, 5.0, 1e-9, 1e6) == (False, pytest.approx(5e-3))
    assert _judge(True, 2.0, 3.0, True, 1e-3, 0.3, 5.0, 1e-9, 1e6)[0]  # done: kept though higher
    assert _judge(False, 2.0, 1.0, True, 1e-3, 0.3, 5.0, 1e-9, 1e6)[0] is False  # a failed step is never kept
    assert _judge(True, 2.0, 1.0, False, 1e-9, 0.3, 5.0, 1e-9, 1e6)[1] == 1e-9
    assert _judge(False, 2.0, 1.0, False, 1e6, 0.3, 5.0, 1e-9, 1e6)[1] == 1e6
    assert _stalled(True, 1.0, 0.5, 3, 1e-3) == 0
    assert _stalled(True, 1.0, 1.0 - 1e-6, 3, 1e-3) == 4
    assert _stalled(False, 1.0, 0.5, 3, 1e-3) == 4
