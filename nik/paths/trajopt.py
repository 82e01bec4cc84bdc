"""Whole-trajectory optimisation of a joint path: :func:`optimise_path`, and :func:`polish_path`, the path stage that
uses it where the waypoint chain falls short and keeps its answer only when nothing gets worse.

Waypoint-by-waypoint seeding cannot look ahead: on a redundant arm a chain drifts into a limit and must jump, or
misses a waypoint near a singularity. Here the whole trajectory ``Q: (N, dof)`` is one least-squares problem: every
waypoint's pose error (weighted as nik's LM weighs it, rotation by ``rot_weight``), joint velocity and acceleration
by finite differences (small weights), a hinge on every step above a fraction of ``max_step``, and a barrier near
the joint limits; steps are clamped into the limits, so the limits always hold. The normal matrix is
block-pentadiagonal, solved by a banded Cholesky in ``O(N dof^3)`` (:mod:`nik.kernels.trajopt`, compiled).

Choices (the defaults of :class:`TrajCfg`, for metres and radians): ``w_vel = 1e-4`` and ``w_acc = 1e-3`` keep
the pose error they cost at a few micrometres (a pose row has weight 1); the step hinge ``w_step = 1e-2`` starts at
``0.8 max_step``; the limit barrier ``w_lim = 1e-3`` acts within 2 % of each joint's range. A waypoint's pose counts
as reached inside the call's tolerances (``tol_pos``, ``tol_rot``), as everywhere in nik. With a posture ``q_rest``
(``solve_path(q_rest=)``) every waypoint also has the rows ``sqrt(w_rest) (q_i - q_rest)``, ``w_rest = 1e-4``: as
small as the velocity's, so it moves the self-motion of a redundant arm and costs the pose micrometres (the finish
scales it down with the other shape weights).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "TrajCfg",
    "TrajResult",
    "avoid_path",
    "optimise_path",
    "path_collisions",
    "polish_path",
    "residual_count",
    "trajopt_options",
]


#: The second stage of :func:`optimise_path` scales the shape weights by this: the poses are brought inside their
#: tolerance from the shape the first stage found (on a redundant arm the self-motion stays where it is).
FINISH = 1e-3
#: :func:`polish_path` optimises this many waypoints either side of each problem (a missed waypoint, a step above
#: ``max_step``; windows that overlap merge), the rows outside fixed: a 60-waypoint path is one window, a long one
#: costs in proportion to its problems.
WINDOW = 40
#: :func:`avoid_path`: the step hinge's weight and where it starts (a fraction of ``max_step``) when the collision
#: rows pull (weight 1 per metre of penetration): the path goes round an obstacle in small steps, not in a jump.
AVOID_W_STEP, AVOID_STEP_FRAC = 100.0, 0.3


@dataclass(frozen=True)
class TrajCfg:
    """Weights and LM settings of :func:`optimise_path` (metres, radians; see the module docstring). Without a
    config, :func:`optimise_path` takes ``rot_weight`` from the model's LM (``LMCfg.rot_weight``)."""

    rot_weight: float = 0.5
    w_vel: float = 1e-4
    w_acc: float = 1e-3
    w_step: float = 1e-2
    step_frac: float = 0.8
    w_lim: float = 1e-3
    margin: float = 0.02
    lambda0: float = 1e-3
    max_step_lm: float = 0.3
    eps: float = 1e-9
    stall_rel: float = 1e-7
    iters: int = 100
    w_col: float = 1.0
    col_margin: float = 0.005
    col_sub: int = 4
    w_rest: float = 1e-4


@dataclass
class TrajResult:
    """``q: (N, dof)`` the optimised path, ``pos_err, rot_err: (N,)`` (m, rad), ``iterations`` (factorisations),
    ``clearance`` the smallest signed distance of the collision samples (m; ``inf`` without collision rows)."""

    q: np.ndarray
    pos_err: np.ndarray
    rot_err: np.ndarray
    iterations: int
    clearance: float = math.inf


def trajopt_options(
    cfg: TrajCfg, max_step: float, tol_pos: float = 0.0, tol_rot: float = 0.0, q_rest: np.ndarray | None = None
) -> np.ndarray:
    """``opts`` of :func:`nik.kernels.trajopt.trajopt` for ``cfg`` and the path's ``max_step`` (radians); with
    ``tol_pos > 0`` the optimisation stops as soon as the path is feasible (within the tolerances and ``max_step``).
    ``q_rest: (dof,)``: the posture rows (weight ``cfg.w_rest``), its values appended after the options."""
    from nik.kernels import trajopt as k

    rest = np.empty(0) if q_rest is None else np.asarray(q_rest, dtype=np.float64).ravel()
    opts = np.empty(k.OPTS + rest.size)
    opts[k.OPTS :] = rest
    opts[k.W_REST] = cfg.w_rest if rest.size else 0.0
    opts[k.ROT_WEIGHT], opts[k.W_VEL], opts[k.W_ACC] = cfg.rot_weight, cfg.w_vel, cfg.w_acc
    opts[k.W_STEP], opts[k.STEP_CAP] = cfg.w_step, cfg.step_frac * max_step
    opts[k.W_LIM], opts[k.MARGIN], opts[k.LAMBDA0] = cfg.w_lim, cfg.margin, cfg.lambda0
    opts[k.MAX_STEP_LM], opts[k.EPS], opts[k.STALL_REL] = cfg.max_step_lm, cfg.eps, cfg.stall_rel
    opts[k.TOL_POS], opts[k.TOL_ROT], opts[k.PATH_STEP] = tol_pos, tol_rot, max_step
    opts[k.W_COL], opts[k.COL_MARGIN], opts[k.COL_SUB] = cfg.w_col, cfg.col_margin, cfg.col_sub
    return opts


def residual_count(
    N: int, dof: int, has_start: bool, has_end: bool = False, rows: int = 0, sub: int = 1, rest: bool = False
) -> int:
    """Rows of the residual of :func:`nik.kernels.trajopt.residuals`: pose, velocity + step cap, acceleration,
    limits, posture (with ``rest``: options built with a ``q_rest``); with ``rows`` collision rows per sample
    (:func:`nik.kernels.trajopt.residuals_collision`), those of every waypoint and of ``sub - 1`` samples inside
    every step."""
    steps = N - 1 + int(has_start) + int(has_end)
    fixed = 6 * N + 2 * dof * steps + dof * max(N - 2, 0) + 2 * dof * N + dof * N * int(rest)
    return fixed + rows * (N + steps * (max(sub, 1) - 1))


def optimise_path(
    model,
    T: np.ndarray,
    Q0: np.ndarray,
    *,
    q_start: np.ndarray | None = None,
    q_end: np.ndarray | None = None,
    max_step: float = math.radians(10.0),
    tol_pos: float = 0.0,
    tol_rot: float = 0.0,
    cfg: TrajCfg | None = None,
    collision: tuple | None = None,
    q_rest: np.ndarray | None = None,
) -> TrajResult:
    """The joint path ``Q0: (N, dof)`` optimised as one problem towards the poses ``T: (N, 4, 4)`` (float64, metres).

    ``model``: anything with the chain model ``G, joints`` (:func:`nik.ik.model.model_of`). ``q_start: (dof,)``: the
    joints before the path (its first step counts); ``q_end: (dof,)`` those after it (the step to them counts: a
    window of a longer path). ``Q0`` is clamped into the limits first; the answer is inside
    them. With ``tol_pos > 0`` (and ``tol_rot``) each stage stops as soon as the path is feasible: every waypoint
    within the tolerances, every step at most ``max_step`` (and, with ``collision``, every sample clear). ``collision``:
    the arrays after ``q`` of :func:`nik.kernels.collision.collision_residual` (``Setup.arguments(robot)[1]`` of
    :mod:`nik.ik.collide`): collision rows at the waypoints and inside the steps (``cfg.w_col``, ``cfg.col_margin``,
    ``cfg.col_sub``). ``TrajResult.clearance``: the smallest signed distance of those samples (``inf`` without).
    ``q_rest: (dof,)``: a posture every waypoint is drawn towards (weight ``cfg.w_rest``; the module docstring)."""
    from nik.kernels import trajopt as k

    cfg = _default_cfg(model) if cfg is None else cfg
    G, joints = model.G, model.joints
    T = np.ascontiguousarray(T, dtype=np.float64)
    Q = np.clip(np.array(Q0, dtype=np.float64), joints[:, 1], joints[:, 2])
    N, n = Q.shape
    if T.shape != (N, 4, 4):
        raise ValueError(f"optimise_path: T must have shape ({N}, 4, 4) for Q0 of shape {Q.shape}, got {T.shape}")
    qs = np.zeros(n) if q_start is None else np.ascontiguousarray(q_start, dtype=np.float64)
    qe = np.zeros(n) if q_end is None else np.ascontiguousarray(q_end, dtype=np.float64)
    ends = (qs, q_start is not None, qe, q_end is not None)
    pos, rot, info = np.empty(N), np.empty(N), np.empty(1)
    opts = trajopt_options(cfg, max_step, tol_pos, tol_rot, q_rest)
    col = k._no_collision() if collision is None else tuple(collision)
    its, _ = k.trajopt(G, joints, T, Q, ends, opts, cfg.iters, col, (pos, rot, info))
    feasible = (pos <= tol_pos).all() and (rot <= tol_rot).all() and _largest_step(Q, q_start, q_end) <= max_step
    if tol_pos > 0.0 and feasible and info[0] >= 0.5 * opts[k.COL_MARGIN]:
        return TrajResult(Q, pos, rot, int(its), float(info[0]))  # feasible already
    opts[[k.W_VEL, k.W_ACC, k.W_STEP, k.W_LIM, k.W_REST]] *= FINISH  # the finish: the poses first, the shape kept
    more, _ = k.trajopt(G, joints, T, Q, ends, opts, cfg.iters, col, (pos, rot, info))
    return TrajResult(Q, pos, rot, int(its + more), float(info[0]))


def _default_cfg(model) -> TrajCfg:
    """:class:`TrajCfg` with the rotation weight of the model's LM (``LMCfg.rot_weight``), where it has one."""
    lm = getattr(model, "lm", None)
    if lm is None:
        return TrajCfg()
    from nik.kernels.lm import ROT_WEIGHT

    return TrajCfg(rot_weight=float(lm.opts[ROT_WEIGHT]))


def _largest_step(Q: np.ndarray, q_start: np.ndarray | None, q_end: np.ndarray | None = None) -> float:
    """The largest joint motion between consecutive rows of ``Q: (N, dof)`` (the first from ``q_start``, the last
    to ``q_end``, where given)."""
    rows = [Q] if q_start is None else [q_start[None], Q]
    if q_end is not None:
        rows.append(q_end[None])
    full = np.concatenate(rows)
    return float(np.abs(np.diff(full, axis=0)).max())


def _first_step(Q: np.ndarray, q_start: np.ndarray) -> float:
    """The largest joint motion from ``q_start: (dof,)`` to the first row of ``Q: (N, dof)``."""
    return float(np.abs(Q[0] - q_start).max())


def _turns_nearest(Q: np.ndarray, q_start: np.ndarray | None, joints: np.ndarray) -> np.ndarray:
    """``Q: (N, dof)`` with each joint that turns past a full turn (``wraps``) moved by the whole turns that bring
    it nearest the row before (from ``q_start`` when given), where that stays inside its limits: the waypoint chain
    may answer a waypoint a whole turn away, which no local step undoes (the pose is the same)."""
    from nik.kernels.chain import LOWER, UPPER, WRAPS

    Q = Q.copy()
    two_pi = 2.0 * math.pi
    for j in np.nonzero(joints[:, WRAPS] != 0.0)[0]:
        lo, hi = joints[j, LOWER], joints[j, UPPER]
        prev = Q[0, j] if q_start is None else q_start[j]
        for i in range(Q.shape[0]):
            x = Q[i, j] + two_pi * np.round((prev - Q[i, j]) / two_pi)
            if lo <= x <= hi:
                Q[i, j] = x
            prev = Q[i, j]
    return Q


def polish_path(
    model,
    T: np.ndarray,
    Q: np.ndarray,
    q_start: np.ndarray | None,
    *,
    tol_pos: float,
    tol_rot: float,
    max_step: float,
    reachable: np.ndarray | None = None,
    always: bool = False,
    q_rest: np.ndarray | None = None,
    closed: bool = False,
    collision: tuple | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The path stage: ``Q: (N, dof)`` optimised by :func:`optimise_path` where some waypoint misses the tolerance
    or some step exceeds ``max_step`` (every path with ``always``; a waypoint proven out of reach, ``reachable (N,)``
    False, does not count: no optimisation reaches it), in windows of :data:`WINDOW` waypoints either side of each
    problem, each window kept only when it is no worse: every waypoint in it that was within tolerance still is,
    and its largest step (from the row before, to the row after) does not grow, nor its first step from ``q_start``
    beyond ``max_step`` (the arm starts without a jump); the whole path likewise, else
    ``Q`` as it came. Returns ``(Q, pos_err (N,), rot_err (N,))``, the errors re-checked by FK (metres, radians):
    one compiled call (:func:`nik.kernels.trajopt.path_check`) where nothing needs optimising. ``q_rest: (dof,)``:
    the windows' posture rows (:func:`optimise_path`). ``closed``: a loop (its last row is to equal its first): the
    step from the last row back to the first (modulo whole turns on joints that wrap) counts as one more step, so that
    no window opens a loop to smooth a step (the last window's row after is the first row). ``collision``: the
    collision arrays (as :func:`optimise_path`'s): the windows are optimised with collision rows and kept only where
    they collide at no more samples (:func:`path_collisions`) than before, nor does the whole path. The windows run
    with :func:`optimise_path`'s default configuration for ``model``."""
    from nik.kernels.trajopt import path_check

    Q = np.ascontiguousarray(Q, dtype=np.float64)
    T = np.ascontiguousarray(T, dtype=np.float64)
    N = Q.shape[0]
    has_start = q_start is not None
    qs = np.ascontiguousarray(q_start, dtype=np.float64) if has_start else Q[0]
    pos, rot = np.empty(N), np.empty(N)
    reached, step = path_check(model.G, model.joints, T, Q, qs, has_start, tol_pos, tol_rot, pos, rot)
    if closed:
        step = max(step, _loop_gap(Q, model.joints))
    if not always and step <= max_step:
        if reached == N:  # the usual case: one compiled call, nothing else
            return Q, pos, rot
        if reachable is not None and not (((pos > tol_pos) | (rot > tol_rot)) & reachable).any():
            return Q, pos, rot  # only waypoints out of reach are missed
    Q1 = _turns_nearest(Q, q_start, model.joints)
    ok = (pos <= tol_pos) & (rot <= tol_rot)
    prev = np.concatenate([Q1[:1] if q_start is None else qs[None], Q1[:-1]])
    bad = (np.abs(Q1 - prev).max(axis=1) > max_step) | ~ok
    if reachable is not None:
        bad &= reachable | (np.abs(Q1 - prev).max(axis=1) > max_step)
    if closed and _loop_gap(Q1, model.joints) > max_step:
        bad[-1] = True
    if always:
        bad[:] = True
    lo, hi = model.joints[:, 1], model.joints[:, 2]
    sub = TrajCfg().col_sub

    def hits(rows, before, after) -> int:
        """Colliding samples of ``rows`` (waypoints and inside the steps from ``before``, and to ``after``)."""
        x, y = path_collisions(model, rows, before, collision, sub)
        n = int(x.sum() + y.sum())
        return n if after is None else n + int(path_collisions(model, after[None], rows[-1], collision, sub)[1][0])

    for a, b in _windows(np.nonzero(bad)[0], N):
        before = q_start if a == 0 else Q1[a - 1]
        after = Q1[b] if b < N else (_loop_end(Q1, model.joints) if closed else None)
        res = optimise_path(
            model, T[a:b], Q1[a:b], q_start=before, q_end=after, max_step=max_step, tol_pos=tol_pos, tol_rot=tol_rot,
            q_rest=q_rest, collision=collision,
        )  # fmt: skip
        ok2 = (res.pos_err <= tol_pos) & (res.rot_err <= tol_rot)
        inside = bool(((res.q >= lo) & (res.q <= hi)).all())
        first = a > 0 or before is None or _first_step(res.q, before) <= max(max_step, _first_step(Q1[a:b], before))
        free = collision is None or hits(res.q, before, after) <= hits(Q1[a:b], before, after)
        if (
            inside
            and first
            and free
            and ok2[ok[a:b]].all()
            and _largest_step(res.q, before, after) <= _largest_step(Q1[a:b], before, after)
        ):
            Q1[a:b] = res.q  # this window is no worse: kept
    pos2, rot2 = np.empty(N), np.empty(N)
    _, step2 = path_check(model.G, model.joints, T, Q1, qs, has_start, tol_pos, tol_rot, pos2, rot2)
    if closed:
        step2 = max(step2, _loop_gap(Q1, model.joints))
    ok2 = (pos2 <= tol_pos) & (rot2 <= tol_rot)
    free = collision is None or hits(Q1, q_start, None) <= hits(Q, q_start, None)
    if bool(ok2[ok].all()) and step2 <= step and free:
        return Q1, pos2, rot2
    return Q, pos, rot


def _loop_end(Q: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """The first row of ``Q: (N, dof)`` as the row after its last (a loop), with whole turns on the joints that wrap
    nearest the last row (a path that takes such a joint once around ends a turn further)."""
    from nik.kernels.chain import WRAPS

    end = Q[0].copy()
    w = joints[:, WRAPS] != 0.0
    end[w] += 2.0 * math.pi * np.round((Q[-1, w] - end[w]) / (2.0 * math.pi))
    return end


def _loop_gap(Q: np.ndarray, joints: np.ndarray) -> float:
    """The largest joint difference between the last row of a loop ``Q: (N, dof)`` and its first (:func:`_loop_end`)."""
    return float(np.abs(Q[-1] - _loop_end(Q, joints)).max())


def _windows(bad: np.ndarray, N: int) -> list[tuple[int, int]]:
    """``[(a, b), ...]``: the rows ``a:b`` optimised around each problem waypoint of ``bad`` (indices, increasing),
    :data:`WINDOW` rows either side, overlapping windows merged: the cost stays in proportion to the problems, not
    to the path's length."""
    out: list[tuple[int, int]] = []
    for i in bad:
        a, b = max(int(i) - WINDOW, 0), min(int(i) + WINDOW + 1, N)
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def path_collisions(model, Q: np.ndarray, q_start: np.ndarray | None, collision: tuple, sub: int):
    """``(at (N,), between (N,))`` bool for ``Q: (N, dof)``: waypoint ``i`` collides; some of the ``sub - 1`` evenly
    spaced samples inside the step into waypoint ``i`` (from ``q_start``, for ``i = 0``, where given) collides. The
    sphere check (:func:`nik.kernels.collision.collides_batch`, margin 0) of ``collision``, the arrays after ``q``."""
    from nik.kernels.collision import collides_batch

    N, n = Q.shape
    prev = np.concatenate([Q[:1] if q_start is None else q_start[None], Q[:-1]])
    t = np.arange(1, max(sub, 1)) / max(sub, 1)
    inside = prev[:, None] + t[None, :, None] * (Q - prev)[:, None]
    pts = np.ascontiguousarray(np.concatenate([Q[:, None], inside], axis=1).reshape(-1, n), dtype=np.float64)
    hit = np.empty(len(pts), dtype=bool)
    collides_batch(model.G, model.joints, pts, *collision, 0.0, hit)
    hit = hit.reshape(N, -1)
    return hit[:, 0], hit[:, 1:].any(axis=1)


def avoid_path(
    model,
    T: np.ndarray,
    Q: np.ndarray,
    q_start: np.ndarray | None,
    *,
    tol_pos: float,
    tol_rot: float,
    max_step: float,
    collision: tuple,
    seeds: np.ndarray | None = None,
    polish=None,
    cfg: TrajCfg | None = None,
) -> np.ndarray:
    """``Q: (N, dof)`` with its colliding stretches (waypoints, or samples inside the steps: :func:`path_collisions`)
    optimised with the collision rows (:func:`optimise_path` with ``collision``, in windows of :data:`WINDOW`
    waypoints either side of each, aiming at half the tolerances). ``seeds: (N, dof)``: other answers of the
    waypoints (collision-free ones, where the caller has them), the windows' warm start instead of the path's rows.
    ``polish(a, rows) -> rows``: a last per-waypoint step on each optimised window (waypoints
    ``a ...``; the caller's LM with collision rows: the optimisation trades millimetres of pose for clearance, the
    polish gives them back). A window is kept when it collides at fewer samples, every waypoint reached before still
    is, and its largest step is not above ``max(max_step, the largest step before)``."""
    if cfg is None:  # a stiff step hinge: clearance bought by one joint's jump is no answer
        cfg = dataclasses.replace(_default_cfg(model), w_step=AVOID_W_STEP, step_frac=AVOID_STEP_FRAC)
    Q = np.ascontiguousarray(Q, dtype=np.float64).copy()
    T = np.ascontiguousarray(T, dtype=np.float64)
    at, between = path_collisions(model, Q, q_start, collision, cfg.col_sub)
    if not (at | between).any():
        return Q
    from nik.kernels.lm import pose_errors

    def judged(rows, a, b):
        """(colliding samples, reached (b - a,), largest step) of ``rows`` as waypoints ``a:b``."""
        before = q_start if a == 0 else Q[a - 1]
        x, y = path_collisions(model, rows, before, collision, cfg.col_sub)
        hits = int(x.sum() + y.sum())
        if b < len(Q):
            hits += int(path_collisions(model, Q[b : b + 1], rows[-1], collision, cfg.col_sub)[1][0])
        pos, rot = np.empty(b - a), np.empty(b - a)
        pose_errors(model.G, model.joints, T[a:b], np.ascontiguousarray(rows), pos, rot)
        return hits, (pos <= tol_pos) & (rot <= tol_rot), _largest_step(rows, before, Q[b] if b < len(Q) else None)

    for a, b in _windows(np.nonzero(at | between)[0], len(Q)):
        hits, ok, step = judged(Q[a:b], a, b)
        res = optimise_path(
            model, T[a:b], Q[a:b] if seeds is None else seeds[a:b], q_start=q_start if a == 0 else Q[a - 1],
            q_end=Q[b] if b < len(Q) else None, max_step=max_step, tol_pos=0.5 * tol_pos, tol_rot=0.5 * tol_rot,
            cfg=cfg, collision=collision,
        )  # fmt: skip
        rows = res.q if polish is None else polish(a, res.q)
        hits2, ok2, step2 = judged(rows, a, b)
        if hits2 < hits and ok2[ok].all() and step2 <= max(max_step, step):
            Q[a:b] = rows
    return Q
