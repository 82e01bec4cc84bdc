"""Cartesian paths: N waypoints in order -> one continuous joint trajectory, and an honest report of it.

A path is more than N independent poses: the arm has to move from each answer to the next, so a solution
that jumps to another IK branch half-way (a joint turning 180 degrees between two waypoints 3 mm apart) is no
answer, however exact each pose is. :func:`solve_path` therefore looks at the whole path before it commits:

1. **candidates** at each waypoint. On an arm with a closed form (:func:`nik.analytic.family`): all 8 branches
   of every waypoint, in one compiled call. On other arms (redundant 7-joint arms among them): chains of
   Levenberg-Marquardt, each waypoint seeded by the chain's answer at the previous one, started from
   ``q_start``, or, without it, from the network's hypotheses and from uniform starts at the first waypoint
   (several chains side by side, each the continuation of a different posture).
2. **the choice over the whole path**: by dynamic programming over the branches (:func:`nik.ik.path_kernels.path_dp`),
   the sequence whose largest step is the smallest, and among those the one with the least sum of squared steps
   (then the least total joint motion); with ``q_start`` the step from it to the first waypoint counts too, so the
   trajectory starts nearest it. Among chains, the one with the fewest failed waypoints, then the smallest largest
   step, then the least motion. With ``q_start`` on a closed-form arm the LM chain from ``q_start`` is tried first
   and kept when it follows every waypoint in steps of at most :data:`PATH_FOLLOW_STEP` (its branch meets no
   limit: nothing to look ahead for).
3. **polish**: a waypoint left without a valid candidate (closed-form arms) gets LM seeded by its predecessor's
   answer (its best effort, flagged); the chains are that already.
4. **redundant arms**: the extra freedom is resolved along the path by seeding each waypoint with its
   predecessor's answer moved :data:`PATH_PULL` of the way towards the middle of the joint ranges (at most
   :data:`PATH_PULL_CAP` per joint and waypoint): LM from that seed removes whatever would move the tool, the
   rest is self-motion away from the limits, so the arm does not drift into a limit and then jump.
5. **the report** (:class:`PathReport`): success per waypoint re-checked by FK (and the limits), every step,
   the largest one and where, and a warning naming the first waypoint that is out of reach, beyond a joint limit
   on every branch, not reached, or reached only by a step above ``max_step`` (a reconfiguration).

The step between two configurations is the largest joint motion ``max_j |q_i,j - q_i-1,j|`` (radians; metres on
prismatic joints), measured on the returned joints: a joint whose range is wider than a full turn may cross
pi, one limited to [-pi, pi] may not. Paths are solved on the CPU in float64 (the work is sequential by nature);
the result comes back in the dtype and on the device of the input poses.
"""

from __future__ import annotations

import math
import warnings
import weakref

import numpy as np
import torch

from nik.ik.result import IKResult, PathReport
from nik.ik.targets import check_tolerances, pose_array
from nik.robots.reach import MM_HINT_FACTOR, REACH_SLACK, reach_center, reach_radius

__all__ = ["PATH_MAX_STEP", "PATH_PULL", "PATH_PULL_CAP", "PATH_RESTARTS", "solve_path"]

#: Default threshold of a reconfiguration: a step (largest joint motion between two waypoints) above it is
#: reported and warned about, radians (10 degrees).
PATH_MAX_STEP = math.radians(10.0)
#: Redundant arms: each seed is moved this fraction of the way from the previous answer to the middle of the
#: joint ranges (the secondary objective: distance from the limits).
PATH_PULL = 0.02
#: ... by at most this much per joint and waypoint, radians (0.25 degrees).
PATH_PULL_CAP = math.radians(0.25)
#: Uniform restarts a waypoint that LM does not reach from its predecessor may draw (within reach only).
PATH_RESTARTS = 16
#: Closed-form arms with ``q_start``: the LM chain from ``q_start`` (each waypoint seeded by the previous answer) is
#: the answer when it reaches every waypoint inside the limits with no step above this (radians, 2 degrees) nor
#: above ``max_step``: its branch then never meets a limit, and there is nothing for the look-ahead to avoid. Else
#: the closed form's branches and the dynamic programming decide.
PATH_FOLLOW_STEP = math.radians(2.0)
#: Uniform starts at the first waypoint on an arm without a closed form and without ``q_start`` (beside the
#: network's hypotheses); distinct postures found become parallel chains.
PATH_STARTS = 8
#: Two first-waypoint answers closer than this (largest joint difference, radians) are one chain.
PATH_DEDUPE = 1e-2
#: A joint may turn continuously past +-pi when its range exceeds a full turn by this much (radians).
WRAP_MARGIN = 1e-6


def solve_path(
    solver,
    T_path,
    q_start=None,
    *,
    tol_pos: float,
    tol_rot: float,
    seed: int = 0,
    representation: str | None = None,
    max_step: float = PATH_MAX_STEP,
) -> IKResult:
    """One continuous joint trajectory through the waypoints ``T_path`` (see :meth:`nik.IKSolver.solve_path`).

    Args:
        solver: the :class:`nik.IKSolver` whose robot, closed form and network are used.
        T_path: ``(N, 4, 4)``, ``(N, 7)`` or ``(N, 6)`` waypoints in order (metres, radians), N >= 2.
        q_start: ``(dof,)`` the joints before the path (radians, inside the limits) or None.
        tol_pos, tol_rot: success tolerances, metres and radians.
        seed: seeds the uniform starts and restarts.
        representation: ``"matrix"`` | ``"quat"`` | ``"rpy"``; inferred from the shape when None.
        max_step: steps above it are reconfigurations (reported, warned about), radians.

    Returns:
        :class:`IKResult` of N rows (``q: (N, dof)``) with ``path``: a :class:`PathReport`.

    Raises:
        ValueError: bad poses (NaN, shape, a non-orthonormal rotation), fewer than 2 waypoints, positions that
            look like millimetres, a bad tolerance or ``max_step``, a ``q_start`` of the wrong length, not finite
            or outside the limits.
    """
    Tn, dtype, device = _poses(T_path, representation)
    if Tn.shape[0] < 2:
        raise ValueError(f"T_path: a path needs at least 2 waypoints, got {Tn.shape[0]}")
    check_tolerances(tol_pos, tol_rot)
    if not (isinstance(max_step, int | float) and math.isfinite(max_step) and max_step > 0):
        raise ValueError(f"max_step: expected a number > 0 (radians), got {max_step!r}")
    robot = solver.robot
    facts = _facts(robot)
    d = Tn[:, :3, 3] - facts["center"]
    ratio = np.sqrt((d * d).sum(axis=1)) / facts["radius"]
    worst = int(ratio.argmax())
    if ratio[worst] >= MM_HINT_FACTOR:
        raise ValueError(
            f"T_path: waypoint {worst} lies {ratio[worst]:.3g} x beyond the reach of {robot.name} "
            f"({facts['radius'] * 1e3:.0f} mm); were the positions given in millimetres? nik expects metres"
        )
    reachable = ratio <= 1.0 + REACH_SLACK
    q0 = _q_start(robot, facts, q_start)
    from nik.lm.compiled import CompiledLM

    lm = CompiledLM.of(robot)
    follows = None
    if solver.closed_form and q0 is not None:  # the quick answer: LM from q_start along the path, if it follows
        follows = _follows_from_start(lm, facts, Tn, q0, reachable, tol_pos, tol_rot, seed, max_step)
    if follows is not None:
        q, its, found, source = *follows, None, "q_start"
    elif solver.closed_form:
        q, its, found, source = _closed_form_path(robot, lm, facts, Tn, q0, reachable, tol_pos, tol_rot, seed)
    else:
        q, its, source = _chain_path(solver, lm, Tn, q0, reachable, tol_pos, tol_rot, seed)
        found = None
    pos, rot = _errors(lm, Tn, q)
    inside = ((q >= facts["lo"] - 1e-9) & (q <= facts["hi"] + 1e-9)).all(axis=1)
    success = (pos <= tol_pos) & (rot <= tol_rot) & inside
    reasons = [""] * len(success)
    for i in np.nonzero(~success)[0]:
        why = "" if found is None else found[i]
        reasons[i] = why or ("out of reach" if not reachable[i] else "not reached")
    report = _report(robot, q, q0, success, reasons, max_step)
    if report.warning is not None:
        warnings.warn(report.warning, UserWarning, stacklevel=3)
    like = dict(dtype=dtype, device=device)
    return IKResult(
        torch.from_numpy(q).to(**like),
        torch.from_numpy(pos).to(**like),
        torch.from_numpy(rot).to(**like),
        torch.from_numpy(success).to(device),
        torch.from_numpy(its).to(device),
        source,
        reachable=torch.from_numpy(reachable).to(device),
        path=report,
    )


# ---------------------------------------------------------------------------
# input
# ---------------------------------------------------------------------------
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


def _facts(robot) -> dict:
    """Per robot, once: limits, the joints that may turn past +-pi, the reach bound, the compiled closed form."""
    facts = _ROBOTS.get(robot)
    if facts is None:
        lo, hi = robot.limits.double().numpy().T.copy()
        prismatic = robot.prismatic.numpy().astype(bool)
        facts = {
            "lo": lo,
            "hi": hi,
            "prismatic": prismatic,
            "wraps": ((hi - lo) > 2 * math.pi + WRAP_MARGIN) & ~prismatic,
            "center": reach_center(robot).double().numpy(),
            "radius": max(reach_radius(robot), 1e-300),
            "closed": None,
        }
        from nik.analytic import family

        if family(robot) is not None:
            from nik.analytic.solve import closed_form
            from nik.kernels.closed import closed_form_array

            facts["closed"] = closed_form_array(closed_form(robot))
        _ROBOTS[robot] = facts
    return facts


_ROBOTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _q_start(robot, facts, q_start) -> np.ndarray | None:
    """``q_start`` as ``(dof,)`` float64, checked: length, finite, inside the limits (ValueError naming the joint)."""
    if q_start is None:
        return None
    if isinstance(q_start, torch.Tensor):
        q_start = q_start.detach().cpu().double().numpy()
    try:
        q = np.asarray(q_start, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"q_start: expected {robot.dof} numbers (radians), got {type(q_start).__name__}") from err
    if q.shape != (robot.dof,):
        raise ValueError(f"q_start: expected shape ({robot.dof},) for {robot.name}, got {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError(f"q_start: joint {int(np.argmin(np.isfinite(q)))} is NaN or inf")
    lo, hi = facts["lo"], facts["hi"]
    out = np.nonzero((q < lo - 1e-9) | (q > hi + 1e-9))[0]
    if out.size:
        j = int(out[0])
        prismatic = bool(robot.prismatic[j])
        f, unit = (1e3, "mm") if prismatic else (180.0 / math.pi, "deg")
        raise ValueError(
            f"q_start: joint {j} ({robot.joint_names[j]}) = {q[j] * f:.6g} {unit} lies outside its limits "
            f"[{lo[j] * f:.6g}, {hi[j] * f:.6g}] {unit}"
        )
    return q


def _errors(lm, Tn: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and rotation (rad) errors of ``q: (N, dof)`` against ``Tn: (N, 4, 4)`` (compiled FK)."""
    from nik.kernels.lm import pose_errors

    pos, rot = np.empty(q.shape[0]), np.empty(q.shape[0])
    pose_errors(lm.G, lm.joints, Tn, np.ascontiguousarray(q), pos, rot)
    return pos, rot


def _options(lm, tol_pos: float, tol_rot: float) -> tuple[np.ndarray, np.ndarray]:
    """The compiled LM's options with the call's tolerances (the seed is the first start)."""
    from nik.kernels import lm as klm

    opts, iopts = lm.opts.copy(), lm.iopts.copy()
    opts[klm.TOL_POS], opts[klm.TOL_ROT] = tol_pos, tol_rot
    iopts[klm.FIRST_STARTS] = 0
    return opts, iopts


def _chains(lm, Tn, starts, reachable, tol_pos, tol_rot, seed, *, pull: float, restarts: int = PATH_RESTARTS):
    """:func:`nik.ik.path_kernels.path_chains` from ``starts: (K, dof)``: ``q (K, N, dof)``, iterations, ok."""
    from nik.ik.path_kernels import path_chains
    from nik.kernels.lm import seed_state

    K, n, N = starts.shape[0], starts.shape[1], Tn.shape[0]
    opts, iopts = _options(lm, tol_pos, tol_rot)
    q = np.empty((K, N, n))
    its, ok = np.empty((K, N), dtype=np.int64), np.empty((K, N), dtype=bool)
    pos, rot = np.empty((K, N)), np.empty((K, N))
    budget = np.where(reachable, restarts, 0).astype(np.int64)
    path_chains(
        lm.G, lm.joints, Tn, np.ascontiguousarray(starts, dtype=np.float64), opts, iopts, budget,
        seed_state(seed), pull, PATH_PULL_CAP if pull > 0 else 0.0, q, its, ok, pos, rot,
    )  # fmt: skip
    return q, its, ok


def _follows_from_start(lm, facts, Tn, q0, reachable, tol_pos, tol_rot, seed, max_step):
    """``(q (N, dof), iterations (N,))`` of the LM chain from ``q0`` when it follows the whole path smoothly
    (:data:`PATH_FOLLOW_STEP`), else None."""
    q, its, ok = _chains(lm, Tn, q0[None], reachable, tol_pos, tol_rot, seed, pull=0.0, restarts=0)
    q, its = q[0], its[0]
    if not ok.all():
        return None
    steps = np.abs(np.diff(np.concatenate([q0[None], q]), axis=0)).max()
    inside = ((q >= facts["lo"] - 1e-9) & (q <= facts["hi"] + 1e-9)).all()
    return (q, its) if inside and steps <= min(PATH_FOLLOW_STEP, max_step) else None


# ---------------------------------------------------------------------------
# arms with a closed form: every branch at every waypoint, the choice by dynamic programming
# ---------------------------------------------------------------------------
def _closed_form_path(robot, lm, facts, Tn, q0, reachable, tol_pos, tol_rot, seed):
    """``(q (N, 6), iterations (N,), reasons, source)`` of a closed-form arm."""
    from nik.ik.path_kernels import path_dp

    N = Tn.shape[0]
    closed = facts["closed"]
    if closed is not None:
        from nik.kernels.closed import solutions

        cand, valid = np.empty((N, 8, 6)), np.empty((N, 8), dtype=bool)
        solutions(closed, lm.G, lm.joints, tol_pos, tol_rot, Tn, cand, valid)
    else:  # an arm that fits its family only within a tolerance: the torch closed form with its Newton polish
        from nik.analytic import solve

        c, v = solve(robot, torch.from_numpy(Tn), tol_pos=tol_pos, tol_rot=tol_rot)
        cand, valid = np.ascontiguousarray(c.numpy()), np.ascontiguousarray(v.numpy())
    wraps = facts["wraps"]
    choice = np.empty(N, dtype=np.int64)
    start = np.zeros(6) if q0 is None else q0
    path_dp(cand, valid, wraps, start, q0 is not None, 1e-9, choice)
    have = choice >= 0
    reasons = [""] * N
    if not have.any():  # no waypoint has a valid branch: LM along the path from q_start or a multistart
        first = _first_answer(lm, Tn, q0, reachable, tol_pos, tol_rot, seed)
        q, its, _ = _chains(lm, Tn, first[None], reachable, tol_pos, tol_rot, seed, pull=0.0, restarts=0)
        q, its = q[0], its[0]
    else:
        q = cand[np.arange(N), np.maximum(choice, 0)]
        if wraps.any():
            q, fits = _unwrap(q, have, wraps, q0, facts["lo"], facts["hi"])
            if not fits:  # some run cannot stay inside its limits: choose the whole turns with the branches
                q = _with_turns(cand, valid, have, wraps, q0, facts["lo"], facts["hi"])
        its = np.zeros(N, dtype=np.int64)
        if not have.all():
            q, its = _fill_gaps(lm, Tn, q, have, reachable, tol_pos, tol_rot, seed)
    for i in np.nonzero(~have)[0]:
        reasons[i] = _closed_form_reason(lm, Tn[i], cand[i], reachable[i], tol_pos, tol_rot)
    return q, its, reasons, "analytic"


def _closed_form_reason(lm, Ti, cand_i, reachable_i, tol_pos, tol_rot) -> str:
    """Why no branch serves a waypoint: some reaches the pose outside the limits, or none reaches it at all."""
    if not reachable_i:
        return "out of reach"
    pos, rot = _errors(lm, np.repeat(Ti[None], 8, axis=0), cand_i)  # the branches' joints before the limits
    return (
        "beyond a joint limit on every branch" if bool(((pos <= tol_pos) & (rot <= tol_rot)).any()) else "out of reach"
    )


def _unwrap(q, have, wraps, q0, lo, hi) -> tuple[np.ndarray, bool]:
    """Joints of ``q: (N, dof)`` that may turn past +-pi made continuous along the path (whole turns added), the
    whole run then shifted by whole turns to fit the limits, starting nearest ``q0`` when given. Also returns
    whether every run fits (False: some joint would have to turn back, see :func:`_with_turns`)."""
    q = q.copy()
    fits = True
    idx = np.nonzero(have)[0]
    for j in np.nonzero(wraps)[0]:
        x = q[idx, j]
        d = np.remainder(np.diff(x) + math.pi, 2 * math.pi) - math.pi
        x = x[0] + np.concatenate([[0.0], np.cumsum(d)])
        if q0 is not None:
            x += 2 * math.pi * np.round((q0[j] - x[0]) / (2 * math.pi))
        shifts = sorted(range(-3, 4), key=abs)
        for k in shifts:  # the nearest whole-turn shift that keeps the run inside the limits
            y = x + 2 * math.pi * k
            if y.min() >= lo[j] - 1e-12 and y.max() <= hi[j] + 1e-12:
                x = y
                break
        else:
            fits = False
        q[idx, j] = x
    return q, fits


def _with_turns(cand, valid, have, wraps, q0, lo, hi) -> np.ndarray:
    """The choice over the whole path when the whole turns matter: every branch of every waypoint with each of
    its turning joints at every value inside the limits (``+-2 pi`` copies), and real (not modulo 2 pi) motion
    between them. ``cand: (N, 8, dof)``; returns ``q: (N, dof)``."""
    from itertools import product

    from nik.ik.path_kernels import path_dp

    N, K, n = cand.shape
    turns = np.zeros((3 ** int(wraps.sum()), n))
    turns[:, wraps] = 2 * math.pi * np.array(list(product((0.0, -1.0, 1.0), repeat=int(wraps.sum()))))
    big = (cand[:, :, None, :] + turns[None, None]).reshape(N, -1, n)  # (N, 8 x 3^w, dof)
    ok = np.repeat(valid, turns.shape[0], axis=1) & ((big >= lo) & (big <= hi)).all(axis=-1)
    order = np.argsort(~ok, axis=1, kind="stable")[:, : max(int(ok.sum(axis=1).max()), 1)]  # the valid ones first
    big = np.ascontiguousarray(np.take_along_axis(big, order[..., None], axis=1))
    ok = np.ascontiguousarray(np.take_along_axis(ok, order, axis=1))
    choice = np.empty(N, dtype=np.int64)
    path_dp(big, ok, np.zeros(n, dtype=bool), np.zeros(n) if q0 is None else q0, q0 is not None, 1e-9, choice)
    return big[np.arange(N), np.maximum(choice, 0)]


def _fill_gaps(lm, Tn, q, have, reachable, tol_pos, tol_rot, seed):
    """Waypoints without a valid branch: LM seeded by the answer next to them (the previous one; for a leading
    gap, the first waypoint that has a branch, walking back), without uniform restarts (the closed form found no
    solution there: a restart could only jump). Their best effort, flagged by the final check."""
    N = q.shape[0]
    kw = {"pull": 0.0, "restarts": 0}
    its = np.zeros(N, dtype=np.int64)
    first = int(np.argmax(have))
    for i in range(first - 1, -1, -1):  # a leading gap, walking back from the first solved waypoint
        qi, it, _ = _chains(lm, Tn[i : i + 1], q[i + 1][None], reachable[i : i + 1], tol_pos, tol_rot, seed, **kw)
        q[i], its[i] = qi[0, 0], it[0, 0]
    i = first + 1
    while i < N:  # the other gaps, each run of missing waypoints in one compiled chain
        if have[i]:
            i += 1
            continue
        j = i
        while j < N and not have[j]:
            j += 1
        qi, it, _ = _chains(lm, Tn[i:j], q[i - 1][None], reachable[i:j], tol_pos, tol_rot, seed + i, **kw)
        q[i:j], its[i:j] = qi[0], it[0]
        i = j
    return q, its


# ---------------------------------------------------------------------------
# other arms: LM chains seeded by the predecessor, the best chain chosen
# ---------------------------------------------------------------------------
def _first_answer(lm, Tn, q0, reachable, tol_pos, tol_rot, seed) -> np.ndarray:
    """A start for a single chain: ``q0``, else LM from uniform starts at the first waypoint."""
    if q0 is not None:
        return q0
    run = lm.solve(Tn[:1], None, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, reachable=reachable[:1])
    return run.q[0]


def _chain_path(solver, lm, Tn, q0, reachable, tol_pos, tol_rot, seed):
    """``(q (N, dof), iterations (N,), source)`` of an arm without a closed form."""
    robot = solver.robot
    pull = PATH_PULL if robot.dof > 6 else 0.0
    if q0 is not None:
        q, its, _ = _chains(lm, Tn, q0[None], reachable, tol_pos, tol_rot, seed, pull=pull)
        return q[0], its[0], "q_start"
    starts, sources = _start_postures(solver, lm, Tn, reachable, tol_pos, tol_rot, seed)
    q, its, ok = _chains(lm, Tn, starts, reachable, tol_pos, tol_rot, seed, pull=pull)
    steps = np.abs(np.diff(q, axis=1)).max(axis=2)  # (K, N - 1)
    fails = (~ok).sum(axis=1)
    motion = np.abs(np.diff(q, axis=1)).sum(axis=(1, 2))
    best = int(np.lexsort((motion, steps.max(axis=1), fails))[0])
    return q[best], its[best], sources[best]


def _start_postures(solver, lm, Tn, reachable, tol_pos, tol_rot, seed) -> tuple[np.ndarray, list[str]]:
    """Distinct solutions of the first waypoint: ``(K, dof)`` and where each came from (``network`` for the
    network's hypotheses polished by LM, ``multistart`` for LM from uniform starts)."""
    seeds, sources = [], []
    net = solver.net
    if net is not None and hasattr(net, "hypotheses"):
        with torch.no_grad():
            hyp = net.hypotheses(torch.from_numpy(Tn[:1]))[0].double().cpu().numpy()
        seeds.append(hyp)
        sources += ["network"] * hyp.shape[0]
    T0 = np.repeat(Tn[:1], PATH_STARTS, axis=0)
    uni = lm.solve(T0, None, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, restarts=False)
    seeds.append(uni.q)
    sources += ["multistart"] * PATH_STARTS
    seeds = np.concatenate(seeds)
    T0 = np.repeat(Tn[:1], seeds.shape[0], axis=0)
    run = lm.solve(T0, seeds, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, restarts=False)
    order = np.argsort(~run.converged, kind="stable")  # reached ones first, network before uniform
    q = run.q[order]
    close = np.abs(q[:, None] - q[None]).max(axis=-1) <= PATH_DEDUPE  # (K, K)
    kept = order[~np.triu(close, k=1).any(axis=0)]  # drop each answer close to an earlier one
    return run.q[kept], [sources[i] for i in kept]


# ---------------------------------------------------------------------------
# the report
# ---------------------------------------------------------------------------
def _report(robot, q, q0, success, reasons, max_step) -> PathReport:
    """Steps, the largest one and where, reconfigurations, and the warning about the first problem."""
    prev = np.concatenate([(q[:1] if q0 is None else q0[None]), q[:-1]])
    dq = np.abs(q - prev)
    steps, joints = dq.max(axis=1), dq.argmax(axis=1)
    at = int(steps.argmax())
    reconf = steps > max_step
    failed = ~success
    problems = np.nonzero(failed | reconf)[0]
    warning = None
    if problems.size:
        i = int(problems[0])
        n_fail = int(failed.sum())
        unit = 1e3 if bool(robot.prismatic[joints[i]]) else 180.0 / math.pi
        shown = "mm" if unit == 1e3 else "deg"
        if reasons[i]:
            what = (
                f"waypoint {i} of {len(reasons)} is {reasons[i]}"
                if reasons[i] != "not reached"
                else (f"waypoint {i} of {len(reasons)} was not reached")
            )
        else:
            src = "q_start" if i == 0 else f"waypoint {i - 1}"
            what = (
                f"waypoint {i} of {len(reasons)} forces a reconfiguration: joint {int(joints[i])} "
                f"({robot.joint_names[int(joints[i])]}) moves {steps[i] * unit:.1f} {shown} from {src} "
                f"(more than max_step, {math.degrees(max_step):.1f} deg)"
            )
        warning = (
            f"solve_path on {robot.name}: {what}; {n_fail} waypoint(s) not reached, {int(reconf.sum())} step(s) above "
            f"max_step, largest step {steps[at] * (180.0 / math.pi):.1f} deg into waypoint {at}"
        )
    return PathReport(
        steps=torch.from_numpy(steps),
        step_joints=torch.from_numpy(joints),
        largest_step=float(steps[at]),
        largest_step_at=at,
        largest_step_joint=int(joints[at]),
        total_motion=float(dq.sum()),
        max_step=float(max_step),
        reconfigurations=torch.from_numpy(reconf),
        reasons=list(reasons),
        warning=warning,
    )
