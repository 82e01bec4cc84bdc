"""The closed form of PUMA-like arms (all 8 solutions), compiled, and the choice among them.

The same solution as ``nik.analytic.puma560`` with its ``wrist="matrix"`` variant, for one target at a time:
the wrist centre of ``G_0^-1 T G_6^-1`` gives two shoulder angles ``theta_1``, two elbows ``phi_3`` and
``theta_2`` from the planar 2R problem; the remaining rotation ``R_36`` is a ZYZ Euler rotation with two wrist
flips. Solution ``k`` (0..7): shoulder ``k >> 2``, elbow ``(k >> 1) & 1``, wrist flip ``k & 1``. Every angle
is moved by whole turns into its limits where possible; a solution is valid when it exists (no square root of
a negative number), lies inside the limits and reaches the pose by FK (the check of ``puma560_ik``).

The geometry comes in as plain arrays (:func:`puma_constants` from the canonical DH numbers ``alpha, a, d``
of rows 1..5; ``base``, ``tool`` and ``offsets`` as ``nik.analytic.PumaGeometry`` holds them), so this room
imports nothing from nik. :func:`puma_pick` then chooses one solution per target as ``nik.ik.guesses``
does: the valid one nearest ``q_near`` (after moving angles by whole turns, within the limits), or the one
farthest inside the joint ranges; with none valid, the clamped solution nearest the target.
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import _chain
from nik.kernels.lm import _residual

__all__ = ["puma_constants", "puma_pick", "puma_solutions"]

# entries of the constants array
S1, A1, D1, A2, Z2, C2, U, W, L2, PSI, CA1, SA1, CA3, SA3, CE, SIG4, TOL1, TOL3 = range(18)
_TWO_PI = 2.0 * math.pi


def puma_constants(alpha, a, d) -> np.ndarray:
    """``(18,)`` float64 constants of the closed form from the canonical DH rows 1..5 (``alpha, a, d: (5,)``,
    radians and metres), as ``nik.analytic.puma560`` derives them for its matrix wrist."""
    al, a, d = (np.asarray(v, dtype=np.float64) for v in (alpha, a, d))
    c2 = 1.0 if math.cos(al[1]) > 0 else -1.0
    u = float(a[2])
    w = c2 * float(-math.sin(al[2]) * d[3])
    h = c2 * float(d[2] + math.cos(al[2]) * d[3])
    al3 = float(al[1] + al[2])
    sig4 = 1.0 if math.sin(al[3]) > 0 else -1.0
    sig5 = 1.0 if math.sin(al[4]) > 0 else -1.0
    scale = float(np.abs(a).sum() + np.abs(d).sum())
    k = np.empty(18)
    k[S1] = 1.0 if math.sin(al[0]) > 0 else -1.0
    k[A1], k[D1], k[A2], k[Z2], k[C2] = a[0], d[0], a[1], h + d[1], c2
    k[U], k[W], k[L2], k[PSI] = u, w, u * u + w * w, math.atan2(w, u)
    k[CA1], k[SA1], k[CA3], k[SA3] = math.cos(al[0]), math.sin(al[0]), math.cos(al3), math.sin(al3)
    k[CE] = -1.0 if sig4 == sig5 else 1.0
    k[SIG4] = sig4
    k[TOL1] = k[TOL3] = 1e-12 * scale * scale
    return k


@kernel
def _rot_rows_z(M, c, s):
    """``M <- Rz(theta)^T M`` (3x3, in place) for ``c, s`` the cosine and sine of theta."""
    for j in range(3):
        u, v = M[0, j], M[1, j]
        M[0, j] = c * u + s * v
        M[1, j] = -s * u + c * v


@kernel
def _rot_rows_x(M, c, s):
    """``M <- Rx(alpha)^T M`` (3x3, in place)."""
    for j in range(3):
        u, v = M[1, j], M[2, j]
        M[1, j] = c * u + s * v
        M[2, j] = -s * u + c * v


@kernel
def _into_limits(x, lo, hi):
    """An angle moved by whole turns into ``[lo, hi]`` where possible (``wrap_into_limits``)."""
    w = (x + math.pi) % _TWO_PI - math.pi
    if lo <= w <= hi:
        return w
    if lo <= w + _TWO_PI <= hi:
        return w + _TWO_PI
    if lo <= w - _TWO_PI <= hi:
        return w - _TWO_PI
    return w


@kernel
def puma_solutions(base, tool, offsets, k, G, joints, tol_pos, tol_rot, T, q, valid):
    """All 8 solutions ``q: (B, 8, 6)`` (radians, moved into the limits where possible) and ``valid: (B, 8)`` of
    the targets ``T: (B, 4, 4)``; ``G, joints``: the robot's model (limits and the FK check)."""
    R = np.empty((3, 3))
    M = np.empty((3, 3))
    p = np.empty(3)
    Tq = np.empty((3, 4))
    e = np.empty(6)
    theta = np.empty(6)
    for b in range(T.shape[0]):
        P = T[b]
        # W = G_0^-1 T G_6^-1: R = Rb^T R_T Rt^T, p = Rb^T (p_T - t_b) - R t_t
        for i in range(3):
            for j in range(3):
                v = 0.0
                for m in range(3):
                    for n in range(3):
                        v += base[m, i] * P[m, n] * tool[j, n]
                R[i, j] = v
        for i in range(3):
            v = 0.0
            for m in range(3):
                v += base[m, i] * (P[m, 3] - base[m, 3])
            p[i] = v - (R[i, 0] * tool[0, 3] + R[i, 1] * tool[1, 3] + R[i, 2] * tool[2, 3])
        px, py, pz = p[0], p[1], p[2]
        disc1 = px * px + py * py - k[Z2] * k[Z2]
        reach1 = disc1 >= -k[TOL1]
        for shoulder in range(2):
            sq1 = math.sqrt(max(disc1, 0.0)) * (1.0 if shoulder == 0 else -1.0)
            th1 = math.atan2(py, px) - math.atan2(-k[S1] * k[Z2], sq1)
            X2 = sq1 - k[A1]
            Y2 = k[S1] * (pz - k[D1])
            kk = (X2 * X2 + Y2 * Y2 - k[A2] * k[A2] - k[L2]) / (2.0 * k[A2])
            disc3 = k[L2] - kk * kk
            reach = reach1 and disc3 >= -k[TOL3]
            for elbow in range(2):
                sq3 = math.sqrt(max(disc3, 0.0)) * (1.0 if elbow == 0 else -1.0)
                phi3 = math.atan2(sq3, kk) - k[PSI]
                c3, s3 = math.cos(phi3), math.sin(phi3)
                rx = k[A2] + k[U] * c3 - k[W] * s3
                ry = k[U] * s3 + k[W] * c3
                th2 = math.atan2(Y2, X2) - math.atan2(ry, rx)
                th23 = th2 + phi3
                for i in range(3):
                    for j in range(3):
                        M[i, j] = R[i, j]
                _rot_rows_z(M, math.cos(th1), math.sin(th1))
                _rot_rows_x(M, k[CA1], k[SA1])
                _rot_rows_z(M, math.cos(th23), math.sin(th23))
                _rot_rows_x(M, k[CA3], k[SA3])
                ce = k[CE]  # N = M E^T, E = Rx(alpha4 + alpha5) in {I, Rx(pi)}
                n00, n01, n02 = M[0, 0], ce * M[0, 1], ce * M[0, 2]
                n10, n11, n12 = M[1, 0], ce * M[1, 1], ce * M[1, 2]
                n22 = ce * M[2, 2]
                bb = math.atan2(math.sqrt(n02 * n02 + n12 * n12), n22)
                aa = math.atan2(n12, n02)
                ca, sa = math.cos(aa), math.sin(aa)
                cc = math.atan2(-sa * n00 + ca * n10, -sa * n01 + ca * n11)
                for flip in range(2):
                    s = shoulder * 4 + elbow * 2 + flip
                    theta[0], theta[1], theta[2] = th1, th2, k[C2] * phi3
                    theta[3] = aa + flip * math.pi
                    theta[4] = (bb if flip == 0 else -bb) * (-k[SIG4])
                    theta[5] = (cc + flip * math.pi) * ce
                    inside = True
                    for j in range(6):
                        lo, hi = joints[j, 1], joints[j, 2]
                        x = _into_limits(theta[j] - offsets[j], lo, hi)
                        q[b, s, j] = x
                        inside = inside and lo <= x <= hi
                    ok = reach and inside
                    if ok:  # the FK check of puma560_ik
                        _chain(G, joints, q[b, s], Tq)
                        _, pos, rot = _residual(P, Tq, 1.0, e)
                        ok = pos <= tol_pos and rot <= tol_rot
                    valid[b, s] = ok


@kernel
def puma_pick(q, valid, G, joints, T, q_near, use_near, limit_rounding, out):
    """One solution per target into ``out: (B, 6)`` (inside the limits): with ``use_near``, the valid solution
    nearest ``q_near: (B, 6)`` after moving each angle by whole turns (within the limits, ``limit_rounding``
    relative) as near ``q_near`` as it goes (all of them when none is valid); else the valid one whose worst
    joint is farthest inside its range; with none valid, the clamped solution nearest the target (metres +
    0.1 x radians)."""
    n = q.shape[2]
    rep = np.empty(n)
    cand = np.empty(n)
    Tq = np.empty((3, 4))
    e = np.empty(6)
    for b in range(q.shape[0]):
        found = False
        for s in range(q.shape[1]):
            found = found or valid[b, s]
        best, best_score = -1, math.inf
        if use_near:
            for s in range(q.shape[1]):
                if found and not valid[b, s]:
                    continue
                dist = 0.0
                for j in range(n):
                    lo, hi, x, target = joints[j, 1], joints[j, 2], q[b, s, j], q_near[b, j]
                    tol = limit_rounding * (1.0 + max(abs(lo), abs(hi)))
                    turns = np.rint((target - x) / _TWO_PI)
                    chosen, chosen_d = x, abs(x - target)
                    for shift in (turns - 1.0, turns, turns + 1.0):
                        c = x + shift * _TWO_PI
                        if lo - tol <= c <= hi + tol:
                            c = min(max(c, lo), hi)
                            if abs(c - target) < chosen_d:
                                chosen, chosen_d = c, abs(c - target)
                    dist += (chosen - target) ** 2
                if dist < best_score:
                    best, best_score = s, dist
            if best >= 0:
                for j in range(n):  # the chosen solution again, moved as near q_near as it goes
                    lo, hi, x, target = joints[j, 1], joints[j, 2], q[b, best, j], q_near[b, j]
                    tol = limit_rounding * (1.0 + max(abs(lo), abs(hi)))
                    turns = np.rint((target - x) / _TWO_PI)
                    chosen, chosen_d = x, abs(x - target)
                    for shift in (turns - 1.0, turns, turns + 1.0):
                        c = x + shift * _TWO_PI
                        if lo - tol <= c <= hi + tol:
                            c = min(max(c, lo), hi)
                            if abs(c - target) < chosen_d:
                                chosen, chosen_d = c, abs(c - target)
                    out[b, j] = min(max(chosen, lo), hi)
                continue
        if found:
            best_margin = -math.inf
            for s in range(q.shape[1]):
                if not valid[b, s]:
                    continue
                margin = math.inf
                for j in range(n):
                    lo, hi = joints[j, 1], joints[j, 2]
                    margin = min(margin, min(q[b, s, j] - lo, hi - q[b, s, j]) / (hi - lo))
                if margin > best_margin:
                    best, best_margin = s, margin
            for j in range(n):
                out[b, j] = min(max(q[b, best, j], joints[j, 1]), joints[j, 2])
            continue
        for s in range(q.shape[1]):  # none valid: the clamped solution nearest the target
            for j in range(n):
                cand[j] = min(max(q[b, s, j], joints[j, 1]), joints[j, 2])
            _chain(G, joints, cand, Tq)
            _, pos, rot = _residual(T[b], Tq, 1.0, e)
            if pos + 0.1 * rot < best_score:
                best, best_score = s, pos + 0.1 * rot
                for j in range(n):
                    rep[j] = cand[j]
        for j in range(n):
            out[b, j] = rep[j]
