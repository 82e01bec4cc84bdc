"""``nik path``: a CSV of waypoints in, a joint trajectory CSV (and a picture) out; the work is
:meth:`nik.IKSolver.solve_path`."""

from __future__ import annotations

import csv
import math
import os
import sys
import warnings
from pathlib import Path

from nik.cli.common import add_robot_arguments, robot_from_args, tool_link_text
from nik.cli.scene import add_scene_argument, world_from_args
from nik.cli.solve import _units, read_poses_csv
from nik.tolerances import DEFAULT_TOL_POS_MM, DEFAULT_TOL_ROT_DEG, describe

__all__ = ["plot_trajectory", "register", "write_trajectory_csv"]

#: Default of ``--max-step-deg`` (the reconfiguration threshold of :data:`nik.paths.solve.PATH_MAX_STEP`).
MAX_STEP_DEG = 10.0


def register(sub) -> None:
    p = sub.add_parser(
        "path",
        help="one continuous joint trajectory through a CSV of waypoints (a Cartesian path)",
        description="Joint angles for every waypoint of a Cartesian path, in order, moving the arm continuously: "
        "the IK branch (or posture) of the whole path is chosen at once, so that no step jumps to another "
        "configuration half-way. Writes the trajectory as CSV (degrees, a column per joint; prismatic joints in mm) "
        "and prints the largest step and where it is. Exit status: 0 when every waypoint was reached within "
        "tolerance, 1 when some was not, 2 on an error.",
    )
    add_robot_arguments(p)
    p.add_argument("--poses", required=True, metavar="FILE.csv", help="waypoints in order, header x,y,z,qw,qx,qy,qz")
    p.add_argument("--unit", choices=["m", "mm"], default="m", help="unit of the input positions (default m)")
    p.add_argument(
        "--q-start",
        nargs="+",
        type=float,
        metavar="DEG",
        help="the joints before the path, degrees (prismatic joints: mm): the trajectory starts nearest them; "
        "default: the start that keeps the whole path continuous with the least joint motion",
    )
    p.add_argument("--out", metavar="FILE.csv", help="write the trajectory as CSV (header included)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the joints against the waypoint index (needs matplotlib)")
    p.add_argument("--tol-mm", type=float, default=DEFAULT_TOL_POS_MM, help="position tolerance, mm (default 0.1)")
    p.add_argument("--tol-deg", type=float, default=DEFAULT_TOL_ROT_DEG, help="rotation tolerance, deg (default 0.1)")
    p.add_argument(
        "--max-step-deg",
        type=float,
        default=MAX_STEP_DEG,
        help=f"a step above this joint motion is reported as a reconfiguration (default {MAX_STEP_DEG:g} deg)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    add_scene_argument(p)
    p.add_argument(
        "--timing",
        action="store_true",
        help="time the trajectory within the robot's joint speed and acceleration limits (toppra, the 'timing' "
        "extra): writes a t_s column (seconds); with --plot, positions and velocities against time. A broken path (a "
        "waypoint not reached, a step above --max-step-deg) is not timed: the warning says why, no t_s column, exit 1",
    )
    p.add_argument("--vel-scale", type=float, default=1.0, metavar="S", help="with --timing: fraction (0, 1] of the "
                   "speed limits (default 1)")  # fmt: skip
    p.add_argument("--acc-scale", type=float, default=1.0, metavar="S", help="with --timing: fraction (0, 1] of the "
                   "acceleration limits (default 1)")  # fmt: skip
    p.add_argument("--free-axis", action="append", metavar="x|y|z", help="rotation about this tool axis free at "
                   "every waypoint (the path uses the freedom for the least joint motion)")  # fmt: skip
    p.add_argument("--open", action="store_true", help="a path whose last pose equals its first is closed (its last "
                   "row of joints equals the first) unless this is given")  # fmt: skip
    p.set_defaults(func=_cmd_path)


def _cmd_path(args) -> int:
    import torch

    from nik.solver import IKSolver

    robot = robot_from_args(args)
    poses = read_poses_csv(args.poses)
    if args.unit == "mm":
        poses[:, :3] *= 1e-3
    if not (args.tol_mm > 0 and args.tol_deg > 0 and args.max_step_deg > 0):
        raise ValueError(
            f"--tol-mm, --tol-deg and --max-step-deg must be > 0, got {args.tol_mm}, {args.tol_deg}, "
            f"{args.max_step_deg}"
        )
    from nik.ik.bounds import bounds_from_cli
    from nik.paths.timing import check_scale

    timing = False
    if args.timing:
        timing = {"vel_scale": check_scale(args.vel_scale, "--vel-scale"),
                  "acc_scale": check_scale(args.acc_scale, "--acc-scale")}  # fmt: skip
        if robot.vel_limits is None:
            raise ValueError(f"--timing: {robot.name} has no joint speed limits (give them in its URDF or YAML)")
    elif args.vel_scale != 1.0 or args.acc_scale != 1.0:
        raise ValueError("--vel-scale and --acc-scale need --timing")
    tol_pos, tol_rot = args.tol_mm * 1e-3, math.radians(args.tol_deg)
    bounds = bounds_from_cli(free_axis=args.free_axis, tol_pos=tol_pos, tol_rot=tol_rot)
    _, shown, factor = _units(robot.prismatic.tolist(), robot.dof)
    q_start = None
    if args.q_start is not None:
        if len(args.q_start) != robot.dof:
            raise ValueError(f"--q-start: {robot.name} has {robot.dof} joints, got {len(args.q_start)} values")
        q_start = torch.tensor([v / f for v, f in zip(args.q_start, factor, strict=True)], dtype=torch.float64)
    solver = IKSolver(robot, world=world_from_args(args))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        res = solver.solve_path(
            poses,
            q_start,
            tol_pos=tol_pos,
            tol_rot=tol_rot,
            seed=args.seed,
            representation="quat",
            max_step=math.radians(args.max_step_deg),
            closed=False if args.open else None,
            timing=timing,
            bounds=bounds,
        )
    for w in caught:
        if issubclass(w.category, UserWarning):
            print(f"nik path: warning: {w.message}", file=sys.stderr)
    if res.path.timing is not None and res.path.timing.acc_assumed:
        from nik.paths.timing import DEFAULT_ACC_PER_VEL

        print(
            f"nik path: note: {robot.name} has no joint acceleration limits: assumed {DEFAULT_ACC_PER_VEL:g}x its "
            "speed limits (full speed within 0.1 s; give acc limits in its URDF or YAML)",
            file=sys.stderr,
        )
    if args.out:
        write_trajectory_csv(args.out, robot, res, q_start)
    if args.plot and res.path.timing is not None:
        from nik.view.timing_plot import plot_timing

        plot_timing(robot, res.path.timing, args.plot)
    elif args.plot:
        plot_trajectory(args.plot, robot, res)
    rep = res.path
    j = rep.largest_step_joint
    ok = int(res.success.sum())
    wrote = ", ".join(str(x) for x in (args.out, args.plot) if x)
    print(
        f"reached {ok} of {len(res)} waypoints within "
        f"{bounds.describe() if bounds is not None else describe(tol_pos, tol_rot)} "
        f"({robot.name}{tool_link_text(robot)}, start: {res.source}); largest step {rep.largest_step * factor[j]:.3g} "
        f"{shown[j]} (joint {j}, {robot.joint_names[j]}) into waypoint {rep.largest_step_at}; "
        f"{int(rep.reconfigurations.sum())} step(s) above {args.max_step_deg:g} deg"
        + (f"; closed loop, last row vs first {math.degrees(rep.closure):.3g} deg" if rep.closed else "")
        + (f"; duration {rep.timing.duration:.3f} s" if rep.timing is not None else "")
        + (f"; wrote {wrote}" if wrote else "")
    )
    if not args.out:
        names = [f"{n}_{u}" for n, u in zip(robot.joint_names, shown, strict=True)]
        times = _time_cells(rep)
        print(",".join(["index", *(["t_s"] if times else []), *names, "success"]))
        for i in range(len(res)):
            row = [f"{v * f:.4f}" for v, f in zip(res.q[i].tolist(), factor, strict=True)]
            print(",".join([str(i), *times[i : i + 1], *row, str(int(bool(res.success[i])))]))
    return 0 if ok == len(res) else 1


def _time_cells(rep) -> list[str]:
    """The ``t_s`` cells of a timed path (:func:`nik.paths.timing.time_cells`), or ``[]``."""
    if rep.t is None:
        return []
    from nik.paths.timing import time_cells

    return time_cells(rep.t.numpy())


def write_trajectory_csv(path: str | Path, robot, res, q_start=None) -> None:
    """One row per waypoint: ``index``, with timing ``t_s`` (seconds, :data:`nik.paths.timing.TIME_COLUMN`), the
    joints in degrees (``<name>_deg``; prismatic: ``<name>_mm``), the position error (mm), rotation error (deg),
    ``success``, ``step_deg`` (the largest motion of a revolute joint
    into that waypoint, degrees), for an arm with prismatic joints also ``step_mm`` (the largest slide of a
    prismatic joint, mm), and ``reason`` (why a waypoint failed, else empty). The step into waypoint 0 is from
    ``q_start`` ((dof,) radians / metres), 0 without it. Written to a temporary name, then renamed."""
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _, shown, factor = _units(robot.prismatic.tolist(), robot.dof)
    q = res.q.detach().cpu().double()
    prev = torch.cat([q[:1] if q_start is None else torch.as_tensor(q_start, dtype=q.dtype).reshape(1, -1), q[:-1]])
    dq = (q - prev).abs()
    slides = robot.prismatic.tolist()
    step_deg = torch.rad2deg(dq[:, [not p for p in slides]].amax(dim=1))
    step_mm = 1e3 * dq[:, slides].amax(dim=1) if any(slides) else None
    rep = res.path
    times = _time_cells(rep)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with tmp.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(
                [
                    "index",
                    *(["t_s"] if times else []),
                    *[f"{n}_{u}" for n, u in zip(robot.joint_names, shown, strict=True)],
                    "pos_err_mm",
                    "rot_err_deg",
                    "success",
                    "step_deg",
                    *(["step_mm"] if step_mm is not None else []),
                    "reason",
                ]
            )
            for i in range(len(res)):
                w.writerow(
                    [
                        i,
                        *times[i : i + 1],
                        *[f"{v * f:.10g}" for v, f in zip(q[i].tolist(), factor, strict=True)],
                        f"{float(res.pos_err[i]) * 1e3:.6g}",
                        f"{math.degrees(float(res.rot_err[i])):.6g}",
                        int(bool(res.success[i])),
                        f"{float(step_deg[i]):.6g}",
                        *([f"{float(step_mm[i]):.6g}"] if step_mm is not None else []),
                        rep.reasons[i],
                    ]
                )
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def plot_trajectory(path: str | Path, robot, res) -> None:
    """A PNG: each joint (degrees; prismatic: mm) against the waypoint index, its limits dashed, failed waypoints
    crossed and the largest step marked. Matplotlib is imported here (``pip install matplotlib``)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:
        raise ValueError("--plot needs matplotlib (pip install matplotlib)") from err
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _, shown, factor = _units(robot.prismatic.tolist(), robot.dof)
    rep = res.path
    q = res.q.detach().cpu().double().numpy()
    idx = list(range(q.shape[0]))
    fig, axes = plt.subplots(robot.dof, 1, figsize=(8, 1.3 * robot.dof + 1), sharex=True, squeeze=False)
    at, jbig = rep.largest_step_at, rep.largest_step_joint
    fail = [i for i in idx if not bool(res.success[i])]
    for j, ax in enumerate(axes[:, 0]):
        f = factor[j]
        ax.plot(idx, q[:, j] * f, color=f"C{j % 10}", lw=1.4)
        lo, hi = (float(v) * f for v in robot.limits[j])
        ax.axhline(lo, color="0.4", ls="--", lw=0.8)
        ax.axhline(hi, color="0.4", ls="--", lw=0.8)
        if fail:
            ax.plot(fail, q[fail, j] * f, "x", color="k", ms=4)
        if at > 0:
            ax.axvspan(at - 1, at, color="red", alpha=0.15 if j != jbig else 0.35, lw=0)
        ax.set_ylabel(f"{robot.joint_names[j]}\n({shown[j]})", fontsize=7)
        ax.tick_params(labelsize=7)
    big = rep.largest_step * factor[jbig]
    axes[0, 0].set_title(
        f"{robot.name}: joints along the path (limits dashed); largest step {big:.3g} {shown[jbig]} "
        f"(joint {jbig}) into waypoint {at}" + (f"; {len(fail)} waypoint(s) not reached (x)" if fail else ""),
        fontsize=8,
    )
    axes[-1, 0].set_xlabel("waypoint index")
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.png")
    try:
        fig.savefig(tmp, dpi=110)
        tmp.replace(path)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
