"""Repairs of a chosen path, each kept only where nothing gets worse: a loop closed by blending its last row into its
first, the last polish to within half the tolerances, colliding stretches re-planned with collision rows, steps
flattened towards :data:`nik.paths.settings.SEARCH_TRIGGER`."""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.ik import collide
from nik.paths.run import _closure, _errors, _final_check, _lm_batch, _Run
from nik.paths.settings import PATH_CLOSE_TOL, PATH_MARGIN, SEARCH_TRIGGER
from nik.paths.trajopt import polish_path
from nik.tolerances import score


def _close_loop(run: _Run, q: np.ndarray, its: np.ndarray, max_step: float, col=None) -> tuple[np.ndarray, np.ndarray]:
    """A closed path's joints with the last row equal to the first (module docstring, "closed loops"): LM from the
    first row at the last waypoint; the difference ``delta`` between that answer and the last row (modulo whole
    turns on wrapping joints) is blended back over the path (row ``i`` seeded at ``q_i + w_i delta``,
    ``w = 3 s^2 - 2 s^3`` of ``s = i / (N - 1)``: no added motion at either end) and every row re-solved by LM from
    its seed (the tool stays, the null-space drift is undone). Kept only when every waypoint reached before is
    still reached, inside the limits, no step grows above ``max(max_step, the largest step before)`` and, among
    obstacles (``col``: the collision arrays of :mod:`nik.ik.collide`), no waypoint nor step that was free collides
    (the sphere check, :func:`nik.paths.trajopt.path_collisions`). Where the blend over the whole path is refused
    (among obstacles, the LM re-solve moves the rows past the box back into it), the blend over the last half, then
    the last quarter and eighth of the path is tried (``s`` running from that row to the end, the rows before
    unchanged: the box a path is planned around lies at its middle as often as not). Else the last row alone is
    moved onto the first (``q_-1 + delta``) where that keeps its waypoint, its step within the same bound and (with
    ``col``) its motion free (a path whose other rows LM would move, near a singularity); else ``q`` as it was (its
    closure is reported)."""
    model = run.model
    if _closure(q, model.wraps) <= PATH_CLOSE_TOL:
        return q, its
    N = q.shape[0]
    end, end_its, ok = _lm_batch(run, q[:1], np.array([N - 1]))
    if not ok[0]:
        return q, its
    delta = end[0] - q[-1]
    w = model.wraps
    delta[w] = np.remainder(delta[w] + math.pi, 2 * math.pi) - math.pi  # never undo a whole turn of the path
    _, _, before = _final_check(run, q)
    old_step = np.abs(np.diff(q, axis=0)).max()
    bound = max(max_step, old_step)
    if col is not None:
        from nik.paths.trajopt import TrajCfg, path_collisions

        was = np.logical_or(*path_collisions(model, q, run.q0, col, TrajCfg.col_sub))

    def new_hits(new: np.ndarray) -> bool:
        """Whether ``new`` collides at a waypoint or inside a step that was free in ``q``."""
        if col is None:
            return False
        return bool((np.logical_or(*path_collisions(model, new, run.q0, col, TrajCfg.col_sub)) & ~was).any())

    for a in (0, N // 2, 3 * N // 4, 7 * N // 8) if col is not None else (0,):
        if N - 1 - a < 2:
            break
        rows = np.arange(a, N)
        s = (rows - a) / (N - 1 - a)
        seeds = np.clip(q[a:] + (3 * s**2 - 2 * s**3)[:, None] * delta, model.lo, model.hi)
        part, part_its, _ = _lm_batch(run, seeds, rows)
        new, new_its = q.copy(), np.zeros_like(its)
        new[a:], new_its[a:] = part, part_its
        new[-1] = q[-1] + delta
        new_its[-1] = end_its[0]
        _, _, after = _final_check(run, new)
        inside = ((new >= model.lo - 1e-9) & (new <= model.hi + 1e-9)).all(axis=1)
        new_step = np.abs(np.diff(new, axis=0)).max()
        if not (before & ~(after & inside)).any() and new_step <= bound and not new_hits(new):
            return new, its + new_its
    last = q.copy()  # the blend refused: the last row alone moved onto the first, where its step stays small
    last[-1] = q[-1] + delta
    step = float(np.abs(last[-1] - last[-2]).max())
    ok = _final_check(run, last)[2][-1]
    inside = bool(((last[-1] >= model.lo - 1e-9) & (last[-1] <= model.hi + 1e-9)).all())
    if (ok or not before[-1]) and inside and step <= bound and not new_hits(last):
        its = its.copy()
        its[-1] += end_its[0]
        return last, its
    return q, its


def _inside_margin(run: _Run, q: np.ndarray, max_step: float, check, closed: bool) -> np.ndarray:
    """``q: (N, dof)`` with each waypoint that is reached but not within :data:`PATH_MARGIN` of the tolerances polished
    by LM (no restarts) from its row towards that fraction of them, kept where its error falls, it moves less than
    :data:`PATH_MARGIN` ``x max_step`` and (with ``check``) comes out free where it was: a path's worst error is not at
    the threshold. A closed path's last row follows its first."""
    pos, rot = _errors(run.model, run.T, q)
    tp, tr = PATH_MARGIN * run.tol_pos, PATH_MARGIN * run.tol_rot
    idx = np.nonzero((pos <= run.tol_pos) & (rot <= run.tol_rot) & ((pos > tp) | (rot > tr)))[0]
    if closed:
        idx = idx[idx != q.shape[0] - 1]  # the last row follows the first
    if not idx.size:
        return q
    res = run.model.lm.solve(run.T[idx], q[idx], tol_pos=tp, tol_rot=tr, seed=run.seed, restarts=False)
    keep = (score(res.pos_err, res.rot_err) < score(pos[idx], rot[idx])) & (
        np.abs(res.q - q[idx]).max(axis=1) <= PATH_MARGIN * max_step
    )
    if check is not None:
        from nik.paths.trajopt import path_collisions

        col = check.arguments(run.model.robot)[1]
        keep &= (
            ~path_collisions(run.model, res.q, None, col, 1)[0] | path_collisions(run.model, q[idx], None, col, 1)[0]
        )
    out = q.copy()
    out[idx[keep]] = res.q[keep]
    if closed:
        out[-1] = q[-1] + (out[0] - q[0])
    return out


def _avoid(solver, run: _Run, q: np.ndarray, check, max_step: float) -> np.ndarray:
    """``q: (N, dof)`` re-planned around the obstacles of ``check`` (:func:`nik.paths.trajopt.avoid_path`: the
    whole-path optimisation with collision rows over each colliding stretch), each optimised stretch then polished
    waypoint by waypoint from its rows: LM towards half the tolerances, and where a row collides, LM with collision
    rows (:func:`nik.ik.collide.resolve`: from the row first, then the network's hypotheses or the closed form's
    branches, then uniform restarts)."""
    from nik.ik.result import IKResult
    from nik.paths.trajopt import TrajCfg, _windows, avoid_path, path_collisions

    col = check.arguments(solver.robot)[1]

    def polish(a: int, rows: np.ndarray) -> np.ndarray:
        """LM with collision rows from each row of waypoints ``a ...`` (:func:`nik.ik.collide.resolve`), kept where
        it reaches the pose within half ``max_step`` of the row (no jump to another posture)."""
        idx = a + np.arange(rows.shape[0])
        pos, rot = _errors(run.model, run.T[idx], rows)
        miss = np.nonzero((pos > 0.5 * run.tol_pos) | (rot > 0.5 * run.tol_rot))[0]
        if miss.size:
            lm = run.model.lm.solve(run.T[idx[miss]], rows[miss], tol_pos=0.5 * run.tol_pos,
                                    tol_rot=0.5 * run.tol_rot, seed=run.seed, restarts=False)  # fmt: skip
            rows = rows.copy()
            rows[miss] = lm.q
            pos[miss], rot[miss] = lm.pos_err, lm.rot_err
        ok = (pos <= run.tol_pos) & (rot <= run.tol_rot)
        res = IKResult(rows, pos, rot, ok, np.zeros(rows.shape[0], dtype=np.int64), "path",
                       reachable=run.reachable[idx])  # fmt: skip
        out = collide.resolve(solver.robot, run.plan, torch.from_numpy(run.T[idx]), res, check)
        good = np.asarray(out.success) & (np.abs(np.asarray(out.q) - rows).max(axis=1) <= 0.5 * max_step)  # no jump
        return np.where(good[:, None], np.asarray(out.q), rows)

    kw = {"tol_pos": run.tol_pos, "tol_rot": run.tol_rot, "max_step": max_step, "collision": col, "polish": polish}
    q = avoid_path(run.model, run.T, q, run.q0, **kw)
    at, between = path_collisions(run.model, q, run.q0, col, TrajCfg.col_sub)
    bad = np.nonzero(at | between)[0]
    if not bad.size:
        return q
    # more candidates: a chain of collision-free answers over each stretch still colliding (each waypoint's LM seeded
    # by the previous free answer, then the collision LM where it collides), the optimisation's other warm start
    seeds = q.copy()
    for a, b in _windows(bad, q.shape[0]):
        prev = (q[a - 1] if a else q[0]) if run.q0 is None or a else run.q0
        for i in range(a, b):
            lm = run.model.lm.solve(run.T[i : i + 1], prev[None], tol_pos=0.5 * run.tol_pos,
                                    tol_rot=0.5 * run.tol_rot, seed=run.seed, restarts=False)  # fmt: skip
            row = polish(i, lm.q)[0]
            if np.abs(row - prev).max() <= max_step:
                seeds[i] = prev = row
    return avoid_path(run.model, run.T, q, run.q0, seeds=seeds, **kw)


def _flatten(run: _Run, q: np.ndarray, its: np.ndarray, max_step: float, closed: bool) -> np.ndarray:
    """``q: (N, dof)`` of an arm without a closed form whose largest step (from ``q0`` on) lies between
    :data:`SEARCH_TRIGGER` and ``max_step``, optimised as one path towards steps of at most :data:`SEARCH_TRIGGER`
    (:func:`nik.paths.trajopt.polish_path`, windows around each larger step; kept only where no waypoint is lost and
    the largest step does not grow): the search picks among the tracks' answers, whose self-motion is not tuned to the
    path (free space only: it has no collision rows, and among obstacles the search's candidates are free ones); the
    optimisation moves it so that no joint takes a step the next waypoints then need back (a circle of
    xarm7 followed by the search in steps of 4.5 deg comes out in steps of 2.9 deg). A closed path keeps it only where
    it still closes as well (:func:`_close_loop` of both): a loop that repeats without a jump beats smaller steps."""
    full = q if run.q0 is None else np.concatenate([run.q0[None], q])
    step = float(np.abs(np.diff(full, axis=0)).max())
    if not SEARCH_TRIGGER < step <= max_step:
        return q
    out, _, _ = polish_path(
        run.model, run.T, q, run.q0, tol_pos=run.tol_pos, tol_rot=run.tol_rot, max_step=SEARCH_TRIGGER,
        reachable=run.reachable, q_rest=run.rest,
    )  # fmt: skip
    if closed and out is not q:
        w = run.model.wraps
        if _closure(_close_loop(run, out, its, max_step)[0], w) > _closure(_close_loop(run, q, its, max_step)[0], w):
            return q
    return out
