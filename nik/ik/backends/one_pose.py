"""One pose, one kernel call: :meth:`nik.IKSolver.solve` on a single pose with nothing but the tolerances and the seed.

A call is: the pose as it comes (a ``(4, 4)`` or ``(1, 4, 4)`` float64 or float32 numpy array, or a CPU tensor of
those; a contiguous float64 tensor is read at its address, :func:`nik.kernels.poses.pose_at`, float32 widened to
float64 as the general path does), checked by the compiled pose check (:func:`nik.kernels.poses.poses_ok`: finite,
orthonormal, bottom row), solved by the driver kernel (:func:`nik.kernels.driver.solve`) with the arguments it takes
from the plan and the robot's model gathered once per solver settings, tolerances, seed and dtype (an
:class:`Entry`, kept on the solver, dropped when a setting changes: ``IKSolver.__setattr__``). The answer is fresh
numpy arrays: an :class:`~nik.ik.result.IKResult` of them for a numpy pose, a
:class:`~nik.ik.result.TensorResult` (its tensors made by ``torch.from_numpy`` when first read) for a tensor pose.
What it costs: ``docs/speed.md`` (``benchmarks/cold_pose.py``).

The answer is the general path's, bit for bit (the same kernel on the same arguments: ``tests/test_one_pose.py``),
the unreachable warning included. Anything else returns None and the general path takes the call: a pose in
another form (quaternion, roll-pitch-yaw) or shape, a pose the check refuses (the general path words the error),
a non-contiguous, read-only or integer array, a tensor off the CPU or of another dtype, ``q_near``, ``bounds``,
``q_rest``, ``costs``, ``world``, ``plan``, ``max_iters`` or ``representation`` given, a collision check active, a
network the kernels do not pack, the torch backend or a refinement other than LM.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from nik.ik import model as _models
from nik.ik.backends.compiled import as_float32
from nik.ik.collide import has_attached
from nik.ik.result import IKResult, TensorResult

__all__ = ["Entry", "entry", "one_pose"]

_F64, _F32 = np.dtype(np.float64), np.dtype(np.float32)
_T64, _T32 = torch.float64, torch.float32
_POSES_OK = None  # nik.kernels.poses.poses_ok, set with the first entry (import nik loads no numba)
_POSE_AT = None  # nik.kernels.poses.pose_at
_SOLVE = None  # nik.kernels.driver.solve
_ORTHONORMAL_TOL = 0.0


@dataclass(frozen=True)
class Entry:
    """What a one-pose call takes from the solver's settings, its tolerances, seed and the answer's dtype: the
    plan's ``model``; the driver's four argument tuples ``a0..a3``
    (:meth:`~nik.ik.backends.compiled.CompiledBackend.driver_args`); the guess's ``source``; whether the network
    takes the targets in the arm's frame (``arm_frame``); whether the answer is float32 (``f32``, with the asked
    tolerances ``tol_pos, tol_rot``); whether an attached collision model must be looked for per call
    (``look_attached``); the model generation it was made in."""

    model: Any
    a0: tuple
    a1: tuple
    a2: tuple
    a3: tuple
    source: str
    arm_frame: bool
    f32: bool
    tol_pos: float
    tol_rot: float
    look_attached: bool
    generation: int


_LATER = object()  # entry(): not yet (the driver not compiled); not kept


def entry(solver, tol_pos, tol_rot, seed, f32: bool):
    """The :class:`Entry` of ``solver`` for these tolerances, seed and answer dtype, None where the one-pose path
    does not apply (module docstring), ``_LATER`` while the driver has nothing compiled (not kept). Raises the
    one-line ``ValueError`` of a bad tolerance."""
    global _POSES_OK, _POSE_AT, _SOLVE, _ORTHONORMAL_TOL
    from nik.ik.backends import compiled_backend
    from nik.ik.targets import check_tolerances

    check_tolerances(tol_pos, tol_rot)
    if solver.backend == "torch" or solver.refine != "lm" or solver.world is not None or solver.self_collision:
        return None
    if _SOLVE is None:
        from nik.kernels import driver, poses
        from nik.poses import ORTHONORMAL_TOL

        _POSES_OK, _POSE_AT, _SOLVE, _ORTHONORMAL_TOL = poses.poses_ok, poses.pose_at, driver.solve, ORTHONORMAL_TOL
    if not _SOLVE.signatures and solver.backend != "compiled" and compiled_backend().defer:
        from nik.kernels import background

        if background.cold(_SOLVE):  # nothing compiled on this machine: the general path answers from torch while
            return _LATER  # the driver compiles (nik.kernels.background); asked again on the next call
    generation = _models.generation
    plan = solver.plan(backend="compiled", tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, poses=1)
    model = _models.model_of(solver.robot, plan.lm_cfg)
    packed = None
    if plan.source == "network":
        packed = model.packed(plan.net)
        if packed is None:
            return None
    dtype = torch.float32 if f32 else torch.float64
    a0, a1, a2, a3 = compiled_backend().driver_args(plan, model, dtype, packed)
    return Entry(
        model, a0, a1, a2, a3, plan.source, packed is not None and plan.net_in_arm_frame, f32, plan.tol_pos,
        plan.tol_rot, solver.self_collision is None, generation,
    )  # fmt: skip


def one_pose(solver, T_target, tol_pos, tol_rot, seed) -> IKResult | None:
    """``solver.solve(T_target, tol_pos, tol_rot, seed)`` for one pose in one kernel call, or None where the general
    path must take the call (module docstring)."""
    kind = type(T_target)
    if kind is torch.Tensor:
        dt = T_target.dtype
        f32 = dt is _T32
        if not (f32 or dt is _T64) or not T_target.is_cpu:
            return None
    elif kind is np.ndarray:
        f32 = False
    else:
        return None
    shape = T_target.shape
    if shape != (4, 4) and shape != (1, 4, 4):
        return None
    key = (tol_pos, tol_rot, seed, f32)
    cache = solver._one
    try:
        e = cache.get(key, False)
    except TypeError:  # an unhashable tolerance (a numpy array of one number): the general path
        return None
    if e is False or e is not None and e.generation != _models.generation:
        if len(cache) >= 64:  # tolerances or seeds given as new objects each call (tensors hash by identity)
            cache.clear()
        e = entry(solver, tol_pos, tol_rot, seed, f32)
        if e is _LATER:
            return None
        cache[key] = e
    if e is None:
        return None
    if kind is torch.Tensor:
        if not f32 and T_target.is_contiguous() and not T_target.is_neg():
            a = np.empty((1, 4, 4))  # read at its address: no Tensor.numpy()
            if not _POSE_AT(T_target.data_ptr(), _ORTHONORMAL_TOL, a):
                return None
        else:
            a = T_target.detach().numpy().reshape(1, 4, 4).astype(np.float64)
            if not _POSES_OK(a, _ORTHONORMAL_TOL):
                return None
    else:
        a = T_target if len(shape) == 3 else T_target[None]
        dt = a.dtype
        if dt is not _F64 and dt != _F64:
            if dt != _F32:
                return None
            a = a.astype(np.float64)
        elif not a.flags.carray:  # C-contiguous, aligned, writeable: the one kernel version there is
            return None
        if not _POSES_OK(a, _ORTHONORMAL_TOL):
            return None
    model = e.model
    if e.look_attached and has_attached(model.robot):
        return None
    q, pos, rot = np.empty((1, model.dof)), np.empty(1), np.empty(1)
    ok, it, reach = np.empty(1, dtype=np.bool_), np.empty(1, dtype=np.int64), np.empty(1, dtype=np.bool_)
    Tin = model.arm_targets(a) if e.arm_frame else a
    if not _SOLVE(e.a0, a, e.a1, Tin, e.a2, q, False, e.a3, (q, pos, rot, ok, it, reach)):
        warnings.warn(model.unreachable_message(a, reach), UserWarning, stacklevel=3)
    if f32:
        q, pos, rot, ok = as_float32(model, a, q, e.tol_pos, e.tol_rot)
    if kind is torch.Tensor:
        return TensorResult.of(q, pos, rot, ok, it, reach, e.source)
    return IKResult(q, pos, rot, ok, it, e.source, reachable=reach)
