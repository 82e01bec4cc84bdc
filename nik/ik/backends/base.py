"""What every backend shares: :class:`Job` (one call's targets and tolerances) and :class:`Refined` (a refiner's
answers)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Job", "Refined"]


@dataclass
class Job:
    """One call of :meth:`nik.IKSolver.solve`: B targets and what their answers must meet (how to solve them is the
    call's :class:`~nik.ik.plan.Plan`).

    Attributes:
        backend: the backend that computes it (:mod:`nik.ik.backends`); arrays below are of its kind.
        robot: the robot.
        T: (B, 4, 4) target poses, metres (float64 numpy on the compiled backend; the input's tensor on torch).
        reachable: (B,) bool, False where the reach bound proves a target out of reach.
        q_near: (B, dof) radians or None, the configuration to stay near.
        tol_pos: metres; tol_rot: radians (geodesic): what the stages refine to
            (:meth:`nik.ik.plan.Plan.stage_tolerances`: for float32 targets a fraction of the asked one, both backends).
        dtype: the answer's dtype (torch); success_pos, success_rot: the asked tolerances (the result's success).
        model: the robot's compiled model (:mod:`nik.ik.model`: chain arrays, limits, reach, closed form, LM,
            packed networks) on the compiled backend, looked up once per call; None on torch.
        numpy_out: the answer's arrays are numpy (the input was not a tensor), else tensors.
    """

    backend: Any
    robot: Any
    T: Any
    reachable: Any
    q_near: Any
    tol_pos: float
    tol_rot: float
    dtype: Any = None
    success_pos: float | None = None
    success_rot: float | None = None
    model: Any = None
    numpy_out: bool = False

    @property
    def size(self) -> int:
        return int(self.T.shape[0])


@dataclass
class Refined:
    """A refiner's answers for b targets: ``q (b, dof)``, ``pos_err``, ``rot_err`` ``(b,)`` by FK,
    ``iterations (b,)``."""

    q: Any
    pos_err: Any
    rot_err: Any
    iterations: Any
