"""One compiled model per robot: every per-robot fact the compiled stages need, built once and kept.

:func:`model_of` ``(robot, lm_cfg=None) -> Model`` builds the :class:`Model` of a robot (and an LM config) on first
use and keeps it while the robot lives (a weak reference: a dropped robot drops its model). The compiled backend
(:mod:`nik.ik.backends.compiled`), the paths (:mod:`nik.paths.solve`) and the viewer read these facts here; nothing
else keeps per-robot facts.

What a model holds (numpy, float64 unless said; ``n`` joints):

- ``G: (n + 1, 4, 4)``, ``joints: (n, 5)``: the chain arrays of the kernels (:meth:`nik.Robot.chain_arrays`);
- ``lo, hi: (n,)`` the limits; ``lo32, hi32: (n,)`` float32 the limits as a float32 answer must respect them
  (rounded inwards as :meth:`nik.Robot.limits_as` rounds them); ``prismatic: (n,)`` bool;
- ``wraps: (n,)`` bool: revolute joints whose range *exceeds* a full turn (by :data:`WRAP_MARGIN`), so that a
  path may carry them past +-pi by whole turns (the kernels' ``WRAPS`` column, a range of at least a full turn,
  decides instead whether a value past a limit may move by whole turns);
- ``center: (3,)``, ``radius``: the provable reach bound (:mod:`nik.robots.reach`); :meth:`Model.reach_ratio`,
  :meth:`Model.reach_flags` and :meth:`Model.unreachable_message` apply it;
- ``closed``: the constants of the compiled closed form (:mod:`nik.kernels.closed`) or None (no closed form);
  ``closed_check``: the FK tolerance (metres, radians) by the targets' torch dtype at which a closed-form solution
  counts as valid; ``approximate``: True for an arm that fits its family only within the tolerance of
  :mod:`nik.analytic.geometry` (URDF origins rounded to float32; the Jaco2's wrist axes miss by 8e-8 m).
  **One policy for approximate closed forms**: such an arm gets the *ideal* arm's closed form, each solution
  checked by FK on the real arm at :data:`APPROXIMATE_CHECK_TOL` (1e-5 m / 1e-5 rad, ten times inside the
  default solver tolerance); whoever asks for a tighter tolerance polishes by LM (the solve's refine stage does;
  a path polishes its chosen branches the same way). The torch closed form's Newton polish
  (``nik.analytic.solve``) is not used by the compiled stages;
- ``lm``: the compiled LM (:class:`nik.lm.compiled.CompiledLM`) of the robot and the LM config;
- ``base_inv, tool_inv``: ``(4, 4)`` inverses of the robot's base and tool frames, or None:
  :meth:`Model.arm_targets` maps targets into the frame of the bare arm, where a network trained for the arm
  without frames guesses (:attr:`nik.Robot.arm_hash`);
- :meth:`Model.packed` ``(net)``: the network packed for the kernels (:func:`nik.nets.compiled.pack`), once per net.

The model is read-only after it is built (its small caches are dicts filled under the GIL): threads may share it.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from nik.robots.reach import REACH_SLACK

__all__ = ["APPROXIMATE_CHECK_TOL", "CLOSED_FORM_TOL", "WRAP_MARGIN", "Model", "forget_model", "model_of"]

#: The FK check of a closed-form solution (metres, radians) by the targets' dtype: ``nik.analytic.solve``'s
#: defaults (a float32 pose is a rotation only to about 1e-7).
CLOSED_FORM_TOL = {torch.float64: 1e-9, torch.float32: 2e-5}
#: The same check on an arm whose closed form is that of the ideal arm it is within tolerance of (metres,
#: radians): the Jaco2's wrist axes miss each other by 8e-8 m, its closed-form solutions by about as much.
APPROXIMATE_CHECK_TOL = 1e-5
#: A revolute joint "wraps" (a path may carry it past +-pi) when its range exceeds a full turn by this (radians).
WRAP_MARGIN = 1e-6


@dataclass(eq=False)
class Model:
    """The compiled facts of one robot (module docstring). Build with :func:`model_of`."""

    robot_ref: Any
    G: np.ndarray
    joints: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    lo32: np.ndarray
    hi32: np.ndarray
    prismatic: np.ndarray
    wraps: np.ndarray
    center: np.ndarray
    radius: float
    closed: np.ndarray | None
    closed_check: dict | None
    approximate: bool
    lm: Any
    base_inv: np.ndarray | None = None
    tool_inv: np.ndarray | None = None
    _packed: Any = field(default_factory=weakref.WeakKeyDictionary, repr=False)
    #: the compiled backend's driver arguments per (plan, dtype), gathered once per plan (plans are immutable)
    driver_args: dict = field(default_factory=dict, repr=False)

    @property
    def robot(self):
        """The robot (None once it is gone)."""
        return self.robot_ref()

    @property
    def dof(self) -> int:
        return int(self.joints.shape[0])

    @property
    def has_frames(self) -> bool:
        """True when the robot carries a base or tool frame (:meth:`arm_targets` is not the identity)."""
        return self.base_inv is not None or self.tool_inv is not None

    # -- reach ---------------------------------------------------------------------------------------------------
    def reach_ratio(self, T: np.ndarray) -> np.ndarray:
        """``(B,)``: distance of each position of ``T: (B, 4, 4)`` from the first axis point over the reach
        radius (> 1 + ``REACH_SLACK``: provably out of reach)."""
        d = T[:, :3, 3] - self.center
        return np.sqrt((d * d).sum(axis=1)) / self.radius

    def reach_flags(self, T: np.ndarray) -> np.ndarray:
        """``(B,)`` bool: False where the reach bound proves ``T: (B, 4, 4)`` float64 out of reach."""
        return self.reach(T)[0]

    def reach(self, T: np.ndarray) -> tuple[np.ndarray, bool]:
        """``(flags (B,) bool, every)``: :meth:`reach_flags` and whether every target is within reach, in one
        kernel call (:func:`nik.kernels.poses.reach_flags`)."""
        flags = np.empty(T.shape[0], dtype=bool)
        return flags, bool(_k().reach_flags(T, self.center, self.radius, REACH_SLACK, flags))

    def unreachable_message(self, T: np.ndarray, flags: np.ndarray, *, unit_hint: str = "") -> str | None:
        """The one line about the targets ``flags`` marks out of reach (:func:`nik.robots.reach.unreachable_message`:
        with the millimetre question beyond ``MM_HINT_FACTOR``), or None."""
        from nik.robots.reach import unreachable_message

        if flags.all():
            return None
        return unreachable_message(self.robot, torch.from_numpy(T), torch.from_numpy(flags), unit_hint=unit_hint)

    # -- closed form ---------------------------------------------------------------------------------------------
    def closed_solutions(
        self, T: np.ndarray, tol_pos: float | None = None, tol_rot: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """All 8 closed-form branches of ``T: (B, 4, 4)`` float64: ``q: (B, 8, 6)`` (each angle moved by whole turns
        into its limits where possible) and ``valid: (B, 8)`` (the branch exists, lies inside the limits and reaches
        the pose by FK within ``tol_pos`` m / ``tol_rot`` rad; default :attr:`closed_check` of float64, i.e.
        :data:`APPROXIMATE_CHECK_TOL` on an approximate arm). Raises ``ValueError`` on an arm without one."""
        from nik.kernels.closed import solutions

        if self.closed is None:
            raise ValueError("closed_solutions: this arm has no closed form")
        check = self.closed_check[torch.float64]
        tp = check if tol_pos is None else tol_pos
        tr = check if tol_rot is None else tol_rot
        B = T.shape[0]
        q, valid = np.empty((B, 8, self.dof)), np.empty((B, 8), dtype=bool)
        solutions(self.closed, self.G, self.joints, tp, tr, np.ascontiguousarray(T, dtype=np.float64), q, valid)
        return q, valid

    # -- networks ------------------------------------------------------------------------------------------------
    def arm_targets(self, T: np.ndarray) -> np.ndarray:
        """``T: (B, 4, 4)`` mapped into the bare arm's frame, ``base^-1 @ T @ tool^-1`` (``T`` itself without
        frames): what a network trained for the arm without frames takes."""
        if self.base_inv is not None:
            T = self.base_inv @ T
        if self.tool_inv is not None:
            T = T @ self.tool_inv
        return np.ascontiguousarray(T)

    def packed(self, net):
        """``net`` packed for the kernels (:func:`nik.nets.compiled.pack`, once per network), or None for a kind
        that is not packed (the caller runs torch)."""
        try:
            found = self._packed.get(net)
        except TypeError:  # not weak-referenceable: pack each time
            found = None
        if found is None:
            from nik.nets.compiled import pack

            found = pack(net) or False
            try:
                self._packed[net] = found
            except TypeError:
                pass
        return found or None


_K = None


def _k():
    """:mod:`nik.kernels.poses`, imported on first use (``import nik`` does not import numba)."""
    global _K
    if _K is None:
        from nik.kernels import poses

        _K = poses
    return _K


def _inverse(frame) -> np.ndarray | None:
    if frame is None:
        return None
    M = np.asarray(frame.numpy() if isinstance(frame, torch.Tensor) else frame, dtype=np.float64)
    R, p = M[:3, :3], M[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ p
    return out


def _closed_constants(robot) -> tuple[np.ndarray | None, dict | None, bool]:
    """``(constants of the compiled closed form, its FK check tolerance by dtype, approximate)``; ``(None, None,
    False)`` without a closed form."""
    from nik.analytic import family

    if family(robot) is None:
        return None, None, False
    from nik.analytic.solve import closed_form
    from nik.kernels.closed import closed_form_array

    k = closed_form(robot)
    if k.get("polish"):  # within tolerance of its family: the ideal arm's closed form (module docstring)
        return closed_form_array({**k, "polish": False}), dict.fromkeys(CLOSED_FORM_TOL, APPROXIMATE_CHECK_TOL), True
    return closed_form_array(k), dict(CLOSED_FORM_TOL), False


def _build(robot, lm_cfg) -> Model:
    from nik.lm.compiled import CompiledLM
    from nik.robots.reach import reach_center, reach_radius

    G, joints = robot.chain_arrays()
    lo, hi = (np.ascontiguousarray(c) for c in robot.limits.double().numpy().T)
    lo32, hi32 = robot.limits_as(torch.empty(0, dtype=torch.float32))
    prismatic = robot.prismatic.numpy().astype(bool)
    closed, check, approximate = _closed_constants(robot)
    return Model(
        weakref.ref(robot),
        G,
        joints,
        lo,
        hi,
        lo32.numpy(),
        hi32.numpy(),
        prismatic,
        ((hi - lo) > 2 * math.pi + WRAP_MARGIN) & ~prismatic,
        reach_center(robot).double().numpy(),
        max(reach_radius(robot), 1e-300),
        closed,
        check,
        approximate,
        CompiledLM.of(robot, lm_cfg),
        _inverse(getattr(robot, "base", None)),
        _inverse(getattr(robot, "tool", None)),
    )


_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Counts :func:`forget_model` calls: what keeps a model beyond a call (:mod:`nik.ik.backends.one_pose`) compares it.
generation = 0


def forget_model(robot) -> None:
    """Drop the models kept for ``robot`` (its frames changed: :func:`nik.robots.frames.adopt_arm`)."""
    global generation
    _MODELS.pop(robot, None)
    generation += 1


def model_of(robot, lm_cfg=None) -> Model:
    """The :class:`Model` of ``robot`` with the compiled LM of ``lm_cfg`` (a :class:`nik.lm.LMCfg`; None: the
    default), built on first use and kept while the robot lives; rebuilt when the robot's chain arrays change."""
    per_robot = _MODELS.get(robot)
    if per_robot is None:
        per_robot = _MODELS[robot] = {}
    key = None if lm_cfg is None else tuple(vars(lm_cfg).values())
    model = per_robot.get(key)
    if model is None or model.G is not robot.chain_arrays()[0]:
        model = per_robot[key] = _build(robot, lm_cfg)
    return model
