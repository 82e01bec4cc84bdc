"""The compiled path of :meth:`nik.IKSolver.solve` for CPU batches (one pose up to :data:`LEAN_MAX_BATCH`).

For one pose the torch pipeline spends about a millisecond in per-operation overhead, not arithmetic. This
path does the same job with numpy and the compiled kernels, in tens of microseconds per pose:

1. the targets (``(B, 4, 4)``, ``(B, 7)`` xyz + quaternion or ``(B, 6)`` xyz + roll-pitch-yaw, or one pose)
   and ``q_near`` are checked in numpy with the tolerances of :func:`nik.ik.targets.as_poses`; input these
   checks do not accept goes to the torch path, which raises its usual one-line error (so the messages are
   the same on both paths);
2. the reach bound (:func:`nik.robots.reach.within_reach`) in numpy; targets proven out of reach get the same
   warning, no restarts, and ``success=False`` with the best effort;
3. Levenberg-Marquardt through the compiled kernel (:class:`nik.lm.compiled.CompiledLM`, the solver's
   :class:`~nik.lm.LMCfg`) from the best of ``FIRST_STARTS`` uniform configurations, with the batched LM's
   restart budget for the targets within reach; with ``q_near``, a second LM from ``q_near`` and, per target,
   the rule of the ``near`` stage (a successful answer first, then the one nearer ``q_near``). An arm with a
   closed form (spherical wrist, UR type) instead gets it compiled (:mod:`nik.kernels.closed`: the 8 solutions
   of ``nik.analytic.solve``, the one chosen as ``nik.ik.guesses.analytic_guess`` chooses it), then LM from it
   where it misses the tolerance within reach;
4. an :class:`~nik.ik.result.IKResult` of tensors in the targets' dtype (float64 inside), joints inside
   the limits, errors measured by FK of the returned joints, ``source`` ``"multistart"`` or ``"analytic"``.

When (:func:`applies`, checked in :meth:`nik.IKSolver.solve` before anything else): CPU targets, at most
:data:`LEAN_MAX_BATCH` of them (:data:`LEAN_MAX_BATCH_CLOSED_FORM` on a closed-form arm), ``refine="lm"``,
and: a closed-form arm without a network, or another arm with no network or with ``fallback="multistart"``
(the default: a failing target draws uniform restarts on both paths). The network's guess is not used here:
the forward pass of a shipped network (3 x 512, float64, compiled) alone costs 80 us for one pose of a
multi-head network and 450 us for the 8 branches of a branch network (torch float32: 100 / 220 us), more than
this whole solve from uniform starts (20-50 us median on panda; ``benchmarks/latency_kernels.py``). Same seed,
same answer on this path; the random starts are the kernel's own (the batched path's differ).
"""

from __future__ import annotations

import warnings
import weakref

import numpy as np
import torch

from nik.ik.guesses import LIMIT_ROUNDING
from nik.ik.result import IKResult
from nik.ik.targets import QUAT_NORM_TOL
from nik.lm.batched import LMCfg
from nik.lm.compiled import CompiledLM, CompiledRun
from nik.poses import DEGREES_SUSPECT, ORTHONORMAL_TOL
from nik.robots.reach import REACH_SLACK, reach_center, reach_radius, unreachable_message

__all__ = ["LEAN_MAX_BATCH", "LEAN_MAX_BATCH_CLOSED_FORM", "applies", "solve"]

#: Largest number of CPU targets :meth:`nik.IKSolver.solve` hands to this path on an arm solved by LM.
#: ``benchmarks/crossover.py`` (default IKSolver, panda and ur5 by LM, 1 and 2 threads, B = 1 ... 10,000 on a
#: shared 2-core machine) found no crossover: the compiled path was faster at every size, 15-25x for one pose,
#: 5-13x at 1,024 and still 1.8-2.0x (panda) / 13x (ur5) at 10,000 targets on one thread, with as many
#: successes or more. 10,000 is the largest size measured; beyond it (and on machines with many cores, not
#: measured) the batched torch path.
LEAN_MAX_BATCH = 10_000
#: The same for an arm with a closed form, where the batched torch closed form catches up: one thread, the
#: compiled path was 34-59x faster for one pose, 2.1-2.2x at 1,024 targets, 0.83x (ur5) / 3.3x (kuka_kr) at
#: 4,096 and 1.06x / 1.38x at 10,000: the crossover lies between 1,024 and 4,096 targets.
LEAN_MAX_BATCH_CLOSED_FORM = 2_048

_DTYPES = (torch.float64, torch.float32)
#: The FK check of a closed-form solution (metres, radians) by the targets' dtype: ``nik.analytic.solve``'s
#: defaults (a float32 pose is a rotation only to about 1e-7).
CLOSED_FORM_TOL = {torch.float64: 1e-9, torch.float32: 2e-5}
_ROBOTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_unavailable = False


def applies(solver) -> bool:
    """True when the solver's configuration is one this path reproduces (see the module docstring)."""
    if _unavailable or solver.refine != "lm":
        return False
    if solver.closed_form:  # the closed form is the guess unless a network was given
        return not solver.has_network and _facts(solver.robot)["closed"] is not None
    return not solver.has_network or solver.fallback == "multistart"


def solve(solver, T_target, tol_pos, tol_rot, seed, q_near, max_iters, representation) -> IKResult | None:
    """:meth:`nik.IKSolver.solve` on this path (tolerances already checked); None when the input is not for it
    (not on the CPU, more than :data:`LEAN_MAX_BATCH` targets, another dtype, or something its checks refuse:
    the torch path then answers or raises)."""
    global _unavailable
    limit = LEAN_MAX_BATCH_CLOSED_FORM if solver.closed_form else LEAN_MAX_BATCH
    try:
        poses = _poses(T_target, representation, limit)
    except ImportError as err:  # pragma: no cover - numba is a dependency
        _unavailable = True
        warnings.warn(f"compiled kernels unavailable ({err}); using the torch path", RuntimeWarning, stacklevel=3)
        return None
    if poses is None:
        return None
    T, dtype = poses
    robot = solver.robot
    near = None
    if q_near is not None:
        joints = robot.chain_arrays()[1]
        near = _joints(q_near, T.shape[0], robot.dof, joints[:, 3] != 0.0, joints[:, 1], joints[:, 2])
        if near is None:
            return None
    facts = _facts(robot)
    reachable = np.empty(T.shape[0], dtype=bool)
    if not _kernels().reach_flags(T, facts["center"], facts["radius"], REACH_SLACK, reachable):
        msg = unreachable_message(robot, torch.from_numpy(T), torch.from_numpy(reachable))
        warnings.warn(msg, UserWarning, stacklevel=3)
    lm = CompiledLM.of(robot, solver.swarm_cfg if isinstance(solver.swarm_cfg, LMCfg) else None)
    # float32 answers: solved to half the tolerance in float64, so that rounding the joints to float32 (about
    # 1e-7 rad) cannot carry an answer just inside the tolerance out of it
    margin = 1.0 if dtype == torch.float64 else 0.5
    kw = {"tol_pos": tol_pos * margin, "tol_rot": tol_rot * margin, "seed": seed, "max_iters": max_iters}
    if solver.closed_form:
        source = "analytic"
        check = CLOSED_FORM_TOL[dtype]
        run = _closed_form(robot, lm, T, near, reachable, check, restarts=solver.fallback == "multistart", **kw)
    else:
        source = "multistart"
        run = lm.solve(T, None, reachable=reachable, **kw)
        if near is not None:
            run = _nearer(run, lm.solve(T, near, reachable=reachable, **kw), near)
    q, pos, rot, ok = run.q, run.pos_err, run.rot_err, run.converged
    if dtype != torch.float64:  # the answer in the targets' dtype, inside the limits, its errors measured
        q = np.clip(q.astype(np.float32), facts["lo32"], facts["hi32"])
        pos, rot = np.empty(q.shape[0]), np.empty(q.shape[0])
        _kernels().pose_errors(lm.G, lm.joints, T, q.astype(np.float64), pos, rot)
        ok = (pos <= tol_pos) & (rot <= tol_rot)
        pos, rot = pos.astype(np.float32), rot.astype(np.float32)
    return IKResult(
        torch.from_numpy(q),
        torch.from_numpy(pos),
        torch.from_numpy(rot),
        torch.from_numpy(ok),
        torch.from_numpy(run.iterations),
        source,
        reachable=torch.from_numpy(reachable),
    )


def _kernels():
    """The kernels this path calls (:mod:`nik.kernels.poses` and ``pose_errors``), imported on first use."""
    global _KERNELS
    if _KERNELS is None:
        from types import SimpleNamespace

        from nik.kernels import closed, lm, poses

        _KERNELS = SimpleNamespace(
            poses_ok=poses.poses_ok,
            quat_poses=poses.quat_poses,
            rpy_poses=poses.rpy_poses,
            reach_flags=poses.reach_flags,
            pose_errors=lm.pose_errors,
            closed_guess=closed.guess,
        )
    return _KERNELS


_KERNELS = None


def _closed_form(robot, lm, T, near, reachable, check_tol, *, restarts: bool, **kw) -> CompiledRun:
    """The stages of a closed-form arm, compiled: the solution of the closed form chosen as ``analytic_guess``
    chooses it (nearest ``near`` when given, else farthest inside the limits; out of reach, the clamped one
    nearest the target), then LM from it for the targets it leaves outside tolerance that are within reach
    (restarts as the solver's fallback says), kept where it is not worse."""
    B = T.shape[0]
    q, pos, rot, ok = np.empty((B, 6)), np.empty(B), np.empty(B), np.empty(B, dtype=bool)
    use_near = near is not None
    todo = _kernels().closed_guess(
        _facts(robot)["closed"], lm.G, lm.joints, check_tol, T, near if use_near else q, use_near,
        LIMIT_ROUNDING, kw["tol_pos"], kw["tol_rot"], reachable, q, pos, rot, ok,
    )  # fmt: skip
    run = CompiledRun(q, np.zeros(B, dtype=np.int64), ok, pos, rot)
    if todo:
        todo = np.flatnonzero(~ok & reachable)
        res = lm.solve(T[todo], q[todo], restarts=restarts, **kw)
        better = (res.pos_err + 0.1 * res.rot_err) <= (pos[todo] + 0.1 * rot[todo])
        keep = todo[better]
        run.q[keep], run.pos_err[keep], run.rot_err[keep] = res.q[better], res.pos_err[better], res.rot_err[better]
        run.converged[keep] = res.converged[better]
        run.iterations[todo] += res.iterations
    return run


def _nearer(a: CompiledRun, b: CompiledRun, q_near: np.ndarray) -> CompiledRun:
    """Per target, the answer of the ``near`` stage's rule between ``a`` (from uniform starts) and ``b`` (from
    ``q_near``): a successful one first, then the nearer ``q_near``; if neither succeeded, the smaller error.
    The iterations of both count."""
    dist_a = np.linalg.norm(a.q - q_near, axis=-1)
    dist_b = np.linalg.norm(b.q - q_near, axis=-1)
    worse_a = (a.pos_err + 0.1 * a.rot_err) > (b.pos_err + 0.1 * b.rot_err)
    take_b = (b.converged & (~a.converged | (dist_b < dist_a))) | (~a.converged & ~b.converged & worse_a)
    return CompiledRun(
        np.where(take_b[:, None], b.q, a.q),
        a.iterations + b.iterations,
        np.where(take_b, b.converged, a.converged),
        np.where(take_b, b.pos_err, a.pos_err),
        np.where(take_b, b.rot_err, a.rot_err),
    )


def _facts(robot) -> dict:
    """Per robot, once: the reach bound's centre and radius, float32 limits rounded inward, and for an arm with
    a closed form the compiled one's constants (None where the kernel does not cover it)."""
    facts = _ROBOTS.get(robot)
    if facts is None:
        from nik.analytic import family

        lo32, hi32 = robot.limits_as(torch.empty(0, dtype=torch.float32))
        facts = {
            "center": reach_center(robot).numpy(),
            "radius": max(reach_radius(robot), 1e-300),
            "lo32": lo32.numpy(),
            "hi32": hi32.numpy(),
            "closed": None,
        }
        if family(robot) is not None:
            from nik.analytic.solve import closed_form
            from nik.kernels.closed import closed_form_array

            facts["closed"] = closed_form_array(closed_form(robot))
        _ROBOTS[robot] = facts
    return facts


# ---------------------------------------------------------------------------
# input checks in numpy (None: not accepted here; the torch path decides)
# ---------------------------------------------------------------------------
def _poses(T_target, representation, limit: int = LEAN_MAX_BATCH) -> tuple[np.ndarray, torch.dtype] | None:
    """``(T: (B, 4, 4) float64, dtype of the result)`` when the targets pass every check of
    :func:`nik.ik.targets.as_poses` and ``1 <= B <= limit``, else None."""
    if isinstance(T_target, torch.Tensor):
        if T_target.device.type != "cpu" or T_target.dtype not in _DTYPES:
            return None
        dtype, a = T_target.dtype, T_target.detach().numpy()
    else:
        dtype = torch.float64
        try:
            a = np.asarray(T_target, dtype=np.float64)
        except (TypeError, ValueError):
            return None
    rep = representation
    if rep is None:
        if a.ndim >= 2 and a.shape[-2:] == (4, 4):
            rep = "matrix"
        elif a.ndim >= 1 and a.shape[-1] in (6, 7):
            rep = "quat" if a.shape[-1] == 7 else "rpy"
        else:
            return None
    if rep == "matrix":
        a = a[None] if a.ndim == 2 else a
        if a.ndim != 3 or a.shape[1:] != (4, 4):
            return None
    elif rep in ("quat", "rpy"):
        a = a[None] if a.ndim == 1 else a
        if a.ndim != 2 or a.shape[1] != (7 if rep == "quat" else 6):
            return None
        if rep == "rpy" and np.abs(a[:, 3:]).max() > DEGREES_SUSPECT:
            return None  # degrees? the torch path warns
    else:
        return None
    if not 1 <= a.shape[0] <= min(limit, LEAN_MAX_BATCH):
        return None
    if a.dtype != np.float64 or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a, dtype=np.float64)
    kernels = _kernels()
    if rep != "matrix":
        T = np.empty((a.shape[0], 4, 4))
        ok = kernels.quat_poses(a, QUAT_NORM_TOL, T) if rep == "quat" else kernels.rpy_poses(a, T)
        if not ok:
            return None
        a = T
    return (a, dtype) if kernels.poses_ok(a, ORTHONORMAL_TOL) else None


def _joints(q_near, B: int, dof: int, prismatic: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """``q_near`` as ``(B, dof)`` float64 when :func:`nik.ik.targets.as_q_near` would accept it without a warning
    (an angle beyond 2 pi outside its joint's range: degrees?), else None."""
    if isinstance(q_near, torch.Tensor):
        if q_near.device.type != "cpu" or not q_near.is_floating_point():
            return None
        a = q_near.detach().numpy()
    else:
        try:
            a = np.asarray(q_near, dtype=np.float64)
        except (TypeError, ValueError):
            return None
    if a.ndim == 1 and a.shape[0] == dof:
        a = np.broadcast_to(a, (B, dof))
    if a.shape != (B, dof) or not np.isfinite(a).all():
        return None
    if np.abs(a).max() > DEGREES_SUSPECT:
        suspect = (np.abs(a) > DEGREES_SUSPECT) & ~prismatic & ((a < lo) | (a > hi))
        if suspect.any():
            return None  # degrees? the torch path warns
    return np.ascontiguousarray(a, dtype=np.float64)
