"""The two closed forms as batched tensor kernels: spherical wrist and three parallel axes.

Both work in the frames of the normal form ``T = G_0 Rz(th_1) G_1 ... Rz(th_6) G_6`` (:mod:`nik.kinematics`),
where every joint turns about the z axis of its frame ``F_i``. Each step is a Paden-Kahan subproblem
about z (IK-Geo, Elias and Wen 2022, in the frame of the joint that turns):

- SP1 (rotation about one axis taking one vector to another): ``th = atan2(cross_z, dot_xy)``;
- SP4 (rotation about an axis giving a projection): ``h . Rz(th) p = d``, with
  ``h . Rz(th) p = A cos th + B sin th + h_z p_z``, so ``th = atan2(B, A) +- atan2(sqrt(A^2 + B^2 - d'^2), d')``;
- SP3 (rotation giving a distance) of a planar pair of parallel joints reduces to SP4: ``|t + C Rz(th) w|^2``
  is affine in ``cos th, sin th``.

**Spherical wrist** (axes 4, 5, 6 meet in the wrist centre ``c``; axes 2, 3 parallel). The wrist centre
is fixed in the tool frame, so the target gives it: ``c_T = R_T c_tool + p_T``. Its height along axis 2
(z of ``F_2``) does not change with joints 2 and 3: SP4 gives ``th_1`` (2 shoulder solutions). The
distance of ``c`` from axis 2 fixes ``th_3`` (SP3 as SP4, 2 elbow solutions) and SP1 gives ``th_2``.
Joints 2 and 3 turn about one direction, so ``F_4 = F_2 Rz(psi) D`` with ``psi = th_2 + beta_2 +- th_3``
and a constant ``D``. The rest of the rotation, ``W = F_4^T R_T R_6^T = Rz(th_4) A Rz(th_5) B Rz(th_6)``:
the z component of axis 6 in ``F_4`` fixes ``th_5`` (SP4, 2 wrist solutions), SP1 on the axis gives
``th_4`` and SP1 on ``W e_x`` gives ``th_6``.

**Three parallel** (axes 2, 3, 4 parallel; 5 and 6 meet in ``P``). ``P`` is fixed in the tool frame
and in link 4, so its height along axis 2 fixes ``th_1`` (SP4, 2 shoulder solutions). The height of
axis 6 (known from the target) along axis 2 fixes ``th_5`` (SP4, 2 wrist solutions); SP1 on axis 6
gives the sum angle ``psi`` of joints 2..4 and SP1 on ``W e_x`` gives ``th_6``. Then ``P`` minus the
known part ``Rz(psi) D p_4`` is the tip of the planar pair 2, 3: SP3 (as SP4) for ``th_3`` (2 elbow
solutions), SP1 for ``th_2`` and ``th_4`` from ``psi``.

**Singularities.** Every angle comes from ``atan2``, never from ``acos`` or a division, and every square
root is of a clamped discriminant, so singular poses give finite angles that reach the pose: where a
subproblem has a continuum of solutions (``atan2(0, 0)``) one member is taken and the later
subproblems, solved from the full target, absorb it. At the wrist singularity (axis 6 along axis 4,
or along axes 2..4 of a three-parallel arm; detected as ``|n_xy| < 100 eps``) the free angle is fixed:
joint 4 at the middle of its range (spherical wrist); the sum angle ``psi`` that puts the planar pair
mid-way in its reach (three parallel: there ``psi`` also moves the pair's target point). Where a
discriminant can be computed from a quantity that vanishes at the singularity (the wrist:
``1 - n_z^2 = n_x^2 + n_y^2``), it is, so that a wrist-singular pose gives ``th_5`` exactly.

**Solution order.** Slot ``k`` of the 8 is ``shoulder + 2 elbow + 4 wrist``; for arms that
:func:`nik.data.branches.ik_branch_classifier` labels (PUMA-type and UR-type arms) the signs of the
square roots are chosen, once per arm, so that slot ``k`` holds the solution of branch label ``k``.

**Cost.** Plain elementwise tensor code (it also runs under ``torch.compile``), arranged for eager speed
on a CPU, where a sine costs about 15 multiplications: constants are Python floats folded into the code
(zero coefficients drop out, so a DH arm with axis-aligned frames costs fewer operations than a general
one); the cosine and sine of an angle found by ``atan2(y, x)`` are ``x / r, y / r`` rather than
``cos``/``sin`` of it; every quantity lives in the smallest shape of ``(wrist, elbow, shoulder, pose)``
it depends on (joint 1: ``(2, N)``), with the poses last, so that broadcasts run over contiguous memory;
each joint is wrapped into its limits in that shape, and the 8 solutions are laid out once at the end.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.analytic.geometry import ArmGeometry

__all__ = ["KernelConstants", "build_constants", "run_kernel"]

_SNAP = 1e-14
_TWO_PI = 2.0 * math.pi


class KernelConstants(dict):
    """Constants of one arm's closed form (Python floats and small nested lists); see :func:`build_constants`."""


# ---------------------------------------------------------------------------
# Tensor helpers: 3-vectors are tuples of three tensors (or Python floats for constants)
# ---------------------------------------------------------------------------
def _lin(*terms):
    """``sum c * x`` over ``(c, x)`` pairs, with constant floats ``c``: zero terms drop out, +-1 need no multiply."""
    acc = None
    const = 0.0
    for c, x in terms:
        if c == 0.0:
            continue
        if not isinstance(x, torch.Tensor):
            const += c * x
            continue
        if acc is None:
            acc = x if c == 1.0 else (-x if c == -1.0 else x * c)
        elif c == 1.0:
            acc = acc + x
        elif c == -1.0:
            acc = acc - x
        else:
            acc = torch.add(acc, x, alpha=c)
    if acc is None:
        return const
    return acc + const if const != 0.0 else acc


def _matvec(M, v):
    """Constant ``M: 3x3`` (nested lists) times ``v``."""
    return tuple(_lin(*((M[r][c], v[c]) for c in range(3))) for r in range(3))


def _rz_t(c, s, v):
    """``Rz(th)^T v`` with ``c, s`` the cosine and sine of ``th``."""
    return (c * v[0] + s * v[1], c * v[1] - s * v[0], v[2])


def _angle(y, x):
    """``(atan2(y, x), cos, sin)``, the cosine and sine from ``x, y`` (no cos/sin); ``(0, 1, 0)`` at ``x = y = 0``."""
    th = torch.atan2(y, x)
    r2 = x * x + y * y
    ok = r2 > 0
    inv = torch.rsqrt(torch.where(ok, r2, 1.0))
    return th, torch.where(ok, x * inv, 1.0), y * inv


def _sp4(phi0: float, disc, d, sign):
    """The SP4 roots ``phi0 + sign * atan2(sqrt(disc), d)`` (``disc`` clamped at 0) with their cosines and sines."""
    h, ch, sh = _angle(torch.sqrt(torch.clamp(disc, min=0.0)), d)
    ssh = sign * sh
    c0, s0 = _snap(math.cos(phi0)), _snap(math.sin(phi0))
    return phi0 + sign * h, _lin((c0, ch), (-s0, ssh)), _lin((s0, ch), (c0, ssh))


def _sp1(m, n):
    """SP1 about z: the angle ``th`` with ``Rz(th) m`` along ``n`` in the xy plane, with its cosine and sine."""
    return _angle(m[0] * n[1] - m[1] * n[0], m[0] * n[0] + m[1] * n[1])


def _wrap(th, j: int, k, lim):
    """Joint ``j``'s angle ``th - offset`` moved by a multiple of 2 pi into its limits where possible (as
    :func:`nik.analytic.puma560.wrap_into_limits`), and whether it is inside them."""
    lo, hi = lim[0][j], lim[1][j]
    x = th - k["off"][j] if k["off"][j] != 0.0 else th
    w = torch.remainder(x + math.pi, _TWO_PI) - math.pi
    inside = (w >= lo) & (w <= hi)
    if hi < math.pi and lo >= -math.pi:  # a turn up or down can never land inside
        return w, inside
    other = w
    if lo < -math.pi:
        down = w - _TWO_PI
        other = torch.where((down >= lo) & (down <= hi), down, w)
    if hi >= math.pi:
        up = w + _TWO_PI
        other = torch.where((up >= lo) & (up <= hi), up, other)
    w = torch.where(inside, w, other)
    return w, (w >= lo) & (w <= hi)


# ---------------------------------------------------------------------------
# The kernel
# ---------------------------------------------------------------------------
def run_kernel(Tf: torch.Tensor, k: KernelConstants, lim) -> tuple[torch.Tensor, torch.Tensor, list[torch.Tensor]]:
    """All 8 closed-form solutions, wrapped into the limits.

    Args:
        Tf: (N, 4, 4) target poses (base frame, metres).
        k: :func:`build_constants` output.
        lim: ``(lower, upper)``, two lists of 6 Python floats (the limits in ``Tf``'s dtype).

    Returns:
        ``q: (N, 8, 6)`` joint angles (radians; each moved by a multiple of 2 pi into its limits where
        possible), ``ok: (N, 8)`` bool: inside the limits, and no square root of a clearly negative
        number on the way (the pose may be reachable), and ``qs``: the same joint angles per joint, each in
        the shape it has before the 8 solutions are laid out, ``(wrist, elbow, shoulder, pose)`` (``(2, N)`` for
        joint 1: one value per shoulder choice; ``(2, 2, 2, N)`` at most). The poses are the last axis, so that
        the broadcasts between these shapes run over contiguous memory.
    """
    dt, dev = Tf.dtype, Tf.device
    R = [[Tf[:, r, c] for c in range(3)] for r in range(3)]
    p = (Tf[:, 0, 3], Tf[:, 1, 3], Tf[:, 2, 3])

    def rot_target(a):  # R_T a for a constant a
        return tuple(_lin(*((a[c], R[r][c]) for c in range(3))) for r in range(3))

    # the point (wrist centre or P) and the axis-6 frame columns, in the frame F_1 = G_0
    pt = rot_target(k["point_tool"])
    x = _matvec(k["R0T"], tuple(pt[i] + p[i] - k["t0"][i] for i in range(3)))
    qz = _matvec(k["R0T"], rot_target(k["g6z"]))
    qx = _matvec(k["R0T"], rot_target(k["g6x"]))

    # shoulder (SP4 about axis 1): g . Rz(phi) x = K' with phi = -th1; phi = atan2(B, A) +- atan2(sqrt(disc), d)
    g = k["g"]
    A1 = _lin((g[0], x[0]), (g[1], x[1]))
    B1 = _lin((g[1], x[0]), (-g[0], x[1]))
    d1 = k["K1"] - g[2] * x[2] if g[2] != 0.0 else torch.full_like(x[0], k["K1"])
    disc1 = k["gxy2"] * (x[0] * x[0] + x[1] * x[1]) - d1 * d1
    ok = disc1 >= -k["tol_len2"]
    sign1 = torch.tensor(k["s1"], dtype=dt, device=dev)[:, None]  # (2, 1): (shoulder, pose)
    phi, cphi, sphi = _angle(B1, A1)
    h, ch, sh = _angle(torch.sqrt(torch.clamp(disc1, min=0.0)), d1)
    ssh = sign1 * sh
    th1 = -(phi + sign1 * h)  # (2, N)
    c1 = cphi * ch - sphi * ssh  # cos(phi + sign h) = cos(-th1)
    s1 = -(sphi * ch + cphi * ssh)

    def after1(v):  # R1^T Rz(-th1) v
        return _matvec(k["R1T"], _rz_t(c1, s1, v))

    wz = after1(qz)  # W e_z and W e_x of W = R1^T Rz(-th1) R0^T R_T R6^T, in F_2
    wx = after1(qx)
    pF2 = after1(x)
    pF2 = tuple(pF2[i] - k["R1Tt1"][i] for i in range(3))  # the point in F_2

    if k["family"] == "spherical_wrist":
        ths, ok = _spherical(pF2, wz, wx, ok, k, dt, dev)
    else:
        ths, ok = _three_parallel(pF2, wz, wx, ok, k, dt, dev)
    ths = (th1,) + ths
    qs = []
    for j, th in enumerate(ths):
        w, inside = _wrap(th, j, k, lim)
        qs.append(w)
        ok = ok & inside
    # (2, 2, 2, N): wrist, elbow, shoulder, pose; numpy's rule (torch.broadcast_shapes' first call imports sympy)
    shape = np.broadcast_shapes(*(tuple(w.shape) for w in qs))
    q = torch.stack([w.expand(shape) for w in qs], dim=-1).permute(3, 0, 1, 2, 4).reshape(-1, 8, 6)
    return q, ok.expand(shape).permute(3, 0, 1, 2).reshape(-1, 8), qs


def _planar(cx, cy, k, sign3):
    """Planar pair of parallel joints 2, 3: ``Rz(th2) (t2 + C2 Rz(th3) w) = c`` in the xy plane of ``F_2``.

    Returns ``(th2, c2, s2), (th3, disc3)``; the two elbow roots carry the signs ``sign3``.
    """
    rhs = 0.5 * (cx * cx + cy * cy) - k["K3"]
    disc3 = k["rho3sq"] - rhs * rhs
    th3, c3, s3 = _sp4(k["phi3"], disc3, rhs, sign3)
    w = k["w"]
    C = k["C2xy"]
    rw0 = _lin((w[0], c3), (-w[1], s3))  # Rz(th3) w, xy
    rw1 = _lin((w[1], c3), (w[0], s3))
    vx = _lin((C[0][0], rw0), (C[0][1], rw1)) + k["t2"][0]
    vy = _lin((C[1][0], rw0), (C[1][1], rw1)) + k["t2"][1]
    return _sp1((vx, vy), (cx, cy)), (th3, disc3)


def _spherical(pF2, wz, wx, ok, k, dt, dev):
    sign3 = torch.tensor(k["s3"], dtype=dt, device=dev)[..., None]  # (1, 2, 2, 1): per (elbow, shoulder)
    sign5 = torch.tensor(k["s5"], dtype=dt, device=dev)[..., None]  # (2, 2, 2, 1): per (wrist, elbow, shoulder)
    (th2, _, _), (th3, disc3) = _planar(pF2[0], pF2[1], k, sign3)  # (1, 2, 2, N)
    psi = th2 + k["sig2"] * th3 + k["beta2"]
    cp, sp = torch.cos(psi), torch.sin(psi)
    # W = D^T Rz(-psi) (R1^T Rz(-th1) Q): its columns e_z (n) and e_x (ex), in F_4
    n = _matvec(k["DT"], _rz_t(cp, sp, wz))
    ex = _matvec(k["DT"], _rz_t(cp, sp, wx))
    free = (k["th4_free"], math.cos(k["th4_free"]), math.sin(k["th4_free"]))
    (th4, _, _), th5, th6, disc5 = _wrist(n, ex, k, sign5, free)
    ok = ok & (disc3 >= -k["tol_len4"]) & (disc5 >= -k["tol_unit"])
    return (th2, th3, th4, th5, th6), ok


def _wrist(n, ex, k, sign5, free):
    """``W = Rz(th4) A Rz(th5) B Rz(th6)`` from its columns ``n = W e_z`` and ``ex = W e_x``.

    Spherical wrist: ``W`` in ``F_4``, ``A = R(G_4)``. Three parallel: ``W`` in ``F_2``, ``th4`` is the sum
    angle ``psi`` of joints 2..4 and ``A = D R(G_4)``. ``free``: ``(th4, cos, sin)`` where ``th4`` is free
    (axis 6 along axis 4). Returns ``(th4, c4, s4), th5, th6`` and the discriminant of ``th5``.
    """
    A = k["A"]
    # th5: (A^T e_z) . Rz(th5) (B e_z) = n_z  (SP4 about axis 5)
    az, bz = k["az"], k["bz"]
    d5 = n[2] - az * bz if az * bz != 0.0 else n[2]
    s2 = n[0] * n[0] + n[1] * n[1]  # = 1 - n_z^2, exact near the wrist singularity
    disc5 = s2 - (az * az + bz * bz) + (2.0 * az * bz) * n[2] if (az != 0.0 or bz != 0.0) else s2
    th5, c5, s5 = _sp4(k["phi5"], disc5, d5, sign5)
    b = k["b"]
    rb = (_lin((b[0], c5), (-b[1], s5)), _lin((b[1], c5), (b[0], s5)), b[2])  # Rz(th5) b
    m = _matvec(A, rb)
    th4, c4, s4 = _sp1(m, n)
    # axis 6 along axis 4 (wrist singular): th4 is free and its atan2 is of rounding noise; take a fixed value
    sing = s2 < (100.0 * torch.finfo(s2.dtype).eps) ** 2
    th4 = torch.where(sing, free[0], th4)
    c4 = torch.where(sing, free[1], c4)
    s4 = torch.where(sing, free[2], s4)
    r = _matvec(k["AT"], _rz_t(c4, s4, ex))  # A^T Rz(-th4) W e_x
    r = _rz_t(c5, s5, r)
    BT = k["BT"]
    rx = _lin((BT[0][0], r[0]), (BT[0][1], r[1]), (BT[0][2], r[2]))
    ry = _lin((BT[1][0], r[0]), (BT[1][1], r[1]), (BT[1][2], r[2]))
    th6 = torch.atan2(ry, rx)
    return (th4, c4, s4), th5, th6, disc5


def _three_parallel(pF2, wz, wx, ok, k, dt, dev):
    sign5 = torch.tensor(k["s5"], dtype=dt, device=dev)[..., None]  # (2, 1, 2, 1): per (wrist, shoulder)
    sign3 = torch.tensor(k["s3"], dtype=dt, device=dev)[..., None]  # (2, 2, 2, 1): per (wrist, elbow, shoulder)
    # wrist singular (axis 6 along axes 2..4): psi is free, but it moves P - Rz(psi) D p4, the tip of the planar
    # pair; take the psi that puts that tip mid-way in the pair's annulus (|c|^2 = 2 K3), or as near as it gets
    pxy2 = pF2[0] * pF2[0] + pF2[1] * pF2[1]
    r4sq = k["r4sq"]
    span = 2.0 * torch.sqrt(pxy2 * r4sq)  # |c|^2 = pxy2 + r4sq - span cos(angle of p4 from P)
    near = torch.clamp(pxy2 + (r4sq - 2.0 * k["K3"]), min=-span, max=span)
    ang = torch.atan2(torch.sqrt(torch.clamp(span * span - near * near, min=0.0)), near)
    free = torch.atan2(pF2[1], pF2[0]) + ang - k["a4"]
    # th5 from the height of axis 6 along axis 2, psi (sum of joints 2..4) from its direction, th6 from W e_x
    (psi, cp, sp), th5, th6, disc5 = _wrist(wz, wx, k, sign5, (free, torch.cos(free), torch.sin(free)))
    p4 = k["Dp4"]
    cx = pF2[0] - _lin((p4[0], cp), (-p4[1], sp))
    cy = pF2[1] - _lin((p4[0], sp), (p4[1], cp))
    (th2, _, _), (th3, disc3) = _planar(cx, cy, k, sign3)  # (2, 2, 2, N)
    th4 = k["sig23"] * (psi - th2 - k["sig2"] * th3 - k["beta23"])
    ok = ok & (disc3 >= -k["tol_len4"]) & (disc5 >= -k["tol_unit"])
    return (th2, th3, th4, th5, th6), ok


# ---------------------------------------------------------------------------
# Constants
# ---------------------------------------------------------------------------
def _snap(v: float) -> float:
    v = float(v)
    for target in (0.0, 1.0, -1.0):
        if abs(v - target) < _SNAP:
            return target
    return v


def _m(M: np.ndarray) -> list:
    return [[_snap(M[r, c]) for c in range(M.shape[1])] for r in range(M.shape[0])]


def _v(a: np.ndarray) -> list:
    return [_snap(x) for x in a]


def _z_turn(C: np.ndarray) -> tuple[float, float]:
    """A rotation ``C`` with ``C e_z = +-e_z`` as ``Rz(beta) F``, ``F`` = I or Rx(pi): returns ``(beta, sigma)``."""
    sigma = 1.0 if C[2, 2] > 0 else -1.0
    return math.atan2(C[1, 0], C[0, 0]), sigma


def build_constants(geom: ArmGeometry, G: np.ndarray, offsets: np.ndarray, limits: np.ndarray) -> KernelConstants:
    """The constants of :func:`run_kernel` for an arm of family ``geom.family``.

    Args:
        geom: :func:`nik.analytic.geometry.arm_geometry` of the arm.
        G: (7, 4, 4) normal form; offsets: (6,) radians; limits: (6, 2) radians.

    The elbow and wrist signs are the natural ones (+ first); :func:`order_by_branch` reorders them.
    """
    F = geom.frames  # F_1 .. F_6 and the tool pose at q = 0
    o = np.asarray(offsets, dtype=float)
    R0, t0 = G[0, :3, :3], G[0, :3, 3]
    R1, t1 = G[1, :3, :3], G[1, :3, 3]
    C2, t2 = G[2, :3, :3], G[2, :3, 3]
    C3, t3 = G[3, :3, :3], G[3, :3, 3]
    A, B = G[4, :3, :3], G[5, :3, :3]
    R6 = G[6, :3, :3]
    M = F[6]
    P = geom.point
    point_tool = M[:3, :3].T @ (P - M[:3, 3])
    # height K of the point along axis 2 (z of F_2): constant while joints 2.. turn
    K = float((np.linalg.inv(F[1]) @ np.append(P, 1.0))[2])
    g = R1[:, 2]
    beta2, sig2 = _z_turn(C2)
    size = geom.size
    k = KernelConstants(
        family=geom.family,
        point_tool=_v(point_tool),
        R0T=_m(R0.T),
        t0=_v(t0),
        g6z=_v(R6.T[:, 2]),
        g6x=_v(R6.T[:, 0]),
        g=_v(g),
        gxy2=_snap(g[0] ** 2 + g[1] ** 2),
        K1=_snap(K + g @ t1),
        R1T=_m(R1.T),
        R1Tt1=_v(R1.T @ t1),
        B=_m(B),
        BT=_m(B.T),
        b=_v(B[:, 2]),
        bz=_snap(B[2, 2]),
        t2=_v(t2),
        C2xy=_m(C2[:2, :2]),
        beta2=beta2,
        sig2=sig2,
        s1=[1.0, -1.0],
        off=[float(v) for v in o],
        tol_len2=1e-12 * size * size,
        tol_len4=1e-12 * size**4,
        tol_unit=1e-12,
    )
    # the planar pair: |t2 + C2 Rz(th3) w|^2 over the xy plane = |c|^2, i.e. u . Rz(th3) w = |c|^2 / 2 - K3
    if geom.family == "spherical_wrist":
        X3 = F[2] @ _rz4(o[2])  # frame after joint 3 turns, at q = 0
        w = (np.linalg.inv(X3) @ np.append(P, 1.0))[:3]  # the wrist centre in it (fixed in link 3)
        D = np.diag([1.0, sig2, sig2]) @ C3  # F_4 = F_2 Rz(psi) D, psi = th2 + beta2 + sig2 th3
        k.update(
            DT=_m(D.T),
            A=_m(A),
            AT=_m(A.T),
            az=_snap(A[2, 2]),
            s3=[[[1.0, 1.0], [-1.0, -1.0]]],
            s5=[[[1.0, 1.0], [1.0, 1.0]], [[-1.0, -1.0], [-1.0, -1.0]]],
            th4_free=float(0.5 * (limits[3, 0] + limits[3, 1]) + o[3]),  # wrist singular: joint 4 mid-range
        )
        a = A[2, :]
    else:
        X4 = F[3] @ _rz4(o[3])
        p4 = (np.linalg.inv(X4) @ np.append(P, 1.0))[:3]  # P in link 4 (it lies on axis 5)
        beta3, sig3 = _z_turn(C3)
        Fl = np.diag([1.0, sig2 * sig3, sig2 * sig3])  # D = F2 F3
        DA = Fl @ A
        w = t3
        k.update(
            A=_m(DA),
            AT=_m(DA.T),
            Dp4=_v(Fl @ p4),
            az=_snap(DA[2, 2]),
            sig23=sig2 * sig3,
            beta23=beta2 + sig2 * beta3,
            s5=[[[1.0, 1.0]], [[-1.0, -1.0]]],
            s3=[[[1.0, 1.0], [-1.0, -1.0]], [[1.0, 1.0], [-1.0, -1.0]]],
            r4sq=float((Fl @ p4)[:2] @ (Fl @ p4)[:2]),
            a4=math.atan2((Fl @ p4)[1], (Fl @ p4)[0]),
        )
        a = DA[2, :]
    b = B[:, 2]
    # SP4 of th5: a . Rz(th5) b = A5 cos + B5 sin + a_z b_z
    k["phi5"] = math.atan2(a[1] * b[0] - a[0] * b[1], a[0] * b[0] + a[1] * b[1])
    u = C2[:2, :2].T @ t2[:2]  # C2^T t2 in the xy plane (C2 keeps the plane)
    wxy = w[:2]
    k.update(
        w=_v(w),
        K3=_snap(0.5 * (t2[:2] @ t2[:2] + wxy @ wxy)),
        rho3sq=float((u @ u) * (wxy @ wxy)),
        phi3=math.atan2(u[1] * wxy[0] - u[0] * wxy[1], u[0] * wxy[0] + u[1] * wxy[1]),
    )
    return k


def _rz4(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    R = np.eye(4)
    R[:2, :2] = [[c, -s], [s, c]]
    return R
