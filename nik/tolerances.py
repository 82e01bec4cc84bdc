"""The one success tolerance of nik: 0.1 mm and 0.1 degree, what every table in the docs measures.

Every solver, refinement, the evaluation, the CLI and the benchmarks default to these (ground room: no imports
from nik, no torch, so the CLI can show them without loading anything).
"""

from __future__ import annotations

import math

__all__ = [
    "DEFAULT_TOL_POS",
    "DEFAULT_TOL_POS_MM",
    "DEFAULT_TOL_ROT",
    "DEFAULT_TOL_ROT_DEG",
    "SCORE_ROT_WEIGHT",
    "describe",
    "score",
]

#: Position tolerance in millimetres (what users read) and metres (what nik computes in).
DEFAULT_TOL_POS_MM = 0.1
DEFAULT_TOL_POS = 1e-4  # m
#: Rotation tolerance (geodesic angle) in degrees and radians: 0.1 deg = 1.745e-3 rad.
DEFAULT_TOL_ROT_DEG = 0.1
DEFAULT_TOL_ROT = math.radians(DEFAULT_TOL_ROT_DEG)  # rad


#: Weight of the rotation error (radians) beside the position error (metres) where two answers are compared by one
#: number (:func:`score`): which hypothesis, closed-form branch or start is the best, which answer a stage keeps.
#: 0.1 m per radian: a 1 mm position error weighs as much as a 0.57 deg rotation error.
SCORE_ROT_WEIGHT = 0.1

#: The near stage's walk from ``q_near`` (:func:`nik.kernels.driver.near_prior`, and its torch twin in
#: :mod:`nik.ik.stages`) for the answers of a redundant arm still farther than ``NEAR_FAR`` rad (some joint) from
#: ``q_near``: the weights of the pull towards ``q_near``, annealed, ``NEAR_PRIOR_STEPS`` steps each.
NEAR_FAR, NEAR_PRIOR, NEAR_PRIOR_STEPS = 0.5, (1.0, 0.3, 0.1, 0.03, 0.01), 10


def score(pos_err, rot_err):
    """``pos_err + SCORE_ROT_WEIGHT * rot_err``: one number per answer, lower is better (metres and radians; floats,
    numpy arrays or tensors of any shape). The compiled kernels use :data:`SCORE_ROT_WEIGHT` itself."""
    return pos_err + SCORE_ROT_WEIGHT * rot_err


def describe(tol_pos: float, tol_rot: float) -> str:
    """``"0.1 mm / 0.1 deg"``: tolerances given in metres and radians, printed in mm and degrees, rounded."""
    return f"{tol_pos * 1e3:.3g} mm / {math.degrees(tol_rot):.3g} deg"
