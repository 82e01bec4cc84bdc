"""``IKResult``: what :meth:`nik.IKSolver.solve` returns for B targets; ``PathReport``: what
:meth:`nik.IKSolver.solve_path` adds about the path."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch

__all__ = ["IKResult", "PathReport", "TensorResult"]


@dataclass
class IKResult:
    """Result of :meth:`IKSolver.solve` for B targets.

    The arrays are of the input's kind: torch tensors (on the targets' device) for a tensor input, numpy arrays for a
    numpy input (no torch on the way on the CPU's compiled path), torch tensors for other input (lists). The dtype of
    ``q``, ``pos_err`` and ``rot_err`` is the targets' (float64 for non-tensor input); ``success`` and ``reachable``
    are bool, ``iterations`` int64.

    Attributes:
        q: (B, dof) joint angles, radians, inside the joint limits.
        pos_err: (B,) position error of ``q`` (FK), metres.
        rot_err: (B,) geodesic rotation error of ``q``, radians.
        success: (B,) bool, ``pos_err <= tol_pos`` and ``rot_err <= tol_rot``.
        iterations: (B,) long, refinement iterations spent (0 where the guess was already within tolerance).
        source: where the initial guess came from: ``network``, ``analytic`` or ``multistart``
            (:meth:`IKSolver.solve_path` also ``q_start``: the LM chain from the given start).
        reachable: (B,) bool, False where no configuration can reach the target (provable reach
            bound, :func:`nik.robots.reach.within_reach`); such targets get ``success=False`` and a best effort.
        axis_err: (B, 6) under a tolerant goal (``bounds=``): the error per axis of the target's tool frame, ``x, y,
            z`` (m) and ``rx, ry, rz`` (rad; with one rotation axis free the swing of that axis, its own entry 0):
            success is ``|axis_err| <= bounds`` (:mod:`nik.ik.goals`); None otherwise.
        path: for :meth:`IKSolver.solve_path`, how the trajectory follows its path (:class:`PathReport`:
            every step, the largest and where, reconfigurations, why a waypoint failed); None otherwise.
        collision_free: (B,) bool where a collision model is active (a world, or self-collision:
            :mod:`nik.ik.collide`): the returned ``q`` is free of the world and of the arm itself (with a world,
            self-collision is checked unless ``self_collision=False``), by the sphere check (conservative: free on
            the meshes too) or, with a mesh verdict (``IKSolver(mesh_verdict=)``), by the meshes; ``success``
            requires it. None where no collision model is active.
        collisions: where a collision model is active, a list of B entries: None where the answer is free, else the
            sorted names of what overlaps, by the verdict's check: ``"linkA|linkB"`` (the arm against itself) and
            ``"link|box 2"`` (a link and the world's obstacle of that kind, ``sphere`` | ``box`` | ``capsule``, and
            index in :meth:`nik.World.packed`); None (not a list) where no collision model is active, and from
            :meth:`IKSolver.solve_path` (its ``path.reasons`` say ``"colliding"``).
        unmet: with ``costs=`` (:mod:`nik.ik.costs`), a list of B entries: None where the answer meets every
            constraint term, else what it misses (``["above_plane: residual above 1e-06"]``); None without costs.
    """

    q: torch.Tensor | np.ndarray
    pos_err: torch.Tensor | np.ndarray
    rot_err: torch.Tensor | np.ndarray
    success: torch.Tensor | np.ndarray
    iterations: torch.Tensor | np.ndarray
    source: str = ""
    reachable: torch.Tensor | np.ndarray | None = None
    path: PathReport | None = None
    collision_free: torch.Tensor | np.ndarray | None = None
    axis_err: torch.Tensor | np.ndarray | None = None
    collisions: list | None = None
    unmet: list | None = None

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def to(self, device: str | torch.device) -> IKResult:
        """The same result with every array as a tensor on ``device``."""
        moved = {f.name: getattr(self, f.name) for f in fields(self)}
        moved = {k: torch.as_tensor(v).to(device) if isinstance(v, torch.Tensor | np.ndarray) else v
                 for k, v in moved.items()}  # fmt: skip
        return IKResult(**moved)

    def numpy(self) -> IKResult:
        """The same result with every array as a numpy array (CPU)."""
        moved = {f.name: getattr(self, f.name) for f in fields(self)}
        moved = {k: v.detach().cpu().numpy() if isinstance(v, torch.Tensor) else v for k, v in moved.items()}
        return IKResult(**moved)


class _Tensor:
    """A field of :class:`TensorResult`: its numpy array until first read, then the tensor that shares its memory
    (``torch.from_numpy``), kept in the instance (a non-data descriptor: the instance's value wins once set)."""

    def __init__(self, index: int):
        self.index = index

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        value = obj.__dict__[self.name] = torch.from_numpy(obj.__dict__["_arrays"][self.index])
        return value


class TensorResult(IKResult):
    """An :class:`IKResult` of CPU tensors made from numpy arrays when first read: what one pose given as a tensor gets
    from the one-pose path (:mod:`nik.ik.backends.one_pose`). Each array field (``q``, ``pos_err``, ``rot_err``,
    ``success``, ``iterations``, ``reachable``) is ``torch.from_numpy`` of the kernel's output, as the batch path
    returns it (same dtype, shape, memory), made on first read (a microsecond each) rather than for every field of
    every call; the other fields are those of a plain result. Built by :meth:`of`; the dataclass constructor (and
    ``dataclasses.replace``) gives one whose fields are all set."""

    q = _Tensor(0)
    pos_err = _Tensor(1)
    rot_err = _Tensor(2)
    success = _Tensor(3)
    iterations = _Tensor(4)
    reachable = _Tensor(5)

    @classmethod
    def of(cls, q, pos_err, rot_err, success, iterations, reachable, source: str) -> TensorResult:
        """The result of the numpy arrays ``q: (B, dof)``, ``pos_err, rot_err, success, iterations, reachable: (B,)``
        (kept; their tensors share their memory)."""
        res = cls.__new__(cls)
        res.__dict__.update(_arrays=(q, pos_err, rot_err, success, iterations, reachable), source=source)
        return res


@dataclass
class PathReport:
    """How a joint trajectory follows its path (:meth:`nik.IKSolver.solve_path`; ``res.path``).

    Attributes:
        steps: (N,) largest joint motion into each waypoint (radians; metres on prismatic joints); entry 0 is the
            motion from ``q_start`` (0 without it).
        step_joints: (N,) long, the joint that moves most in each step.
        largest_step: the largest of ``steps``; largest_step_at: the waypoint it leads into;
            largest_step_joint: the joint that makes it.
        total_motion: sum over steps and joints of ``|dq|`` (radians / metres), from ``q_start`` when given.
        max_step: the threshold of a reconfiguration, radians (:data:`nik.paths.solve.PATH_MAX_STEP` unless given).
        reconfigurations: (N,) bool, ``steps > max_step``.
        reasons: per waypoint, ``""`` when reached, else why not (``"out of reach"``, ``"beyond a joint limit on
            every branch"``, ``"not reached"``, ``"reached only by a step above max_step from the waypoint before"``:
            FK reaches it, but only by a reconfiguration from a reached neighbour, so it counts as not reached).
        warning: one line naming the first waypoint that failed or forced a reconfiguration (None when none did).
        closed: the path was taken as closed (its last pose equals its first; ``solve_path(closed=)``) and closes
            continuously: a loop that closes only by a step above ``max_step`` is left open (False; the warning says
            it, ``closure`` is its gap).
        closure: on a path taken as closed (closed or left open), the largest joint difference between the last row
            and the first (radians; metres on prismatic joints; modulo whole turns on joints whose range exceeds a
            full turn); None on an open path.
        t: (N,) seconds at each waypoint, with ``timing=True`` on a whole path (None otherwise: a waypoint not
            reached or a step between waypoints above ``max_step`` gets no schedule, the warning says why); qd, qdd:
            (N, dof) the joint velocities and accelerations there; timing: the whole
            :class:`nik.paths.timing.Timing` (sample it at 1 ms).
    """

    steps: torch.Tensor
    step_joints: torch.Tensor
    largest_step: float
    largest_step_at: int
    largest_step_joint: int
    total_motion: float
    max_step: float
    reconfigurations: torch.Tensor
    reasons: list[str]
    warning: str | None = None
    closed: bool = False
    closure: float | None = None
    t: torch.Tensor | None = None
    qd: torch.Tensor | None = None
    qdd: torch.Tensor | None = None
    timing: object | None = None

    @property
    def continuous(self) -> bool:
        """True when no step exceeds ``max_step``."""
        return not bool(self.reconfigurations.any())
