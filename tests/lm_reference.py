"""A second implementation of nik's Levenberg-Marquardt for one pose, in plain float64 numpy: a test reference.

Not part of the package (no solver runs it): the same algorithm as the compiled kernel :mod:`nik.kernels.lm` and
the batched torch :mod:`nik.lm.batched` (same error, Marquardt-scaled damping, active set at the limits, stall test,
restarts for a failing target), written independently, so that tests and ``benchmarks/latency_kernels.py`` can
compare the kernels with it. (It was ``nik.lm.single``, the one-pose path of :meth:`nik.IKSolver.solve` before the
kernels.)

The FK + Jacobian: joint ``i`` contributes ``M_i = Rz(q_i + o_i) G_i = c P_i + s Q_i + R_i`` with
constant ``P_i, Q_i, R_i`` (rows of ``G_i`` mixed by the rotation), so all ``M_i`` come from three
broadcast operations and the chain is ``n`` small matrix products (a prismatic joint contributes
``Tz(q_i + o_i) G_i = G_i + d Z_i`` with ``Z_i`` the third row of ``G_i`` moved to the translation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["SingleLM", "lm_solve_one"]


@dataclass
class SingleLM:
    """Precomputed constants of one robot for :func:`lm_solve_one` (build with :meth:`from_robot`)."""

    P: np.ndarray  # (n, 4, 4)
    Q: np.ndarray  # (n, 4, 4)
    R: np.ndarray  # (n, 4, 4)
    G0: np.ndarray  # (4, 4)
    offsets: np.ndarray  # (n,)
    lo: np.ndarray  # (n,)
    hi: np.ndarray  # (n,)
    wrap: np.ndarray  # (n,) bool
    prismatic: np.ndarray  # (n,) bool

    @property
    def any_prismatic(self) -> bool:
        return bool(self._any_pm)

    def __post_init__(self):
        self._any_pm = bool(self.prismatic.any())
        self._any_wrap = bool(self.wrap.any())

    @classmethod
    def from_robot(cls, robot) -> SingleLM:
        from nik.robots.joints import wrap_mask

        G = robot.G.numpy()
        n = robot.dof
        prismatic = getattr(robot, "prismatic", None)
        pm = np.zeros(n, dtype=bool) if prismatic is None else prismatic.numpy().astype(bool)
        P = np.zeros((n, 4, 4))
        Q = np.zeros((n, 4, 4))
        R = np.zeros((n, 4, 4))
        for i in range(n):
            Gi = G[i + 1]
            if pm[i]:  # Tz(d) G = G + d * e_z e_w^T G: the translation gains d times G's last row's z part
                R[i] = Gi
                P[i, 2] = Gi[3]  # d * row 3 added to row 2
            else:
                P[i, 0], P[i, 1] = Gi[0], Gi[1]
                Q[i, 0], Q[i, 1] = -Gi[1], Gi[0]
                R[i, 2], R[i, 3] = Gi[2], Gi[3]
        wrap = wrap_mask(robot.limits).numpy() & ~pm
        return cls(P, Q, R, G[0].copy(), robot.offsets.numpy().copy(), *robot.limits.numpy().T.copy(), wrap, pm)

    def fk_jacobian(self, q: np.ndarray):
        """``q: (n,)`` -> ``T (4, 4)`` and ``J (6, n)`` (linear rows, then angular)."""
        th = q + self.offsets
        c, s = np.cos(th), np.sin(th)
        pm = self.prismatic
        any_pm = self.any_prismatic
        if any_pm:
            c = np.where(pm, th, c)  # the prismatic P_i carries the displacement, Q_i is zero
            s = np.where(pm, 0.0, s)
        M = c[:, None, None] * self.P + s[:, None, None] * self.Q + self.R
        T = self.G0
        n = q.shape[0]
        F = np.empty((n, 4, 4))  # frame before each joint
        for i in range(n):
            F[i] = T
            T = T @ M[i]
        z = F[:, :3, 2].T  # (3, n)
        r = T[:3, 3, None] - F[:, :3, 3].T
        J = np.empty((6, q.shape[0]))
        J[0] = z[1] * r[2] - z[2] * r[1]  # z x r, written out (np.cross costs more than the rest)
        J[1] = z[2] * r[0] - z[0] * r[2]
        J[2] = z[0] * r[1] - z[1] * r[0]
        J[3:] = z
        if any_pm:
            J[:3] = np.where(pm, z, J[:3])
            J[3:] = np.where(pm, 0.0, z)
        return T, J

    def fk_many(self, q: np.ndarray) -> np.ndarray:
        """``q: (K, n)`` -> ``T: (K, 4, 4)``."""
        th = q + self.offsets
        c = np.where(self.prismatic, th, np.cos(th))
        s = np.where(self.prismatic, 0.0, np.sin(th))
        M = c[..., None, None] * self.P + s[..., None, None] * self.Q + self.R
        T = np.broadcast_to(self.G0, (q.shape[0], 4, 4))
        for i in range(q.shape[1]):
            T = T @ M[:, i]
        return T

    def bounds(self, q: np.ndarray) -> np.ndarray:
        if self._any_wrap:
            two_pi = 2 * math.pi
            up = np.maximum(np.ceil((self.lo - q) / two_pi), 0)
            down = np.maximum(np.ceil((q - self.hi) / two_pi), 0)
            q = np.where(self.wrap, q + two_pi * (up - down), q)
        return np.minimum(np.maximum(q, self.lo), self.hi)


def _residual(Tt: np.ndarray, T: np.ndarray, rw: float):
    dp = Tt[:3, 3] - T[:3, 3]
    M = Tt[:3, :3] @ T[:3, :3].T
    s = 0.5 * np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    c = 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)
    sn = math.sqrt(float(s @ s))
    theta = math.atan2(sn, c)
    w = s * (rw * (theta / sn if sn > 1e-12 else 1.0))
    pos = math.sqrt(float(dp @ dp))
    return np.concatenate([dp, w]), pos * pos + (rw * theta) ** 2, pos, theta


def lm_solve_one(
    model: SingleLM,
    T_target: np.ndarray,
    q0: np.ndarray,
    *,
    cfg,
    tol_pos: float,
    tol_rot: float,
    first_iters: int,
    restarts: int,
    sample,
) -> tuple[np.ndarray, int]:
    """LM for one target ``T_target: (4, 4)`` from ``q0: (n,)``; ``sample() -> (n,)`` draws a fresh start
    (``restarts`` at most, each run ``cfg.iters`` iterations at most). Returns ``(q, iterations)``."""
    rw = cfg.rot_weight
    row_w = np.array([1.0, 1.0, 1.0, rw, rw, rw])[:, None]
    n = q0.shape[0]
    diag = np.diag_indices(n)
    best_q, best_E = None, math.inf
    q = model.bounds(q0)
    limit = first_iters
    total = 0
    for start in range(restarts + 1):
        if start:
            q = model.bounds(sample())
            limit = cfg.iters
        T, J = model.fk_jacobian(q)
        J = J * row_w
        e, E, pos, rot = _residual(T_target, T, rw)
        lam, stall = cfg.lambda0, 0
        for _ in range(limit):
            if pos <= tol_pos and rot <= tol_rot:
                return q, total
            JT = J.T
            at_lo, at_hi = q <= model.lo, q >= model.hi
            held = np.zeros(q.shape[0], dtype=bool)
            try:  # (one LAPACK call: two triangular solves after a Cholesky cost more in numpy at n <= 7)
                for _pass in range(2):  # active set: held where g pushes out of a limit, then where the step does
                    A, g = JT @ J, JT @ e
                    free = ~(held | (at_lo & (g < 0)) | (at_hi & (g > 0)))
                    A = A * np.outer(free, free) + np.diag(~free * 1.0)
                    g = g * free
                    A[diag] += lam * (A[diag] + cfg.eps) + cfg.eps
                    dq = np.linalg.solve(A, g)
                    out = (at_lo & (dq < 0)) | (at_hi & (dq > 0))
                    if not out.any():
                        break
                    held |= out
                big = float(np.abs(dq).max())
                if big > cfg.max_step:
                    dq = dq * (cfg.max_step / big)
                good = bool(np.isfinite(dq).all())
            except np.linalg.LinAlgError:
                good = False
            total += 1
            if good:
                qc = model.bounds(q + dq)
                Tc, Jc = model.fk_jacobian(qc)
                ec, Ec, posc, rotc = _residual(T_target, Tc, rw)
            if good and Ec < E:
                stall = 0 if E - Ec >= cfg.stall_rel * E else stall + 1
                q, J, e, E, pos, rot = qc, Jc * row_w, ec, Ec, posc, rotc
                lam = max(lam * cfg.lambda_down, cfg.lambda_min)
            else:
                stall += 1
                lam = min(lam * cfg.lambda_up, cfg.lambda_max)
            if stall >= cfg.stall_iters:
                break
        if pos <= tol_pos and rot <= tol_rot:
            return q, total
        if E < best_E:
            best_q, best_E = q, E
    return best_q, total


def best_of(model: SingleLM, T_target: np.ndarray, cand: np.ndarray, rw: float) -> np.ndarray:
    """The row of ``cand: (K, n)`` whose pose is nearest ``T_target: (4, 4)`` (|dp|^2 + (rw angle)^2)."""
    T = model.fk_many(cand)
    dp = T[:, :3, 3] - T_target[:3, 3]
    cos = 0.5 * (np.einsum("kij,ij->k", T[:, :3, :3], T_target[:3, :3]) - 1.0)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    return cand[np.argmin((dp * dp).sum(-1) + (rw * angle) ** 2)]
