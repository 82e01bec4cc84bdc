"""Damped Levenberg-Marquardt for one pose, with joint limits and seeded restarts, compiled.

The algorithm is the one of the batched torch LM and its numpy one-pose version (the error, the
Marquardt-scaled damping, the active set at the limits, the stall test, restarts from uniform
configurations), written for one target and compiled once for every robot (the model arrays of
:mod:`nik.kernels.chain` are passed in).

Error of a configuration (6-vector, base frame)::

    e = [p* - p ;  w * log(R* R^T)]        (metres; w = rot_weight, metres per radian)

with the rotation vector's angle taken as ``atan2(|sin|, cos)``. Step::

    dq = (J^T J + lambda (diag(J^T J) + eps) + eps I)^-1 J^T e

(the one step of :mod:`nik.kernels.lm_step`, with its accept and damping rule) by a Cholesky factorisation written
out (a failed factorisation is a rejected step), scaled so that
no joint moves more than ``max_step``, then brought inside the limits (a wrapping joint moves by whole
turns, the others are clamped). A joint held at a limit that the descent direction pushes further out
is left out of the step (active set), and so is one that the step solved without it would push out (the step is
solved once more: the clamp would move that joint less than the others assumed). A step is kept only when it
lowers ``|e|^2``; lambda then shrinks by ``lambda_down``, else grows by ``lambda_up``. A start is spent after
``stall_iters`` iterations in a row that lower ``|e|^2`` by less than the fraction ``stall_rel``, or after its
iteration limit; then, while restarts are left, a fresh start is drawn uniformly inside the limits.

Random numbers come from a splitmix64 stream whose state (``rng: (1,) uint64``) the caller seeds:
same seed, same answer, and no global random state is touched.

Options are two small arrays (:func:`lm_options` builds them from keywords):
``opts: float64`` (indices ``ROT_WEIGHT ... TOL_ROT``) and ``iopts: int64`` (``FIRST_ITERS ... FIRST_STARTS``);
the restart budget is per target (a target proven out of reach gets none).

Tolerant goals (:func:`lm_solve_bounded`, :func:`bounded_errors`; the bounds of :mod:`nik.ik.bounds`): per target
half-widths ``bounds: (6,)`` (``x, y, z`` m, ``rx, ry, rz`` rad along the target's tool axes, ``inf`` = free) and
a rotation mode (:func:`rotation_modes`: -1 none free, 0/1/2 that tool axis free, 3 all). The raw error ``d``
(:func:`_tool_error`) is TRAC-IK's: ``R_t^T (p - p_t)`` and the rotation vector of ``R_t^T R``, or, with tool axis
``k`` free, the swing of that axis (2 rows: the tilt between target and reached axis ``k``; a rotation vector's
components mix twist and tilt, so dropping one of them would not leave the twist free). The residual is a dead
zone, ``r_i = sign(d_i) max(|d_i| - DEAD_ZONE * bound_i, 0)``, with the exact Jacobian of ``d`` (the rotation
vector's through ``J_l^-1``, the swing's through the derivative of the axis); the rows of free axes vanish. The
zone is the inner half of the bound, so a Gauss-Newton step lands inside the bound instead of creeping up to its
edge; a start stops when every ``|d_i| <= bound_i``. A bounded row keeps its Jacobian inside its zone (where the
dead zone's own derivative is 0): the linear model then holds that row where it is instead of letting the step
push it back out. Measured on 200 panda targets from starts 0.3 rad away (bounds 0.1 mm / 1 mrad): the
dead zone's own Jacobian needed 27.7 iterations and reached 87.5 %, the kept rows 4.6 and 100 % (the classic
error: 4.6, 100 %).
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, UPPER, WRAPS, _chain, _chain_jacobian
from nik.kernels.lm_loop import ACCEPT_DONE, ACCEPT_LOWER, _lm_loop, _loop_cfg, problem_kind
from nik.kernels.lm_step import _dense_step

__all__ = [
    "LMOptions",
    "bounded_errors",
    "bounded_residuals",
    "lm_options",
    "lm_solve",
    "lm_solve_bounded",
    "pose_errors",
    "rotation_modes",
    "seed_state",
    "uniform_configurations",
]

# entries of opts (float64) and iopts (int64), see lm_options
ROT_WEIGHT, LAMBDA0, LAMBDA_UP, LAMBDA_DOWN, LAMBDA_MIN, LAMBDA_MAX = 0, 1, 2, 3, 4, 5
EPS, MAX_STEP, STALL_REL, TOL_POS, TOL_ROT = 6, 7, 8, 9, 10
#: the weight of the manipulability preference of :func:`nik.kernels.driver.rest_posture` (0: none; only it reads it)
MANIPULABILITY = 11
FIRST_ITERS, ITERS, STALL_ITERS, FIRST_STARTS, TAIL_AFTER, TAIL_ITERS, TAIL_STALL_ITERS = range(7)

_TWO_PI = 2.0 * math.pi
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV_2_53 = 1.0 / 9007199254740992.0
_STREAM = np.uint64(0xD1B54A32D192ED03)  # separates the random streams of the targets of one call
#: rotation mode of the classic error (norm tolerances), the mode argument of :func:`_lm_one_bounded`
CLASSIC = -2
#: the residual's dead zone, as a fraction of each bound (see the module docstring)
DEAD_ZONE = 0.5

#: One pose's problem for :func:`nik.kernels.lm_loop._lm_loop`: the model ``G, joints``; the goal ``(Tt (4, 4),
#: rw, bnd (6,), mode, tol_pos, tol_rot)`` of :func:`_eval_goal`; the dense step's prior row ``(q_prior (n,),
#: w_prior2)`` (or ``None``), ``eps`` and ``max_step``; scratch ``d (6,)`` and ``work = (A (n, n), g (n,), dq (n,))``.
PoseProblem = namedtuple("PoseProblem", ["G", "joints", "goal", "prior", "eps", "max_step", "d", "work"])
#: One pose's state: ``q (n,)``, its FK ``T (3, 4)``, rows ``J (6, n)``, ``e (6,)``, ``info (3,)`` = its cost,
#: position error (m) and rotation angle (rad), and extra rows ``(Jr (R, n), r (R,), w2)`` (or ``None``).
PoseState = namedtuple("PoseState", ["q", "T", "J", "e", "info", "extra"])


@dataclass(frozen=True)
class LMOptions:
    """The settings of the compiled one-pose LM (defaults: those of the batched LM's ``LMCfg`` and nik's one
    tolerance, 0.1 mm / 0.1 deg).

    Units: ``rot_weight`` m/rad, ``eps`` m^2, ``max_step`` rad (m for prismatic joints), ``tol_pos`` m,
    ``tol_rot`` rad. ``first_iters``: iteration limit of the first start, ``iters``: of each restart;
    ``first_starts``: when > 0, the first start is the best
    (by pose error) of that many uniform configurations instead of ``q0``. The restarts after the first
    ``tail_after`` (default: none) run ``tail_iters`` iterations at most and stop after ``tail_stall_iters``
    without progress (defaults ``iters`` and ``stall_iters``): longer runs for the hard targets that are left.
    """

    rot_weight: float = 0.5
    lambda0: float = 1e-3
    lambda_up: float = 5.0
    lambda_down: float = 0.3
    lambda_min: float = 1e-9
    lambda_max: float = 1e6
    eps: float = 1e-9
    max_step: float = 0.5
    stall_rel: float = 1e-3
    tol_pos: float = 1e-4
    tol_rot: float = math.radians(0.1)
    first_iters: int = 25
    iters: int = 25
    stall_iters: int = 4
    first_starts: int = 0
    tail_after: int | None = None
    tail_iters: int | None = None
    tail_stall_iters: int | None = None


def lm_options(**settings) -> tuple[np.ndarray, np.ndarray]:
    """``(opts, iopts)`` for :func:`lm_solve` from the keywords of :class:`LMOptions` (its fields; an unknown name
    is a ``TypeError``)."""
    o = LMOptions(**settings)
    opts = np.zeros(12)  # opts[MANIPULABILITY] = 0: set per call by the preference's caller
    opts[[ROT_WEIGHT, LAMBDA0, LAMBDA_UP, LAMBDA_DOWN, LAMBDA_MIN, LAMBDA_MAX]] = (
        o.rot_weight, o.lambda0, o.lambda_up, o.lambda_down, o.lambda_min, o.lambda_max
    )  # fmt: skip
    opts[[EPS, MAX_STEP, STALL_REL, TOL_POS, TOL_ROT]] = o.eps, o.max_step, o.stall_rel, o.tol_pos, o.tol_rot
    iopts = np.empty(7, dtype=np.int64)
    iopts[[FIRST_ITERS, ITERS, STALL_ITERS, FIRST_STARTS]] = o.first_iters, o.iters, o.stall_iters, o.first_starts
    iopts[[TAIL_AFTER, TAIL_ITERS, TAIL_STALL_ITERS]] = (
        2**62 if o.tail_after is None else o.tail_after,
        o.iters if o.tail_iters is None else o.tail_iters,
        o.stall_iters if o.tail_stall_iters is None else o.tail_stall_iters,
    )
    if (iopts < 0).any():
        raise ValueError(f"lm_options: iteration counts and starts must be >= 0, got {iopts.tolist()}")
    return opts, iopts


def seed_state(seed: int) -> np.ndarray:
    """The random state ``(1,) uint64`` of a seed (any Python int; taken modulo 2^64)."""
    return np.array([int(seed) & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64)


@kernel
def _work_size(n):
    """Length of :func:`lm_solve`'s scratch for ``n`` joints: ``48 + 12 n + n^2 + 6 n`` float64."""
    return 48 + 12 * n + n * n + 6 * n


# ---------------------------------------------------------------------------
# building blocks
# ---------------------------------------------------------------------------
@kernel
def _copy(src, dst):
    """``dst[:] = src`` for 1-D arrays, as a plain loop."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@kernel
def _uniform(rng):
    """The next number of the splitmix64 stream in ``[0, 1)`` (53 bits); ``rng: (1,) uint64`` advances."""
    z = rng[0] + _GOLDEN
    rng[0] = z
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    z = z ^ (z >> _S31)
    return float(z >> _S11) * _INV_2_53


@kernel
def _draw(joints, rng, q):
    """``q (n,)`` uniform inside the limits."""
    for i in range(q.shape[0]):
        lo, hi = joints[i, LOWER], joints[i, UPPER]
        q[i] = min(max(lo + _uniform(rng) * (hi - lo), lo), hi)


@kernel
def _bounds(joints, q):
    """``q (n,)`` brought inside the limits in place: wrapping joints by whole turns, the others clamped."""
    for i in range(q.shape[0]):
        lo, hi, x = joints[i, LOWER], joints[i, UPPER], q[i]
        if joints[i, WRAPS] != 0.0:
            up = max(math.ceil((lo - x) / _TWO_PI), 0.0)
            down = max(math.ceil((x - hi) / _TWO_PI), 0.0)
            x = x + _TWO_PI * (up - down)
        q[i] = min(max(x, lo), hi)


@kernel
def turns_toward(joints, q, target):
    """``q: (B, n)`` in place: each wrapping joint moved by whole turns, inside its limits, as near ``target: (B, n)``
    as it goes (the same poses; a joint that crossed a limit of a range of 2 pi or more comes back)."""
    for b in range(q.shape[0]):
        for i in range(q.shape[1]):
            if joints[i, WRAPS] == 0.0:
                continue
            lo, hi = joints[i, LOWER], joints[i, UPPER]
            x = q[b, i] + _TWO_PI * math.floor((target[b, i] - q[b, i]) / _TWO_PI + 0.5)
            if x > hi:
                x -= _TWO_PI
            elif x < lo:
                x += _TWO_PI
            q[b, i] = min(max(x, lo), hi)


@kernel
def _residual(Tt, T, rw, e):
    """Weighted error ``e (6,)`` of the pose ``T (3, 4)`` against ``Tt (4, 4)``; returns
    ``(|e|^2, position error m, rotation angle rad)``."""
    dx, dy, dz = Tt[0, 3] - T[0, 3], Tt[1, 3] - T[1, 3], Tt[2, 3] - T[2, 3]
    # M = R* R^T, only what the rotation vector needs
    m01 = Tt[0, 0] * T[1, 0] + Tt[0, 1] * T[1, 1] + Tt[0, 2] * T[1, 2]
    m02 = Tt[0, 0] * T[2, 0] + Tt[0, 1] * T[2, 1] + Tt[0, 2] * T[2, 2]
    m10 = Tt[1, 0] * T[0, 0] + Tt[1, 1] * T[0, 1] + Tt[1, 2] * T[0, 2]
    m12 = Tt[1, 0] * T[2, 0] + Tt[1, 1] * T[2, 1] + Tt[1, 2] * T[2, 2]
    m20 = Tt[2, 0] * T[0, 0] + Tt[2, 1] * T[0, 1] + Tt[2, 2] * T[0, 2]
    m21 = Tt[2, 0] * T[1, 0] + Tt[2, 1] * T[1, 1] + Tt[2, 2] * T[1, 2]
    m00 = Tt[0, 0] * T[0, 0] + Tt[0, 1] * T[0, 1] + Tt[0, 2] * T[0, 2]
    m11 = Tt[1, 0] * T[1, 0] + Tt[1, 1] * T[1, 1] + Tt[1, 2] * T[1, 2]
    m22 = Tt[2, 0] * T[2, 0] + Tt[2, 1] * T[2, 1] + Tt[2, 2] * T[2, 2]
    sx, sy, sz = 0.5 * (m21 - m12), 0.5 * (m02 - m20), 0.5 * (m10 - m01)
    c = 0.5 * (m00 + m11 + m22 - 1.0)
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    theta = math.atan2(sn, c)
    scale = rw * (theta / sn if sn > 1e-12 else 1.0)
    e[0], e[1], e[2] = dx, dy, dz
    e[3], e[4], e[5] = sx * scale, sy * scale, sz * scale
    pos2 = dx * dx + dy * dy + dz * dz
    return pos2 + (rw * theta) ** 2, math.sqrt(pos2), theta


@kernel
def _evaluate(G, joints, q, Tt, rw, T, J, e):
    """FK, Jacobian (rotation rows times ``rw``) and error of ``q``; returns ``(E, pos, rot)``."""
    _chain_jacobian(G, joints, q, T, J)
    for r in range(3, 6):
        for i in range(q.shape[0]):
            J[r, i] *= rw
    return _residual(Tt, T, rw, e)


@kernel
def _tool_error(Tt, T, mode, d):
    """Raw error ``d (6,)`` of ``T (3, 4)`` in the tool frame of ``Tt (4, 4)`` (see the module docstring; entry
    ``k`` of a free axis ``k`` is 0 here, not the twist); returns ``(position error m, rotation angle rad)``."""
    dx, dy, dz = T[0, 3] - Tt[0, 3], T[1, 3] - Tt[1, 3], T[2, 3] - Tt[2, 3]
    for r in range(3):
        d[r] = Tt[0, r] * dx + Tt[1, r] * dy + Tt[2, r] * dz
    # R_rel = R_t^T R, entry by entry
    m00 = Tt[0, 0] * T[0, 0] + Tt[1, 0] * T[1, 0] + Tt[2, 0] * T[2, 0]
    m11 = Tt[0, 1] * T[0, 1] + Tt[1, 1] * T[1, 1] + Tt[2, 1] * T[2, 1]
    m22 = Tt[0, 2] * T[0, 2] + Tt[1, 2] * T[1, 2] + Tt[2, 2] * T[2, 2]
    m01 = Tt[0, 0] * T[0, 1] + Tt[1, 0] * T[1, 1] + Tt[2, 0] * T[2, 1]
    m10 = Tt[0, 1] * T[0, 0] + Tt[1, 1] * T[1, 0] + Tt[2, 1] * T[2, 0]
    m02 = Tt[0, 0] * T[0, 2] + Tt[1, 0] * T[1, 2] + Tt[2, 0] * T[2, 2]
    m20 = Tt[0, 2] * T[0, 0] + Tt[1, 2] * T[1, 0] + Tt[2, 2] * T[2, 0]
    m12 = Tt[0, 1] * T[0, 2] + Tt[1, 1] * T[1, 2] + Tt[2, 1] * T[2, 2]
    m21 = Tt[0, 2] * T[0, 1] + Tt[1, 2] * T[1, 1] + Tt[2, 2] * T[2, 1]
    sx, sy, sz = 0.5 * (m21 - m12), 0.5 * (m02 - m20), 0.5 * (m10 - m01)
    c = 0.5 * (m00 + m11 + m22 - 1.0)
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    theta = math.atan2(sn, c)
    if mode == 3:  # every rotation axis free: nothing to measure
        d[3], d[4], d[5] = 0.0, 0.0, 0.0
    elif mode < 0:
        if sn > 1e-6 or c > 0.0:
            scale = theta / sn if sn > 1e-12 else 1.0
            d[3], d[4], d[5] = sx * scale, sy * scale, sz * scale
        else:  # near pi: the axis from the symmetric part (the antisymmetric one has vanished)
            if m00 >= m11 and m00 >= m22:
                ax = math.sqrt(max(0.5 * (m00 + 1.0), 0.0))
                ay, az = 0.25 * (m01 + m10) / ax, 0.25 * (m02 + m20) / ax
            elif m11 >= m22:
                ay = math.sqrt(max(0.5 * (m11 + 1.0), 0.0))
                ax, az = 0.25 * (m01 + m10) / ay, 0.25 * (m12 + m21) / ay
            else:
                az = math.sqrt(max(0.5 * (m22 + 1.0), 0.0))
                ax, ay = 0.25 * (m02 + m20) / az, 0.25 * (m12 + m21) / az
            d[3], d[4], d[5] = theta * ax, theta * ay, theta * az
    else:
        # swing of tool axis k: v = R_rel e_k, s = phi / |e_k x v| (e_k x v)
        if mode == 0:
            vi, vj, vk = m10, m20, m00
        elif mode == 1:
            vi, vj, vk = m21, m01, m11
        else:
            vi, vj, vk = m02, m12, m22
        sg = math.sqrt(vi * vi + vj * vj)
        i, j = 3 + (mode + 1) % 3, 3 + (mode + 2) % 3
        if sg > 1e-7:
            f = math.atan2(sg, vk) / sg
            d[i], d[j] = -f * vj, f * vi
        elif vk > 0.0:
            d[i], d[j] = -vj, vi
        else:  # the axis turned over: a half turn about an axis of its own choosing
            d[i], d[j] = math.pi, 0.0
        d[3 + mode] = 0.0
    return math.sqrt(dx * dx + dy * dy + dz * dz), theta


@kernel
def _dead_zone(d, bnd, rw, e):
    """``e (6,) = -r`` of the dead-zone residual ``r`` of ``d (6,)`` (rotation rows times ``rw``); returns
    ``(|e|^2, every |d_i| <= bound_i)``."""
    E = 0.0
    inside = True
    for r in range(6):
        b, x = bnd[r], d[r]
        a = abs(x)
        if not a <= b:
            inside = False
        z = DEAD_ZONE * b
        v = 0.0
        if a > z:
            v = x - z if x > 0.0 else x + z
        if r >= 3:
            v *= rw
        e[r] = -v
        E += v * v
    return E, inside


@kernel
def _live(b, w):
    """``w`` for a row with a finite bound ``b``, 0 for a free one."""
    return w if b < math.inf else 0.0


@kernel
def _bounded_evaluate(G, joints, q, Tt, rw, bnd, mode, T, J, e, d):
    """FK, error ``d (6,)`` in the target's tool frame, dead-zone residual ``e = -r (6,)`` and its Jacobian
    ``J (6, n)`` (``dr/dq``, rotation rows times ``rw``); returns ``(E, pos, rot, inside)``."""
    _chain_jacobian(G, joints, q, T, J)
    pos, rot = _tool_error(Tt, T, mode, d)
    E, inside = _dead_zone(d, bnd, rw, e)
    n = q.shape[0]
    # rotation-row coefficients: drot = M a, a = R_t^T omega (the target frame's angular velocity)
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if mode < 0:  # rotation vector: J_l^-1(phi) = I - [phi]x / 2 + c [phi]x^2
        px, py, pz = d[3], d[4], d[5]
        th = math.sqrt(px * px + py * py + pz * pz)
        h = 0.5 * th
        cc = (1.0 - h * math.cos(h) / math.sin(h)) / (th * th) if th > 1e-4 else 1.0 / 12.0
        # [phi]x^2 = phi phi^T - th^2 I
        m00, m11, m22 = 1.0 + cc * (px * px - th * th), 1.0 + cc * (py * py - th * th), 1.0 + cc * (pz * pz - th * th)
        m01, m10 = 0.5 * pz + cc * px * py, -0.5 * pz + cc * px * py
        m02, m20 = -0.5 * py + cc * px * pz, 0.5 * py + cc * px * pz
        m12, m21 = 0.5 * px + cc * py * pz, -0.5 * px + cc * py * pz
    elif mode < 3:  # swing of tool axis k: ds = (ds/dv) (a x v), v = R_rel e_k
        k = mode
        i, j = (k + 1) % 3, (k + 2) % 3
        # v in target coordinates
        v0 = Tt[0, 0] * T[0, k] + Tt[1, 0] * T[1, k] + Tt[2, 0] * T[2, k]
        v1 = Tt[0, 1] * T[0, k] + Tt[1, 1] * T[1, k] + Tt[2, 1] * T[2, k]
        v2 = Tt[0, 2] * T[0, k] + Tt[1, 2] * T[1, k] + Tt[2, 2] * T[2, k]
        vi = v0 if i == 0 else (v1 if i == 1 else v2)
        vj = v0 if j == 0 else (v1 if j == 1 else v2)
        vk = v0 if k == 0 else (v1 if k == 1 else v2)
        s2 = vi * vi + vj * vj
        sg = math.sqrt(s2)
        n2 = s2 + vk * vk
        if sg > 1e-4:
            phi = math.atan2(sg, vk)
            f = phi / sg
            gs = (vk * sg / n2 - phi) / (s2 * sg)  # (df/dsigma) / sigma
        else:
            f, gs = 1.0, -2.0 / 3.0
        fk = -1.0 / n2
        # rows of ds/dv in (i, j, k) coordinates
        a_ii, a_ij, a_ik = -vj * gs * vi, -f - vj * gs * vj, -vj * fk
        b_ji, b_jj, b_jk = f + vi * gs * vi, vi * gs * vj, vi * fk
        # dv = a x v = C (a_i, a_j, a_k): dv_i = v_k a_j - v_j a_k, dv_j = v_i a_k - v_k a_i, dv_k = v_j a_i - v_i a_j
        # ds_i = (a_i*, a_j*, a_k*) . dv: coefficients of (a_i, a_j, a_k)
        ri0, ri1, ri2 = -a_ij * vk + a_ik * vj, a_ii * vk - a_ik * vi, -a_ii * vj + a_ij * vi
        rj0, rj1, rj2 = -b_jj * vk + b_jk * vj, b_ji * vk - b_jk * vi, -b_ji * vj + b_jj * vi
        # scatter to (x, y, z): row i of M is ri, row j is rj, row k stays zero
        if k == 0:  # (i, j, k) = (y, z, x)
            m11, m12, m10, m21, m22, m20 = ri0, ri1, ri2, rj0, rj1, rj2
        elif k == 1:  # (z, x, y)
            m22, m20, m21, m02, m00, m01 = ri0, ri1, ri2, rj0, rj1, rj2
        else:  # (x, y, z)
            m00, m01, m02, m10, m11, m12 = ri0, ri1, ri2, rj0, rj1, rj2
    # free rows vanish; a bounded row keeps its Jacobian inside its dead zone (see the module docstring)
    l0, l1, l2 = _live(bnd[0], 1.0), _live(bnd[1], 1.0), _live(bnd[2], 1.0)
    l3, l4, l5 = _live(bnd[3], rw), _live(bnd[4], rw), _live(bnd[5], rw)
    for c in range(n):
        ux, uy, uz = J[0, c], J[1, c], J[2, c]
        wx, wy, wz = J[3, c], J[4, c], J[5, c]
        a0 = Tt[0, 0] * wx + Tt[1, 0] * wy + Tt[2, 0] * wz
        a1 = Tt[0, 1] * wx + Tt[1, 1] * wy + Tt[2, 1] * wz
        a2 = Tt[0, 2] * wx + Tt[1, 2] * wy + Tt[2, 2] * wz
        J[0, c] = l0 * (Tt[0, 0] * ux + Tt[1, 0] * uy + Tt[2, 0] * uz)
        J[1, c] = l1 * (Tt[0, 1] * ux + Tt[1, 1] * uy + Tt[2, 1] * uz)
        J[2, c] = l2 * (Tt[0, 2] * ux + Tt[1, 2] * uy + Tt[2, 2] * uz)
        J[3, c] = l3 * (m00 * a0 + m01 * a1 + m02 * a2)
        J[4, c] = l4 * (m10 * a0 + m11 * a1 + m12 * a2)
        J[5, c] = l5 * (m20 * a0 + m21 * a1 + m22 * a2)
    return E, pos, rot, inside


@kernel
def _measure_pose(prob, s, bar):
    """The loop's measure of a pose problem (:data:`PoseProblem`): FK, rows and cost of ``s.q`` into the state
    ``s`` (:data:`PoseState`); returns ``(cost, done)`` (:func:`_eval_goal`; ``bar`` unused: every row counts)."""
    E, pos, rot, done = _eval_goal(prob.G, prob.joints, s.q, prob.goal, s.T, s.J, s.e, prob.d)
    s.info[0], s.info[1], s.info[2] = E, pos, rot
    return E, done


@kernel
def _propose_dense(prob, s, lam, c):
    """The loop's proposal of a pose problem: the dense damped step of :func:`nik.kernels.lm_step._dense_step` (the
    state's extra rows, the problem's prior), ``c.q = s.q + dq`` brought inside the limits (:func:`_bounds`);
    returns ``(good, inf)`` (no tiny-step rule)."""
    good = _dense_step(s.J, s.e, s.extra, prob.prior, s.q, prob.joints, lam, prob.eps, prob.max_step, prob.work)
    if good:
        dq = prob.work[2]
        for i in range(s.q.shape[0]):
            c.q[i] = s.q[i] + dq[i]
        _bounds(prob.joints, c.q)
    return good, math.inf


problem_kind(PoseProblem, _measure_pose, _propose_dense)


@kernel
def _eval_goal(G, joints, q, goal, T, J, e, d):
    """FK, Jacobian and error of ``q`` towards ``goal = (Tt, rw, bnd, mode, tol_pos, tol_rot)`` by the classic error
    (``mode == CLASSIC``) or the bounded one; returns ``(E, pos, rot, done)`` (``done``: within both tolerances, or
    inside every bound)."""
    Tt, rw, bnd, mode, tol_pos, tol_rot = goal
    if mode == CLASSIC:
        E, pos, rot = _evaluate(G, joints, q, Tt, rw, T, J, e)
        return E, pos, rot, pos <= tol_pos and rot <= tol_rot
    return _bounded_evaluate(G, joints, q, Tt, rw, bnd, mode, T, J, e, d)


@kernel
def _score(Tt, T, rw, bnd, mode, e, d):
    """``|e|^2`` of the pose ``T (3, 4)``, classic or bounded (no Jacobian)."""
    if mode == CLASSIC:
        E, _, _ = _residual(Tt, T, rw, e)
        return E
    E, _, _, _ = _bounded_check(Tt, T, bnd, mode, rw, e, d)
    return E


@kernel
def _bounded_check(Tt, T, bnd, mode, rw, e, d):
    """Ranking and final check of the pose ``T (3, 4)`` against a tolerant goal (for drivers that rank
    hypotheses): ``(E, inside, pos, rot)``: the dead-zone ``|e|^2``, every axis inside its bound, the position
    error (m) and the geodesic angle (rad). Scratch ``e, d: (6,)``."""
    pos, rot = _tool_error(Tt, T, mode, d)
    E, inside = _dead_zone(d, bnd, rw, e)
    return E, inside, pos, rot


@kernel
def _best_uniform(G, joints, goal, m, rng, q, scratch):
    """``q (n,)``: the best of ``m`` uniform configurations by ``|e|^2`` towards ``goal`` (as :func:`_eval_goal`'s);
    ``scratch = (cand (n,), T (3, 4), e (6,), d (6,))``."""
    Tt, rw, bnd, mode, _, _ = goal
    cand, T, e, d = scratch
    best = math.inf
    for _ in range(m):
        _draw(joints, rng, cand)
        _chain(G, joints, cand, T)
        E = _score(Tt, T, rw, bnd, mode, e, d)
        if E < best:
            best = E
            _copy(cand, q)


# ---------------------------------------------------------------------------
# the kernel
# ---------------------------------------------------------------------------
@kernel
def _lm_one(G, joints, Tt, q0, opts, iopts, restarts, rng, q, work):
    """LM for one target ``Tt (4, 4)`` (see :func:`lm_solve`); returns ``(iterations, converged, pos, rot)``."""
    return _lm_one_bounded(G, joints, Tt, q0, opts[:6], CLASSIC, opts, iopts, restarts, rng, q, work)


@kernel
def _lm_one_bounded(G, joints, Tt, q0, bnd, mode, opts, iopts, restarts, rng, q, work):
    """LM for one target ``Tt (4, 4)`` towards the bounds ``bnd (6,)`` with rotation mode ``mode``
    (:func:`rotation_modes`; ``CLASSIC``: the tolerances of ``opts``, ``bnd`` unused); returns
    ``(iterations, converged, pos, rot)`` (``converged``: inside every bound; ``pos, rot``: position error m and
    geodesic rotation angle rad of ``q``)."""
    n = q0.shape[0]
    rw, tol_pos, tol_rot = opts[ROT_WEIGHT], opts[TOL_POS], opts[TOL_ROT]
    damping = (opts[LAMBDA_DOWN], opts[LAMBDA_UP], opts[LAMBDA_MIN], opts[LAMBDA_MAX])
    iters, stall_iters, tail_after = iopts[ITERS], iopts[STALL_ITERS], iopts[TAIL_AFTER]
    # scratch views
    o = 0
    T = work[o : o + 12].reshape((3, 4))
    o += 12
    Tc = work[o : o + 12].reshape((3, 4))
    o += 12
    e = work[o : o + 6]
    o += 6
    ec = work[o : o + 6]
    o += 6
    J = work[o : o + 6 * n].reshape((6, n))
    o += 6 * n
    Jc = work[o : o + 6 * n].reshape((6, n))
    o += 6 * n
    A = work[o : o + n * n].reshape((n, n))
    o += n * n
    g = work[o : o + n]
    o += n
    dq = work[o : o + n]
    o += n
    qa = work[o : o + n]
    o += n
    qc = work[o : o + n]
    o += n
    best_q = work[o : o + n]
    o += n
    cand = work[o : o + n]
    o += n
    d = work[o : o + 6]
    o += 6
    info = work[o : o + 3]
    o += 3
    infoc = work[o : o + 3]

    goal = (Tt, rw, bnd, mode, tol_pos, tol_rot)
    if iopts[FIRST_STARTS] > 0:
        _best_uniform(G, joints, goal, iopts[FIRST_STARTS], rng, qa, (cand, T, e, d))
    else:
        _copy(q0, qa)
    _bounds(joints, qa)
    prob = PoseProblem(G, joints, goal, None, opts[EPS], opts[MAX_STEP], d, (A, g, dq))
    cur, other = PoseState(qa, T, J, e, info, None), PoseState(qc, Tc, Jc, ec, infoc, None)
    accept = ACCEPT_LOWER if mode == CLASSIC else ACCEPT_DONE
    limit = iopts[FIRST_ITERS]
    total = 0
    best_E, best_pos, best_rot = math.inf, math.inf, math.inf
    for start in range(restarts + 1):
        stall_limit = stall_iters
        if start > 0:
            _draw(joints, rng, cur.q)
            limit = iters
            if start > tail_after:
                limit, stall_limit = iopts[TAIL_ITERS], iopts[TAIL_STALL_ITERS]
        stall = (opts[STALL_REL], stall_limit)
        cfg = _loop_cfg(limit, opts[LAMBDA0], damping, math.inf, stall, (-math.inf, 0.0), accept)
        E, done = _measure_pose(prob, cur, math.inf)
        its, E, done, cur, other = _lm_loop(prob, cfg, cur, other, E, done)
        total += its
        if done:
            _copy(cur.q, q)
            return total, True, cur.info[1], cur.info[2]
        if E < best_E:
            best_E, best_pos, best_rot = E, cur.info[1], cur.info[2]
            _copy(cur.q, best_q)
    _copy(best_q, q)
    return total, False, best_pos, best_rot


@kernel
def lm_solve(G, joints, Tt, q0, opts, iopts, restarts, seed, out):
    """Levenberg-Marquardt towards each target ``Tt[b]`` from ``q0[b]`` (or from the best of ``first_starts``
    uniform configurations), restarting from uniform configurations while the target is not reached.

    Args:
        G, joints: the model (:func:`nik.kernels.chain.chain_model`).
        Tt: (B, 4, 4) target poses, metres.
        q0: (B, n) first starts (brought inside the limits first); ignored when ``iopts[FIRST_STARTS] > 0``.
        opts, iopts: options (:func:`lm_options`).
        restarts: (B,) int64, fresh uniform starts each target may draw at most (0 for one proven out of reach).
        seed: (1,) uint64 (:func:`seed_state`); target ``b`` draws from its own stream of it, so its answer
            depends on the seed and ``b`` only.
        out: ``(q, iterations, converged, pos, rot)``, written here: ``q (B, n)`` the answers, inside the limits:
            the first start within tolerance, else the start with the lowest error (best effort); ``iterations (B,)
            int64`` LM iterations spent (all starts); ``converged (B,) bool``: ``q`` is within both tolerances;
            ``pos, rot (B,)`` float64: position (m) and rotation (rad) error of ``q``.

    The scratch is allocated here, per call (measured: no slower than a buffer kept by the caller, within
    0.1 us of a 4.4 us one-pose call), so threads sharing one model run side by side.
    """
    q, iterations, converged, pos, rot = out
    scratch = np.empty(_work_size(q0.shape[1]))
    rng = np.empty(1, dtype=np.uint64)
    for b in range(Tt.shape[0]):
        rng[0] = seed[0] ^ (np.uint64(b) * _STREAM)
        iterations[b], converged[b], pos[b], rot[b] = _lm_one(
            G, joints, Tt[b], q0[b], opts, iopts, restarts[b], rng, q[b], scratch
        )


@kernel
def lm_solve_bounded(G, joints, Tt, q0, goal, opts, iopts, restarts, seed, out):
    """:func:`lm_solve` towards tolerant goals: target ``b`` is reached when its error in the target's tool frame
    lies inside ``bounds[b]`` on every axis (see the module docstring).

    Args:
        goal: ``(bounds, modes)``: ``bounds (B, 6)`` float64 half-widths ``x, y, z`` (m), ``rx, ry, rz`` (rad),
            ``inf`` = free (:class:`nik.ik.bounds.Bounds`, ``expand(B)``); ``modes (B,)`` int64 rotation modes
            (:func:`rotation_modes` of ``bounds``).
        the others: as :func:`lm_solve` (``opts``' tolerances are not used); ``converged``: inside every bound;
        ``pos, rot``: the position error (m) and geodesic rotation angle (rad) of ``q`` (for reports).
    """
    bounds, modes = goal
    q, iterations, converged, pos, rot = out
    scratch = np.empty(_work_size(q0.shape[1]))
    rng = np.empty(1, dtype=np.uint64)
    for b in range(Tt.shape[0]):
        rng[0] = seed[0] ^ (np.uint64(b) * _STREAM)
        iterations[b], converged[b], pos[b], rot[b] = _lm_one_bounded(
            G, joints, Tt[b], q0[b], bounds[b], modes[b], opts, iopts, restarts[b], rng, q[b], scratch
        )


@kernel
def bounded_errors(G, joints, Tt, q, modes, d):
    """The error ``d: (B, 6)`` of configurations ``q: (B, n)`` in the tool frames of ``Tt: (B, 4, 4)``, TRAC-IK's
    (position m, rotation vector rad; with tool axis ``k`` free, ``modes[b] == k``, the swing of that axis and
    0 in entry ``k``): :func:`nik.poses.tool_error` by the kernels' FK. A goal is met where ``|d| <= bounds``."""
    T = np.empty((3, 4))
    for b in range(q.shape[0]):
        _chain(G, joints, q[b], T)
        _tool_error(Tt[b], T, modes[b], d[b])


@kernel
def bounded_residuals(G, joints, Tt, q, bounds, modes, rw, e, J):
    """LM's bounded residual and Jacobian of configurations ``q: (B, n)`` against ``Tt: (B, 4, 4)``,
    ``bounds: (B, 6)``, ``modes: (B,)``: ``e: (B, 6)`` out, minus the dead-zone residual (rotation rows times
    ``rw``), ``J: (B, 6, n)`` out, the Jacobian of the error (rotation rows times ``rw``, free rows zero)."""
    T = np.empty((3, 4))
    d = np.empty(6)
    for b in range(q.shape[0]):
        _bounded_evaluate(G, joints, q[b], Tt[b], rw, bounds[b], modes[b], T, J[b], e[b], d)


def rotation_modes(bounds: np.ndarray) -> np.ndarray:
    """``(B,)`` int64 rotation modes of ``bounds: (B, 6)``: -1 no rotation axis free, 0/1/2 that tool axis free,
    3 all (two or more free; :func:`nik.poses.rotation_modes` in numpy)."""
    free = np.isinf(np.asarray(bounds)[:, 3:])
    n = free.sum(1)
    return np.ascontiguousarray(np.where(n == 0, -1, np.where(n == 1, free.argmax(1), 3)).astype(np.int64))


@kernel
def pose_errors(G, joints, Tt, q, pos, rot):
    """Position (m) and geodesic rotation (rad) errors ``pos, rot: (B,)`` of configurations ``q: (B, n)`` against
    ``Tt: (B, 4, 4)`` (the FK of the kernels; the angle as ``atan2(|sin|, cos)``)."""
    T = np.empty((3, 4))
    e = np.empty(6)
    for b in range(q.shape[0]):
        _chain(G, joints, q[b], T)
        _, pos[b], rot[b] = _residual(Tt[b], T, 1.0, e)


@kernel
def uniform_configurations(joints, rng, q):
    """``q: (m, n)`` filled with configurations uniform inside the limits (the stream of ``rng``)."""
    for k in range(q.shape[0]):
        _draw(joints, rng, q[k])
