"""The closed forms of 6R arms (spherical wrist; three parallel axes), compiled, and the choice among solutions.

The same computation as ``nik.analytic.kernels.run_kernel`` (Paden-Kahan subproblems in the frames of the
normal form; see that module for the derivation), written for one target at a time: 8 candidate solutions,
each angle moved by whole turns into its limits where possible, and a validity mask (the candidate exists,
lies inside the limits and reaches the pose by FK within the tolerance, the test of ``nik.analytic.solve``).
Slot ``k`` is ``shoulder + 2 elbow + 4 wrist``, as there. The constants come in as one float64 array
(:func:`closed_form_array` packs the mapping ``nik.analytic.solve.closed_form(robot)`` returns), so this room
imports nothing from nik. Arms that fit their family only within a tolerance (``polish``: three Newton steps
after the closed form in ``nik.analytic.solve``) are not handled here (:func:`closed_form_array` says so).

:func:`pick` then chooses one solution per target (the one rule: ``nik.ik.guesses.analytic_guess`` calls it
too): the valid one nearest ``q_near`` (each angle moved by whole turns, within the limits, as near ``q_near`` as
it goes), or the one whose worst joint is farthest inside its range; with none valid, the clamped solution nearest
the target.

Scratch is allocated inside each kernel, per call: threads may share the constants and the model arrays.
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER, _chain
from nik.kernels.lm import _residual
from nik.tolerances import SCORE_ROT_WEIGHT

__all__ = ["FIELDS", "closed_form_array", "guess", "pick", "solutions"]

#: Entries of the constants array: (name, size) in order; matrices row by row, the sign tables
#: ``s3, s5`` broadcast to ``(wrist, elbow, shoulder) = (2, 2, 2)``.
FIELDS = (
    ("three_parallel", 1), ("point_tool", 3), ("R0T", 9), ("t0", 3), ("g6z", 3), ("g6x", 3), ("g", 3),
    ("gxy2", 1), ("K1", 1), ("R1T", 9), ("R1Tt1", 3), ("BT", 9), ("b", 3), ("bz", 1), ("t2", 3), ("C2xy", 4),
    ("beta2", 1), ("sig2", 1), ("s1", 2), ("off", 6), ("tol_len2", 1), ("tol_len4", 1), ("tol_unit", 1),
    ("DT", 9), ("A", 9), ("AT", 9), ("az", 1), ("s3", 8), ("s5", 8), ("th4_free", 1), ("Dp4", 3), ("sig23", 1),
    ("beta23", 1), ("r4sq", 1), ("a4", 1), ("phi5", 1), ("w", 3), ("K3", 1), ("rho3sq", 1), ("phi3", 1),
    ("c_phi3", 1), ("s_phi3", 1), ("c_phi5", 1), ("s_phi5", 1),
)  # fmt: skip
_AT = {}
_n = 0
for _name, _size in FIELDS:
    _AT[_name] = _n
    _n += _size
SIZE = _n
(THREE_PARALLEL, POINT_TOOL, R0T, T0, G6Z, G6X, G_AX, GXY2, K1, R1T, R1TT1, BT, B_AX, BZ, T2, C2XY, BETA2, SIG2,
 S1, OFF, TOL_LEN2, TOL_LEN4, TOL_UNIT, DT, A, AT, AZ, S3, S5, TH4_FREE, DP4, SIG23, BETA23, R4SQ, A4, PHI5, W, K3,
 RHO3SQ, PHI3, C_PHI3, S_PHI3, C_PHI5, S_PHI5) = (_AT[name] for name, _ in FIELDS)  # fmt: skip
# (G_AX: the vector ``g``; B_AX: the vector ``b = B e_z``; BT: the matrix ``B^T``)
_TWO_PI = 2.0 * math.pi
_SNAP = 1e-14
_SING = (100.0 * np.finfo(np.float64).eps) ** 2


def _snap(v: float) -> float:
    for target in (0.0, 1.0, -1.0):
        if abs(v - target) < _SNAP:
            return target
    return float(v)


def closed_form_array(k) -> np.ndarray | None:
    """The ``(SIZE,)`` float64 constants of ``k`` (the mapping of ``nik.analytic.solve.closed_form``), or None
    when its arm needs the Newton polish this kernel does not do."""
    if k.get("polish"):
        return None
    out = np.zeros(SIZE)
    three = k["family"] == "three_parallel"
    out[THREE_PARALLEL] = 1.0 if three else 0.0
    for name, size in FIELDS:
        if name in ("three_parallel", "c_phi3", "s_phi3", "c_phi5", "s_phi5"):
            continue
        if name not in k:  # the other family's constants
            continue
        value = np.asarray(k[name], dtype=np.float64)
        if name in ("s3", "s5"):
            value = np.broadcast_to(value, (2, 2, 2))
        out[_AT[name] : _AT[name] + size] = value.reshape(size)
    out[C_PHI3], out[S_PHI3] = _snap(math.cos(k["phi3"])), _snap(math.sin(k["phi3"]))
    out[C_PHI5], out[S_PHI5] = _snap(math.cos(k["phi5"])), _snap(math.sin(k["phi5"]))
    return out


# ---------------------------------------------------------------------------
# building blocks (scalars; 3-vectors as three floats)
# ---------------------------------------------------------------------------
@kernel
def _mv(k, at, x, y, z):
    """``M (x, y, z)`` for the 3x3 matrix stored row by row at ``k[at:at + 9]``."""
    return (
        k[at] * x + k[at + 1] * y + k[at + 2] * z,
        k[at + 3] * x + k[at + 4] * y + k[at + 5] * z,
        k[at + 6] * x + k[at + 7] * y + k[at + 8] * z,
    )


@kernel
def _angle(y, x):
    """``(atan2(y, x), cos, sin)`` with the cosine and sine from ``x, y``; ``(0, 1, 0)`` at ``x = y = 0``."""
    r2 = x * x + y * y
    if r2 > 0.0:
        inv = 1.0 / math.sqrt(r2)
        return math.atan2(y, x), x * inv, y * inv
    return math.atan2(y, x), 1.0, 0.0


@kernel
def _sp4(phi0, c0, s0, disc, d, sign):
    """SP4 root ``phi0 + sign atan2(sqrt(disc), d)`` with its cosine and sine."""
    h, ch, sh = _angle(math.sqrt(max(disc, 0.0)), d)
    ssh = sign * sh
    return phi0 + sign * h, c0 * ch - s0 * ssh, s0 * ch + c0 * ssh


@kernel
def _planar(k, cx, cy, sign3):
    """Planar pair of joints 2, 3 reaching ``(cx, cy)``: ``(th2, th3, disc3)``."""
    rhs = 0.5 * (cx * cx + cy * cy) - k[K3]
    disc3 = k[RHO3SQ] - rhs * rhs
    th3, c3, s3 = _sp4(k[PHI3], k[C_PHI3], k[S_PHI3], disc3, rhs, sign3)
    rw0 = k[W] * c3 - k[W + 1] * s3
    rw1 = k[W + 1] * c3 + k[W] * s3
    vx = k[C2XY] * rw0 + k[C2XY + 1] * rw1 + k[T2]
    vy = k[C2XY + 2] * rw0 + k[C2XY + 3] * rw1 + k[T2 + 1]
    th2, _, _ = _angle(vx * cy - vy * cx, vx * cx + vy * cy)
    return th2, th3, disc3


@kernel
def _wrist(k, n0, n1, n2, e0, e1, e2, sign5, free, cfree, sfree):
    """``W = Rz(th4) A Rz(th5) B Rz(th6)`` from ``n = W e_z`` and ``e = W e_x``: ``(th4, c4, s4, th5, th6, disc5)``."""
    az, bz = k[AZ], k[BZ]
    d5 = n2 - az * bz
    s2 = n0 * n0 + n1 * n1
    disc5 = s2 - (az * az + bz * bz) + (2.0 * az * bz) * n2
    th5, c5, s5 = _sp4(k[PHI5], k[C_PHI5], k[S_PHI5], disc5, d5, sign5)
    rb0 = k[B_AX] * c5 - k[B_AX + 1] * s5
    rb1 = k[B_AX + 1] * c5 + k[B_AX] * s5
    m0, m1, _ = _mv(k, A, rb0, rb1, k[B_AX + 2])
    th4, c4, s4 = _angle(m0 * n1 - m1 * n0, m0 * n0 + m1 * n1)
    if s2 < _SING:  # axis 6 along axis 4: th4 is free; take the fixed value
        th4, c4, s4 = free, cfree, sfree
    r0, r1, r2 = _mv(k, AT, c4 * e0 + s4 * e1, c4 * e1 - s4 * e0, e2)
    r0, r1 = c5 * r0 + s5 * r1, c5 * r1 - s5 * r0
    rx = k[BT] * r0 + k[BT + 1] * r1 + k[BT + 2] * r2
    ry = k[BT + 3] * r0 + k[BT + 4] * r1 + k[BT + 5] * r2
    return th4, c4, s4, th5, math.atan2(ry, rx), disc5


@kernel
def _wrap(x, lo, hi):
    """An angle moved by whole turns into ``[lo, hi]`` where possible (a turn up preferred to a turn down)."""
    w = (x + math.pi) % _TWO_PI - math.pi
    if lo <= w <= hi:
        return w
    if lo <= w + _TWO_PI <= hi:
        return w + _TWO_PI
    if lo <= w - _TWO_PI <= hi:
        return w - _TWO_PI
    return w


# ---------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------
@kernel
def solutions(k, G, joints, tol_pos, tol_rot, T, q, valid):
    """All 8 solutions ``q: (B, 8, 6)`` (radians, moved into the limits where possible) and ``valid: (B, 8)`` of
    the targets ``T: (B, 4, 4)``; ``k``: :func:`closed_form_array`; ``G, joints``: the robot's model (limits,
    and the FK check: position within ``tol_pos`` m, rotation within ``tol_rot`` rad)."""
    Tq = np.empty((3, 4))
    th = np.empty(6)
    for b in range(T.shape[0]):
        _solve_one(k, G, joints, tol_pos, tol_rot, T[b], q[b], valid[b], Tq, th)


@kernel
def guess(k, G, joints, check_tol, T, q_near, use_near, limit_rounding, tol_pos, tol_rot, reachable, out):
    """The closed-form guess of each target ``T: (B, 4, 4)`` in one call: its 8 solutions (:func:`solutions`, FK
    check within ``check_tol``), the one :func:`pick` chooses into ``q: (B, 6)``, that answer's position (m) and
    rotation (rad) errors ``pos, rot: (B,)`` and ``ok: (B,)``: within ``tol_pos, tol_rot``; ``out = (q, pos, rot,
    ok)``, written in place. Returns how many targets miss the tolerance while ``reachable: (B,)`` (those a
    refinement should take up)."""
    q, pos, rot, ok = out
    n = joints.shape[0]
    q8, valid8 = np.empty((1, 8, n)), np.empty((1, 8), dtype=np.bool_)
    Tq = np.empty((3, 4))
    th = np.empty(6)
    e = np.empty(6)
    todo = 0
    for b in range(T.shape[0]):
        _solve_one(k, G, joints, check_tol, check_tol, T[b], q8[0], valid8[0], Tq, th)
        _pick_one(q8[0], valid8[0], G, joints, T[b], q_near[b], use_near, limit_rounding, q[b], Tq, e)
        _chain(G, joints, q[b], Tq)
        _, pos[b], rot[b] = _residual(T[b], Tq, 1.0, e)
        ok[b] = pos[b] <= tol_pos and rot[b] <= tol_rot
        if reachable[b] and not ok[b]:
            todo += 1
    return todo


@kernel
def _solve_one(k, G, joints, tol_pos, tol_rot, P, q, valid, Tq, th):
    """The 8 solutions ``q: (8, 6)`` and ``valid: (8,)`` of one target ``P: (4, 4)``."""
    rot2_tol = 8.0 * math.sin(0.5 * tol_rot) ** 2
    three = k[THREE_PARALLEL] != 0.0
    # R_T a for the constant vectors a, then into F_1 = G_0
    pt0, pt1, pt2 = _mv_target(P, k[POINT_TOOL], k[POINT_TOOL + 1], k[POINT_TOOL + 2])
    x0, x1, x2 = _mv(k, R0T, pt0 + P[0, 3] - k[T0], pt1 + P[1, 3] - k[T0 + 1], pt2 + P[2, 3] - k[T0 + 2])
    a0, a1, a2 = _mv_target(P, k[G6Z], k[G6Z + 1], k[G6Z + 2])
    qz0, qz1, qz2 = _mv(k, R0T, a0, a1, a2)
    a0, a1, a2 = _mv_target(P, k[G6X], k[G6X + 1], k[G6X + 2])
    qx0, qx1, qx2 = _mv(k, R0T, a0, a1, a2)
    g0, g1, g2 = k[G_AX], k[G_AX + 1], k[G_AX + 2]
    A1 = g0 * x0 + g1 * x1
    B1 = g1 * x0 - g0 * x1
    d1 = k[K1] - g2 * x2
    disc1 = k[GXY2] * (x0 * x0 + x1 * x1) - d1 * d1
    ok1 = disc1 >= -k[TOL_LEN2]
    phi, cphi, sphi = _angle(B1, A1)
    h, ch, sh = _angle(math.sqrt(max(disc1, 0.0)), d1)
    for shoulder in range(2):
        sign1 = k[S1 + shoulder]
        ssh = sign1 * sh
        th1 = -(phi + sign1 * h)
        c1 = cphi * ch - sphi * ssh
        s1 = -(sphi * ch + cphi * ssh)
        # after1(v) = R1^T Rz(-th1) v
        wz0, wz1, wz2 = _mv(k, R1T, c1 * qz0 + s1 * qz1, c1 * qz1 - s1 * qz0, qz2)
        wx0, wx1, wx2 = _mv(k, R1T, c1 * qx0 + s1 * qx1, c1 * qx1 - s1 * qx0, qx2)
        p0, p1, p2 = _mv(k, R1T, c1 * x0 + s1 * x1, c1 * x1 - s1 * x0, x2)
        p0, p1, p2 = p0 - k[R1TT1], p1 - k[R1TT1 + 1], p2 - k[R1TT1 + 2]
        for elbow in range(2):
            for wrist in range(2):
                sign3 = k[S3 + 4 * wrist + 2 * elbow + shoulder]
                sign5 = k[S5 + 4 * wrist + 2 * elbow + shoulder]
                if not three:
                    th2, th3, disc3 = _planar(k, p0, p1, sign3)
                    psi = th2 + k[SIG2] * th3 + k[BETA2]
                    cp, sp = math.cos(psi), math.sin(psi)
                    n0, n1, n2 = _mv(k, DT, cp * wz0 + sp * wz1, cp * wz1 - sp * wz0, wz2)
                    e0, e1, e2 = _mv(k, DT, cp * wx0 + sp * wx1, cp * wx1 - sp * wx0, wx2)
                    f = k[TH4_FREE]
                    th4, _, _, th5, th6, disc5 = _wrist(k, n0, n1, n2, e0, e1, e2, sign5, f, math.cos(f), math.sin(f))
                else:
                    pxy2 = p0 * p0 + p1 * p1
                    span = 2.0 * math.sqrt(pxy2 * k[R4SQ])
                    near = min(max(pxy2 + (k[R4SQ] - 2.0 * k[K3]), -span), span)
                    ang = math.atan2(math.sqrt(max(span * span - near * near, 0.0)), near)
                    f = math.atan2(p1, p0) + ang - k[A4]
                    psi, cp, sp, th5, th6, disc5 = _wrist(
                        k, wz0, wz1, wz2, wx0, wx1, wx2, sign5, f, math.cos(f), math.sin(f)
                    )
                    cx = p0 - (k[DP4] * cp - k[DP4 + 1] * sp)
                    cy = p1 - (k[DP4] * sp + k[DP4 + 1] * cp)
                    th2, th3, disc3 = _planar(k, cx, cy, sign3)
                    th4 = k[SIG23] * (psi - th2 - k[SIG2] * th3 - k[BETA23])
                ok = ok1 and disc3 >= -k[TOL_LEN4] and disc5 >= -k[TOL_UNIT]
                th[0], th[1], th[2], th[3], th[4], th[5] = th1, th2, th3, th4, th5, th6
                s = shoulder + 2 * elbow + 4 * wrist
                for j in range(6):
                    lo, hi = joints[j, LOWER], joints[j, UPPER]
                    v = _wrap(th[j] - k[OFF + j], lo, hi)
                    q[s, j] = v
                    ok = ok and lo <= v <= hi
                if ok:  # the FK check of nik.analytic.solve (reaches)
                    _chain(G, joints, q[s], Tq)
                    pos2 = 0.0
                    rot2 = 0.0
                    for r in range(3):
                        pos2 += (Tq[r, 3] - P[r, 3]) ** 2
                        for c in range(3):
                            rot2 += (Tq[r, c] - P[r, c]) ** 2
                    ok = pos2 <= tol_pos * tol_pos and rot2 <= rot2_tol
                valid[s] = ok


@kernel
def _mv_target(P, a0, a1, a2):
    """``R_T a`` for the rotation of the target ``P (4, 4)``."""
    return (
        P[0, 0] * a0 + P[0, 1] * a1 + P[0, 2] * a2,
        P[1, 0] * a0 + P[1, 1] * a1 + P[1, 2] * a2,
        P[2, 0] * a0 + P[2, 1] * a1 + P[2, 2] * a2,
    )


@kernel
def _nearest_turn(x, target, lo, hi, limit_rounding):
    """``x`` moved by whole turns (within the limits, ``limit_rounding`` relative) as near ``target`` as it goes."""
    tol = limit_rounding * (1.0 + max(abs(lo), abs(hi)))
    turns = np.rint((target - x) / _TWO_PI)
    chosen, chosen_d = x, abs(x - target)
    for shift in (turns - 1.0, turns, turns + 1.0):
        c = x + shift * _TWO_PI
        if lo - tol <= c <= hi + tol:
            c = min(max(c, lo), hi)
            if abs(c - target) < chosen_d:
                chosen, chosen_d = c, abs(c - target)
    return chosen


@kernel
def pick(q, valid, G, joints, T, q_near, use_near, limit_rounding, out):
    """One solution per target into ``out: (B, 6)`` (inside the limits): with ``use_near``, the valid solution
    nearest ``q_near: (B, 6)`` after moving each angle by whole turns as near it as it goes (all of them when none
    is valid); else the valid one whose worst joint is farthest inside its range; with none valid, the clamped
    solution nearest the target (metres + 0.1 x radians)."""
    Tq = np.empty((3, 4))
    e = np.empty(6)
    for b in range(q.shape[0]):
        _pick_one(q[b], valid[b], G, joints, T[b], q_near[b], use_near, limit_rounding, out[b], Tq, e)


@kernel
def _pick_one(q, valid, G, joints, P, q_near, use_near, limit_rounding, out, Tq, e):
    """:func:`pick` for one target: ``q: (8, n)``, ``valid: (8,)``, ``P: (4, 4)``, ``q_near, out: (n,)``."""
    n = q.shape[1]
    found = False
    for s in range(q.shape[0]):
        found = found or valid[s]
    best, best_score = -1, math.inf
    if use_near:
        for s in range(q.shape[0]):
            if found and not valid[s]:
                continue
            dist = 0.0
            for j in range(n):
                x = _nearest_turn(q[s, j], q_near[j], joints[j, LOWER], joints[j, UPPER], limit_rounding)
                dist += (x - q_near[j]) ** 2
            if dist < best_score:
                best, best_score = s, dist
        for j in range(n):
            lo, hi = joints[j, LOWER], joints[j, UPPER]
            out[j] = min(max(_nearest_turn(q[best, j], q_near[j], lo, hi, limit_rounding), lo), hi)
    elif found:
        best_margin = -math.inf
        for s in range(q.shape[0]):
            if not valid[s]:
                continue
            margin = math.inf
            for j in range(n):
                lo, hi = joints[j, LOWER], joints[j, UPPER]
                margin = min(margin, min(q[s, j] - lo, hi - q[s, j]) / (hi - lo))
            if margin > best_margin:
                best, best_margin = s, margin
        for j in range(n):
            out[j] = min(max(q[best, j], joints[j, LOWER]), joints[j, UPPER])
    else:  # none valid: the clamped solution nearest the target
        cand = np.empty(n)
        for s in range(q.shape[0]):
            for j in range(n):
                cand[j] = min(max(q[s, j], joints[j, LOWER]), joints[j, UPPER])
            _chain(G, joints, cand, Tq)
            _, pos, rot = _residual(P, Tq, 1.0, e)
            if pos + SCORE_ROT_WEIGHT * rot < best_score:
                best, best_score = s, pos + SCORE_ROT_WEIGHT * rot
                for j in range(n):
                    out[j] = cand[j]
