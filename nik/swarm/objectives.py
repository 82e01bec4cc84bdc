"""Swarm objectives: the fitness of every particle of every target, from one batched FK.

All objectives take ``T_target: (B, 1, 3, 4)`` (or ``(B, 3, 4)``) and reached poses
``T: (B, P, 3, 4)`` (the top three rows of the homogeneous pose, metres) and return
``(B, P)`` (lower is better). Names accepted by :func:`make_objective`:

``pose`` (default of every solver but SA-PSO)
    ``||p - p*|| + rot_weight * angle(R*^T R)``: position error in metres plus the geodesic
    rotation angle in radians times ``rot_weight`` (metres per radian; the swarms default to
    0.5, about one link length: with 0.1 they settled in the wrong IK branch more often).
``paper_a`` (paper A eq. 4; default of SA-PSO, whose temperature T0 = 20 is in its units)
    ``sum_ij |T_ij - T*_ij|`` over the 3x4 upper part, with each of the nine rotation entries
    replaced by its arccos in degrees (inputs clamped to [-1, 1]) and positions in millimetres,
    so that degrees and millimetres weigh alike.
``paper_d_position`` (paper D's f1)
    ``||p* - p||`` in metres.
``paper_d_orientation`` (paper D's f2)
    ``||x* - x||`` with ``x`` the orientation written as the nine entries of ``R`` (row-major),
    i.e. the Frobenius norm ``||R* - R||_F = 2 sqrt(2) sin(theta / 2)``, theta the geodesic
    angle. Paper D does not define ``x``; the rotation-matrix entries are smooth, free of
    Euler-angle wrap-around, and monotonic in the geodesic angle.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from nik.poses import rotation_angle

__all__ = [
    "OBJECTIVES",
    "Objective",
    "make_objective",
    "pose_objective",
    "paper_a_objective",
    "paper_d_position",
    "paper_d_orientation",
]

Objective = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]

_DEG = 180.0 / math.pi


def _bcast(T_target: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """Give ``T_target`` a particle dimension when ``T`` has one more leading dim."""
    return T_target.unsqueeze(-3) if T_target.ndim == T.ndim - 1 else T_target


def pose_objective(T_target: torch.Tensor, T: torch.Tensor, *, rot_weight: float = 0.5) -> torch.Tensor:
    """``||p - p*||`` (m) ``+ rot_weight`` (m/rad) ``* geodesic angle`` (rad); shapes ``(..., 3|4, 4)`` -> ``(...)``."""
    Tt = _bcast(T_target, T)
    pos = torch.linalg.vector_norm(T[..., :3, 3] - Tt[..., :3, 3], dim=-1)
    R_rel = Tt[..., :3, :3].transpose(-1, -2) @ T[..., :3, :3]
    return pos + rot_weight * rotation_angle(R_rel)


def paper_a_objective(T_target: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """Paper A eq. (4): arccos (degrees) of the nine rotation entries and positions in mm, summed |differences|."""
    Tt = _bcast(T_target, T)
    a = torch.rad2deg(torch.arccos(T[..., :3, :3].clamp(-1.0, 1.0)))
    b = torch.rad2deg(torch.arccos(Tt[..., :3, :3].clamp(-1.0, 1.0)))
    rot = (a - b).abs().sum(dim=(-1, -2))
    pos = 1000.0 * (T[..., :3, 3] - Tt[..., :3, 3]).abs().sum(dim=-1)
    return rot + pos


def paper_d_position(T_target: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """Paper D's f1: ``||p* - p||``, metres."""
    Tt = _bcast(T_target, T)
    return torch.linalg.vector_norm(T[..., :3, 3] - Tt[..., :3, 3], dim=-1)


def paper_d_orientation(T_target: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """Paper D's f2: ``||R* - R||_F`` (x = the nine rotation entries), dimensionless."""
    Tt = _bcast(T_target, T)
    return torch.linalg.matrix_norm(T[..., :3, :3] - Tt[..., :3, :3])


OBJECTIVES = ("pose", "paper_a", "paper_d_position", "paper_d_orientation")


def make_objective(name: str, *, rot_weight: float = 0.5) -> Objective:
    """The objective called ``name`` (see the module docstring); ``rot_weight`` only affects ``pose``."""
    if name == "pose":
        return lambda Tt, T: pose_objective(Tt, T, rot_weight=rot_weight)
    if name == "paper_a":
        return paper_a_objective
    if name == "paper_d_position":
        return paper_d_position
    if name == "paper_d_orientation":
        return paper_d_orientation
    raise ValueError(f"unknown swarm objective {name!r}; expected one of {list(OBJECTIVES)}")
