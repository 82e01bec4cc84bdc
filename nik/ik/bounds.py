"""Tolerant goals: ``bounds=`` per axis of the tool frame (TRAC-IK's bounds), parsed and checked once.

A goal is met when every axis of the error, measured in the **target's** tool frame, lies inside its bound:
``x, y, z`` the position error along the target tool's axes (metres), ``rx, ry, rz`` the rotation error about
them (radians), ``math.inf`` = free. The error is :func:`nik.poses.tool_error` (torch) and
:func:`nik.kernels.lm.bounded_errors` (numba): the same numbers, TRAC-IK's ``diffRelative`` (position
``R_t^T (p - p_t)``, rotation vector of ``R_t^T R``), except where a rotation axis is free: there the other two
entries are the swing of that tool axis (the tilt between target and reached axis), since a rotation vector
cannot leave one axis free (see :func:`nik.poses.tool_error`).

Accepted forms (:func:`parse_bounds`):

- ``None``: the classic tolerances (norm of the position error <= ``tol_pos``, geodesic angle <= ``tol_rot``):
  :func:`parse_bounds` returns None and the pipeline keeps its classic path;
- 6 numbers ``(x, y, z, rx, ry, rz)``, one goal for the whole call, or ``(B, 6)`` one per target;
- ``"position"``: orientation free; ``"axis_x" | "axis_y" | "axis_z"``: rotation about that tool axis free.
  The shorthands keep nik's tolerances as norms: each position axis gets ``tol_pos / sqrt(3)`` and each
  bounded rotation axis ``tol_rot / sqrt(2)``, so that a goal met per axis is also met as a norm (position
  error <= ``tol_pos``, tilt of the tool axis <= ``tol_rot``).

Refused with a one-line ``ValueError``: a wrong shape or type, NaN, a negative bound (``-inf`` included), an
unknown shorthand, and two free rotation axes with the third bounded: rotations about two tool axes compose
every orientation, so that bound could never bind (say ``"position"``, or free one axis only). A bound of 0
is allowed (never met in floating point except by an exact pose: the caller asked for it).

On the CLI (:func:`bounds_from_cli`) the lengths are millimetres and the angles degrees; ``--bounds``,
``--position-only`` and ``--free-axis`` exclude one another, and ``--free-axis`` is given once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["AXES", "SHORTHANDS", "Bounds", "bounds_from_cli", "parse_bounds"]

#: Names of the six entries of a bound, in order (metres, metres, metres, radians, radians, radians).
AXES = ("x", "y", "z", "rx", "ry", "rz")
#: The accepted shorthands and the rotation axis each leaves free (3: all rotation).
SHORTHANDS = {"position": 3, "axis_x": 0, "axis_y": 1, "axis_z": 2}


@dataclass(frozen=True)
class Bounds:
    """A validated tolerant goal.

    Attributes:
        half: ``(B, 6)`` float64 half-widths ``x, y, z`` (m), ``rx, ry, rz`` (rad), ``inf`` = free; ``B = 1`` for
            one goal shared by the call (:meth:`expand` repeats it).
        per_target: True when given per target (``(B, 6)``), False for one goal for every target.
        rot_mode: ``(B,)`` int64: which rotation is free, -1 none, 0/1/2 about that tool axis, 3 all
            (:func:`nik.poses.rotation_modes`, :func:`nik.kernels.lm.rotation_modes`).
        source: what was given, for messages (``"axis_z"``, ``"(6 numbers)"``, ``"(B, 6)"``).
    """

    half: np.ndarray
    per_target: bool
    rot_mode: np.ndarray
    source: str

    @property
    def free(self) -> np.ndarray:
        """``(B, 6)`` bool: the free axes."""
        return np.isinf(self.half)

    @property
    def position_only(self) -> bool:
        """Every rotation axis free on every target."""
        return bool((self.rot_mode == 3).all())

    def expand(self, batch: int) -> np.ndarray:
        """``(batch, 6)`` C-contiguous float64 half-widths (one goal repeated; per-target ones checked)."""
        if self.per_target:
            if self.half.shape[0] != batch:
                raise ValueError(f"bounds: {self.half.shape[0]} rows for {batch} targets")
            return np.ascontiguousarray(self.half)
        return np.ascontiguousarray(np.repeat(self.half, batch, axis=0))

    def as_tensor(self, batch: int, like=None):
        """``(batch, 6)`` torch tensor of :meth:`expand`, in the dtype/device of ``like`` (default float64 CPU)."""
        import torch

        t = torch.from_numpy(self.expand(batch))
        return t if like is None else t.to(dtype=like.dtype, device=like.device)

    def modes(self, batch: int) -> np.ndarray:
        """``(batch,)`` int64 rotation modes (see ``rot_mode``)."""
        return np.ascontiguousarray(np.broadcast_to(self.rot_mode, (batch,)) if not self.per_target else self.rot_mode)

    def describe(self) -> str:
        """``"x 0.058 mm, ..., rz free"``: the goal in mm and degrees (the first target's when per target)."""
        parts = []
        for i, name in enumerate(AXES):
            v = float(self.half[0, i])
            if math.isinf(v):
                parts.append(f"{name} free")
            else:
                parts.append(f"{name} {v * 1e3:.3g} mm" if i < 3 else f"{name} {math.degrees(v):.3g} deg")
        return ", ".join(parts) + (" (per target)" if self.per_target else "")


def _modes(half: np.ndarray) -> np.ndarray:
    free = np.isinf(half[:, 3:])
    n = free.sum(1)
    return np.where(n == 0, -1, np.where(n == 1, free.argmax(1), 3)).astype(np.int64)


def _shorthand(name: str, tol_pos: float, tol_rot: float) -> np.ndarray:
    axis = SHORTHANDS[name]
    half = np.full(6, tol_rot / math.sqrt(2.0))
    half[:3] = tol_pos / math.sqrt(3.0)
    if axis == 3:
        half[3:] = math.inf
    else:
        half[3 + axis] = math.inf
    return half[None]


def parse_bounds(
    bounds,
    *,
    batch: int | None = None,
    tol_pos: float = DEFAULT_TOL_POS,
    tol_rot: float = DEFAULT_TOL_ROT,
) -> Bounds | None:
    """Check ``bounds`` (see the module docstring) and return a :class:`Bounds`, or None for the classic tolerances.

    Args:
        bounds: None, a shorthand string, 6 numbers (tuple, list, numpy, torch) or ``(B, 6)``, or a
            :class:`Bounds` (checked against ``batch``).
        batch: the number of targets, when known: a ``(B, 6)`` goal must have ``B == batch`` (or 1).
        tol_pos, tol_rot: metres, radians: what the shorthands are made of.

    Raises:
        ValueError: one line naming the problem.
    """
    if bounds is None:
        return None
    if isinstance(bounds, Bounds):
        if batch is not None and bounds.per_target and bounds.half.shape[0] != batch:
            raise ValueError(f"bounds: {bounds.half.shape[0]} rows for {batch} targets")
        return bounds
    if isinstance(bounds, str):
        if bounds not in SHORTHANDS:
            raise ValueError(
                f"bounds: unknown shorthand {bounds!r}; expected one of {', '.join(map(repr, SHORTHANDS))} "
                "or 6 numbers (x, y, z m, rx, ry, rz rad)"
            )
        half = _shorthand(bounds, tol_pos, tol_rot)
        return Bounds(half, False, _modes(half), bounds)
    if hasattr(bounds, "detach"):  # a torch tensor
        bounds = bounds.detach().cpu().numpy()
    try:
        half = np.array(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"bounds: expected 6 numbers (x, y, z m, rx, ry, rz rad), (B, 6) or a shorthand, got {bounds!r:.60}"
        ) from None
    if half.ndim not in (1, 2) or half.shape[-1] != 6 or half.size == 0:
        raise ValueError(f"bounds: expected 6 numbers (x, y, z m, rx, ry, rz rad) or (B, 6), got shape {half.shape}")
    per_target = half.ndim == 2 and half.shape[0] > 1
    half = half.reshape(-1, 6)
    where = (lambda r: f" of target {r}") if per_target else (lambda r: "")
    nan = np.isnan(half)
    if nan.any():
        r, c = np.argwhere(nan)[0]
        raise ValueError(f"bounds: {AXES[c]}{where(r)} is NaN; give a half-width >= 0 (math.inf = free)")
    neg = half < 0
    if neg.any():
        r, c = np.argwhere(neg)[0]
        raise ValueError(
            f"bounds: {AXES[c]}{where(r)} = {half[r, c]:g} is negative; give a half-width >= 0 (math.inf = free)"
        )
    free = np.isinf(half[:, 3:])
    two = free.sum(1) == 2
    if two.any():
        r = int(np.argmax(two))
        names = [AXES[3 + i] for i in range(3) if free[r, i]]
        bound = [AXES[3 + i] for i in range(3) if not free[r, i]][0]
        raise ValueError(
            f"bounds: rotation free about {names[0]} and {names[1]} but bounded about {bound}{where(r)}: rotations "
            'about two axes reach every orientation; free all three ("position") or one axis only'
        )
    if batch is not None and per_target and half.shape[0] != batch:
        raise ValueError(f"bounds: {half.shape[0]} rows for {batch} targets")
    return Bounds(half, per_target, _modes(half), "(B, 6)" if per_target else "(6 numbers)")


def _cli_number(text: str, scale: float, name: str) -> float:
    if text.lower() in ("inf", "free", "+inf"):
        return math.inf
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--bounds: {name} = {text!r} is not a number (or 'free')") from None
    if not value >= 0:  # NaN too
        unit = "mm" if scale < 1e-2 else "deg"
        raise ValueError(f"--bounds: {name} = {text} {unit}: expected a half-width >= 0 (or 'free')")
    return value * scale


def bounds_from_cli(
    bounds: list[str] | None = None,
    *,
    position_only: bool = False,
    free_axis: list[str] | str | None = None,
    tol_pos: float = DEFAULT_TOL_POS,
    tol_rot: float = DEFAULT_TOL_ROT,
) -> Bounds | None:
    """The goal of ``nik solve|path``'s options, or None when none is given (the classic tolerances).

    Args:
        bounds: ``--bounds X Y Z RX RY RZ``: 6 strings, millimetres and degrees, ``inf`` or ``free`` = free.
        position_only: ``--position-only`` (the ``"position"`` shorthand).
        free_axis: ``--free-axis x|y|z`` (an argparse ``append`` list or one string): rotation about that
            tool axis free (the ``"axis_<a>"`` shorthand).
        tol_pos, tol_rot: metres, radians (the command's ``--tol-pos`` / ``--tol-rot`` converted): the shorthands'.

    Raises:
        ValueError: one line (the CLI prints ``nik: error: ...``): options combined, ``--free-axis`` given twice
        or not one of x, y, z, a value not a number, and every error of :func:`parse_bounds`.
    """
    axes = [free_axis] if isinstance(free_axis, str) else list(free_axis or [])
    given = [name for name, on in (("--bounds", bounds is not None), ("--position-only", position_only),
                                   ("--free-axis", bool(axes))) if on]  # fmt: skip
    if len(given) > 1:
        raise ValueError(f"{' and '.join(given)} exclude one another: give one")
    if len(axes) > 1:
        if len(set(axes)) == 1:
            raise ValueError(f"--free-axis {axes[0]} given twice")
        raise ValueError(f"--free-axis given twice ({', '.join(axes)}): free rotation about two axes frees all; "
                         "use --position-only")  # fmt: skip
    if axes:
        a = axes[0].lower()
        if a not in ("x", "y", "z"):
            raise ValueError(f"--free-axis: expected x, y or z (a tool axis), got {axes[0]!r}")
        return parse_bounds(f"axis_{a}", tol_pos=tol_pos, tol_rot=tol_rot)
    if position_only:
        return parse_bounds("position", tol_pos=tol_pos, tol_rot=tol_rot)
    if bounds is None:
        return None
    if len(bounds) != 6:
        raise ValueError(f"--bounds: expected 6 values X Y Z (mm) RX RY RZ (deg), got {len(bounds)}")
    scales = (1e-3,) * 3 + (math.pi / 180.0,) * 3
    values = [_cli_number(str(t), s, n) for t, s, n in zip(bounds, scales, AXES, strict=True)]
    return parse_bounds(values)
