"""One path call's state and the measures of an answer: :class:`_Run` (plan, model, waypoints, tolerant goal,
posture) with its LM chains along the path (:mod:`nik.paths.kernels`), LM for some waypoints, pose errors by FK
(metres, radians), the final check, and a loop's closure gap."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from nik.paths.settings import PATH_PULL_CAP, PATH_RESTARTS


@dataclass
class _Run:
    """One call: its plan (:mod:`nik.ik.plan`), the robot's model, the waypoints ``T (N, 4, 4)``, ``q0 (dof,)`` or
    None and ``reachable (N,)``."""

    plan: Any
    model: Any
    T: np.ndarray
    q0: np.ndarray | None
    reachable: np.ndarray
    half: np.ndarray | None = None  # (N, 6) a tolerant goal's half-widths (nik.ik.bounds), None: the tolerances
    modes: np.ndarray | None = None  # (N,) its rotation modes
    rest: np.ndarray | None = None  # (dof,) q_rest: the posture the chains drift towards (else the middle)

    @property
    def tol_pos(self) -> float:
        return self.plan.tol_pos

    @property
    def tol_rot(self) -> float:
        return self.plan.tol_rot

    @property
    def seed(self) -> int:
        return self.plan.seed

    @property
    def refine(self) -> bool:
        """False with ``refine="none"``: the closed form's branches as they are, no LM."""
        return self.plan.refine != "none"

    @property
    def restarts(self) -> int:
        """Uniform restarts a waypoint the chain does not reach may draw: :data:`PATH_RESTARTS` with
        ``fallback="multistart"``, else none."""
        return PATH_RESTARTS if self.plan.fallback == "multistart" else 0

    def chains(self, T, starts, reachable, *, pull: float, restarts: int, seed: int | None = None, offset: int = 0):
        """:func:`nik.paths.kernels.path_chains` along ``T`` from ``starts: (K, dof)``: ``q (K, N, dof)``,
        iterations ``(K, N)``, ok ``(K, N)`` (LM options: the model's LM with this call's tolerances; with a tolerant
        goal, :func:`~nik.paths.kernels.path_chains_bounded` towards the bounds of waypoints ``offset ...`` of
        the path, which ``T`` are): :meth:`tracks` drifting towards ``q_rest``, else the middle of the ranges."""
        from nik.kernels.chain import LOWER, UPPER

        joints, K = self.model.lm.joints, starts.shape[0]
        rest = self.rest if self.rest is not None else 0.5 * (joints[:, LOWER] + joints[:, UPPER])
        pulls, caps = np.full(K, pull), np.full(K, PATH_PULL_CAP if pull > 0 else 0.0)
        return self.tracks(T, starts, np.repeat(rest[None], K, axis=0), pulls, caps, reachable, restarts, offset,
                           seed=seed)  # fmt: skip

    def _goal(self, offset: int, N: int, backward: bool) -> tuple[np.ndarray, np.ndarray]:
        """``(half (N, 6), modes (N,))`` of the tolerant goal at waypoints ``offset ... offset + N`` (reversed on a
        backward chain)."""
        at = slice(offset, offset + N)
        half, modes = self.half[at], self.modes[at]
        if backward:
            half, modes = half[::-1], modes[::-1]
        return np.ascontiguousarray(half), np.ascontiguousarray(modes)

    def tracks(
        self, T, starts, targets, pull, cap, reachable, restarts: int, offset: int = 0, backward: bool = False,
        seed: int | None = None,
    ):  # fmt: skip
        """:func:`nik.paths.kernels.path_chains_toward` along ``T`` from ``starts: (K, dof)``, chain ``c`` drifting
        towards ``targets[c]`` (``pull, cap: (K,)``): ``q (K, N, dof)``, iterations ``(K, N)``, ok ``(K, N)``; with a
        tolerant goal, :func:`~nik.paths.kernels.path_chains_bounded_toward` towards the bounds of waypoints
        ``offset ...`` (``backward``: ``T`` runs from the last of them to the first)."""
        from nik.kernels.lm import seed_state
        from nik.paths.kernels import path_chains_bounded_toward, path_chains_toward

        lm = self.model.lm
        K, n, N = starts.shape[0], starts.shape[1], T.shape[0]
        opts, iopts = lm.options(self.tol_pos, self.tol_rot)
        q = np.empty((K, N, n))
        its, ok = np.empty((K, N), dtype=np.int64), np.empty((K, N), dtype=bool)
        pos, rot = np.empty((K, N)), np.empty((K, N))
        budget = np.where(reachable, restarts, 0).astype(np.int64)
        c = np.ascontiguousarray
        head = (lm.G, lm.joints, c(T), c(starts, dtype=np.float64))
        drift = (c(targets, dtype=np.float64), c(pull, dtype=np.float64), c(cap, dtype=np.float64))
        run = (opts, iopts, budget, seed_state(self.seed if seed is None else seed))
        out = (q, its, ok, pos, rot)
        if self.half is None:
            path_chains_toward(*head, drift, run, out)
        else:
            path_chains_bounded_toward(*head, drift, self._goal(offset, N, backward), run, out)
        return q, its, ok


def _errors(model, Tn: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and rotation (rad) errors of ``q: (N, dof)`` against ``Tn: (N, 4, 4)`` (compiled FK)."""
    from nik.kernels.lm import pose_errors

    pos, rot = np.empty(q.shape[0]), np.empty(q.shape[0])
    pose_errors(model.G, model.joints, Tn, np.ascontiguousarray(q), pos, rot)
    return pos, rot


def _final_check(run: _Run, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(pos (N,), rot (N,), within (N,))`` of ``q`` by FK: with the tolerances, the position error (m), the
    geodesic rotation error (rad) and both within them; with a tolerant goal, the error in each waypoint's tool frame
    (:func:`nik.kernels.lm.bounded_errors`): ``pos`` its position part's norm, ``rot`` its rotation part's norm (with
    a free tool axis, the swing of that axis: the rotation about it does not count), ``within`` every axis inside
    its half-width."""
    if run.half is None:
        pos, rot = _errors(run.model, run.T, q)
        return pos, rot, (pos <= run.tol_pos) & (rot <= run.tol_rot)
    from nik.kernels.lm import bounded_errors

    d = np.empty((q.shape[0], 6))
    bounded_errors(run.model.G, run.model.joints, run.T, np.ascontiguousarray(q), run.modes, d)
    within = (np.abs(d) <= run.half).all(axis=1)
    return np.linalg.norm(d[:, :3], axis=1), np.linalg.norm(d[:, 3:], axis=1), within


def _lm_batch(run: _Run, q0: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LM (no restarts) for waypoints ``rows`` from ``q0: (M, dof)``, towards the call's tolerances or its tolerant
    goal: ``(q (M, dof), iterations (M,), converged (M,))``."""
    lm, T = run.model.lm, np.ascontiguousarray(run.T[rows])
    if run.half is None:
        res = lm.solve(T, q0, tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, restarts=False)
        return res.q, res.iterations, res.converged
    from nik.kernels.lm import lm_solve_bounded, seed_state

    M, n = q0.shape
    opts, iopts = lm.options(run.tol_pos, run.tol_rot)
    q, its, ok = np.empty((M, n)), np.empty(M, dtype=np.int64), np.empty(M, dtype=bool)
    pos, rot = np.empty(M), np.empty(M)
    lm_solve_bounded(
        lm.G, lm.joints, T, np.ascontiguousarray(q0, dtype=np.float64),
        (np.ascontiguousarray(run.half[rows]), np.ascontiguousarray(run.modes[rows])), opts, iopts,
        np.zeros(M, dtype=np.int64), seed_state(run.seed), (q, its, ok, pos, rot),
    )  # fmt: skip
    return q, its, ok


def _closure(q: np.ndarray, wraps: np.ndarray) -> float:
    """The largest joint difference between the last row of ``q: (N, dof)`` and its first (radians; metres on
    prismatic joints), modulo whole turns on the joints that wrap (their range exceeds a full turn)."""
    d = np.abs(q[-1] - q[0])
    d[wraps] = np.abs(np.remainder(d[wraps] + math.pi, 2 * math.pi) - math.pi)
    return float(d.max())
