"""``IKSolver``: initial guess (network, closed form or multi-start) -> swarm/LM refinement -> result.

The pipeline of :meth:`IKSolver.solve`, for a batch of B target poses:

1. **initial guess**: the trained network's prediction when a checkpoint is given; else, for a
   PUMA-like arm (:func:`nik.analytic.is_puma_like`), the closed-form solution (the valid one
   nearest ``q_near``, or the one farthest inside the joint ranges); else a multi-start (the swarm
   starts from particles spread uniformly inside the limits, LM from the best of
   ``LMCfg.first_starts`` uniform configurations);
2. **refinement** of the targets the guess leaves outside tolerance: by default (``refine="lm"``)
   Levenberg-Marquardt (:func:`nik.swarm.lm_solve`) from the guess, then restarts from uniform starts
   only for the targets that still fail and are not provably out of reach (:mod:`nik.reach`); the
   swarm methods (``ipso`` | ``pso`` | ``sapso`` | ``ga``) through :func:`nik.swarm.refine` (finished by
   an LM polish unless ``polish=False``); ``refine="none"`` returns the raw guess;
3. **result**: joint angles inside the limits, their true errors measured by FK, an honest
   success flag and ``reachable`` (False where the reach bound proves the target out of reach;
   :meth:`IKSolver.solve` warns about those, and asks about millimetres when they lie 100 x beyond).

The parts are small callables that :class:`IKSolver` composes: guess providers
``(robot, T, ...) -> q (B, dof)`` in :mod:`nik.guesses` (closed form, network, multistart), refiners
``(robot, T, q0) -> RefineResult`` in :mod:`nik.refiners` (LM; the swarms through
:func:`nik.swarm.refine`), and the final check here (FK errors, success, reachability).

Units are SI (metres, radians) throughout.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch

from nik.guesses import analytic_guess, multistart_guess, nearest_solution, network_guess
from nik.poses import (
    POSE_DIMS,
    make_pose,
    pose_error,
    quaternion_to_matrix,
    rpy_to_matrix,
    validate_joints,
    validate_pose,
)
from nik.reach import unreachable_message, within_reach
from nik.refiners import RefineResult, lm_refine
from nik.robots import Robot, load_robot
from nik.threads import threads_for

__all__ = ["REFINE_METHODS", "IKResult", "IKSolver", "RefineResult", "as_poses", "lm_refine", "nearest_solution"]

#: Values of ``IKSolver(refine=...)``.
REFINE_METHODS = ("none", "pso", "sapso", "ipso", "ga", "lm")

#: Largest accepted deviation of a quaternion's norm from 1; nearer ones are normalised.
QUAT_NORM_TOL = 1e-2


@dataclass
class IKResult:
    """Result of :meth:`IKSolver.solve` for B targets.

    Attributes:
        q: (B, dof) joint angles, radians, inside the joint limits.
        pos_err: (B,) position error of ``q`` (FK), metres.
        rot_err: (B,) geodesic rotation error of ``q``, radians.
        success: (B,) bool, ``pos_err <= tol_pos`` and ``rot_err <= tol_rot``.
        iterations: (B,) long, refinement iterations spent (0 where the guess was already within tolerance).
        source: where the initial guess came from: ``network``, ``analytic`` or ``multistart``.
        reachable: (B,) bool, False where no configuration can reach the target (provable reach
            bound, :func:`nik.reach.within_reach`); such targets get ``success=False`` and a best effort.
    """

    q: torch.Tensor
    pos_err: torch.Tensor
    rot_err: torch.Tensor
    success: torch.Tensor
    iterations: torch.Tensor
    source: str = ""
    reachable: torch.Tensor | None = None

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def to(self, device: str | torch.device) -> IKResult:
        """The same result with every tensor on ``device``."""
        moved = {f.name: getattr(self, f.name) for f in fields(self)}
        moved = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in moved.items()}
        return IKResult(**moved)


# ---------------------------------------------------------------------------
# Input forms
# ---------------------------------------------------------------------------
def as_poses(T_target, representation: str | None = None, *, name: str = "T_target") -> torch.Tensor:
    """Bring targets to ``(B, 4, 4)`` homogeneous poses, validated.

    Args:
        T_target: ``(B, 4, 4)`` matrices, ``(B, 7)`` xyz + quaternion (w, x, y, z) or ``(B, 6)``
            xyz + roll-pitch-yaw (paper C: ``R = Rz(yaw) Ry(pitch) Rx(roll)``), metres and radians;
            a tensor, a numpy array or nested lists. A single pose ``(4, 4)``, ``(7,)`` or ``(6,)``
            is taken as B = 1. Non-tensor input and integer tensors become float64.
        representation: ``"matrix"``, ``"quat"`` or ``"rpy"``; None infers it from the shape.

    Returns:
        ``(B, 4, 4)`` floating-point poses (dtype and device of a floating tensor input).

    Raises:
        ValueError: wrong shape, NaN/inf, a quaternion whose norm is 0 or further than
            :data:`QUAT_NORM_TOL` from 1, a non-orthonormal rotation; the message names the field and row.
    """
    if isinstance(T_target, torch.Tensor):
        T = T_target if T_target.is_floating_point() else T_target.to(torch.float64)
    else:
        try:
            T = torch.as_tensor(np.asarray(T_target, dtype=np.float64))
        except (TypeError, ValueError) as err:
            raise ValueError(f"{name}: expected numbers (poses), got {type(T_target).__name__}: {err}") from err
    if representation is None:
        if T.ndim >= 2 and T.shape[-2:] == (4, 4):
            representation = "matrix"
        elif T.ndim >= 1 and T.shape[-1] == POSE_DIMS["quat"]:
            representation = "quat"
        elif T.ndim >= 1 and T.shape[-1] == POSE_DIMS["rpy"]:
            representation = "rpy"
        else:
            raise ValueError(
                f"{name}: cannot tell the pose form from shape {tuple(T.shape)}; expected (B, 4, 4), "
                "(B, 7) xyz + quaternion (w, x, y, z) or (B, 6) xyz + roll-pitch-yaw"
            )
    if representation == "matrix":
        if T.ndim == 2 and T.shape == (4, 4):
            T = T.unsqueeze(0)
        if T.ndim != 3 or T.shape[-2:] != (4, 4):
            raise ValueError(f"{name}: expected shape (B, 4, 4) for 4x4 poses, got {tuple(T.shape)}")
        return validate_pose(T, name=name)
    if representation not in ("quat", "rpy"):
        raise ValueError(f"{name}: representation must be 'matrix', 'quat' or 'rpy', got {representation!r}")
    width = POSE_DIMS[representation]
    if T.ndim == 1:
        T = T.unsqueeze(0)
    if T.ndim != 2 or T.shape[-1] != width:
        raise ValueError(
            f"{name}: a {representation!r} pose has {width} numbers per row; expected shape (B, {width}), "
            f"got {tuple(T.shape)}"
        )
    fields = ("x, y, z", "quaternion (w, x, y, z)" if representation == "quat" else "roll, pitch, yaw")
    for label, part in zip(fields, (T[:, :3], T[:, 3:]), strict=True):
        bad = ~torch.isfinite(part).all(dim=-1)
        if bool(bad.any()):
            raise ValueError(f"{name}: row {int(bad.nonzero()[0])}: {label} contains NaN or inf")
    p, rot = T[:, :3], T[:, 3:]
    if representation == "quat":
        norm = torch.linalg.vector_norm(rot, dim=-1)
        bad = (norm - 1).abs() > QUAT_NORM_TOL
        if bool(bad.any()):
            i = int(bad.nonzero()[0])
            raise ValueError(
                f"{name}: row {i}: quaternion (w, x, y, z) has norm {float(norm[i]):.6g}; "
                f"a unit quaternion is expected (norm within {QUAT_NORM_TOL:g} of 1 is normalised)"
            )
        R = quaternion_to_matrix(rot / norm[:, None])
    else:
        R = rpy_to_matrix(rot)
    return validate_pose(make_pose(R, p), name=name)


def dedupe(q: torch.Tensor, *, tol: float = 1e-3, prismatic: torch.Tensor | None = None) -> torch.Tensor:
    """Drop from ``q: (K, dof)`` every row within ``tol`` (max abs joint difference, radians or metres;
    wrapped modulo 2 pi except on ``prismatic: (dof,)`` joints) of an earlier row; the order of the rest is kept."""
    if q.shape[0] <= 1:
        return q
    diff = q[:, None] - q[None]
    wrapped = torch.remainder(diff + math.pi, 2 * math.pi) - math.pi
    diff = wrapped if prismatic is None else torch.where(prismatic.to(q.device), diff, wrapped)
    close = diff.abs().amax(-1) < tol
    dup = torch.triu(close, diagonal=1).any(dim=0)
    return q[~dup]


def check_tolerances(tol_pos: float, tol_rot: float) -> None:
    """Raise ``ValueError`` unless both tolerances are numbers >= 0 (NaN and negatives are refused)."""
    for name, value, unit in (("tol_pos", tol_pos, "metres"), ("tol_rot", tol_rot, "radians")):
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected a number >= 0 ({unit}), got {value!r}") from None
        if math.isnan(v) or v < 0:
            raise ValueError(f"{name}: expected a number >= 0 ({unit}), got {value!r}")


# ---------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------
def _shipped_network(robot: Robot):
    """The network shipped for ``robot`` when one exists for its name and definition hash, else None."""
    from nik.pretrained import available, read_meta

    if robot.name not in available() or read_meta(robot.name).get("robot_hash") != robot.definition_hash:
        return None
    from nik.models import load_pretrained

    return load_pretrained(robot)


class IKSolver:
    """Inverse kinematics for one robot: guess, refine, report honestly.

    Args:
        robot: a :class:`nik.Robot`, or a built-in name, YAML or URDF path for :func:`nik.load_robot`.
        checkpoint: ``"auto"`` (default): the network shipped with nik for this robot
            (:func:`nik.models.load_pretrained`) when one exists for its name and definition hash, else none;
            on a PUMA-like arm with ``analytic=True`` the closed form stays the guess and no network is
            loaded. A path: a trained network (``.ckpt`` from ``train.py`` or
            :func:`nik.models.save_checkpoint`), loaded safely by :func:`nik.models.load_checkpoint`; one
            made for another robot is refused. ``None``: no network. A multi-solution network
            (:mod:`nik.multinet`) guesses its best hypothesis by FK; targets the refinement leaves outside
            tolerance then get LM from each of its other hypotheses (before any ``fallback``);
            :meth:`solve_all` starts LM from all of them.
        refine: ``lm`` (the default: Levenberg-Marquardt from the guess, restarts only for the targets
            that fail; the fastest) | ``none`` | ``pso`` | ``sapso`` | ``ipso`` | ``ga`` (swarms, then LM polish).
        polish: finish swarm refinements with Levenberg-Marquardt (``nik.swarm.refine(polish=True)``).
        swarm_cfg: optional config of the refinement method (e.g. :class:`nik.swarm.IPSOCfg`).
        analytic: use the closed form for PUMA-like arms when no checkpoint is given (default True).
        device: where the network lives (``"cpu"``, ``"cuda"``); :meth:`solve` computes on the device of
            its input poses (``T.to("cuda")``) and the network's guess is moved there.
        fallback: a second chance for targets still outside tolerance after the refinement:
            ``"analytic"``, the closed-form solution nearest the first answer (PUMA-like arms only);
            ``"multistart"``, Levenberg-Marquardt from fresh uniform starts (with ``refine="lm"`` these
            are the LM's own restarts, drawn only for the targets that fail and are within reach);
            ``"auto"`` (or True, the default), analytic where available, else multistart;
            ``"none"`` (or False: with ``refine="lm"`` and a guess, no restarts). It is not used where it
            would repeat the first pass (no network on a PUMA-like arm), nor with ``refine="none"``,
            nor for targets proven out of reach. The evaluation turns it off to measure what the
            network's guess alone delivers.
    """

    def __init__(
        self,
        robot: Robot | str | Path,
        checkpoint: str | Path | None = "auto",
        refine: str = "lm",
        *,
        polish: bool = True,
        swarm_cfg=None,
        analytic: bool = True,
        fallback: bool | str = "auto",
        device: str | torch.device | None = None,
    ):
        from nik.device import resolve_device

        self.device = resolve_device(device)
        if refine not in REFINE_METHODS:
            raise ValueError(f"IKSolver: refine must be one of {list(REFINE_METHODS)}, got {refine!r}")
        self.robot = load_robot(robot) if not isinstance(robot, Robot) else robot
        self.refine = refine
        self.polish = bool(polish)
        self.swarm_cfg = swarm_cfg
        fallback = {True: "auto", False: "none"}.get(fallback, fallback)
        if fallback not in ("auto", "analytic", "multistart", "none"):
            raise ValueError(f"IKSolver: fallback must be auto, analytic, multistart or none, got {fallback!r}")
        self.net = None
        self._analytic = False
        if analytic:
            from nik.analytic import is_puma_like

            self._analytic = is_puma_like(self.robot)
        if isinstance(checkpoint, str) and checkpoint == "auto":
            if not self._analytic:
                self.net = _shipped_network(self.robot)
        elif checkpoint is not None:
            from nik.models import load_checkpoint

            self.net = load_checkpoint(checkpoint, robot=self.robot)
        if self.net is not None:
            self.net = self.net.to(self.device)
        if fallback == "analytic" and not self._analytic:
            raise ValueError(f"IKSolver: fallback='analytic' needs a PUMA-like arm; {self.robot.name} is not")
        if fallback == "auto":
            fallback = "analytic" if self._analytic else "multistart"
        self.fallback = fallback

    def __repr__(self) -> str:
        return (
            f"IKSolver(robot={self.robot.name!r}, network={self.net is not None}, "
            f"analytic={self._analytic}, refine={self.refine!r})"
        )

    @property
    def initial_source(self) -> str:
        """Where :meth:`solve` takes its initial guess: ``network``, ``analytic`` or ``multistart``."""
        if self.net is not None:
            return "network"
        return "analytic" if self._analytic else "multistart"

    # -- helpers ----------------------------------------------------------
    def _q_near(self, q_near, B: int, like: torch.Tensor) -> torch.Tensor | None:
        if q_near is None:
            return None
        q = q_near if isinstance(q_near, torch.Tensor) else torch.as_tensor(np.asarray(q_near, dtype=np.float64))
        validate_joints(q, self.robot.dof, name="q_near")
        q = q.to(dtype=like.dtype, device=like.device)
        if q.ndim == 1:
            q = q.expand(B, -1)
        if q.shape != (B, self.robot.dof):
            dof = self.robot.dof
            raise ValueError(f"q_near: expected shape ({dof},) or ({B}, {dof}), got {tuple(q.shape)}")
        return q

    def _multistart_guess(self, T: torch.Tensor, seed: int, n_starts: int = 64) -> torch.Tensor:
        return multistart_guess(self.robot, T, seed=seed, n_starts=n_starts)

    def _analytic_guess(self, T: torch.Tensor, q_near: torch.Tensor | None) -> torch.Tensor:
        return analytic_guess(self.robot, T, q_near=q_near)

    def _refine(self, T, q_init, *, tol_pos, tol_rot, seed, max_iters, reachable=None):
        if self.refine == "lm":
            return lm_refine(
                self.robot,
                T,
                q_init,
                tol_pos=tol_pos,
                tol_rot=tol_rot,
                seed=seed,
                max_iters=max_iters,
                cfg=self.swarm_cfg,
                # without a guess the restarts are the multistart itself
                restarts=self.fallback == "multistart" or q_init is None,
                reachable=reachable,
            )
        from nik.swarm import refine as swarm_refine

        kwargs = {}
        if self.refine != "lm":
            kwargs["polish"] = self.polish
        return swarm_refine(
            self.robot,
            T,
            method=self.refine,
            q_init=q_init,
            cfg=self.swarm_cfg,
            tol_pos=tol_pos,
            tol_rot=tol_rot,
            max_iters=max_iters,
            seed=seed,
            **kwargs,
        )

    def _other_hypotheses(self, T, q, pos, rot, success, iterations, *, tol_pos, tol_rot, seed, max_iters):
        """Targets still outside tolerance after refining the best hypothesis of a multi-solution network:
        LM from its other hypotheses, as ``K - 1`` starts per failing target in one batch (no uniform
        restarts); the answer is kept where it improves on the current one."""
        from nik.swarm import lm_solve

        idx = (~success).nonzero().squeeze(1)
        hyp = self.net.ranked_hypotheses(T[idx])[0][:, 1:]  # (b, K - 1, dof), the best one was refined already
        g = torch.Generator(device=T.device).manual_seed(int(seed))
        hq, it = lm_solve(
            self.robot, T[idx], hyp, tol_pos=tol_pos, tol_rot=tol_rot, max_iters=max_iters, restarts=0, generator=g
        )
        hq = self.robot.clamp(hq).to(q.dtype)
        hpos, hrot = pose_error(T[idx], self.robot.fk(hq))
        better = (hpos + 0.1 * hrot) < (pos[idx] + 0.1 * rot[idx])
        keep = idx[better]
        q, pos, rot, iterations = q.clone(), pos.clone(), rot.clone(), iterations.clone()
        q[keep], pos[keep], rot[keep] = hq[better], hpos[better].to(pos.dtype), hrot[better].to(rot.dtype)
        iterations[idx] += it.to(torch.long)
        return q, pos, rot, (pos <= tol_pos) & (rot <= tol_rot), iterations

    # -- public -----------------------------------------------------------
    def initial_guess(self, T_target, *, q_near=None, seed: int = 0, representation: str | None = None) -> torch.Tensor:
        """The raw initial guess ``(B, dof)`` (network, analytic or best-of-64 uniform), inside the limits."""
        T = as_poses(T_target, representation)
        q_near = self._q_near(q_near, T.shape[0], T)
        if self.net is not None:
            return network_guess(self.net, self.robot, T)
        if self._analytic:
            return self._analytic_guess(T, q_near)
        return self._multistart_guess(T, seed)

    def solve(
        self,
        T_target,
        tol_pos: float = 1e-4,
        tol_rot: float = 1e-3,
        seed: int = 0,
        q_near=None,
        max_iters: int | None = None,
        representation: str | None = None,
    ) -> IKResult:
        """Joint angles that reach the target poses.

        Args:
            T_target: ``(B, 4, 4)``, ``(B, 7)`` xyz + quaternion (w, x, y, z) or ``(B, 6)`` xyz +
                roll-pitch-yaw, metres/radians (see :func:`as_poses`; a single pose counts as B = 1).
                The computation runs in its dtype and device (non-tensor input: float64).
            tol_pos: success tolerance on the position, metres.
            tol_rot: success tolerance on the geodesic rotation error, radians.
            seed: seeds every random choice (same seed, same answer).
            q_near: ``(dof,)`` or ``(B, dof)`` current configuration, radians: among the solutions
                found, return the one nearest to it (joint motion, see :func:`nearest_solution`).
                Analytic arms pick among the 8 closed-form solutions; otherwise the refinement is
                also run from ``q_near`` itself and the successful answer nearest ``q_near`` is kept.
            max_iters: iteration limit of the refinement (default: the method's config).
            representation: ``"matrix"`` | ``"quat"`` | ``"rpy"``; inferred from the shape when None.

        Returns:
            :class:`IKResult` with ``(B, ...)`` fields; errors and success measured by FK on the returned ``q``.

        Raises:
            ValueError: bad poses, a negative or NaN tolerance, a malformed ``q_near``.

        Targets that the reach bound proves out of reach are flagged (``reachable``), get no restarts,
        and a ``UserWarning`` names them (asking about millimetres when they lie 100 x beyond the reach).
        """
        check_tolerances(tol_pos, tol_rot)
        T = as_poses(T_target, representation)
        reachable = within_reach(self.robot, T)
        msg = unreachable_message(self.robot, T, reachable)
        if msg is not None:
            warnings.warn(msg, UserWarning, stacklevel=2)
        with threads_for(T.shape[0]):
            res = self._solve(T, tol_pos, tol_rot, seed, q_near, max_iters, reachable)
        res.reachable = reachable
        return res

    def _solve(self, T, tol_pos, tol_rot, seed, q_near, max_iters, reachable) -> IKResult:
        B = T.shape[0]
        robot = self.robot
        q_near_t = self._q_near(q_near, B, T)
        source = self.initial_source
        if self.net is not None:
            q0 = network_guess(self.net, robot, T)
        elif self._analytic:
            q0 = self._analytic_guess(T, q_near_t)
        elif self.refine in ("none",):
            q0 = self._multistart_guess(T, seed)
        else:
            q0 = None  # multi-start: uniform particles (swarm) or uniform starts (LM)
        iterations = torch.zeros(B, dtype=torch.long, device=T.device)
        if q0 is not None:
            pos, rot = pose_error(T, robot.fk(q0))
            q = q0
        if self.refine == "none":
            return IKResult(q, pos, rot, (pos <= tol_pos) & (rot <= tol_rot), iterations, source)

        if q0 is None:
            todo = torch.arange(B, device=T.device)
            q = torch.zeros(B, robot.dof, dtype=T.dtype, device=T.device)
            pos = torch.full((B,), float("inf"), dtype=T.dtype, device=T.device)
            rot = pos.clone()
        else:
            todo = ~((pos <= tol_pos) & (rot <= tol_rot))
            if source == "analytic":  # out of reach: the clamped closed form nearest the target is the best effort
                todo &= reachable
            todo = todo.nonzero().squeeze(1)
        use_near = q_near_t is not None and not self._analytic
        if use_near:
            todo = torch.arange(B, device=T.device)  # q_near: also look for a solution near q_near everywhere
        if todo.numel():
            Tt = T[todo]
            init = None if q0 is None else q0[todo]
            res = self._refine(
                Tt, init, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, max_iters=max_iters, reachable=reachable[todo]
            )
            cand_q, cand_pos, cand_rot, cand_it = res.q, res.pos_err, res.rot_err, res.iterations
            if use_near:
                near = self._refine(
                    Tt,
                    q_near_t[todo],
                    tol_pos=tol_pos,
                    tol_rot=tol_rot,
                    seed=seed,
                    max_iters=max_iters,
                    reachable=reachable[todo],
                )
                ok_a = (cand_pos <= tol_pos) & (cand_rot <= tol_rot)
                ok_b = (near.pos_err <= tol_pos) & (near.rot_err <= tol_rot)
                qn = q_near_t[todo]
                dist_a = torch.linalg.vector_norm(cand_q - qn, dim=-1)
                dist_b = torch.linalg.vector_norm(near.q - qn, dim=-1)
                worse_a = (cand_pos + 0.1 * cand_rot) > (near.pos_err + 0.1 * near.rot_err)
                # a successful answer first, then the nearer one; if neither succeeded, the smaller error
                take_b = (ok_b & (~ok_a | (dist_b < dist_a))) | (~ok_a & ~ok_b & worse_a)
                cand_q = torch.where(take_b[:, None], near.q, cand_q)
                cand_pos = torch.where(take_b, near.pos_err, cand_pos)
                cand_rot = torch.where(take_b, near.rot_err, cand_rot)
                cand_it = cand_it + near.iterations
            # never worse than the guess: keep the refined answer unless the guess was better
            better = (cand_pos + 0.1 * cand_rot) <= (pos[todo] + 0.1 * rot[todo]) if q0 is not None else None
            if better is not None and not use_near:
                cand_q = torch.where(better[:, None], cand_q, q[todo])
                cand_pos = torch.where(better, cand_pos, pos[todo])
                cand_rot = torch.where(better, cand_rot, rot[todo])
            q, pos, rot = q.clone(), pos.clone(), rot.clone()
            q[todo], pos[todo], rot[todo] = cand_q.to(q.dtype), cand_pos.to(pos.dtype), cand_rot.to(rot.dtype)
            iterations[todo] = cand_it.to(torch.long)
        if not (B == 1 and T.device.type == "cpu" and self.refine == "lm"):
            # (the one-pose lean path returns q inside the limits with its errors measured by FK already)
            q = robot.clamp(q)
            pos, rot = pose_error(T, robot.fk(q))
        success = (pos <= tol_pos) & (rot <= tol_rot)
        if getattr(self.net, "n_hypotheses", 1) > 1 and not bool(success.all()):
            q, pos, rot, success, iterations = self._other_hypotheses(
                T, q, pos, rot, success, iterations, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, max_iters=max_iters
            )
        # the LM refinement already restarts its failures (the multistart fallback); the closed form
        # without a network is the first pass itself
        first_pass_is_fallback = (self.net is None and self._analytic) or (
            self.refine == "lm" and self.fallback == "multistart"
        )
        if self.fallback != "none" and not first_pass_is_fallback and not bool((success | ~reachable).all()):
            idx = (~success & reachable).nonzero().squeeze(1)
            if self.fallback == "analytic":  # the closed-form solution nearest the first answer (or q_near)
                near = q_near_t[idx] if q_near_t is not None else q[idx]
                fq = self._analytic_guess(T[idx], near)
                fpos, frot = pose_error(T[idx], robot.fk(fq))
                fit = torch.zeros_like(iterations[idx])
            else:  # Levenberg-Marquardt from uniform starts
                res = lm_refine(robot, T[idx], None, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed)
                fq, fpos, frot, fit = res.q, res.pos_err, res.rot_err, res.iterations.to(torch.long)
            better = (fpos + 0.1 * frot) < (pos[idx] + 0.1 * rot[idx])
            keep = idx[better]
            q, pos, rot = q.clone(), pos.clone(), rot.clone()
            q[keep], pos[keep], rot[keep] = fq[better], fpos[better], frot[better]
            iterations[idx] += fit
            success = (pos <= tol_pos) & (rot <= tol_rot)
        return IKResult(q, pos, rot, success, iterations, source)

    def solve_all(
        self,
        T_target,
        *,
        tol_pos: float = 1e-4,
        tol_rot: float = 1e-3,
        seed: int = 0,
        n_starts: int = 256,
        dedupe_tol: float = 1e-3,
        representation: str | None = None,
    ) -> torch.Tensor:
        """Every distinct solution found for one pose: ``(K, dof)`` radians inside the limits (K may be 0).

        PUMA-like arms (``analytic=True``): the valid closed-form solutions (at most 8; exact). Otherwise
        LM from every hypothesis of the network (each IK branch of a branch network, each head of a
        multi-head one; the guess of a plain network) and then ``n_starts`` uniform starts; the
        successful ones (within ``tol_pos`` metres / ``tol_rot`` radians) are de-duplicated
        (two solutions are the same when no joint differs by more than ``dedupe_tol`` radians,
        modulo 2 pi). For a redundant arm (7 joints) the solutions form a continuum; K is then
        simply how many distinct samples of it the starts found.
        """
        T = as_poses(T_target, representation)
        if T.shape[0] != 1:
            raise ValueError(f"solve_all: expected one pose, got {T.shape[0]}")
        robot = self.robot
        if self._analytic:
            from nik.analytic import puma560_ik

            sols, valid = puma560_ik(robot, T[0])
            return dedupe(sols[valid], tol=dedupe_tol)
        from nik.swarm import lm_solve

        g = torch.Generator(device=T.device).manual_seed(int(seed))
        starts = robot.sample(n_starts, generator=g, dtype=T.dtype, device=T.device)
        if self.net is not None:  # every hypothesis of the network first (one for a plain IKNet)
            hyp = self.net.hypotheses(T)[0] if hasattr(self.net, "hypotheses") else self.net.predict(T)
            starts = torch.cat([robot.clamp(hyp), starts])
        Tk = T.expand(starts.shape[0], 4, 4)
        q, _ = lm_solve(robot, Tk, starts, tol_pos=tol_pos, tol_rot=tol_rot, max_iters=100, restarts=0)
        q = robot.clamp(q)
        pos, rot = pose_error(Tk, robot.fk(q))
        ok = (pos <= tol_pos) & (rot <= tol_rot)
        q, score = q[ok], (pos + 0.1 * rot)[ok]
        return dedupe(q[score.argsort()], tol=dedupe_tol, prismatic=robot.prismatic)
