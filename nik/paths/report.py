"""The report of a path (:class:`nik.ik.result.PathReport`): the reason per waypoint not reached, every step, the
jumps between reached waypoints, the warning, and the timing of the answer (TOPP-RA) where the path is whole."""

from __future__ import annotations

import math

import numpy as np
import torch

from nik.ik.result import PathReport

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
