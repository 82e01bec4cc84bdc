"""Closed-form inverse kinematics of PUMA-560-type arms (paper B, methods.md 1.1).

Geometry
--------
nik keeps a robot only as its FK normal form ``T = G_0 Rz(th_1) G_1 ... Rz(th_6) G_6`` with
``th_i = q_i + offset_i`` (:mod:`nik.kinematics`). :func:`puma560_params` first brings that
chain to canonical Denavit-Hartenberg form: every inner ``G_i`` (i = 1..5) becomes
``Tz(d_i) Tx(a_i) Rx(alpha_i)`` (``x`` along the common normal of joint axes ``i`` and ``i + 1``),
a rotation about a joint axis moves into that joint's offset and a slide along it into the
next factor; ``G_0`` (base) and ``G_6`` (tool, e.g. ``d6``) stay general. Standard DH,
modified DH (Craig) and screw-axis tables of the same arm all reduce to the same canonical
numbers, so paper B's modified-DH closed form and the Fu-Gonzalez-Lee standard-DH table
(the built-in ``puma560``), paper A's variant (``a2 = 431.8``, ``a3 = 0``), ``kuka_kr`` and
``rebot_v_6r`` are all handled. A robot is PUMA-like when

- it has 6 joints, axis 1 is perpendicular to axis 2 (``|sin alpha_1| = 1``),
- axes 2 and 3 are parallel (``sin alpha_2 = 0``) and ``a_2 != 0``,
- axes 4, 5, 6 meet in one point, the wrist centre (``a_4 = a_5 = d_5 = 0``), with
  ``|sin alpha_4| = |sin alpha_5| = 1``.

The solution
------------
Position first (paper B): the wrist centre is the position of ``G_0^-1 T G_6^-1`` (this is
where the tool offset ``d6`` is removed). Two shoulder choices give ``theta_1``, two elbow
choices ``theta_3``, then ``theta_2`` follows from the planar 2R problem of joints 2 and 3.
The remaining rotation ``R_36 = R_03^T R`` is a ZYZ Euler rotation ``Rz(th4) Ry(-+th5) Rz(th6)``
with two wrist flips. ``wrist="quaternion"`` (paper B) converts the target rotation once to a
unit quaternion (Shepperd's method), forms ``q_36 = conj(q_03) * q`` by quaternion products and
reads the angles from half-angle ``atan2``s, which stay exact at the wrist singularity
(``theta_5 = 0``, where only ``theta_4 + theta_6`` is determined; it then splits it evenly).
``wrist="matrix"`` does the same with 3x3 rotation matrices.

Solution ``k`` (0..7) of the 8: shoulder ``k >> 2``, elbow ``(k >> 1) & 1``, wrist flip ``k & 1``.
"""

from __future__ import annotations

import math
import warnings
import weakref
from dataclasses import dataclass

import numpy as np
import torch

from nik.kinematics import chain_fk_eager
from nik.poses import matrix_to_quaternion, pose_error

__all__ = ["PumaGeometry", "is_puma_like", "puma560_ik", "puma560_params", "wrap_into_limits"]

_TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------------------
# Geometry: canonical DH parameters recovered from the normal form
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class PumaGeometry:
    """Canonical DH description of a PUMA-like arm (SI units: metres, radians).

    ``T(q) = base @ A_1 ... A_6 @ tool`` with ``A_i = Rz(q_i + offsets[i]) Tz(d_i) Tx(a_i) Rx(alpha_i)``
    for i = 1..5 and ``A_6 = Rz(q_6 + offsets[5])``.
    """

    base: np.ndarray  # (4, 4) G_0, metres
    tool: np.ndarray  # (4, 4) canonical G_6 (holds d6 and any tool transform), metres
    offsets: np.ndarray  # (6,) radians, theta_i = q_i + offsets[i]
    alpha: np.ndarray  # (5,) radians, alpha_1..alpha_5
    a: np.ndarray  # (5,) metres, a_1..a_5
    d: np.ndarray  # (5,) metres, d_1..d_5

    @property
    def d6(self) -> float:
        """Distance (metres) from the wrist centre to the tool origin along the last axis."""
        return float(self.tool[2, 3])


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def _tr(x: float = 0.0, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[0, 3], T[2, 3] = x, z
    return T


def _snap(angle: float) -> float:
    """Snap an angle within 1e-12 of a multiple of pi/2 onto it (exact 0/+-1 sines and cosines)."""
    k = round(angle / (math.pi / 2))
    return k * (math.pi / 2) if abs(angle - k * math.pi / 2) < 1e-12 else angle


def canonical_dh(G: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rewrite a normal form so that every inner factor is ``Tz(d) Tx(a) Rx(alpha)``.

    Args:
        G: (n + 1, 4, 4) normal-form transforms (SI).
        offsets: (n,) joint offsets, radians.

    Returns:
        ``(G', offsets', dh)`` describing the same FK, with ``dh: (n - 1, 3)`` rows
        ``(alpha_i, a_i, d_i)`` of ``G'_i`` for i = 1..n-1.
    """
    G = np.array(G, dtype=float, copy=True)
    o = np.array(offsets, dtype=float, copy=True)
    n = G.shape[0] - 1
    ez = np.array([0.0, 0.0, 1.0])
    dh = np.zeros((max(n - 1, 0), 3))
    for i in range(1, n):
        R, t = G[i, :3, :3], G[i, :3, 3]
        z_new = R[:, 2]
        normal = np.cross(ez, z_new)
        parallel = np.linalg.norm(normal) < 1e-9
        if not parallel:
            x = normal / np.linalg.norm(normal)
        else:
            tp = np.array([t[0], t[1], 0.0])
            x = tp / np.linalg.norm(tp) if np.linalg.norm(tp) > 1e-12 else np.array([1.0, 0.0, 0.0])
        gamma = math.atan2(x[1], x[0])  # rotation about joint i's axis, into offset i
        beta = math.atan2(x @ R[:, 1], x @ R[:, 0])  # rotation about joint i+1's axis
        alpha = _snap(math.atan2(np.cross(ez, z_new) @ x, z_new[2]))
        if not parallel:
            d, a, e = np.linalg.solve(np.stack([ez, x, z_new], axis=1), t)
        else:
            d, a, e = t[2], float(t @ x), 0.0
        d, a = (0.0 if abs(v) < 1e-13 else float(v) for v in (d, a))
        C = _tr(z=d) @ _tr(x=a) @ _rx(alpha)
        # G_i = Rz(gamma) C_i Tz(e) Rz(-beta): Rz(gamma) joins offset i, Tz(e) Rz(-beta) moves past joint i+1
        if np.abs(_rz(gamma) @ C @ _tr(z=e) @ _rz(-beta) - G[i]).max() > 1e-9 * (1 + np.abs(t).sum()):
            raise RuntimeError(f"canonical_dh: factor {i} has no DH form")  # pragma: no cover
        G[i] = C
        G[i + 1] = _tr(z=e) @ G[i + 1]
        o[i - 1] += gamma
        o[i] -= beta
        dh[i - 1] = (alpha, a, d)
    o = np.array([_snap(v) for v in o])
    return G, o, dh


_GEOMETRY_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def puma560_params(robot) -> PumaGeometry:
    """Recover the canonical DH geometry of a PUMA-like ``robot`` (see the module docstring).

    Raises:
        ValueError: the robot is not PUMA-like; the message names the failed condition.
    """
    key = robot.definition_hash
    hit = _GEOMETRY_CACHE.get(robot)
    if hit is not None and hit[0] == key:
        return hit[1]
    geom = _geometry(robot)
    _GEOMETRY_CACHE[robot] = (key, geom)
    return geom


def is_puma_like(robot) -> bool:
    """True when :func:`puma560_ik` can solve ``robot`` in closed form."""
    try:
        puma560_params(robot)
    except ValueError:
        return False
    return True


def _rigid(G: np.ndarray, name: str) -> np.ndarray:
    """``G: (n + 1, 4, 4)`` with each rotation replaced by the nearest rotation matrix (polar factor).

    URDF origins pass through float32 in pytorch-kinematics, so a URDF arm's rotations are orthonormal to
    about 1e-7 only; the DH rewrite needs them exact. The closed form then solves this rounded copy and
    :func:`puma560_ik` checks every solution by FK of the robot itself. More than 1e-5 away from a rotation
    is not a rounding: ``ValueError``.
    """
    G = np.array(G, dtype=float, copy=True)
    U, _, Vt = np.linalg.svd(G[:, :3, :3])
    R = U @ Vt
    worst = float(np.abs(R - G[:, :3, :3]).max()) if len(G) else 0.0
    if worst > 1e-5 or (np.linalg.det(R) < 0).any():
        raise ValueError(
            f"puma560_ik: robot {name!r} has a fixed transform that is not a rotation (off by {worst:.3g})"
        )
    G[:, :3, :3] = R
    return G


def _geometry(robot) -> PumaGeometry:
    name = getattr(robot, "name", "robot")
    prismatic = getattr(robot, "prismatic", None)
    if prismatic is not None and bool(prismatic.any()):
        joints = [i + 1 for i in range(robot.dof) if bool(prismatic[i])]
        raise ValueError(f"puma560_ik: robot {name!r} has prismatic joint(s) {joints}; a PUMA-like arm is all revolute")
    if robot.dof != 6:
        raise ValueError(f"puma560_ik: robot {name!r} has {robot.dof} joints; a PUMA-like arm has 6")
    G0 = _rigid(robot.G.numpy(), name)
    o0 = robot.offsets.numpy()
    G, o, dh = canonical_dh(G0, o0)
    # self-check: the canonical chain must reproduce the robot's FK
    q = torch.as_tensor(np.random.default_rng(0).uniform(-math.pi, math.pi, (16, 6)))
    ref = chain_fk_eager(q, torch.as_tensor(G0), torch.as_tensor(o0))
    new = chain_fk_eager(q, torch.as_tensor(G), torch.as_tensor(o))
    scale = 1.0 + float(np.abs(G0[:, :3, 3]).sum())
    if float((ref - new).abs().max()) > 1e-9 * scale:  # pragma: no cover - would be a bug here
        raise RuntimeError(f"puma560_params: canonical DH form of {name!r} does not reproduce its FK")
    alpha, a, d = dh[:, 0], dh[:, 1], dh[:, 2]
    tol = 1e-9 * scale
    s = np.sin(alpha)

    def need(cond: bool, what: str) -> None:
        if not cond:
            table = ", ".join(f"(alpha={math.degrees(al):.6g} deg, a={ai:.6g} m, d={di:.6g} m)" for al, ai, di in dh)
            raise ValueError(f"puma560_ik: robot {name!r} is not PUMA-like: {what} (canonical DH rows 1..5: {table})")

    need(abs(abs(s[0]) - 1) < 1e-9, "joint axes 1 and 2 are not perpendicular")
    need(abs(s[1]) < 1e-9, "joint axes 2 and 3 are not parallel")
    need(abs(a[1]) > tol, "a2 = 0 (no upper arm between joints 2 and 3)")
    need(abs(a[3]) < tol and abs(a[4]) < tol and abs(d[4]) < tol, "joint axes 4, 5, 6 do not meet in one point")
    need(abs(abs(s[3]) - 1) < 1e-9 and abs(abs(s[4]) - 1) < 1e-9, "wrist axes are not mutually perpendicular")
    return PumaGeometry(base=G[0], tool=G[6], offsets=o, alpha=alpha, a=a, d=d)


# ---------------------------------------------------------------------------
# Angle wrapping
# ---------------------------------------------------------------------------
def wrap_into_limits(q: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Each angle of ``q: (..., dof)`` moved by a multiple of 2 pi into ``[lo, hi]`` where possible.

    The representative in ``[-pi, pi)`` is kept when it lies inside; otherwise ``+2 pi`` then
    ``-2 pi`` are tried; an angle with no representative inside stays in ``[-pi, pi)``.
    """
    w = torch.remainder(q + math.pi, _TWO_PI) - math.pi
    up, down = w + _TWO_PI, w - _TWO_PI
    inside = (w >= lo) & (w <= hi)
    other = torch.where((down >= lo) & (down <= hi), down, w)
    return torch.where(inside, w, torch.where((up >= lo) & (up <= hi), up, other))


# ---------------------------------------------------------------------------
# The kernel (elementwise tensor work; compiled on request)
# ---------------------------------------------------------------------------
def _qz_left(c, s, q):
    """(c, 0, 0, s) * q, Hamilton product; q = (w, x, y, z) components."""
    w, x, y, z = q
    return (c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w)


def _qx_left(c, s, q):
    """(c, s, 0, 0) * q."""
    w, x, y, z = q
    return (c * w - s * x, c * x + s * w, c * y - s * z, c * z + s * y)


def _qx_right(q, c, s):
    """q * (c, s, 0, 0)."""
    w, x, y, z = q
    return (c * w - s * x, c * x + s * w, c * y + s * z, c * z - s * y)


def _rz_left_t(c, s, rows):
    """Rz(theta)^T @ A for A given by its rows (each a 3-tuple of tensors)."""
    r0, r1, r2 = rows
    return (
        tuple(c * u + s * v for u, v in zip(r0, r1, strict=True)),
        tuple(-s * u + c * v for u, v in zip(r0, r1, strict=True)),
        r2,
    )


def _rx_left_t(c, s, rows):
    """Rx(alpha)^T @ A for A given by its rows."""
    r0, r1, r2 = rows
    return (
        r0,
        tuple(c * u + s * v for u, v in zip(r1, r2, strict=True)),
        tuple(-s * u + c * v for u, v in zip(r1, r2, strict=True)),
    )


def _ik_kernel(p: torch.Tensor, R: torch.Tensor, k: dict, quaternion: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """Core closed form.

    Args:
        p: (N, 3) wrist-centre positions in the base-removed frame (metres).
        R: (N, 3, 3) wrist rotations ``G_0^-1 T G_6^-1`` (rotation part).
        k: Python-float constants of the geometry (see :func:`_constants`).
        quaternion: wrist by unit quaternions (True) or rotation matrices (False).

    Returns:
        ``theta: (N, 8, 6)`` canonical joint angles and ``reach: (N, 8)`` bool.
    """
    sign = torch.tensor([1.0, -1.0], dtype=p.dtype, device=p.device)
    px, py, pz = p[:, 0:1], p[:, 1:2], p[:, 2:3]  # (N, 1)
    # shoulder: theta_1 (N, 2)
    disc1 = px * px + py * py - k["Z2"] ** 2
    reach1 = disc1 >= -k["tol1"]
    sq1 = torch.sqrt(torch.clamp(disc1, min=0.0)) * sign
    th1 = torch.atan2(py, px) - torch.atan2(torch.full_like(sq1, -k["s1"] * k["Z2"]), sq1)
    X2 = sq1 - k["a1"]  # (N, 2)
    Y2 = (k["s1"] * (pz - k["d1"])).expand_as(X2)
    # elbow: phi_3 (N, 2, 2)
    kk = (X2 * X2 + Y2 * Y2 - k["a2"] ** 2 - k["L2"]) / (2.0 * k["a2"])
    disc3 = k["L2"] - kk * kk
    reach3 = disc3 >= -k["tol3"]
    sq3 = torch.sqrt(torch.clamp(disc3, min=0.0))[..., None] * sign
    phi3 = torch.atan2(sq3, kk[..., None].expand_as(sq3)) - k["psi"]
    c3, s3 = torch.cos(phi3), torch.sin(phi3)
    rx = k["a2"] + k["u"] * c3 - k["w"] * s3
    ry = k["u"] * s3 + k["w"] * c3
    th2 = torch.atan2(Y2, X2)[..., None] - torch.atan2(ry, rx)  # (N, 2, 2)
    th23 = th2 + phi3
    th1e = th1[..., None].expand_as(th2)
    if quaternion:
        # q_36 = conj(q_03) * q_R * qx(-(alpha4 + alpha5)), q_03 = qz(th1) qx(al1) qz(th23) qx(al3')
        qR = matrix_to_quaternion(R)  # (N, 4) Shepperd
        qR = tuple(c[:, None, None] for c in qR.unbind(-1))
        qR = _qx_right(qR, k["qe_c"], k["qe_s"])
        h1, h23 = -0.5 * th1e, -0.5 * th23
        qN = _qz_left(torch.cos(h1), torch.sin(h1), qR)
        qN = _qx_left(k["ca1"], -k["sa1"], qN)
        qN = _qz_left(torch.cos(h23), torch.sin(h23), qN)
        w, x, y, z = _qx_left(k["ca3"], -k["sa3"], qN)
        half_sum = torch.atan2(z, w)  # (a + c) / 2
        half_diff = torch.atan2(-x, y)  # (a - c) / 2
        b = 2.0 * torch.atan2(torch.sqrt(x * x + y * y), torch.sqrt(w * w + z * z))
        a_ = half_sum + half_diff
        c_ = half_sum - half_diff
    else:
        rows = tuple(tuple(R[:, i, j][:, None, None] for j in range(3)) for i in range(3))
        rows = _rz_left_t(torch.cos(th1e), torch.sin(th1e), rows)
        rows = _rx_left_t(k["ca1"], k["sa1"], rows)
        rows = _rz_left_t(torch.cos(th23), torch.sin(th23), rows)
        (n00, n01, n02), (n10, n11, n12), (n20, n21, n22) = _rx_left_t(k["ca3"], k["sa3"], rows)
        # N = M E^T with E = Rx(alpha4 + alpha5) in {I, Rx(pi)}: negate columns 1 and 2 for Rx(pi)
        e = k["ce"]
        n01, n02, n11, n12, n22 = e * n01, e * n02, e * n11, e * n12, e * n22
        b = torch.atan2(torch.sqrt(n02 * n02 + n12 * n12), n22)
        a_ = torch.atan2(n12, n02)
        ca, sa = torch.cos(a_), torch.sin(a_)
        c_ = torch.atan2(-sa * n00 + ca * n10, -sa * n01 + ca * n11)
    # two wrist flips: (a, b, c) and (a + pi, -b, c + pi); theta5 = -sigma4 * b, theta6 = eps * c
    th4 = torch.stack([a_, a_ + math.pi], dim=-1)
    th5 = torch.stack([b, -b], dim=-1) * (-k["sig4"])
    th6 = torch.stack([c_, c_ + math.pi], dim=-1) * k["ce"]
    expand = th4.shape
    theta = torch.stack(
        [
            th1e[..., None].expand(expand),
            th2[..., None].expand(expand),
            (k["c2"] * phi3)[..., None].expand(expand),
            th4,
            th5,
            th6,
        ],
        dim=-1,
    ).reshape(-1, 8, 6)
    reach = (reach1 & reach3)[..., None, None].expand(expand).reshape(-1, 8)
    return theta, reach


def _solve(Tf, base, tool, off, lo, hi, k: dict, quaternion: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """``Tf: (N, 4, 4)`` -> ``q: (N, 8, 6)`` wrapped into the limits, ``valid: (N, 8)`` (reach and limits)."""
    # wrist frame W = G_0^-1 T G_6^-1: removes the base and the tool (d6) transforms
    Rb, tb, Rt, tt = base[:3, :3], base[:3, 3], tool[:3, :3], tool[:3, 3]
    R = Rb.T @ Tf[:, :3, :3] @ Rt.T
    p = (Tf[:, :3, 3] - tb) @ Rb - R @ tt  # Rb^T (p_T - t_b) - R_W t_t
    theta, reach = _ik_kernel(p, R, k, quaternion)
    q = wrap_into_limits(theta - off, lo, hi)
    return q, reach & ((q >= lo) & (q <= hi)).all(dim=-1)


_compiled_kernels: dict = {}


def compiled_once(fn, what: str):
    """``fn`` compiled by ``torch.compile(dynamic=True)``, once per process; ``fn`` itself (with one warning naming
    ``what``) where compiling is unavailable. Serves both closed forms' ``compiled=True``."""
    if fn not in _compiled_kernels:
        try:
            _compiled_kernels[fn] = torch.compile(fn, dynamic=True)
        except Exception as err:  # pragma: no cover - platform dependent
            warnings.warn(f"torch.compile unavailable ({err}); {what} runs eager", stacklevel=4)
            _compiled_kernels[fn] = fn
    return _compiled_kernels[fn]


def _kernel(compiled: bool):
    return compiled_once(_solve, "puma560_ik") if compiled else _solve


def _constants(g: PumaGeometry) -> dict:
    al, a, d = g.alpha, g.a, g.d
    c2 = 1.0 if math.cos(al[1]) > 0 else -1.0
    u = float(a[2])
    w = c2 * float(-math.sin(al[2]) * d[3])  # v3 = G3 (0, 0, d4) = (a3, -sin(al3) d4, d3 + cos(al3) d4)
    h = c2 * float(d[2] + math.cos(al[2]) * d[3])
    al3 = float(al[1] + al[2])  # Rx(alpha2) Rx(alpha3), alpha2 in {0, pi}
    sig4 = 1.0 if math.sin(al[3]) > 0 else -1.0
    sig5 = 1.0 if math.sin(al[4]) > 0 else -1.0
    ce = -1.0 if sig4 == sig5 else 1.0  # E = Rx(alpha4 + alpha5): Rx(pi) when the signs agree
    scale = float(np.abs(a).sum() + np.abs(d).sum())
    return {
        "s1": 1.0 if math.sin(al[0]) > 0 else -1.0,
        "a1": float(a[0]),
        "d1": float(d[0]),
        "a2": float(a[1]),
        "Z2": h + float(d[1]),
        "c2": c2,
        "u": u,
        "w": w,
        "L2": u * u + w * w,
        "psi": math.atan2(w, u),
        "ca1": math.cos(al[0] / 2),
        "sa1": math.sin(al[0] / 2),
        "ca3": math.cos(al3 / 2),
        "sa3": math.sin(al3 / 2),
        "ce": ce,
        # qx(-(alpha4 + alpha5)): the identity, or a half turn about x (its sign does not matter)
        "qe_c": 1.0 if ce > 0 else 0.0,
        "qe_s": 0.0 if ce > 0 else 1.0,
        "sig4": sig4,
        "tol1": 1e-12 * scale * scale,
        "tol3": 1e-12 * scale * scale,
    }


def _constants_matrix(g: PumaGeometry) -> dict:
    k = _constants(g)
    al3 = float(g.alpha[1] + g.alpha[2])
    k["ca1"], k["sa1"] = math.cos(g.alpha[0]), math.sin(g.alpha[0])
    k["ca3"], k["sa3"] = math.cos(al3), math.sin(al3)
    return k


# ---------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------
def puma560_ik(
    robot,
    T: torch.Tensor,
    *,
    wrist: str = "quaternion",
    check: bool = True,
    tol_pos: float | None = None,
    tol_rot: float | None = None,
    compiled: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    """All 8 closed-form IK solutions of a PUMA-like arm.

    Args:
        robot: a :class:`nik.Robot` with PUMA-560-type geometry (``puma560``, ``kuka_kr``,
            ``rebot_v_6r``, any DH table of that shape); otherwise ``ValueError``.
        T: (..., 4, 4) target tool poses, metres; any float dtype/device.
        wrist: ``"quaternion"`` (paper B) or ``"matrix"``: how theta_4..6 are extracted.
        check: verify every solution by FK (batched) and mark it invalid unless it reaches the pose
            within ``tol_pos`` / ``tol_rot``. With ``check=False`` the mask is reachability and
            joint limits only.
        tol_pos: metres; default 1e-6 (float64) or 2e-5 (lower precision).
        tol_rot: radians; default 1e-6 (float64) or 2e-5 (lower precision).
        compiled: run a ``torch.compile``'d kernel (large batches; the first call compiles).

    Returns:
        ``q: (..., 8, 6)`` joint angles (radians, dtype/device of ``T``; each angle moved by
        2 pi into its limits where possible) and ``valid: (..., 8)`` bool: the solution exists
        (no square root of a negative number), lies inside the joint limits and (with ``check``)
        reaches the pose. Invalid entries hold finite, meaningless values. Solution ``k``:
        shoulder ``k >> 2``, elbow ``(k >> 1) & 1``, wrist flip ``k & 1``.
    """
    if wrist not in ("quaternion", "matrix"):
        raise ValueError(f"puma560_ik: wrist must be 'quaternion' or 'matrix', got {wrist!r}")
    if not isinstance(T, torch.Tensor) or T.ndim < 2 or T.shape[-2:] != (4, 4) or not T.is_floating_point():
        shape = tuple(T.shape) if isinstance(T, torch.Tensor) else type(T).__name__
        raise ValueError(f"puma560_ik: T must be a floating-point tensor of shape (..., 4, 4), got {shape}")
    geom = puma560_params(robot)
    batch = T.shape[:-2]
    Tf = T.reshape(-1, 4, 4)
    base = torch.as_tensor(geom.base, dtype=T.dtype, device=T.device)
    tool = torch.as_tensor(geom.tool, dtype=T.dtype, device=T.device)
    off = torch.as_tensor(geom.offsets, dtype=T.dtype, device=T.device)
    lo, hi = robot.limits_as(Tf)
    k = _constants(geom) if wrist == "quaternion" else _constants_matrix(geom)
    q, valid = _kernel(compiled)(Tf, base, tool, off, lo, hi, k, wrist == "quaternion")
    if check:
        exact = T.dtype == torch.float64
        tp = tol_pos if tol_pos is not None else (1e-6 if exact else 2e-5)
        tr = tol_rot if tol_rot is not None else (1e-6 if exact else 2e-5)
        reached = robot.fk(q.reshape(-1, 6), compiled=compiled).reshape(-1, 8, 4, 4)
        pe, re = pose_error(Tf[:, None], reached)
        valid = valid & (pe <= tp) & (re <= tr)
    return q.reshape(*batch, 8, 6), valid.reshape(*batch, 8)
