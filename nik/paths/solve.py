"""Cartesian paths: N waypoints in order -> one continuous joint trajectory, and an honest report of it.

A path is more than N independent poses: the arm has to move from each answer to the next, so a solution
that jumps to another IK branch half-way (a joint turning 180 degrees between two waypoints 3 mm apart) is no
answer, however exact each pose is. :func:`solve_path` therefore looks at the whole path before it commits. Its
stages are those of :meth:`nik.IKSolver.solve` (:mod:`nik.ik.stages`) on the robot's one compiled model
(:func:`nik.ik.model.model_of`: limits, wraps, reach, closed form, LM), plus one: the choice over the whole path.

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
from nik.ik.result import IKResult, PathReport
from nik.ik.targets import check_tolerances, pose_array, q_near_array
from nik.paths.trajopt import polish_path
from nik.tolerances import score

__all__ = [
    "JUMP_REASON",
    "PATH_MAX_STEP",
    "PATH_PULL",
    "PATH_PULL_CAP",
    "PATH_RESTARTS",
    "jumps",
    "open_note",
    "solve_path",
    "untimed_reason",
]

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
#: Two first-waypoint answers closer than this (largest joint difference, radians) are one chain; a closed path's
#: last candidate this close to its first is on the same branch.
PATH_DEDUPE = 1e-2
#: Closed paths on closed-form arms: start candidates tried with the end pinned to their branch (when the free
#: choice does not close).
PATH_CLOSED_STARTS = 8
#: A closed path whose last row is within this of its first (largest joint difference, radians; modulo whole turns
#: on joints that wrap) is closed as it is; else :func:`_close_loop` closes it.
PATH_CLOSE_TOL = 1e-9
#: Most entries of one of the dynamic programming's ``(N, K, K)`` tables (with a free tool axis, K grows with the
#: sampled angles: :func:`_free_samples`).
PATH_DP_CELLS = 30_000_000
#: The last polish aims at this fraction of the tolerances (every reached waypoint whose error is above it), so that a
#: path's worst error is not at the threshold; a waypoint moves at most this fraction of ``max_step`` for it.
PATH_MARGIN = 0.5
#: The global search's tracks (arms without a closed form): each waypoint's seed moves this fraction of the way from
#: the previous answer towards the track's own posture ...
SEARCH_PULL = 0.05
#: ... by at most this much per joint and waypoint, radians (0.5 degrees).
SEARCH_PULL_CAP = math.radians(0.5)
#: The network's hypotheses (or uniform LM answers) per waypoint that the tracks drift towards (at the middle and the
#: last waypoint), and how far apart two of them must be (largest joint difference, radians) to count twice.
SEARCH_HYPOTHESES, SEARCH_DISTINCT = 4, math.radians(20.0)
#: The search's closed paths: distinct start candidates tried with the end pinned (:func:`_choose`; with ``q_start``
#: they all lie within ``max_step`` of it).
SEARCH_CLOSED_STARTS = 4
#: Among obstacles, how many times the search's choice is made again without the candidates that a colliding step
#: leads to (:func:`_free_steps`).
SEARCH_RECHOOSE = 3
#: Among obstacles, the waypoints (fractions of the path) whose answers the tracks drift towards.
SEARCH_ANCHORS = (0.25, 0.5, 0.75, 1.0)
#: Among obstacles, each posture also gets a fast track from the start: this pull, at most this per waypoint (radians,
#: 3 degrees, under the 7 degree steps a path may take): the self-motion swings away from a box met early.
SEARCH_FAST_PULL, SEARCH_FAST_CAP = 0.3, math.radians(3.0)
#: The search's answer replaces the chain's where it reaches more waypoints, closes a loop the chain leaves open, or
#: (else equal) cuts the largest step by more than this (radians, 0.5 degrees): on a tie the chain stays.
SEARCH_GAIN = math.radians(0.5)
#: The search runs where the chain takes a step above this (radians, 2 degrees, as :data:`PATH_FOLLOW_STEP`; or above
#: ``max_step``), misses a waypoint, collides, or leaves a loop open: below it a chain's path is taken as smooth (the
#: search costs about 30 chains; at 3 degrees, one panda circle in 19 more keeps a 3.1 degree step).
SEARCH_TRIGGER = math.radians(2.0)


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
    world=None,
    closed: bool | None = None,
    timing: bool | dict = False,
    vel_limits=None,
    acc_limits=None,
    bounds=None,
    q_rest=None,
) -> IKResult:
    """One continuous joint trajectory through the waypoints ``T_path`` (see :meth:`nik.IKSolver.solve_path`).

    Args:
        solver: the :class:`nik.IKSolver` whose robot, closed form, network and settings are used (see the module
            docstring, "settings").
        T_path: ``(N, 4, 4)``, ``(N, 7)`` or ``(N, 6)`` waypoints in order (metres, radians), N >= 2.
        q_start: ``(dof,)`` the joints before the path (radians, inside the limits) or None.
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


# ---------------------------------------------------------------------------
# input, settings
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


def _plan(solver, tol_pos: float, tol_rot: float, seed: int):
    """The solver's :class:`~nik.ik.plan.Plan` of a compiled call (:meth:`nik.IKSolver.plan`: the network that
    guesses, the LM config, refine, fallback), refused in one line where a path cannot follow it."""
    if solver.backend == "torch":
        raise ValueError(
            "solve_path: the path's chains run on the compiled kernels (each waypoint seeded by the one before); "
            "this solver forces backend='torch'"
        )
    if solver.refine == "none" and not solver.closed_form:
        raise ValueError(
            f"solve_path: refine='none' leaves {solver.robot.name} (no closed form) without a way to follow the path; "
            "use refine='lm'"
        )
    return solver.plan(backend="compiled", tol_pos=tol_pos, tol_rot=tol_rot, seed=seed)


@dataclass
class _Run:
    """One call: its plan (:mod:`nik.ik.plan`), the robot's model, the waypoints ``T (N, 4, 4)``, ``q0 (dof,)`` or
    None and ``reachable (N,)``."""

    plan: Any
    model: Any
    T: np.ndarray
    q0: np.ndarray | None
    reachable: np.ndarray
    half: np.ndarray | None = None  # (N, 6) a tolerant goal's half-widths (nik.ik.bounds), None: the tolerances
    modes: np.ndarray | None = None  # (N,) its rotation modes
    rest: np.ndarray | None = None  # (dof,) q_rest: the posture the chains drift towards (else the middle)

    @property
    def tol_pos(self) -> float:
        return self.plan.tol_pos

    @property
    def tol_rot(self) -> float:
        return self.plan.tol_rot

    @property
    def seed(self) -> int:
        return self.plan.seed

    @property
    def refine(self) -> bool:
        """False with ``refine="none"``: the closed form's branches as they are, no LM."""
        return self.plan.refine != "none"

    @property
    def restarts(self) -> int:
        """Uniform restarts a waypoint the chain does not reach may draw: :data:`PATH_RESTARTS` with
        ``fallback="multistart"``, else none."""
        return PATH_RESTARTS if self.plan.fallback == "multistart" else 0

    def chains(self, T, starts, reachable, *, pull: float, restarts: int, seed: int | None = None, offset: int = 0):
        """:func:`nik.paths.kernels.path_chains` along ``T`` from ``starts: (K, dof)``: ``q (K, N, dof)``,
        iterations ``(K, N)``, ok ``(K, N)`` (LM options: the model's LM with this call's tolerances; with a tolerant
        goal, :func:`~nik.paths.kernels.path_chains_bounded` towards the bounds of waypoints ``offset ...`` of
        the path, which ``T`` are): :meth:`tracks` drifting towards ``q_rest``, else the middle of the ranges."""
        from nik.kernels.chain import LOWER, UPPER

        joints, K = self.model.lm.joints, starts.shape[0]
        rest = self.rest if self.rest is not None else 0.5 * (joints[:, LOWER] + joints[:, UPPER])
        pulls, caps = np.full(K, pull), np.full(K, PATH_PULL_CAP if pull > 0 else 0.0)
        return self.tracks(T, starts, np.repeat(rest[None], K, axis=0), pulls, caps, reachable, restarts, offset,
                           seed=seed)  # fmt: skip

    def _goal(self, offset: int, N: int, backward: bool) -> tuple[np.ndarray, np.ndarray]:
        """``(half (N, 6), modes (N,))`` of the tolerant goal at waypoints ``offset ... offset + N`` (reversed on a
        backward chain)."""
        at = slice(offset, offset + N)
        half, modes = self.half[at], self.modes[at]
        if backward:
            half, modes = half[::-1], modes[::-1]
        return np.ascontiguousarray(half), np.ascontiguousarray(modes)

    def tracks(
        self, T, starts, targets, pull, cap, reachable, restarts: int, offset: int = 0, backward: bool = False,
        seed: int | None = None,
    ):  # fmt: skip
        """:func:`nik.paths.kernels.path_chains_toward` along ``T`` from ``starts: (K, dof)``, chain ``c`` drifting
        towards ``targets[c]`` (``pull, cap: (K,)``): ``q (K, N, dof)``, iterations ``(K, N)``, ok ``(K, N)``; with a
        tolerant goal, :func:`~nik.paths.kernels.path_chains_bounded_toward` towards the bounds of waypoints
        ``offset ...`` (``backward``: ``T`` runs from the last of them to the first)."""
        from nik.kernels.lm import seed_state
        from nik.paths.kernels import path_chains_bounded_toward, path_chains_toward

        lm = self.model.lm
        K, n, N = starts.shape[0], starts.shape[1], T.shape[0]
        opts, iopts = lm.options(self.tol_pos, self.tol_rot)
        q = np.empty((K, N, n))
        its, ok = np.empty((K, N), dtype=np.int64), np.empty((K, N), dtype=bool)
        pos, rot = np.empty((K, N)), np.empty((K, N))
        budget = np.where(reachable, restarts, 0).astype(np.int64)
        c = np.ascontiguousarray
        head = (lm.G, lm.joints, c(T), c(starts, dtype=np.float64), c(targets, dtype=np.float64))
        head += (c(pull, dtype=np.float64), c(cap, dtype=np.float64))
        tail = (opts, iopts, budget, seed_state(self.seed if seed is None else seed), q, its, ok, pos, rot)
        if self.half is None:
            path_chains_toward(*head, *tail)
        else:
            path_chains_bounded_toward(*head, *self._goal(offset, N, backward), *tail)
        return q, its, ok


def _q_rest(robot, q_rest) -> np.ndarray:
    """``q_rest`` as ``(dof,)`` float64 (``"mid"``: the middle of the ranges), checked by
    :func:`nik.ik.goals.rest_target` (one posture for the whole path)."""
    from nik.ik.goals import rest_target

    shape = np.shape(q_rest) if not isinstance(q_rest, str | torch.Tensor) else tuple(getattr(q_rest, "shape", ()))
    if not isinstance(q_rest, str) and shape != (robot.dof,):
        raise ValueError(f"q_rest: expected 'mid' or one posture of shape ({robot.dof},) for a path, got {shape}")
    return np.ascontiguousarray(rest_target(robot, q_rest, 1)[0])


def _q_start(robot, model, q_start) -> np.ndarray | None:
    """``q_start`` as ``(dof,)`` float64: one configuration, checked as ``q_near`` is
    (:func:`nik.ik.targets.q_near_array`: finite, degrees warned about), then inside the limits (ValueError naming
    the joint: the arm is there)."""
    if q_start is None:
        return None
    shape = tuple(q_start.shape) if isinstance(q_start, torch.Tensor | np.ndarray) else np.shape(q_start)
    if shape != (robot.dof,):
        raise ValueError(f"q_start: expected shape ({robot.dof},) for {robot.name}, got {shape}")
    q = q_near_array(q_start, 1, robot, name="q_start")[0]
    out = np.nonzero((q < model.lo - 1e-9) | (q > model.hi + 1e-9))[0]
    if out.size:
        j = int(out[0])
        f, unit = (1e3, "mm") if model.prismatic[j] else (180.0 / math.pi, "deg")
        raise ValueError(
            f"q_start: joint {j} ({robot.joint_names[j]}) = {q[j] * f:.6g} {unit} lies outside its limits "
            f"[{model.lo[j] * f:.6g}, {model.hi[j] * f:.6g}] {unit}"
        )
    return np.ascontiguousarray(q)


def _errors(model, Tn: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and rotation (rad) errors of ``q: (N, dof)`` against ``Tn: (N, 4, 4)`` (compiled FK)."""
    from nik.kernels.lm import pose_errors

    pos, rot = np.empty(q.shape[0]), np.empty(q.shape[0])
    pose_errors(model.G, model.joints, Tn, np.ascontiguousarray(q), pos, rot)
    return pos, rot


def _final_check(run: _Run, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(pos (N,), rot (N,), within (N,))`` of ``q`` by FK: with the tolerances, the position error (m), the
    geodesic rotation error (rad) and both within them; with a tolerant goal, the error in each waypoint's tool frame
    (:func:`nik.kernels.lm.bounded_errors`): ``pos`` its position part's norm, ``rot`` its rotation part's norm (with
    a free tool axis, the swing of that axis: the rotation about it does not count), ``within`` every axis inside
    its half-width."""
    if run.half is None:
        pos, rot = _errors(run.model, run.T, q)
        return pos, rot, (pos <= run.tol_pos) & (rot <= run.tol_rot)
    from nik.kernels.lm import bounded_errors

    d = np.empty((q.shape[0], 6))
    bounded_errors(run.model.G, run.model.joints, run.T, np.ascontiguousarray(q), run.modes, d)
    within = (np.abs(d) <= run.half).all(axis=1)
    return np.linalg.norm(d[:, :3], axis=1), np.linalg.norm(d[:, 3:], axis=1), within


def _lm_batch(run: _Run, q0: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LM (no restarts) for waypoints ``rows`` from ``q0: (M, dof)``, towards the call's tolerances or its tolerant
    goal: ``(q (M, dof), iterations (M,), converged (M,))``."""
    lm, T = run.model.lm, np.ascontiguousarray(run.T[rows])
    if run.half is None:
        res = lm.solve(T, q0, tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, restarts=False)
        return res.q, res.iterations, res.converged
    from nik.kernels.lm import lm_solve_bounded, seed_state

    M, n = q0.shape
    opts, iopts = lm.options(run.tol_pos, run.tol_rot)
    q, its, ok = np.empty((M, n)), np.empty(M, dtype=np.int64), np.empty(M, dtype=bool)
    pos, rot = np.empty(M), np.empty(M)
    lm_solve_bounded(
        lm.G, lm.joints, T, np.ascontiguousarray(q0, dtype=np.float64),
        (np.ascontiguousarray(run.half[rows]), np.ascontiguousarray(run.modes[rows])), opts, iopts,
        np.zeros(M, dtype=np.int64), seed_state(run.seed), (q, its, ok, pos, rot),
    )  # fmt: skip
    return q, its, ok


# ---------------------------------------------------------------------------
# closed loops
# ---------------------------------------------------------------------------
def _is_closed(Tn: np.ndarray, tol_pos: float, tol_rot: float) -> bool:
    """True when the last pose of ``Tn: (N, 4, 4)`` equals its first within the tolerances (position, geodesic
    rotation)."""
    a, b = Tn[0], Tn[-1]
    cos = np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) <= tol_pos and math.acos(cos) <= tol_rot)


def _closure(q: np.ndarray, wraps: np.ndarray) -> float:
    """The largest joint difference between the last row of ``q: (N, dof)`` and its first (radians; metres on
    prismatic joints), modulo whole turns on the joints that wrap (their range exceeds a full turn)."""
    d = np.abs(q[-1] - q[0])
    d[wraps] = np.abs(np.remainder(d[wraps] + math.pi, 2 * math.pi) - math.pi)
    return float(d.max())


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


def _time(report: PathReport, robot, q: np.ndarray, timing, vel_limits, acc_limits, success: np.ndarray) -> None:
    """Fills ``report.t``, ``qd``, ``qdd`` and ``timing`` with :func:`nik.paths.timing.time_path` of ``q`` (the robot's
    limits unless given; ``timing`` a dict: its keywords), where the path is whole: every waypoint reached
    (``success: (N,)``) and no step between two waypoints above ``report.max_step`` (the step from ``q_start`` is not
    timed and does not count). A broken path gets no schedule (``t``, ``qd``, ``qdd``, ``timing`` stay None): a
    schedule of a trajectory that misses its poses or jumps is no plan a controller should run; the reason is added
    to ``report.warning``."""
    from nik.paths.timing import time_path

    why = untimed_reason(success, report.reconfigurations.numpy()[1:])
    if why is not None:
        note = f"not timed (res.path.t is None): {why}"
        report.warning = f"{report.warning}; {note}" if report.warning else f"solve_path on {robot.name}: {note}"
        return
    kw = timing if isinstance(timing, dict) else {}
    tm = time_path(q, vel_limits, acc_limits, robot=robot, **kw)
    report.timing = tm
    report.t, report.qd, report.qdd = (torch.from_numpy(np.ascontiguousarray(a)) for a in (tm.t, tm.qd, tm.qdd))


def _chain_from_start(run: _Run) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q (N, dof), iterations (N,), ok (N,))``: the LM chain from ``q0``, each waypoint seeded by the answer before
    (no restarts: a restart could only jump); ``ok`` where it reaches the waypoint inside the limits."""
    q, its, ok = run.chains(run.T, run.q0[None], run.reachable, pull=0.0, restarts=0)
    inside = ((q[0] >= run.model.lo - 1e-9) & (q[0] <= run.model.hi + 1e-9)).all(axis=1)
    return q[0], its[0], ok[0] & inside


def _follows(run: _Run, chain, max_step: float):
    """``(q (N, dof), iterations (N,))`` of the chain from ``q0`` (:func:`_chain_from_start`) when it follows the whole
    path smoothly (:data:`PATH_FOLLOW_STEP`), else None."""
    q, its, ok = chain
    steps = np.abs(np.diff(np.concatenate([run.q0[None], q]), axis=0)).max()
    return (q, its) if ok.all() and steps <= min(PATH_FOLLOW_STEP, max_step) else None


# ---------------------------------------------------------------------------
# arms with a closed form: every branch at every waypoint, the choice by dynamic programming
# ---------------------------------------------------------------------------
def _closed_form_path(run: _Run, closed: bool = False, chain=None, max_step: float = math.inf):
    """``(q (N, 6), iterations (N,), reasons, source)`` of a closed-form arm: the guess stage (every branch of every
    waypoint; with a free tool axis, every branch of every sampled angle: :func:`_branches`; with ``q_start``, the LM
    chain from it as one more candidate on an approximate closed form, ``chain`` of :func:`_chain_from_start`: its
    branches may miss the posture ``q_start`` is in, and the chain keeps it; the first waypoint's candidates within
    ``max_step`` of ``q_start`` only, where there are any: a jump the path cannot avoid comes where it must, not at
    the start), the choice over the whole path (a closed path ends on its start's branch: :func:`_choose`), then the
    refine stage (LM from the chosen branch where it misses the tolerance: an approximate closed form,
    :mod:`nik.ik.model`; LM from the neighbour's answer where no branch serves)."""
    model, Tn, q0 = run.model, run.T, run.q0
    N = Tn.shape[0]
    cand, valid = _branches(run)
    if chain is not None and model.approximate:
        cand = np.ascontiguousarray(np.concatenate([cand, chain[0][:, None]], axis=1))
        valid = np.ascontiguousarray(np.concatenate([valid, chain[2][:, None]], axis=1))
    if q0 is not None:
        d = np.abs(cand[0] - q0)
        d[:, model.wraps] = np.abs(np.remainder(d[:, model.wraps] + math.pi, 2 * math.pi) - math.pi)
        near = valid[0] & (d.max(axis=1) <= max_step)
        if near.any():
            valid = valid.copy()
            valid[0] = near
    wraps = model.wraps
    choice = _choose(cand, valid, wraps, q0, closed)
    have = choice >= 0
    its = np.zeros(N, dtype=np.int64)
    if not have.any() and run.refine:  # no waypoint has a valid branch: LM along the path from q_start or a start
        first = _first_answer(run)
        q, its, _ = run.chains(Tn, first[None], run.reachable, pull=0.0, restarts=0)
        q, its = q[0], its[0]
    elif not have.any():  # refine="none": the clamped branch nearest each pose (nik.kernels.closed.pick)
        q = _nearest_clamped(model, Tn, cand)
    else:
        q = cand[np.arange(N), np.maximum(choice, 0)]
        if wraps.any():
            q, fits = _unwrap(q, have, wraps, q0, model.lo, model.hi)
            if not fits:  # some run cannot stay inside its limits: choose the whole turns with the branches
                q = _with_turns(cand, valid, have, wraps, q0, model.lo, model.hi)
        if run.refine:
            q, its = _polish(run, q, have)
            if not have.all():
                q, its = _fill_gaps(run, q, its, have)
        elif not have.all():
            gaps = np.nonzero(~have)[0]
            q[gaps] = _nearest_clamped(model, Tn[gaps], cand[gaps])
    reasons = [""] * N
    for i in np.nonzero(~have)[0]:
        reasons[i] = _closed_form_reason(run, i, cand[i])
    return q, its, reasons, "analytic"


def _branches(run: _Run) -> tuple[np.ndarray, np.ndarray]:
    """``(cand (N, K, 6), valid (N, K))``: the closed form's branches of every waypoint, valid where inside the limits
    and within the call's tolerance by FK (an approximate closed form: within the model's check, the one policy of
    :mod:`nik.ik.model`; LM then polishes what misses the call's tolerance). With one free tool axis (a tolerant
    goal, :mod:`nik.ik.bounds`) the branches of every sampled angle about it (:mod:`nik.ik.free_axis`'s sampling:
    evenly from 0, :func:`_free_samples` of them), checked at the goal's tightest half-widths, the valid ones first
    (K: the most any waypoint has)."""
    model, Tn = run.model, run.T
    tol = () if model.approximate else (run.tol_pos, run.tol_rot)
    if run.half is None or not set(run.modes.tolist()) <= {0, 1, 2}:
        return model.closed_solutions(Tn, *tol)
    N, S = Tn.shape[0], _free_samples(Tn.shape[0])
    gamma = 2.0 * math.pi * np.arange(S) / S
    gamma = np.where(gamma > math.pi, gamma - 2.0 * math.pi, gamma)
    c, s = np.cos(gamma), np.sin(gamma)
    R = np.zeros((N, S, 4, 4))
    R[..., 3, 3] = 1.0
    for k in range(3):  # the rotation about each waypoint's free axis k
        at = run.modes == k
        i, j = (k + 1) % 3, (k + 2) % 3
        R[at, :, k, k] = 1.0
        R[at, :, i, i], R[at, :, i, j], R[at, :, j, i], R[at, :, j, j] = c, -s, s, c
    Tm = np.ascontiguousarray((Tn[:, None] @ R).reshape(N * S, 4, 4))
    if not model.approximate:
        rot = run.half[:, 3:]
        tol = (float(run.half[:, :3].min()), float(rot[np.isfinite(rot)].min()))
    cand, valid = model.closed_solutions(Tm, *tol)
    cand, valid = cand.reshape(N, S * 8, -1), valid.reshape(N, S * 8)
    order = np.argsort(~valid, axis=1, kind="stable")[:, : max(int(valid.sum(axis=1).max()), 1)]
    cand = np.ascontiguousarray(np.take_along_axis(cand, order[..., None], axis=1))
    return cand, np.ascontiguousarray(np.take_along_axis(valid, order, axis=1))


def _free_samples(N: int) -> int:
    """Angles sampled about a free tool axis on a path of ``N`` waypoints: 36 (every 10 degrees, as
    :func:`nik.ik.free_axis.closed_form_free_axis`), fewer on long paths so that the dynamic programming's
    ``(N, K, K)`` tables (``K = 8`` per angle) stay within :data:`PATH_DP_CELLS` (at least 4)."""
    return int(np.clip(math.isqrt(PATH_DP_CELLS // N) // 8, 4, 36))


def _choose(cand, valid, wraps, q0, closed: bool, close_within: float = PATH_DEDUPE, tries: int = PATH_CLOSED_STARTS):
    """``choice (N,)``: :func:`nik.paths.kernels.path_dp` over the candidates; on a closed path, the choice that
    ends on its start's branch (the last waypoint's candidate nearest the first's, modulo whole turns on the joints
    that wrap): when the free choice does not, each distinct start candidate (at most ``tries``) is tried
    with the end pinned to its match, and the least-motion sequence (largest step, then sum of squared steps) is
    kept (with ``q0``, the step from it counted)."""
    from nik.paths.kernels import path_dp

    N = cand.shape[0]
    choice = np.empty(N, dtype=np.int64)
    start = np.zeros(cand.shape[2]) if q0 is None else q0
    path_dp(cand, valid, wraps, start, q0 is not None, 1e-9, choice)
    if not closed or choice[0] < 0 or choice[-1] < 0:
        return choice
    if _closure(cand[[0, -1], choice[[0, -1]]], wraps) <= PATH_DEDUPE:
        return choice
    first = [int(choice[0])] + [int(k) for k in np.nonzero(valid[0])[0] if k != choice[0]]
    tried: list[int] = []  # distinct start candidates only (tracks from q_start start alike)
    for k in first:
        if len(tried) < tries and all(np.abs(cand[0, k] - cand[0, t]).max() > PATH_DEDUPE for t in tried):
            tried.append(k)
    best, best_cost = choice, (math.inf, math.inf)
    for k in tried:
        d = np.abs(cand[-1] - cand[0, k])  # _closure of each last candidate against start k
        d[:, wraps] = np.abs(np.remainder(d[:, wraps] + math.pi, 2 * math.pi) - math.pi)
        gap = d.max(axis=1)
        gap[~valid[-1]] = math.inf
        end = int(np.argmin(gap))
        if gap[end] > close_within:
            continue
        pinned = valid.copy()
        pinned[0], pinned[-1] = False, False
        pinned[0, k], pinned[-1, end] = True, True
        c = np.empty(N, dtype=np.int64)
        path_dp(cand, pinned, wraps, start, q0 is not None, 1e-9, c)
        if (c < 0).any() and not ((c < 0) == (choice < 0)).all():
            continue
        seq = cand[np.nonzero(c >= 0)[0], c[c >= 0]]
        if q0 is not None:  # the step from q_start counts: a start on another branch is a jump
            seq = np.concatenate([q0[None], seq])
        d = np.abs(np.diff(seq, axis=0))
        d[:, wraps] = np.abs(np.remainder(d[:, wraps] + math.pi, 2 * math.pi) - math.pi)
        steps = d.max(axis=1) if d.size else np.zeros(1)
        cost = (float(steps.max()), float((steps**2).sum()))
        if cost < best_cost:
            best, best_cost = c, cost
    return best


def _nearest_clamped(model, T: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """``(B, 6)``: per pose of ``T: (B, 4, 4)``, the branch of ``cand: (B, 8, 6)`` that comes nearest it once clamped
    into the limits (the closed form's one rule for a pose no branch reaches: :func:`nik.kernels.closed.pick`)."""
    from nik.ik.guesses import LIMIT_ROUNDING
    from nik.kernels.closed import pick

    out = np.empty((T.shape[0], cand.shape[2]))
    none = np.zeros((T.shape[0], 8), dtype=bool)
    T, near = np.ascontiguousarray(T), np.zeros_like(out)
    pick(np.ascontiguousarray(cand), none, model.G, model.joints, T, near, False, LIMIT_ROUNDING, out)
    return out


def _polish(run: _Run, q: np.ndarray, have: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The refine stage on the chosen branches: LM (no restarts) from each one that misses the call's tolerance (an
    approximate closed form's branch, checked at :data:`nik.ik.model.APPROXIMATE_CHECK_TOL`), kept where better."""
    its = np.zeros(q.shape[0], dtype=np.int64)
    if not run.model.approximate or run.half is not None:  # a tolerant goal: its branches are checked as they are
        return q, its
    pos, rot = _errors(run.model, run.T, q)
    idx = np.nonzero(have & ((pos > run.tol_pos) | (rot > run.tol_rot)))[0]
    if idx.size:
        res = run.model.lm.solve(
            run.T[idx], q[idx], tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, restarts=False
        )
        better = score(res.pos_err, res.rot_err) <= score(pos[idx], rot[idx])
        q = q.copy()
        q[idx[better]] = res.q[better]
        its[idx] = res.iterations
    return q, its


def _closed_form_reason(run: _Run, i: int, cand_i: np.ndarray) -> str:
    """Why no branch serves waypoint ``i``: some reaches the pose outside the limits, or none reaches it at all."""
    if not run.reachable[i]:
        return "out of reach"
    Ti = np.repeat(run.T[i][None], cand_i.shape[0], axis=0)
    pos, rot = _errors(run.model, Ti, cand_i)  # the branches before the limits
    near = bool(((pos <= run.tol_pos) & (rot <= run.tol_rot)).any())
    return "beyond a joint limit on every branch" if near else "out of reach"


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

    from nik.paths.kernels import path_dp

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


def _fill_gaps(run: _Run, q: np.ndarray, its: np.ndarray, have: np.ndarray):
    """Waypoints without a valid branch: LM seeded by the answer next to them (the previous one; for a leading
    gap, the first waypoint that has a branch, walking back), uniform restarts only with ``fallback="multistart"``
    (the closed form found no solution there: a restart could only jump). Their best effort, flagged by the final
    check."""
    N, Tn, reachable = q.shape[0], run.T, run.reachable
    kw = {"pull": 0.0, "restarts": run.restarts}
    its = its.copy()
    first = int(np.argmax(have))
    for i in range(first - 1, -1, -1):  # a leading gap, walking back from the first solved waypoint
        qi, it, _ = run.chains(Tn[i : i + 1], q[i + 1][None], reachable[i : i + 1], offset=i, **kw)
        q[i], its[i] = qi[0, 0], it[0, 0]
    i = first + 1
    while i < N:  # the other gaps, each run of missing waypoints in one compiled chain
        if have[i]:
            i += 1
            continue
        j = i
        while j < N and not have[j]:
            j += 1
        qi, it, _ = run.chains(Tn[i:j], q[i - 1][None], reachable[i:j], seed=run.seed + i, offset=i, **kw)
        q[i:j], its[i:j] = qi[0], it[0]
        i = j
    return q, its


# ---------------------------------------------------------------------------
# other arms: LM chains seeded by the predecessor, the choice over the whole path
# ---------------------------------------------------------------------------
def _first_answer(run: _Run) -> np.ndarray:
    """A start for a single chain: ``q0``, else LM from uniform starts at the first waypoint."""
    if run.q0 is not None:
        return run.q0
    res = run.model.lm.solve(
        run.T[:1], None, tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, reachable=run.reachable[:1]
    )
    return res.q[0]


def _chain_path(run: _Run):
    """``(q (N, dof), iterations (N,), source)`` of an arm without a closed form: chains of LM from the start
    postures (candidates at every waypoint: each chain's answer), the choice over the whole path by
    :func:`nik.paths.kernels.path_dp` over those candidates."""
    from nik.paths.kernels import path_dp

    pull = PATH_PULL if run.model.dof > 6 else 0.0
    kw = {"pull": pull, "restarts": run.restarts}
    if run.q0 is not None:
        q, its, _ = run.chains(run.T, run.q0[None], run.reachable, **kw)
        return q[0], its[0], "q_start"
    starts, sources = _start_postures(run)
    if run.rest is not None:  # the start nearest q_rest first
        order = np.argsort(np.abs(starts - run.rest).max(axis=1), kind="stable")
        starts, sources = starts[order], [sources[i] for i in order]
    q, its, ok = run.chains(run.T, starts, run.reachable, **kw)
    if q.shape[0] == 1:
        return q[0], its[0], sources[0]
    N = run.T.shape[0]
    cand = np.ascontiguousarray(q.transpose(1, 0, 2))  # (N, K, dof): every chain's answer at every waypoint
    choice = np.empty(N, dtype=np.int64)
    path_dp(cand, np.ascontiguousarray(ok.T), run.model.wraps, np.zeros(run.model.dof), False, 1e-9, choice)
    if (choice < 0).all():  # no chain reaches any waypoint: the chain with the least largest step
        steps = np.abs(np.diff(q, axis=1)).max(axis=(1, 2))
        best = int(np.argmin(steps))
        return q[best], its[best], sources[best]
    chosen = np.nonzero(choice >= 0)[0]
    for i in np.nonzero(choice < 0)[0]:  # a waypoint no chain reaches: the chain chosen before it continues
        before = chosen[chosen < i]
        choice[i] = choice[before[-1]] if before.size else choice[chosen[0]]
    rows = np.arange(N)
    return q[choice, rows], its[choice, rows], sources[int(choice[0])]


def _smooth(run: _Run, q: np.ndarray, max_step: float, closed: bool, col=None) -> bool:
    """Whether the chain's answer ``q: (N, dof)`` needs no search: every waypoint reached inside the limits, no step
    (from ``q0`` on) above :data:`SEARCH_TRIGGER` nor ``max_step``, a closed path's last row within ``max_step``
    of its first (:func:`_close_loop` closes the rest) and, with ``col`` (the collision arrays of
    :mod:`nik.ik.collide`), no waypoint colliding."""
    _, _, within = _final_check(run, q)
    if col is not None:
        within &= ~_colliding(run.model, q, col)
    inside = ((q >= run.model.lo - 1e-9) & (q <= run.model.hi + 1e-9)).all()
    _, _, step = _path_cost(q, within, run.q0)
    closes = not closed or _closure(q, run.model.wraps) <= max_step
    return bool(within.all() and inside and closes and step <= min(SEARCH_TRIGGER, max_step))


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


def _colliding(model, q: np.ndarray, col) -> np.ndarray:
    """``(...)`` bool: configurations of ``q: (..., dof)`` that collide (the sphere check, margin 0)."""
    from nik.kernels.collision import collides_batch

    flat = np.ascontiguousarray(q.reshape(-1, q.shape[-1]), dtype=np.float64)
    hit = np.empty(flat.shape[0], dtype=bool)
    collides_batch(model.G, model.joints, flat, *col, 0.0, hit)
    return hit.reshape(q.shape[:-1])


def _search_path(run: _Run, max_step: float, closed: bool, chain, rest: np.ndarray | None = None, col=None):
    """``(q (N, dof), iterations (N,), source)``: the global search of an arm without a closed form (module
    docstring, "global search"). Tracks: LM chains (:func:`nik.paths.kernels.path_chains_toward`) from ``q0`` (else
    from every distinct start posture, :func:`_start_postures`), each drifting along the self-motion towards a
    posture of its own: the middle of the ranges (the plain chain, :func:`_chain_path`'s), its own start, no
    posture, ``rest`` (``q_rest``), and the network's hypotheses (else uniform LM answers) at the middle and the last
    waypoint. Every track's answer at every waypoint is a candidate (among obstacles, ``col``: the collision arrays of
    :mod:`nik.ik.collide`, one that collides is not); :func:`_choose` picks the sequence with the
    smallest largest step, then the least sum of squared steps (from ``q0``; on a closed path, ending next to its
    first row, within ``max_step``), switching tracks where they meet. Kept over ``chain`` (``(q, iterations, source)``
    of :func:`_chain_path`) and the plain chains unless one of them reaches more waypoints, closes where the search
    does not, or has the smaller largest step (by :data:`SEARCH_GAIN`: the search never answers worse than the
    chain)."""
    model, N = run.model, run.T.shape[0]
    if run.q0 is not None:
        starts, sources = run.q0[None], ["q_start"]
    else:
        starts, sources = _start_postures(run)
    extra = ()
    if col is not None:  # the stretch the chain collides on: its ends are anchors
        hit = np.nonzero(_colliding(model, chain[0], col))[0]
        extra = (int(hit[0]), int(hit[-1])) if hit.size else ()
    postures = _search_postures(run, rest, col, extra)
    mid = 0.5 * (model.lo + model.hi)
    K0 = starts.shape[0]
    plain = mid if rest is None else rest
    tracks = [(k, plain, PATH_PULL, PATH_PULL_CAP) for k in range(K0)]  # track k < K0: start k's plain chain
    for k in range(K0):
        for target, pull in [(starts[k], SEARCH_PULL), (mid, 0.0), *((p, SEARCH_PULL) for p in postures)]:
            tracks.append((k, target, pull, SEARCH_PULL_CAP))
        if col is not None:
            tracks += [(k, p, SEARCH_FAST_PULL, SEARCH_FAST_CAP) for p in postures]
    of = np.array([t[0] for t in tracks])
    q, its, ok = run.tracks(
        run.T, starts[of], np.array([t[1] for t in tracks]), np.array([t[2] for t in tracks]),
        np.array([t[3] for t in tracks]), run.reachable, run.restarts,
    )  # fmt: skip
    # backward tracks, from the last waypoint to the first: from the postures (and, on a closed path, from the start
    # postures, which answer its last pose too), drifting towards the middle of the ranges or their own start
    back = [*(starts if closed else []), *postures]
    if back:
        b_starts = np.repeat(np.array(back), 2, axis=0)
        b_targets = np.stack([x for p in back for x in (mid, p)])
        b_pull = np.tile([PATH_PULL, SEARCH_PULL], len(back))
        b_cap = np.tile([PATH_PULL_CAP, SEARCH_PULL_CAP], len(back))
        if col is not None and closed:  # a loop's way back to its start: fast tracks from it towards the postures
            fast = [(k, p) for k in range(K0) for p in postures]
            b_starts = np.concatenate([b_starts, starts[[k for k, _ in fast]]]) if fast else b_starts
            b_targets = np.concatenate([b_targets, np.array([p for _, p in fast])]) if fast else b_targets
            b_pull = np.concatenate([b_pull, np.full(len(fast), SEARCH_FAST_PULL)])
            b_cap = np.concatenate([b_cap, np.full(len(fast), SEARCH_FAST_CAP)])
        qb, itsb, okb = run.tracks(
            run.T[::-1], b_starts, b_targets, b_pull, b_cap, run.reachable[::-1], run.restarts, backward=True
        )
        q = np.concatenate([q, qb[:, ::-1]])
        its, ok = np.concatenate([its, itsb[:, ::-1]]), np.concatenate([ok, okb[:, ::-1]])
        of = np.concatenate([of, np.full(len(b_starts), -1)])
    inside = ((q >= model.lo - 1e-9) & (q <= model.hi + 1e-9)).all(axis=-1)
    ok = ok & inside
    if col is not None:  # among obstacles: a colliding answer is no candidate
        ok &= ~_colliding(model, q, col)
    cand = np.ascontiguousarray(q.transpose(1, 0, 2))  # (N, K, dof): every track's answer at every waypoint
    valid = np.ascontiguousarray(ok.T)
    if run.q0 is not None:
        near = valid[0] & (np.abs(cand[0] - run.q0).max(axis=1) <= max_step)
        if near.any():
            valid[0] = near
    raw = np.zeros_like(model.wraps)  # real joint motion: tracks are continuous in the joints' own values
    choice = _choose(cand, valid, raw, run.q0, closed, close_within=max_step, tries=SEARCH_CLOSED_STARTS)
    if (choice < 0).all():
        return chain
    if col is not None:
        choice = _free_steps(run, cand, valid, raw, closed, max_step, col, choice)
    chosen = np.nonzero(choice >= 0)[0]
    for i in np.nonzero(choice < 0)[0]:  # a waypoint no track reaches: the track chosen before it continues
        before = chosen[chosen < i]
        choice[i] = choice[before[-1]] if before.size else choice[chosen[0]]
    rows = np.arange(N)
    found, found_its = cand[rows, choice], its.T[rows, choice]
    wraps = raw if closed else None
    c_ok = _final_check(run, chain[0])[2] & ((chain[0] >= model.lo - 1e-9) & (chain[0] <= model.hi + 1e-9)).all(axis=1)
    if col is not None:
        c_ok &= ~_colliding(model, chain[0], col)
    c_ok &= ~jumps(chain[0], c_ok, max_step)  # a waypoint reached only by a jump is missed (the report's rule)
    s_ok = ok.T[rows, choice]
    s_ok &= ~jumps(found, s_ok, max_step)
    c_cost = _path_cost(chain[0], c_ok, run.q0, wraps, max_step)
    s_cost = _path_cost(found, s_ok, run.q0, wraps, max_step)
    if c_cost[:2] < s_cost[:2] or (c_cost[:2] == s_cost[:2] and s_cost[2] > c_cost[2] - SEARCH_GAIN):
        return chain
    return found, found_its, sources[int(of[choice[0]])] if of[choice[0]] >= 0 else "search"


def _free_steps(run: _Run, cand, valid, raw, closed: bool, max_step: float, col, choice: np.ndarray) -> np.ndarray:
    """``choice (N,)`` of the search among obstacles with no step that collides inside (the dynamic programming
    judges the candidates, each one free, not the motion between two of them: a switch between tracks may cross the
    obstacle): up to :data:`SEARCH_RECHOOSE` times, the candidate each colliding step leads to is no candidate and the
    choice is made again; the first choice whose motion is free (else the one with the fewest colliding steps)."""
    from nik.paths.trajopt import TrajCfg, path_collisions

    N = cand.shape[0]
    valid = valid.copy()
    best, fewest = choice, None
    for _ in range(SEARCH_RECHOOSE + 1):
        if (choice < 0).any():
            break
        between = path_collisions(run.model, cand[np.arange(N), choice], run.q0, col, TrajCfg.col_sub)[1]
        n = int(between.sum())
        if fewest is None or n < fewest:
            best, fewest = choice, n
        if n == 0:
            break
        bad = np.nonzero(between)[0]
        valid[bad, choice[bad]] = False
        choice = _choose(cand, valid, raw, run.q0, closed, close_within=max_step, tries=SEARCH_CLOSED_STARTS)
    return best


def _path_cost(q: np.ndarray, ok: np.ndarray, q0: np.ndarray | None, wraps=None, within: float = 0.0) -> tuple:
    """``(waypoints missed, open, largest step)`` of a path ``q: (N, dof)`` (the first step from ``q0`` where given;
    ``open``: with ``wraps``, a closed path whose last row is more than ``within`` from its first, else 0): the order
    in which the search and the plain chain are compared."""
    full = q if q0 is None else np.concatenate([q0[None], q])
    step = float(np.abs(np.diff(full, axis=0)).max()) if full.shape[0] > 1 else 0.0
    gap = 0 if wraps is None else int(_closure(q, wraps) > within)
    return int((~ok).sum()), gap, round(step, 9)


def _search_postures(run: _Run, rest: np.ndarray | None, col=None, extra=()) -> list[np.ndarray]:
    """The postures the search's tracks drift towards (beside the middle of the ranges and their own start): ``rest``,
    then distinct answers at the middle and the last waypoint: the network's hypotheses there (ranked by FK,
    :data:`SEARCH_HYPOTHESES` per waypoint) where the plan has a network, else LM from uniform starts. Among obstacles
    (``col``: the collision arrays of :mod:`nik.ik.collide`), at the waypoints ``extra`` (where the chain starts and
    stops colliding: the stretch to go round) and at :data:`SEARCH_ANCHORS`: the network's hypotheses and LM's
    answers from uniform starts side by side (:data:`SEARCH_HYPOTHESES` of each: the network adds postures, it
    replaces none), those that collide left out."""
    out = [] if rest is None else [np.asarray(rest, dtype=np.float64)]
    N = run.T.shape[0]
    anchors = {N // 2, N - 1} if col is None else {int(f * (N - 1)) for f in SEARCH_ANCHORS}
    at = np.array([*dict.fromkeys([*extra, *sorted(anchors)])])
    hyp = _hypotheses(run, at)
    if hyp is not None:
        hyp = hyp[:, :SEARCH_HYPOTHESES]
    if hyp is None or col is not None:  # among obstacles the network's and LM's, side by side
        lm = run.model.lm
        T = np.repeat(run.T[at], SEARCH_HYPOTHESES, axis=0)
        res = lm.solve(T, None, tol_pos=run.tol_pos, tol_rot=run.tol_rot, seed=run.seed, restarts=False)
        uni = res.q.reshape(at.size, SEARCH_HYPOTHESES, -1)
        hyp = uni if hyp is None else np.concatenate([hyp, uni], axis=1)
    free = np.ones(hyp.shape[:2], dtype=bool)
    if col is not None:  # the collision check inside the limits
        hyp = np.clip(hyp, run.model.lo, run.model.hi)
        free = ~_colliding(run.model, hyp, col)
    for h, f in zip(hyp, free, strict=True):
        for p in h[f]:
            if all(np.abs(p - o).max() > SEARCH_DISTINCT for o in out):
                out.append(p)
    return out


def _start_postures(run: _Run) -> tuple[np.ndarray, list[str]]:
    """Distinct solutions of the first waypoint: ``(K, dof)`` and where each came from (``network`` for the
    network's hypotheses, the guess stage's packed network, polished by LM; ``multistart`` for LM from uniform
    starts)."""
    lm, T0, tol = run.model.lm, run.T[:1], {"tol_pos": run.tol_pos, "tol_rot": run.tol_rot, "seed": run.seed}
    seeds, sources = [], []
    hyp = _hypotheses(run)
    if hyp is not None:
        hyp = hyp[0]
        seeds.append(hyp)
        sources += ["network"] * hyp.shape[0]
    uni = lm.solve(np.repeat(T0, PATH_STARTS, axis=0), None, restarts=False, **tol)
    seeds.append(uni.q)
    sources += ["multistart"] * PATH_STARTS
    seeds = np.concatenate(seeds)
    res = lm.solve(np.repeat(T0, seeds.shape[0], axis=0), seeds, restarts=False, **tol)
    order = np.argsort(~res.converged, kind="stable")  # reached ones first, network before uniform
    q = res.q[order]
    close = np.abs(q[:, None] - q[None]).max(axis=-1) <= PATH_DEDUPE  # (K, K)
    kept = order[~np.triu(close, k=1).any(axis=0)]  # drop each answer close to an earlier one
    return res.q[kept], [sources[i] for i in kept]


def _hypotheses(run: _Run, rows=None) -> np.ndarray | None:
    """``(len(rows), K, dof)`` the plan's network's hypotheses for the waypoints ``rows`` (default the first), ranked
    by FK: the compiled backend's guess stage (the packed network, targets in the arm's frame where the network was
    made for the bare arm), or None where the plan has no network."""
    if run.plan.net is None:
        return None
    from nik.ik.backends import Job, compiled_backend

    rows = np.array([0]) if rows is None else rows
    be, m, T = compiled_backend(), run.model, np.ascontiguousarray(run.T[rows])
    job = Job(be, m.robot, T, run.reachable[rows], None, run.tol_pos, run.tol_rot, torch.float64, model=m)
    return np.ascontiguousarray(be.network(run.plan, job)[0])


# ---------------------------------------------------------------------------
# the report
# ---------------------------------------------------------------------------
#: ``res.path.reasons`` of a waypoint reached (by FK) only by a step above ``max_step`` from a reached waypoint.
JUMP_REASON = "reached only by a step above max_step from the waypoint before"


def jumps(q: np.ndarray, reached: np.ndarray, max_step: float) -> np.ndarray:
    """``(N,)`` bool: waypoint ``i`` of ``q: (N, dof)`` is reached (``reached[i]``, by FK) and so is waypoint ``i - 1``,
    but the step between them (largest joint motion, joints' own values) is above ``max_step``: the arm gets there only
    by a reconfiguration, so ``i`` counts as not reached (its reason :data:`JUMP_REASON`). Judged on the flags as given
    (no cascade): the waypoint after a jump, reached by a small step from it, stays reached. The step from ``q_start``
    into waypoint 0 is no step between waypoints (warned about, not flagged)."""
    out = np.zeros(q.shape[0], dtype=bool)
    if q.shape[0] > 1:
        out[1:] = reached[1:] & reached[:-1] & (np.abs(np.diff(q, axis=0)).max(axis=1) > max_step)
    return out


def untimed_reason(success: np.ndarray, reconf: np.ndarray) -> str | None:
    """Why a path is not timed (``success: (N,)`` per waypoint, ``reconf``: steps between waypoints above
    ``max_step``), in a few words, or None where it is whole."""
    miss, big = int((~success).sum()), int(reconf.sum())
    if not miss and not big:
        return None
    parts = [f"{miss} waypoint(s) not reached (first: {int(np.argmin(success))})"] if miss else []
    parts += [f"{big} step(s) between waypoints above max_step"] if big else []
    return " and ".join(parts)


def open_note(gap: float, max_step: float) -> str:
    """The warning's words for a loop left open: its last row is ``gap`` (radians) from its first."""
    return (
        f"the loop is left open (res.path.closed False): its last row is {math.degrees(gap):.1f} deg from its first "
        f"and it closes only by a step above max_step ({math.degrees(max_step):.1f} deg)"
    )


def _report(robot, q, q0, success, reasons, max_step, reach_note=None) -> PathReport:
    """Steps, the largest one and where, reconfigurations, and the warning about the first problem (with the reach
    bound's line, ``reach_note``, where waypoints lie provably out of reach)."""
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
        if reasons[i] and reasons[i] != JUMP_REASON:
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
                + (" and counts as not reached" if reasons[i] == JUMP_REASON else "")
            )
        warning = (
            f"solve_path on {robot.name}: {what}; {n_fail} waypoint(s) not reached, {int(reconf.sum())} step(s) above "
            f"max_step, largest step {steps[at] * (180.0 / math.pi):.1f} deg into waypoint {at}"
        )
        if reach_note is not None:
            warning += f"; {reach_note}"
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
