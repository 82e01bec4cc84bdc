"""Cartesian paths: N waypoints in order -> one continuous joint trajectory, and an honest report of it.

A path is more than N independent poses: the arm has to move from each answer to the next, so a solution
that jumps to another IK branch half-way (a joint turning 180 degrees between two waypoints 3 mm apart) is no
answer, however exact each pose is. :func:`solve_path` therefore looks at the whole path before it commits. Its
stages are those of :meth:`nik.IKSolver.solve` (:mod:`nik.ik.stages`) on the robot's one compiled model
(:func:`nik.ik.model.model_of`: limits, wraps, reach, closed form, LM), plus one: the choice over the whole path.

This module holds :func:`solve_path`, which runs the stages below in order; each stage lives in a module of its own
in :mod:`nik.paths`: :mod:`~nik.paths.parse` (the input checked), :mod:`~nik.paths.run` (one call's state, its LM
chains, the final check), :mod:`~nik.paths.candidates` (the candidates at each waypoint and the closed-form path),
:mod:`~nik.paths.choice` (the choice over the whole path), :mod:`~nik.paths.search` (the global posture search),
:mod:`~nik.paths.repair` (loops closed, the last polish, obstacles avoided, steps flattened), :mod:`~nik.paths.report`
(the report, the timing) and :mod:`~nik.paths.settings` (the constants named below). The private names below are
those modules' functions.

1. **the reach bound** (the model's compiled flags): waypoints provably out of reach are flagged (``reachable``)
   and get no restarts; the warning carries the words of :func:`nik.robots.reach.unreachable_message`, with the
   millimetre question 100 x beyond the reach, as :meth:`~nik.IKSolver.solve` warns (neither raises).
2. **guess: candidates** at each waypoint. On an arm with a closed form (:func:`nik.analytic.family`): all 8
   branches of every waypoint, in one compiled call (the model's closed form; an arm that fits its family only
   within a tolerance gets the ideal arm's closed form checked at the model's tolerance, the one policy of
   :mod:`nik.ik.model`). On other arms (redundant 7-joint arms among them): chains of Levenberg-Marquardt, each
   waypoint seeded by the chain's answer at the previous one, started from ``q_start``, or, without it, from the
   network's hypotheses (the compiled backend's guess stage: the packed network) and from uniform starts at the
   first waypoint (several chains side by side, each the continuation of a different posture).
3. **the choice over the whole path**: by dynamic programming over the candidates
   (:func:`nik.paths.kernels.path_dp`; the branches, or every chain's answer at every waypoint), the sequence
   whose largest step is the smallest, and among those the one with the least sum of squared steps (then the least
   total joint motion); with ``q_start`` the step from it to the first waypoint counts too, so the trajectory starts
   nearest it. With ``q_start`` on a closed-form arm the LM chain from ``q_start`` is tried first and kept when it
   follows every waypoint in steps of at most :data:`PATH_FOLLOW_STEP` (its branch meets no limit: nothing to look
   ahead for); else that chain is one more candidate on an approximate closed form (whose branches may miss the
   posture ``q_start`` is in), and the first waypoint's candidates are those within ``max_step`` of ``q_start``
   where there are any (open or closed: a jump the path cannot avoid is not taken at the start).
4. **refine**: a chosen branch that misses the tolerance (an approximate closed form) gets LM from it; a waypoint
   left without a valid branch gets LM seeded by its neighbour's answer (its best effort, flagged); the chains are
   that already.
5. **redundant arms**: the extra freedom is resolved along the path by seeding each waypoint with its
   predecessor's answer moved :data:`PATH_PULL` of the way towards the middle of the joint ranges (``q_rest``
   where given; at most :data:`PATH_PULL_CAP` per joint and waypoint): LM from that seed removes whatever would move
   the tool, the rest is self-motion away from the limits, so the arm does not drift into a limit and then jump.
6. **global search** (arms without a closed form, :func:`_search_path`), where that chain does not follow the path
   smoothly (a waypoint missed, a step above :data:`SEARCH_TRIGGER` or ``max_step``, a loop left more than
   ``max_step`` open, a waypoint colliding): tracks, LM chains each drifting along the self-motion towards a posture
   of its own (:data:`SEARCH_PULL`, at most :data:`SEARCH_PULL_CAP` per waypoint): from ``q_start`` (else from every
   start posture) towards the middle of the ranges, its start, ``q_rest``, and the network's hypotheses at the
   middle and the last waypoint (without a network: LM answers from uniform starts there); backward tracks from
   those postures (and, on a loop, from the start, which answers its last pose too). Every track's answer at every
   waypoint is a candidate (inside the limits, within the tolerances or the tolerant goal, free of collision among
   obstacles); the dynamic programming (:func:`nik.paths.kernels.path_dp`, real joint motion) chooses the sequence,
   switching tracks where they meet; a loop's end pinned next to its start. Among obstacles
   (:func:`_search_postures`): the free ones among the network's hypotheses and LM's uniform answers, side by side, at
   :data:`SEARCH_ANCHORS` and the ends of the chain's colliding stretch, each with a fast track too
   (:data:`SEARCH_FAST_CAP`); a choice whose step collides inside is made again (:func:`_free_steps`); the
   whole-path optimisation that follows has collision rows and keeps a loop closed (``polish_path(closed=,
   collision=)``). The chain's answer stays unless the
   search reaches more waypoints, closes a loop the chain leaves open, or cuts the largest step by
   :data:`SEARCH_GAIN`: the search never answers worse than the chain. Where the answer's largest step still lies
   between :data:`SEARCH_TRIGGER` and ``max_step`` (free space), the whole-path optimisation aims at steps of
   :data:`SEARCH_TRIGGER` (:func:`_flatten`, kept only where nothing gets worse).
7. **the report** (:class:`PathReport`): success per waypoint re-checked by FK (and the limits), every step,
   the largest one and where, and a warning naming the first waypoint that is out of reach, beyond a joint limit
   on every branch, not reached, or reached only by a step above ``max_step`` (a reconfiguration). A waypoint that FK
   reaches but only by a step above ``max_step`` from a reached neighbour counts as not reached (:func:`jumps`,
   reason :data:`JUMP_REASON`): a path is never continued by a jump between two successes. The step from
   ``q_start`` into the first waypoint is warned about, not flagged (the arm gets there before the path).

**Closed loops** (``closed=None``: detected when the last pose equals the first within the tolerances; True /
False force it): the last row of joints equals the first, so the cycle repeats without a jump. Closed-form arms:
the choice ends on the start's branch (:func:`_choose`: when the free choice does not, each start branch is tried
with the end pinned to its own). Every arm, after the path: where the last row still differs from the first (an
LM chain's drift in the null space), :func:`_close_loop` solves the last waypoint from the first row and blends the
difference back over the path, kept only when no waypoint is lost and no step grows beyond ``max_step`` (or the
largest step before). On joints that turn past a full turn (``wraps``) the rows are equal modulo whole turns: a
path that takes such a joint once around ends one turn further (turning back would be a jump); ``res.path.closure``
reports the gap. A loop is never closed by a jump: where the closed answer has a step above ``max_step`` between two
reached waypoints, the path is solved again as open and that answer kept where it reaches more waypoints (as many:
where its largest step between reached waypoints is smaller by :data:`SEARCH_GAIN`); such a loop, and one whose last
row stays more than ``max_step`` from its first, is left open: ``res.path.closed`` False, ``closure`` the gap, the
warning says it (:func:`open_note`). The second solve costs as much as the first, on loops with a jump only.

**Tolerant paths** (``bounds=``, :mod:`nik.ik.bounds`): with one free tool axis on a closed-form arm the candidates
are the closed form's branches at sampled angles about it (:func:`_branches`) and the dynamic programming picks the
least-motion sequence; other goals and arms run the LM chains towards the bounds
(:func:`nik.paths.kernels.path_chains_bounded`). Success is checked by FK in each waypoint's tool frame
(:func:`_final_check`); ``rot_err`` is then the rotation error that counts (with a free axis, its swing).

**Posture** (``q_rest=``: one posture ``(dof,)`` or ``"mid"``): on arms without a closed form the chains and the
search's plain tracks drift towards it instead of the middle of the ranges (and the start posture nearest it comes
first); the closed form's branches are chosen by motion alone; the whole-path optimisation (where it runs: a
waypoint missed or a step above ``max_step``) has posture rows towards it (:class:`nik.paths.trajopt.TrajCfg`
``w_rest``).

**Timing** (``timing=True`` or a dict of :func:`nik.paths.timing.time_path` keywords): the answer is timed after the
path (TOPP-RA, rest to rest) within ``vel_limits`` / ``acc_limits`` (the robot's unless given; none known is a
one-line ValueError before any work): ``res.path.t``, ``qd``, ``qdd``, ``timing``. A broken path (a waypoint not
reached, a step between waypoints above ``max_step``) gets no schedule: those stay None and the warning says why
(:func:`_time`); ``nik path --timing`` then writes no ``t_s`` column and exits 1.

**Settings**: the solver's, as :meth:`~nik.IKSolver.solve` reads them. The LM config (``swarm_cfg`` an
:class:`nik.lm.LMCfg`) is the chains' and polishes' LM; ``fallback="multistart"`` (the default without a closed
form) lets a waypoint the chain does not reach draw up to :data:`PATH_RESTARTS` uniform restarts (within reach),
``"none"`` or ``"analytic"`` none (on a closed-form arm a restart could only jump to another branch);
``refine="none"`` keeps the closed form's branches as they are (no LM; refused on an arm without a closed form,
which has no other way along the path); the swarm methods are local along a path, where each waypoint is seeded by
the one before: their LM polish is the chains' LM. ``backend="torch"`` is refused (the chains run in the compiled
kernels); ``checkpoint=None`` (no network) leaves the uniform starts alone.

The step between two configurations is the largest joint motion ``max_j |q_i,j - q_i-1,j|`` (radians; metres on
prismatic joints), measured on the returned joints: a joint whose range is wider than a full turn may cross
pi, one limited to [-pi, pi] may not. Paths are solved on the CPU in float64 (the work is sequential by nature);
the result comes back in the dtype and on the device of the input poses. ``q_start`` is checked as ``q_near`` is
(:func:`nik.ik.targets.q_near_array`), and must lie inside the limits.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from nik.ik import collide
from nik.ik.bounds import parse_bounds
from nik.ik.model import model_of
from nik.ik.result import IKResult
from nik.ik.targets import check_tolerances
from nik.paths.candidates import _chain_from_start, _chain_path, _closed_form_path, _follows
from nik.paths.parse import _is_closed, _plan, _poses, _q_rest, _q_start
from nik.paths.repair import _avoid, _close_loop, _flatten, _inside_margin
from nik.paths.report import JUMP_REASON, _report, _time, jumps, open_note, untimed_reason
from nik.paths.run import _closure, _errors, _final_check, _Run  # noqa: F401 - _errors: read here by benchmarks
from nik.paths.search import _search_path, _smooth
from nik.paths.settings import (  # noqa: F401 - PATH_CLOSE_TOL, PATH_MARGIN, SEARCH_TRIGGER: read here by tests
    PATH_CLOSE_TOL,
    PATH_MARGIN,
    PATH_MAX_STEP,
    PATH_PULL,
    PATH_PULL_CAP,
    PATH_RESTARTS,
    SEARCH_GAIN,
    SEARCH_TRIGGER,
)
from nik.paths.trajopt import polish_path

__all__ = [
    "JUMP_REASON",
    "PATH_MAX_STEP",
    "PATH_PULL",
    "PATH_PULL_CAP",
    "PATH_RESTARTS",
    "PathOptions",
    "jumps",
    "open_note",
    "solve_path",
    "untimed_reason",
]


@dataclass(frozen=True)
class PathOptions:
    """The options of one :func:`solve_path` call: :meth:`nik.IKSolver.solve_path`'s keywords (metres, radians),
    described in :func:`solve_path`'s Args. ``tol_pos``, ``tol_rot`` have no default: the caller states them."""

    tol_pos: float
    tol_rot: float
    seed: int = 0
    representation: str | None = None
    max_step: float = PATH_MAX_STEP
    world: Any = None
    closed: bool | None = None
    timing: bool | dict = False
    vel_limits: Any = None
    acc_limits: Any = None
    bounds: Any = None
    q_rest: Any = None


def solve_path(solver, T_path, q_start, options: PathOptions) -> IKResult:
    """One continuous joint trajectory through the waypoints ``T_path`` (see :meth:`nik.IKSolver.solve_path`).

    Args:
        solver: the :class:`nik.IKSolver` whose robot, closed form, network and settings are used (see the module
            docstring, "settings").
        T_path: ``(N, 4, 4)``, ``(N, 7)`` or ``(N, 6)`` waypoints in order (metres, radians), N >= 2.
        q_start: ``(dof,)`` the joints before the path (radians, inside the limits) or None.
        options: the call's :class:`PathOptions`, whose fields are:
        tol_pos, tol_rot: success tolerances, metres and radians.
        seed: seeds the uniform starts and restarts.
        representation: ``"matrix"`` | ``"quat"`` (w first) | ``"quat_xyzw"`` (ROS order) | ``"rpy"``; inferred from the
            shape when None (7 numbers: ``"quat"``).
        max_step: steps above it are reconfigurations (reported, warned about), radians.
        world: a :class:`nik.World` (else the solver's; with self-collision by :func:`nik.ik.collide.setup`'s rule):
            on an arm without a closed form a chain that collides is searched again with colliding answers left out
            (module docstring, "global search"); the path's colliding stretches (waypoints, or samples inside the
            steps) are re-planned by the path optimisation with collision rows (:func:`_avoid`); what still collides
            is infeasible, reason ``"colliding"`` (the waypoint) or ``"colliding on the way from the waypoint before"``
            (the motion).
        closed: None: the path is closed when its last pose equals its first within the tolerances (position and
            rotation); True / False force it. A closed path returns joints whose last row equals its first, unless it
            closes only by a step above ``max_step``: then it is left open (module docstring, "closed loops").
        timing: True (or a dict of :func:`nik.paths.timing.time_path` keywords: ``tool_speed``, ``vel_scale``,
            ``acc_scale``) times the trajectory: ``res.path.t``, ``qd``, ``qdd`` and ``timing``; a broken path (a
            waypoint not reached, a step above ``max_step``) is not timed (None, and the warning says why).
        vel_limits, acc_limits: ``(dof,)`` joint speed / acceleration limits of the timing (default the robot's).
        bounds: a tolerant goal for every waypoint (:func:`nik.ik.bounds.parse_bounds`: ``"axis_z"``, 6 numbers,
            ``(N, 6)``); None: ``tol_pos`` / ``tol_rot``. Module docstring, "tolerant paths".
        q_rest: ``(dof,)`` a preferred posture (radians) or ``"mid"`` (the middle of the ranges), or None. Module
            docstring, "posture".

    Returns:
        :class:`IKResult` of N rows (``q: (N, dof)``) with ``path``: a :class:`PathReport`.

    Warns:
        UserWarning: one line naming the first waypoint out of reach (with the reach bound's own words, and the
            millimetre question where a waypoint lies 100 x beyond: :func:`nik.robots.reach.unreachable_message`,
            as :meth:`nik.IKSolver.solve` warns), beyond a joint limit on every branch, not reached, or forcing a
            reconfiguration.

    Raises:
        ValueError: bad poses (NaN, shape, a non-orthonormal rotation), fewer than 2 waypoints, a bad tolerance or
            ``max_step``, a ``q_start`` refused as ``q_near`` is (:func:`nik.ik.targets.q_near_array`) or outside
            the limits, a solver whose settings a path cannot follow (``backend="torch"``; ``refine="none"`` on an
            arm without a closed form).
    """
    o = options
    tol_pos, tol_rot, seed, representation, max_step = o.tol_pos, o.tol_rot, o.seed, o.representation, o.max_step
    world, closed, timing, vel_limits, acc_limits = o.world, o.closed, o.timing, o.vel_limits, o.acc_limits
    bounds, q_rest = o.bounds, o.q_rest
    Tn, dtype, device = _poses(T_path, representation)
    if Tn.shape[0] < 2:
        raise ValueError(f"T_path: a path needs at least 2 waypoints, got {Tn.shape[0]}")
    check_tolerances(tol_pos, tol_rot)
    if not (isinstance(max_step, int | float) and math.isfinite(max_step) and max_step > 0):
        raise ValueError(f"max_step: expected a number > 0 (radians), got {max_step!r}")
    if closed is not None and not isinstance(closed, bool):
        raise ValueError(f"closed: expected None, True or False, got {closed!r}")
    if not isinstance(timing, bool | dict):
        raise ValueError(f"timing: expected True, False or a dict of time_path keywords, got {timing!r:.60}")
    unknown = sorted(set(timing) - {"tool_speed", "vel_scale", "acc_scale"}) if isinstance(timing, dict) else []
    if unknown:
        raise ValueError(f"timing: unknown keyword {unknown[0]!r} (expected tool_speed, vel_scale, acc_scale)")
    goal = parse_bounds(bounds, batch=Tn.shape[0], tol_pos=tol_pos, tol_rot=tol_rot)
    robot = solver.robot
    if timing is not False and vel_limits is None and robot.vel_limits is None:
        raise ValueError(f"timing needs joint speed limits: {robot.name} has none (give vel_limits=, rad/s per joint)")
    plan = _plan(solver, tol_pos, tol_rot, seed)
    model = model_of(robot, plan.lm_cfg)
    reachable, every = model.reach(Tn)
    reach_note = None if every else model.unreachable_message(Tn, reachable)
    q0 = _q_start(robot, model, q_start)
    N = Tn.shape[0]
    rest = None if q_rest is None else _q_rest(robot, q_rest)
    half, modes = (None, None) if goal is None else (goal.expand(N), goal.modes(N))
    is_closed = _is_closed(Tn, tol_pos, tol_rot) if closed is None else closed
    run = _Run(plan, model, Tn, q0, reachable, half, modes, rest)
    check = collide.setup(robot, solver.world if world is None else world, solver.self_collision)
    col = None if check is None else check.arguments(robot)[1]

    def attempt(closed_loop: bool):
        """The stages of the module docstring for the loop taken as closed or open: ``(q, its, source, pos, rot,
        success, free, reasons, largest step between two reached waypoints)``."""
        follows = chain = None
        free_axis = goal is not None and set(modes.tolist()) <= {0, 1, 2}  # one free tool axis: closed form's samples
        closed_form = solver.closed_form and (goal is None or free_axis or not np.isinf(half).any())
        if closed_form and q0 is not None and run.refine:  # the quick answer: LM from q_start, if it follows
            chain = _chain_from_start(run)
            follows = _follows(run, chain, max_step)
        if follows is not None:
            q, its, found, source = *follows, None, "q_start"
        elif closed_form:
            q, its, found, source = _closed_form_path(run, closed_loop, chain, max_step)
        else:
            q, its, source = _chain_path(run)
            if run.refine and not _smooth(run, q, max_step, closed_loop, col):
                q, its, source = _search_path(run, max_step, closed_loop, (q, its, source), run.rest, col)
            found = None
        if run.refine and run.half is None:  # whole-trajectory optimisation where a waypoint is missed or a step too
            # large (the classic tolerances only), kept if no worse
            q, _, _ = polish_path(
                model, Tn, q, q0, tol_pos=tol_pos, tol_rot=tol_rot, max_step=max_step, reachable=reachable,
                q_rest=rest, closed=closed_loop, collision=col,
            )  # fmt: skip
            if not closed_form and check is None:  # among obstacles the search's free candidates stay as they are
                q = _flatten(run, q, its, max_step, closed_loop)
        if check is not None and run.refine and run.half is None:  # obstacles: the colliding stretches re-planned
            q = _avoid(solver, run, q, check, max_step)
        if closed_loop:
            q, its = _close_loop(run, q, its, max_step, col)
        if run.refine and run.half is None:
            q = _inside_margin(run, q, max_step, check, closed_loop)
        pos, rot, within = _final_check(run, q)
        inside = ((q >= model.lo - 1e-9) & (q <= model.hi + 1e-9)).all(axis=1)
        success = within & inside
        success, free, colliding = collide.path_waypoints(solver, q, world, success)
        if check is not None:  # the motion between waypoints: samples inside each step (the sphere check)
            from nik.paths.trajopt import TrajCfg, path_collisions

            _, between = path_collisions(model, q, q0, check.arguments(robot)[1], TrajCfg.col_sub)
            for i in np.nonzero(between & free)[0]:
                colliding[i] = "colliding on the way from the waypoint before"
            success = success & ~between
        reasons = [""] * len(success)
        for i in np.nonzero(~success)[0]:
            why = "" if found is None else found[i]
            reasons[i] = why or colliding[i] or ("out of reach" if not reachable[i] else "not reached")
        jump = jumps(q, success, max_step)
        for i in np.nonzero(jump)[0]:
            reasons[i] = JUMP_REASON
        pairs = np.abs(np.diff(q, axis=0)).max(axis=1)[success[1:] & success[:-1]]  # steps between reached waypoints
        return q, its, source, pos, rot, success & ~jump, free, reasons, float(pairs.max(initial=0.0))

    q, its, source, pos, rot, success, free, reasons, big = attempt(is_closed)
    left_open = False
    if is_closed and JUMP_REASON in reasons:  # a loop closed by a jump: open, kept where it reaches more waypoints
        opened = attempt(False)  # (as many: where its largest step between reached waypoints is smaller)
        if (opened[5].sum(), -opened[8]) > (success.sum(), -big + SEARCH_GAIN):
            q, its, source, pos, rot, success, free, reasons, big = opened
            left_open = True
    gap = _closure(q, model.wraps) if is_closed else None
    report = _report(robot, q, q0, success, reasons, max_step, reach_note)
    report.closed = bool(is_closed and not left_open and gap <= max_step)
    report.closure = gap
    if is_closed and not report.closed:
        report.warning = (report.warning + "; " if report.warning else f"solve_path on {robot.name}: ") + open_note(
            gap, max_step
        )
    if timing is not False:
        _time(report, robot, q, timing, vel_limits, acc_limits, success)
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
        collision_free=None if free is None else torch.from_numpy(free).to(device),
    )
