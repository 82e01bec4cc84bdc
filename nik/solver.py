"""``IKSolver``: initial guess (network, closed form or multi-start) -> swarm/LM refinement -> result.

The pipeline of :meth:`IKSolver.solve`, for a batch of B target poses:

1. **initial guess**: the trained network's prediction when a checkpoint is given; else, for a
   PUMA-like arm (:func:`nik.analytic.is_puma_like`), the closed-form solution (the valid one
   nearest ``q_near``, or the one farthest inside the joint ranges); else a multi-start (the swarm
   starts from particles spread uniformly inside the limits, LM from ``LMCfg.starts`` uniform starts);
2. **refinement** (``refine`` = ``ipso`` | ``pso`` | ``sapso`` | ``ga`` | ``lm``) of the targets the
   guess leaves outside tolerance, through :func:`nik.swarm.refine` (swarm methods finish with an
   LM polish unless ``polish=False``); ``refine="none"`` returns the raw guess;
3. **result**: joint angles inside the limits, their true errors measured by FK, and an honest
   success flag.

Units are SI (metres, radians) throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from nik.poses import (
    POSE_DIMS,
    make_pose,
    pose_error,
    quaternion_to_matrix,
    rpy_to_matrix,
    validate_joints,
    validate_pose,
)
from nik.robots import Robot, load_robot

__all__ = ["REFINE_METHODS", "IKResult", "IKSolver", "as_poses", "nearest_solution"]

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
    """

    q: torch.Tensor
    pos_err: torch.Tensor
    rot_err: torch.Tensor
    success: torch.Tensor
    iterations: torch.Tensor
    source: str = ""

    def __len__(self) -> int:
        return int(self.q.shape[0])


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


# ---------------------------------------------------------------------------
# Choosing among solutions
# ---------------------------------------------------------------------------
def _near_representative(sols: torch.Tensor, q_near: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Each angle of ``sols: (B, K, dof)`` moved by a multiple of 2 pi, staying inside ``[lo, hi]``,
    as near as possible to ``q_near: (B, dof)`` (matters for joints with more than a full turn of range)."""
    two_pi = 2 * math.pi
    target = q_near[:, None]
    k = torch.round((target - sols) / two_pi)
    best = sols
    best_d = (sols - target).abs()
    for shift in (k - 1, k, k + 1):
        cand = sols + shift * two_pi
        ok = (cand >= lo) & (cand <= hi)
        d = torch.where(ok, (cand - target).abs(), torch.full_like(cand, float("inf")))
        take = d < best_d
        best = torch.where(take, cand, best)
        best_d = torch.where(take, d, best_d)
    return best


def nearest_solution(
    sols: torch.Tensor, valid: torch.Tensor, q_near: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Among ``sols: (B, K, dof)`` with ``valid: (B, K)``, the one nearest ``q_near: (B, dof)``.

    Distance: Euclidean norm of the joint differences after each angle is moved by multiples of
    2 pi (inside the limits) as near ``q_near`` as it goes, i.e. the joint motion to reach it.

    Returns:
        ``q: (B, dof)`` and ``found: (B,)`` bool (False where no solution is valid; ``q`` is then
        the nearest of all).
    """
    rep = _near_representative(sols, q_near, lo, hi)
    dist = torch.linalg.vector_norm(rep - q_near[:, None], dim=-1)
    found = valid.any(-1)
    dist = torch.where(valid | ~found[:, None], dist, torch.full_like(dist, float("inf")))
    idx = dist.argmin(-1)
    q = torch.gather(rep, 1, idx[:, None, None].expand(-1, 1, rep.shape[-1])).squeeze(1)
    return q, found


def _central_solution(sols: torch.Tensor, valid: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Among valid ``sols: (B, K, dof)``, the one whose worst joint is farthest inside its range."""
    margin = torch.minimum(sols - lo, hi - sols) / (hi - lo)
    score = margin.amin(-1)
    score = torch.where(valid, score, torch.full_like(score, -float("inf")))
    idx = score.argmax(-1)
    return torch.gather(sols, 1, idx[:, None, None].expand(-1, 1, sols.shape[-1])).squeeze(1)


def dedupe(q: torch.Tensor, *, tol: float = 1e-3) -> torch.Tensor:
    """Drop from ``q: (K, dof)`` every row within ``tol`` (max abs wrapped joint difference, radians)
    of an earlier row; the order of the rest is kept."""
    if q.shape[0] <= 1:
        return q
    diff = torch.remainder(q[:, None] - q[None] + math.pi, 2 * math.pi) - math.pi
    close = diff.abs().amax(-1) < tol
    dup = torch.triu(close, diagonal=1).any(dim=0)
    return q[~dup]


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
        refine: ``none`` | ``pso`` | ``sapso`` | ``ipso`` | ``ga`` | ``lm``.
        polish: finish swarm refinements with Levenberg-Marquardt (``nik.swarm.refine(polish=True)``).
        swarm_cfg: optional config of the refinement method (e.g. :class:`nik.swarm.IPSOCfg`).
        analytic: use the closed form for PUMA-like arms when no checkpoint is given (default True).
        fallback: a second chance for targets still outside tolerance after the refinement:
            ``"analytic"``, the closed-form solution nearest the first answer (PUMA-like arms only);
            ``"multistart"``, Levenberg-Marquardt from ``LMCfg.starts`` uniform starts;
            ``"auto"`` (or True, the default), analytic where available, else multistart;
            ``"none"`` (or False). It is not used where it would repeat the first pass (no network
            on a PUMA-like arm, or ``refine="lm"`` without a network), nor with ``refine="none"``.
            The evaluation turns it off to measure what the network's guess alone delivers.
    """

    def __init__(
        self,
        robot: Robot | str | Path,
        checkpoint: str | Path | None = "auto",
        refine: str = "ipso",
        *,
        polish: bool = True,
        swarm_cfg=None,
        analytic: bool = True,
        fallback: bool | str = "auto",
    ):
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
        """Best of ``n_starts`` uniform configurations per target (the guess of ``refine='none'``)."""
        g = torch.Generator(device=T.device).manual_seed(int(seed))
        B = T.shape[0]
        q = self.robot.sample(B * n_starts, generator=g, dtype=T.dtype, device=T.device).reshape(B, n_starts, -1)
        pos, rot = pose_error(T[:, None], self.robot.fk(q))
        idx = (pos + 0.1 * rot).argmin(-1)
        return torch.gather(q, 1, idx[:, None, None].expand(-1, 1, q.shape[-1])).squeeze(1)

    def _analytic_guess(self, T: torch.Tensor, q_near: torch.Tensor | None) -> torch.Tensor:
        from nik.analytic import puma560_ik

        sols, valid = puma560_ik(self.robot, T)
        lo, hi = self.robot.limits_as(T)
        if q_near is not None:
            q, _ = nearest_solution(sols, valid, q_near, lo, hi)
            return self.robot.clamp(q)
        q = _central_solution(sols, valid, lo, hi)
        none = ~valid.any(-1)
        if bool(none.any()):  # unreachable or outside the limits: the clamped solution that comes closest
            clamped = self.robot.clamp(sols[none])
            pos, rot = pose_error(T[none, None], self.robot.fk(clamped))
            idx = (pos + 0.1 * rot).argmin(-1)
            q = q.clone()
            q[none] = torch.gather(clamped, 1, idx[:, None, None].expand(-1, 1, clamped.shape[-1])).squeeze(1)
        return self.robot.clamp(q)

    def _refine(self, T, q_init, *, tol_pos, tol_rot, seed, max_iters):
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
        LM from each of its other hypotheses (one batch of ``(failing targets) x (K - 1)`` starts); the best
        answer per target is kept where it improves on the current one."""
        from nik.swarm import refine as swarm_refine

        idx = (~success).nonzero().squeeze(1)
        hyp = self.net.ranked_hypotheses(T[idx])[0][:, 1:]  # (b, K - 1, dof), the best one was refined already
        b, k, dof = hyp.shape
        Tk = T[idx].repeat_interleave(k, dim=0)
        res = swarm_refine(
            self.robot,
            Tk,
            method="lm",
            q_init=hyp.reshape(b * k, dof),
            tol_pos=tol_pos,
            tol_rot=tol_rot,
            max_iters=max_iters,
            seed=seed,
        )
        score = (res.pos_err + 0.1 * res.rot_err).reshape(b, k)
        j = score.argmin(-1)
        pick = torch.arange(b, device=T.device) * k + j
        hq, hpos, hrot = self.robot.clamp(res.q[pick]).to(q.dtype), res.pos_err[pick], res.rot_err[pick]
        better = (hpos + 0.1 * hrot) < (pos[idx] + 0.1 * rot[idx])
        keep = idx[better]
        q, pos, rot, iterations = q.clone(), pos.clone(), rot.clone(), iterations.clone()
        q[keep], pos[keep], rot[keep] = hq[better], hpos[better].to(pos.dtype), hrot[better].to(rot.dtype)
        iterations[idx] += res.iterations.reshape(b, k).amax(-1).to(torch.long)
        return q, pos, rot, (pos <= tol_pos) & (rot <= tol_rot), iterations

    # -- public -----------------------------------------------------------
    def initial_guess(self, T_target, *, q_near=None, seed: int = 0, representation: str | None = None) -> torch.Tensor:
        """The raw initial guess ``(B, dof)`` (network, analytic or best-of-64 uniform), inside the limits."""
        T = as_poses(T_target, representation)
        q_near = self._q_near(q_near, T.shape[0], T)
        if self.net is not None:
            return self.robot.clamp(self.net.predict(T))
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
        """
        T = as_poses(T_target, representation)
        B = T.shape[0]
        robot = self.robot
        q_near_t = self._q_near(q_near, B, T)
        source = self.initial_source
        if self.net is not None:
            q0 = robot.clamp(self.net.predict(T))
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
            todo = (~((pos <= tol_pos) & (rot <= tol_rot))).nonzero().squeeze(1)
        use_near = q_near_t is not None and not self._analytic
        if use_near:
            todo = torch.arange(B, device=T.device)  # q_near: also look for a solution near q_near everywhere
        if todo.numel():
            Tt = T[todo]
            init = None if q0 is None else q0[todo]
            res = self._refine(Tt, init, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, max_iters=max_iters)
            cand_q, cand_pos, cand_rot, cand_it = res.q, res.pos_err, res.rot_err, res.iterations
            if use_near:
                near = self._refine(
                    Tt, q_near_t[todo], tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, max_iters=max_iters
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
        q = robot.clamp(q)
        pos, rot = pose_error(T, robot.fk(q))
        success = (pos <= tol_pos) & (rot <= tol_rot)
        if getattr(self.net, "n_hypotheses", 1) > 1 and not bool(success.all()):
            q, pos, rot, success, iterations = self._other_hypotheses(
                T, q, pos, rot, success, iterations, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, max_iters=max_iters
            )
        first_pass_is_fallback = (self.net is None and self._analytic) or (self.net is None and self.refine == "lm")
        if self.fallback != "none" and not first_pass_is_fallback and not bool(success.all()):
            idx = (~success).nonzero().squeeze(1)
            if self.fallback == "analytic":  # the closed-form solution nearest the first answer (or q_near)
                near = q_near_t[idx] if q_near_t is not None else q[idx]
                fq = self._analytic_guess(T[idx], near)
                fpos, frot = pose_error(T[idx], robot.fk(fq))
                fit = torch.zeros_like(iterations[idx])
            else:  # Levenberg-Marquardt from uniform starts
                from nik.swarm import refine as swarm_refine

                res = swarm_refine(robot, T[idx], method="lm", q_init=None, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed)
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
        q, _ = lm_solve(robot, Tk, starts, tol_pos=tol_pos, tol_rot=tol_rot, max_iters=100)
        q = robot.clamp(q)
        pos, rot = pose_error(Tk, robot.fk(q))
        ok = (pos <= tol_pos) & (rot <= tol_rot)
        q, score = q[ok], (pos + 0.1 * rot)[ok]
        return dedupe(q[score.argsort()], tol=dedupe_tol)
