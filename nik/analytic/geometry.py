"""Which closed form fits a 6R arm: its kinematic family, read from the joint axes.

nik keeps every arm in the normal form ``T = G_0 Rz(th_1) G_1 ... Rz(th_6) G_6`` (:mod:`nik.kinematics`),
whatever it was defined in (DH, modified DH, product of exponentials, URDF, any base or tool frame,
any joint offsets). At the zero configuration each joint ``i`` turns about a line: the z axis
``h_i`` of the frame ``F_i = G_0 Rz(th_1) G_1 ... G_{i-1}`` through its origin. Whether lines are
parallel or meet does not depend on the definition, nor on the configuration (a line of the chain
moves rigidly with the joints before it), so the family is read from these six lines:

- ``"spherical_wrist"``: axes 4, 5, 6 meet in one point (the wrist centre; 4 and 5, 5 and 6 not
  parallel) and axes 2 and 3 are parallel, axis 1 not parallel to them (PUMA, KUKA KR, ABB IRB,
  Fanuc, Kinova Jaco 2 spherical). The first three joints place the wrist centre, the last three
  orient the tool.
- ``"three_parallel"``: axes 2, 3, 4 parallel, axis 1 not parallel to them, axis 5 not parallel to
  them, axes 5 and 6 meet in a point (Universal Robots UR3..UR30 and their e-series, Unitree Z1 and
  other cobots built like them).
- None otherwise (7-DOF arms, prismatic joints, general 6R arms).

Tolerance: two axes count as parallel when the sine of their angle is at most ``ANGLE_TOL`` (1e-6);
two lines meet when their distance is at most ``LENGTH_TOL`` (1e-6) times the arm's size (the sum of
the lengths of ``G_1 .. G_5``, metres). Axes that must *not* be parallel need a sine above
``DEGENERATE_SIN`` (1e-3). Tables written in DH, MDH or POE are exact to rounding (deviation ~1e-16);
URDFs read through pytorch-kinematics carry its float32 rounding of ``rpy`` (up to ~1e-8 m: the Kinova
Jaco 2 of example-robot-data). :attr:`ArmGeometry.deviation` records the largest departure; where it
exceeds ``POLISH_ABOVE`` (1e-12) times the size, :func:`nik.analytic.solve` follows the closed form
(exact for the ideal arm) by three damped Newton steps on the robot's own FK, and its FK check decides.

:func:`arm_geometry` returns, besides the family, the joint frames at the zero configuration and the
meeting point the closed forms start from (:mod:`nik.analytic.kernels`).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ANGLE_TOL",
    "DEGENERATE_SIN",
    "FAMILIES",
    "LENGTH_TOL",
    "POLISH_ABOVE",
    "ArmGeometry",
    "arm_geometry",
    "family",
]

FAMILIES = ("spherical_wrist", "three_parallel")
ANGLE_TOL = 1e-6  # sine of the angle between axes that count as parallel
LENGTH_TOL = 1e-6  # times the arm's size (metres): lines that count as meeting
DEGENERATE_SIN = 1e-3  # axes that must not be parallel need a larger sine than this
POLISH_ABOVE = 1e-12  # times the arm's size: a larger deviation from the family gets Newton steps after the closed form


@dataclass(frozen=True)
class ArmGeometry:
    """The family of a 6R arm and the constants of its closed form (SI units).

    ``family`` is None when no closed form fits; ``reason`` then says which condition failed.
    ``frames``: (7, 4, 4) ``F_1 .. F_6`` and the tool pose at the zero configuration (base frame).
    ``point``: the wrist centre (spherical wrist) or the meeting point of axes 5 and 6 (three parallel),
    base frame at the zero configuration. ``deviation``: the largest departure from the family's
    structure found, metres (a sine counts times ``size``).
    """

    family: str | None
    reason: str
    frames: np.ndarray
    size: float
    point: np.ndarray | None = None
    deviation: float = 0.0


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    R = np.eye(4)
    R[:2, :2] = [[c, -s], [s, c]]
    return R


def zero_frames(G: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """``(n + 1, 4, 4)``: the joint frames ``F_1 .. F_n`` at ``q = 0`` and the tool pose (base frame)."""
    n = G.shape[0] - 1
    F = [G[0]]
    for i in range(n):
        F.append(F[-1] @ _rz(float(offsets[i])) @ G[i + 1])
    return np.stack(F)


def _sin(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(np.cross(a, b)))


def _closest(ra, ha, rb, hb) -> tuple[float, np.ndarray]:
    """Distance of two non-parallel lines ``r + t h`` and the midpoint of their closest points."""
    w = rb - ra
    b = float(ha @ hb)
    den = 1.0 - b * b
    ta = (float(ha @ w) - b * float(hb @ w)) / den
    tb = (b * float(ha @ w) - float(hb @ w)) / den
    pa, pb = ra + ta * ha, rb + tb * hb
    return float(np.linalg.norm(pa - pb)), 0.5 * (pa + pb)


def _classify(G: np.ndarray, offsets: np.ndarray, prismatic) -> ArmGeometry:
    n = G.shape[0] - 1
    empty = np.zeros((0, 4, 4))
    if prismatic is not None and bool(np.any(prismatic)):
        joints = [i + 1 for i in range(n) if bool(prismatic[i])]
        return ArmGeometry(None, f"prismatic joint(s) {joints}; the closed forms are for 6 revolute joints", empty, 0.0)
    if n != 6:
        return ArmGeometry(None, f"{n} joints; the closed forms are for 6 revolute joints", empty, 0.0)
    F = zero_frames(G, offsets)
    h = [F[i, :3, 2] for i in range(6)]
    r = [F[i, :3, 3] for i in range(6)]
    size = float(sum(np.linalg.norm(G[i, :3, 3]) for i in range(1, 6)))
    if size <= 0.0:
        return ArmGeometry(None, "all links have zero length", F, size)
    tol_len = LENGTH_TOL * size

    def par(i, j):  # 1-based
        return _sin(h[i - 1], h[j - 1])

    # spherical wrist: axes 4, 5, 6 meet in one point; 2 and 3 parallel, 1 not parallel to them
    wrist_why = ""
    if par(4, 5) <= DEGENERATE_SIN or par(5, 6) <= DEGENERATE_SIN:
        wrist_why = "wrist axes 4 and 5, or 5 and 6, are parallel"
    else:
        d45, c45 = _closest(r[3], h[3], r[4], h[4])
        d56, c56 = _closest(r[4], h[4], r[5], h[5])
        gap = float(np.linalg.norm(c45 - c56))
        if max(d45, d56, gap) > tol_len:
            wrist_why = f"axes 4, 5, 6 do not meet in one point (gaps {d45:.3g}, {d56:.3g}, {gap:.3g} m)"
        elif par(2, 3) > ANGLE_TOL:
            wrist_why = f"spherical wrist, but axes 2 and 3 are not parallel (sine {par(2, 3):.3g})"
        elif par(1, 2) <= DEGENERATE_SIN:
            wrist_why = "spherical wrist, but axes 1 and 2 are parallel"
        else:
            dev = max(d45, d56, gap, par(2, 3) * size)
            return ArmGeometry("spherical_wrist", "", F, size, point=0.5 * (c45 + c56), deviation=dev)
    # three parallel: axes 2, 3, 4 parallel, 1 and 5 not parallel to them, 5 and 6 meet
    if max(par(2, 3), par(2, 4)) > ANGLE_TOL:
        ur_why = "axes 2, 3, 4 are not parallel"
    elif par(1, 2) <= DEGENERATE_SIN or par(4, 5) <= DEGENERATE_SIN:
        ur_why = "axes 2, 3, 4 parallel, but axis 1 or axis 5 is parallel to them too"
    elif par(5, 6) <= DEGENERATE_SIN:
        ur_why = "axes 2, 3, 4 parallel, but axes 5 and 6 are parallel"
    else:
        d56, c56 = _closest(r[4], h[4], r[5], h[5])
        if d56 > tol_len:
            ur_why = f"axes 2, 3, 4 parallel, but axes 5 and 6 do not meet ({d56:.3g} m apart)"
        else:
            dev = max(d56, max(par(2, 3), par(2, 4)) * size)
            return ArmGeometry("three_parallel", "", F, size, point=c56, deviation=dev)
    return ArmGeometry(None, f"no spherical wrist ({wrist_why}) and no three parallel axes ({ur_why})", F, size)


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def arm_geometry(robot) -> ArmGeometry:
    """The :class:`ArmGeometry` of ``robot`` (cached per robot and definition hash)."""
    key = robot.definition_hash
    hit = _CACHE.get(robot)
    if hit is not None and hit[0] == key:
        return hit[1]
    prismatic = getattr(robot, "prismatic", None)
    geom = _classify(
        robot.G.double().numpy(),
        robot.offsets.double().numpy(),
        None if prismatic is None else prismatic.numpy(),
    )
    _CACHE[robot] = (key, geom)
    return geom


def family(robot) -> str | None:
    """``"spherical_wrist"``, ``"three_parallel"`` or None: which closed form fits ``robot`` (module docstring).

    Read from the joint axes of the robot's normal form, so the answer does not depend on how the
    arm was defined (DH, modified DH, POE, URDF), on its base and tool frames or on its joint offsets.
    """
    return arm_geometry(robot).family
