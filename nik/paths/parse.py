"""The input of :func:`nik.paths.solve.solve_path`, checked and converted: the waypoints (``(N, 4, 4)`` float64 on
the CPU), the solver's plan for a path, ``q_start`` and ``q_rest`` as ``(dof,)`` radians, and whether the path is a
closed loop. Each refusal is one line naming the problem."""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.ik.targets import pose_array, q_near_array


def _poses(T_path, representation) -> tuple[np.ndarray, torch.dtype, torch.device]:
    """``(T: (N, 4, 4) float64 C-contiguous, dtype, device)`` of the waypoints, checked by
    :func:`nik.ik.targets.pose_array` (the compiled check, every refusal worded by :func:`~nik.ik.targets.as_poses`).
    Waypoints on a GPU are checked and solved on the CPU; the answer goes back to their device and dtype."""
    device = torch.device("cpu")
    dtype = None
    if isinstance(T_path, torch.Tensor):
        device = T_path.device
        dtype = T_path.dtype if T_path.is_floating_point() else None
        T_path = T_path.detach().cpu()
    Tn, checked_dtype = pose_array(T_path, representation, name="T_path")
    return Tn, dtype or checked_dtype, device


def _plan(solver, tol_pos: float, tol_rot: float, seed: int):
    """The solver's :class:`~nik.ik.plan.Plan` of a compiled call (:meth:`nik.IKSolver.plan`: the network that
    guesses, the LM config, refine, fallback), refused in one line where a path cannot follow it."""
    if solver.backend == "torch":
        raise ValueError(
            "solve_path: the path's chains run on the compiled kernels (each waypoint seeded by the one before); "
            "this solver forces backend='torch'"
        )
    if solver.refine == "none" and not solver.closed_form:
        raise ValueError(
            f"solve_path: refine='none' leaves {solver.robot.name} (no closed form) without a way to follow the path; "
            "use refine='lm'"
        )
    return solver.plan(backend="compiled", tol_pos=tol_pos, tol_rot=tol_rot, seed=seed)


def _q_rest(robot, q_rest) -> np.ndarray:
    """``q_rest`` as ``(dof,)`` float64 (``"mid"``: the middle of the ranges), checked by
    :func:`nik.ik.goals.rest_target` (one posture for the whole path)."""
    from nik.ik.goals import rest_target

    shape = np.shape(q_rest) if not isinstance(q_rest, str | torch.Tensor) else tuple(getattr(q_rest, "shape", ()))
    if not isinstance(q_rest, str) and shape != (robot.dof,):
        raise ValueError(f"q_rest: expected 'mid' or one posture of shape ({robot.dof},) for a path, got {shape}")
    return np.ascontiguousarray(rest_target(robot, q_rest, 1)[0])


def _q_start(robot, model, q_start) -> np.ndarray | None:
    """``q_start`` as ``(dof,)`` float64: one configuration, checked as ``q_near`` is
    (:func:`nik.ik.targets.q_near_array`: finite, degrees warned about), then inside the limits (ValueError naming
    the joint: the arm is there)."""
    if q_start is None:
        return None
    shape = tuple(q_start.shape) if isinstance(q_start, torch.Tensor | np.ndarray) else np.shape(q_start)
    if shape != (robot.dof,):
        raise ValueError(f"q_start: expected shape ({robot.dof},) for {robot.name}, got {shape}")
    q = q_near_array(q_start, 1, robot, name="q_start")[0]
    out = np.nonzero((q < model.lo - 1e-9) | (q > model.hi + 1e-9))[0]
    if out.size:
        j = int(out[0])
        f, unit = (1e3, "mm") if model.prismatic[j] else (180.0 / math.pi, "deg")
        raise ValueError(
            f"q_start: joint {j} ({robot.joint_names[j]}) = {q[j] * f:.6g} {unit} lies outside its limits "
            f"[{model.lo[j] * f:.6g}, {model.hi[j] * f:.6g}] {unit}"
        )
    return np.ascontiguousarray(q)


def _is_closed(Tn: np.ndarray, tol_pos: float, tol_rot: float) -> bool:
    """True when the last pose of ``Tn: (N, 4, 4)`` equals its first within the tolerances (position, geodesic
    rotation)."""
    a, b = Tn[0], Tn[-1]
    cos = np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) <= tol_pos and math.acos(cos) <= tol_rot)
