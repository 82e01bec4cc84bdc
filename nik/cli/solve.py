"""``nik solve`` and ``nik evaluate``: argument parsing and printing; the work is in :mod:`nik.ik`
and :mod:`nik.evaluate`."""

from __future__ import annotations

import csv
import json
import math
import re
import sys
import warnings
from pathlib import Path

from nik.cli.common import add_robot_arguments, quat_wxyz, robot_from_args, tool_link_text
from nik.cli.scene import add_scene_argument, world_from_args
from nik.tolerances import DEFAULT_TOL_POS_MM, DEFAULT_TOL_ROT_DEG, describe

__all__ = ["add_threads_argument", "register", "read_poses_csv", "write_solutions_csv"]

POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
#: nik solve --plot draws the solutions of at most this many poses
PLOT_MAX_POSES = 20
#: and at most this many of each pose's other solutions (--all) as faint arms, as nik view (ViewCfg.max_ghosts)
PLOT_MAX_GHOSTS = 8
REFINE_CHOICES = ("none", "pso", "sapso", "ipso", "ga", "lm")


def register(sub) -> None:
    s = sub.add_parser(
        "solve",
        help="solve inverse kinematics for one pose or a CSV of poses",
        description="Joint angles reaching the given tool poses: the closed form (PUMA-like arms), else the "
        "network shipped with nik for the robot (or --checkpoint), else a multi-start; then the --refine method "
        "to tolerance. Prints joint angles in degrees (prismatic joints: their travel in mm), the position error in "
        "mm, the rotation error in degrees and the success flag. Exit status: 0 when every pose was reached within "
        "tolerance, 1 when some was not, 2 on an error. An arm of fewer than 6 joints cannot reach every "
        "orientation at a position: ask for the position only (--position-only) or for the position and the "
        "direction of the tool's z axis (--free-axis z).",
    )
    add_robot_arguments(s)
    s.add_argument(
        "--checkpoint",
        default="auto",
        help="trained network for the initial guess: an exported NAME.safetensors (+ NAME.json beside it, e.g. from "
        "nik train) or a Lightning .ckpt; 'auto' (default): the network installed or shipped for this robot's "
        "definition, if any (not used where the closed form applies); 'none': no network",
    )
    s.add_argument(
        "--refine",
        choices=REFINE_CHOICES,
        default="lm",
        help="refinement method (default lm: Levenberg-Marquardt, restarts only for the poses that fail)",
    )
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--pose",
        nargs=7,
        type=float,
        metavar=("X", "Y", "Z", "QW", "QX", "QY", "QZ"),
        help="one pose: position (metres, or --unit mm) and unit quaternion (w, x, y, z; with --quat-order xyzw: "
        "x, y, z, w)",
    )
    src.add_argument("--poses", metavar="FILE.csv", help="CSV with header x,y,z,qw,qx,qy,qz (one pose per row)")
    s.add_argument(
        "--unit", choices=["m", "mm"], default="m", help="unit of the input positions (default m; mm converts them)"
    )
    s.add_argument("--out", metavar="FILE.csv", help="write the solutions as CSV (header included)")
    s.add_argument(
        "--json",
        action="store_true",
        help="print JSON (joints in SI and in deg/mm as q_si and q_display; q_rad and q_deg for revolute joints, "
        "null for prismatic ones; errors in SI and mm/deg)",
    )
    s.add_argument(
        "--tol-mm",
        type=float,
        default=DEFAULT_TOL_POS_MM,
        help=f"position tolerance in mm (default {DEFAULT_TOL_POS_MM:g})",
    )
    s.add_argument(
        "--tol-deg",
        type=float,
        default=DEFAULT_TOL_ROT_DEG,
        help=f"rotation tolerance in degrees (default {DEFAULT_TOL_ROT_DEG:g}, the tolerance every table measures)",
    )
    s.add_argument(
        "--q-near",
        nargs="+",
        type=float,
        metavar="DEG",
        help="current joint angles in degrees (prismatic joints: mm): return the solution nearest to them",
    )
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument("--max-iters", type=int, default=None, help="iteration limit of the refinement")
    s.add_argument("--device", default="cpu", help="where to compute: cpu (default), cuda or cuda:N")
    s.add_argument(
        "--all",
        action="store_true",
        help="also find every distinct solution of each pose (IKSolver.solve_all) and print them (degrees); "
        f"--plot draws up to {PLOT_MAX_GHOSTS} of each pose's as faint arms",
    )
    s.add_argument(
        "--plot",
        metavar="FILE.png",
        help=f"draw the arm at its solution(s) and the target frame(s) (the first {PLOT_MAX_POSES} poses) to this "
        "picture (matplotlib; .png, .svg, .pdf)",
    )
    s.add_argument(
        "--bounds",
        nargs=6,
        metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
        help="a tolerant goal: half-widths along the target tool's axes, mm then degrees, inf or free = free axis "
        "(success: inside them, by FK; docs/bounds.md)",
    )
    s.add_argument("--position-only", action="store_true", help="orientation free (the position within --tol-mm)")
    s.add_argument(
        "--free-axis",
        action="append",
        metavar="x|y|z",
        help="rotation about this tool axis free (a drill, a torch, a suction cup); once",
    )
    add_threads_argument(s)
    add_scene_argument(s)
    s.add_argument(
        "--mesh-verdict",
        choices=["auto", "on", "off"],
        default="auto",
        help="with --scene, who judges collision_free: auto (default) the robot's collision meshes where coal "
        "(pip install 'nik-ik[collision-check]') and a URDF with meshes are there, else the spheres; on: the meshes "
        "(an error without them); off: the conservative spheres",
    )
    s.set_defaults(func=_cmd_solve)

    e = sub.add_parser(
        "evaluate",
        help="evaluate the default pipeline, LM multistart, network, refinements, swarm, closed form and "
        "pytorch-kinematics on a test split",
        description="Solve the test poses of a dataset with every pipeline and write a Markdown table "
        "(success at 1 mm / 1 deg and 0.1 mm / 0.1 deg, error percentiles, joints outside limits, time per "
        "target), a JSON copy and a cumulative error plot (PNG).",
    )
    add_robot_arguments(e)
    e.add_argument(
        "--checkpoint",
        default="auto",
        help="network of the network rows: 'auto' (default): the one installed or shipped for this arm's "
        "definition hash, as IKSolver(robot) finds it (nik networks lists them); 'none': no network rows; else a "
        "trained network (NAME.safetensors from nik train / export, or a Lightning .ckpt). "
        "The rows 'default pipeline' (IKSolver(robot)) and 'LM multistart, no network' are always there; rows "
        "marked 'no network' use none whatever is installed; each row's note names the guess that served it",
    )
    e.add_argument("--data", required=True, help="dataset directory (nik generate)")
    e.add_argument("--n", type=int, default=1000, help="number of test poses (default 1000)")
    e.add_argument("--out", default=None, help="output directory (default runs/eval/ROBOT)")
    e.add_argument("--split", default="test", choices=["test", "val", "train"], help="dataset split (default test)")
    e.add_argument(
        "--refinements",
        default="lm,pso,sapso,ipso,ga",
        help="comma-separated refinements after the network (default lm,pso,sapso,ipso,ga)",
    )
    e.add_argument(
        "--swarm",
        choices=["pso", "sapso", "ipso", "ga", "lm"],
        default="ipso",
        help="method of the uniform-init (no network) row (default ipso)",
    )
    e.add_argument("--no-pk", action="store_true", help="leave out the pytorch-kinematics row")
    e.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    e.add_argument("--device", default="cpu", help="where every pipeline computes: cpu (default), cuda or cuda:N")
    add_threads_argument(e, default=1)
    e.set_defaults(func=_cmd_evaluate)


def add_threads_argument(parser, *, default=None) -> None:
    """``--threads N``: torch intra-op threads (applied by :func:`nik.cli.main` through :func:`nik.set_threads`)."""
    parser.add_argument(
        "--threads",
        type=int,
        default=default,
        metavar="N",
        help="torch threads for the maths (default: "
        + ("1" if default == 1 else "1 below 100,000 poses, torch's setting above")
        + "; more threads help only large batches on an idle machine)",
    )


# ---------------------------------------------------------------------------
# CSV
# ---------------------------------------------------------------------------
def read_poses_csv(path: str | Path):
    """``(B, 7)`` float64 tensor from a CSV with header ``x,y,z,qw,qx,qy,qz`` (any column order,
    extra columns ignored; a UTF-8 byte-order mark, as Excel's "CSV UTF-8" writes, is skipped). Errors name the
    file, the line (1-based, as an editor counts them: the header is line 1) and the column; a quaternion whose
    norm is off 1 by more than :data:`nik.ik.targets.QUAT_NORM_TOL`, NaN or inf included, is refused here, by
    its line."""
    import torch

    from nik.ik.targets import QUAT_NORM_TOL

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"poses file not found: {path}")
    with path.open(newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise ValueError(f"{path}: empty file; expected a header {','.join(POSE_COLUMNS)}") from None
        names = [h.strip().lower() for h in header]
        missing = [c for c in POSE_COLUMNS if c not in names]
        if missing:
            raise ValueError(
                f"{path}: header lacks column(s) {missing}; expected {','.join(POSE_COLUMNS)}, got {','.join(header)}"
            )
        cols = [names.index(c) for c in POSE_COLUMNS]
        rows = []
        for rec in reader:
            line = reader.line_num  # the file line this record ends on
            if not rec or all(not v.strip() for v in rec):
                continue
            vals = []
            for c, name in zip(cols, POSE_COLUMNS, strict=True):
                try:
                    vals.append(float(rec[c]))
                except (IndexError, ValueError):
                    got = rec[c] if c < len(rec) else "nothing"
                    raise ValueError(f"{path} line {line}: column {name!r} must be a number, got {got!r}") from None
            norm = math.sqrt(sum(v * v for v in vals[3:]))
            if not all(math.isfinite(v) for v in vals):
                raise ValueError(f"{path} line {line}: a pose contains NaN or inf ({','.join(map(str, vals))})")
            if abs(norm - 1.0) > QUAT_NORM_TOL:
                raise ValueError(
                    f"{path} line {line}: quaternion (qw, qx, qy, qz) has norm {norm:.6g}; a unit quaternion is "
                    f"expected (norm within {QUAT_NORM_TOL:g} of 1 is normalised)"
                )
            rows.append(vals)
    if not rows:
        raise ValueError(f"{path}: no poses after the header")
    return torch.tensor(rows, dtype=torch.float64)


def _units(prismatic, n: int) -> tuple[list[str], list[str], list[float]]:
    """Per joint: SI unit, display unit and the factor SI -> display (rad -> deg, or m -> mm for prismatic)."""
    flags = [False] * n if prismatic is None else [bool(v) for v in prismatic]
    si = ["m" if p else "rad" for p in flags]
    shown = ["mm" if p else "deg" for p in flags]
    return si, shown, [1e3 if p else 180.0 / math.pi for p in flags]


def few_joints_note(robot, success, reachable) -> str | None:
    """One line for an arm of fewer than 6 joints that missed a target its reach bound does not rule out, else None.

    Such an arm reaches a (dof)-dimensional set of the 6-D poses: at a reachable position most orientations are
    out of its reach, and nothing proves which (``reachable`` stays True: it only says the position bound rules
    the target out). The line says so and names the tolerant goals that ask for what it can do."""
    if robot.dof >= 6 or not bool((~success & reachable).any()):
        return None
    return (
        f"{robot.name} has {robot.dof} joints, fewer than the 6 that reach any orientation at a position: most "
        "full poses are beyond it even where the position is within reach; for the position only pass "
        "--position-only, for the position and the direction of the tool's z axis --free-axis z "
        '(Python: bounds="position" / bounds="axis_z")'
    )


def _written_whole(path: Path):
    """A context: an open text file at a temporary name beside ``path``, renamed to ``path`` when the block ends
    without error (a reader never sees half a file; a failed write leaves the old one and no temporary)."""
    import contextlib
    import os

    @contextlib.contextmanager
    def opened():
        tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
        try:
            with tmp.open("w", newline="") as fh:
                yield fh
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)

    return opened()


def write_solutions_csv(path: str | Path, joint_names, result, *, prismatic=None) -> None:
    """Write one row per target: ``index``, joints in radians and degrees (prismatic joints: metres and mm,
    columns ``<name>_m`` / ``<name>_mm``), errors (mm, deg), success, iterations; where collisions were checked
    also ``collision_free`` (1/0) and ``collisions`` (what overlaps, ``;``-separated). Written to a temporary name
    and renamed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    si, shown, factor = _units(prismatic, len(joint_names))
    checked = getattr(result, "collision_free", None) is not None  # any object with the fields of an IKResult
    with _written_whole(path) as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "index",
                *[f"{j}_{u}" for j, u in zip(joint_names, si, strict=True)],
                *[f"{j}_{u}" for j, u in zip(joint_names, shown, strict=True)],
                "pos_err_mm",
                "rot_err_deg",
                "success",
                "iterations",
                *(["collision_free", "collisions"] if checked else []),
            ]
        )
        for i in range(len(result)):
            q = result.q[i].tolist()
            w.writerow(
                [
                    i,
                    *[f"{v:.12g}" for v in q],
                    *[f"{v * f:.10g}" for v, f in zip(q, factor, strict=True)],
                    f"{float(result.pos_err[i]) * 1e3:.6g}",
                    f"{math.degrees(float(result.rot_err[i])):.6g}",
                    int(bool(result.success[i])),
                    int(result.iterations[i]),
                    *([int(bool(result.collision_free[i])), ";".join(_collisions(result, i))] if checked else []),
                ]
            )


def _collisions(res, i: int) -> list[str]:
    """What overlaps in answer ``i`` (``res.collisions``; [] where free or unchecked)."""
    return (res.collisions[i] or []) if res.collisions is not None else []


def _with_scene(names) -> bool:
    """True when one of the overlap names (:attr:`nik.IKResult.collisions`) is a link against an obstacle."""
    return any(re.search(r"\|(sphere|box|capsule) \d+$", n) for n in names)


def failure_summary(res) -> str | None:
    """``"3 of 50 poses not reached: 2 colliding with the scene, 1 out of reach"`` (why each failed pose failed:
    out of reach, colliding with the scene, colliding with the arm itself, else not reached), None when all were."""
    counts = {"colliding with the scene": 0, "colliding with the arm itself": 0, "out of reach": 0, "not reached": 0}
    failed = [i for i in range(len(res)) if not bool(res.success[i])]
    for i in failed:
        if res.reachable is not None and not bool(res.reachable[i]):
            counts["out of reach"] += 1
        elif res.collision_free is not None and not bool(res.collision_free[i]):
            scene = _with_scene(_collisions(res, i))
            counts["colliding with the scene" if scene else "colliding with the arm itself"] += 1
        else:
            counts["not reached"] += 1
    if not failed:
        return None
    why = ", ".join(f"{n} {k}" for k, n in counts.items() if n)
    return f"{len(failed)} of {len(res)} poses not reached: {why}"


# ---------------------------------------------------------------------------
# Commands
# ---------------------------------------------------------------------------
def _cmd_solve(args) -> int:
    import torch

    from nik.ik import as_poses
    from nik.robots.reach import unreachable_message
    from nik.solver import IKSolver

    robot = robot_from_args(args)
    if args.pose is not None:
        poses = torch.tensor([quat_wxyz(args.pose, args)], dtype=torch.float64)
    else:
        poses = read_poses_csv(args.poses)
    if args.unit == "mm":
        poses[:, :3] *= 1e-3
    if args.tol_mm <= 0 or args.tol_deg <= 0:
        raise ValueError(f"--tol-mm and --tol-deg must be > 0, got {args.tol_mm} and {args.tol_deg}")
    from nik.ik.bounds import bounds_from_cli

    tol = (args.tol_mm * 1e-3, math.radians(args.tol_deg))
    goal = bounds_from_cli(args.bounds, position_only=args.position_only, free_axis=args.free_axis, tol_pos=tol[0],
                           tol_rot=tol[1])  # fmt: skip
    tolerance = describe(*tol) if goal is None else goal.describe()
    q_near = None
    if args.q_near is not None:
        if len(args.q_near) != robot.dof:
            raise ValueError(f"--q-near: {robot.name} has {robot.dof} joints, got {len(args.q_near)} angles")
        _, _, factor = _units(robot.prismatic.tolist(), robot.dof)
        q_near = torch.tensor([v / f for v, f in zip(args.q_near, factor, strict=True)], dtype=torch.float64)
    T = as_poses(poses, "quat", name="--pose" if args.pose is not None else str(args.poses))
    checkpoint = None if str(args.checkpoint).lower() == "none" else args.checkpoint
    world = world_from_args(args)
    verdict = {"auto": "auto", "on": True, "off": False}[args.mesh_verdict] if world is not None else False
    solver = IKSolver(robot, checkpoint=checkpoint, refine=args.refine, device=args.device, world=world,
                      mesh_verdict=verdict)  # fmt: skip
    with warnings.catch_warnings():  # the reach warning becomes the one line below
        warnings.simplefilter("ignore", UserWarning)
        res = solver.solve(
            T.to(solver.device),
            tol_pos=args.tol_mm * 1e-3,
            tol_rot=math.radians(args.tol_deg),
            seed=args.seed,
            q_near=q_near,
            plan={"max_iters": args.max_iters},  # the refinement's iteration limit (None: its config)
            bounds=goal,
        )
    res = res.to("cpu")
    every = None
    if args.all:  # one pose at a time: solve_all answers for one pose
        every = [
            solver.solve_all(
                T[i : i + 1].to(solver.device),
                tol_pos=args.tol_mm * 1e-3,
                tol_rot=math.radians(args.tol_deg),
                seed=args.seed,
                bounds=goal,
            ).cpu()
            for i in range(len(T))
        ]
    if args.plot:
        _plot(robot, T, res, every, args.plot, tolerance=tolerance, world=solver.world)
    hint = "pass --unit mm" if args.unit == "m" else ""
    msg = unreachable_message(robot, T, res.reachable, unit_hint=hint)
    if msg is not None:
        print(f"nik solve: {msg}", file=sys.stderr)
    msg = few_joints_note(robot, res.success, res.reachable)
    if msg is not None:
        print(f"nik solve: {msg}", file=sys.stderr)
    if args.out:
        write_solutions_csv(args.out, robot.joint_names, res, prismatic=robot.prismatic.tolist())
    if args.json:
        flags = robot.prismatic.tolist()
        si, shown, factor = _units(flags, robot.dof)
        results = []
        for i in range(len(res)):
            q = res.q[i].tolist()
            results.append(
                {
                    "index": i,
                    "q_rad": [None if p else v for v, p in zip(q, flags, strict=True)],
                    "q_deg": [None if p else math.degrees(v) for v, p in zip(q, flags, strict=True)],
                    "q_si": q,
                    "q_display": [v * f for v, f in zip(q, factor, strict=True)],
                    "pos_err_m": float(res.pos_err[i]),
                    "pos_err_mm": float(res.pos_err[i]) * 1e3,
                    "rot_err_rad": float(res.rot_err[i]),
                    "rot_err_deg": math.degrees(float(res.rot_err[i])),
                    "success": bool(res.success[i]),
                    "reachable": bool(res.reachable[i]),
                    "iterations": int(res.iterations[i]),
                    **(
                        {"collision_free": bool(res.collision_free[i]), "collisions": _collisions(res, i)}
                        if res.collision_free is not None
                        else {}
                    ),
                    **(
                        {
                            "all_q_display": [
                                [v * f for v, f in zip(qk, factor, strict=True)] for qk in every[i].tolist()
                            ]
                        }
                        if every is not None
                        else {}
                    ),
                }
            )
        print(
            json.dumps(
                {
                    "robot": robot.name,
                    "end_link": robot.end_link,
                    "base": None if robot.base is None else robot.base.tolist(),  # 4x4, metres
                    "tool": None if robot.tool is None else robot.tool.tolist(),
                    "joint_names": robot.joint_names,
                    "joint_units_si": si,
                    "joint_units_display": shown,
                    "refine": args.refine,
                    "initial_guess": res.source,
                    "tol_mm": args.tol_mm,
                    "tol_deg": args.tol_deg,
                    "results": results,
                    **({"scene": str(args.scene), "not_reached": failure_summary(res)} if args.scene else {}),
                    **({"out": str(args.out)} if args.out else {}),
                    **({"plot": str(args.plot)} if args.plot else {}),
                },
                indent=2,
            )
        )
    elif args.out:
        ok = int(res.success.sum())
        why = failure_summary(res)
        print(
            f"solved {ok} of {len(res)} poses within {tolerance} "
            f"({robot.name}{tool_link_text(robot)}, guess: {res.source}, refine: {args.refine}"
            f"{_scene_text(args)}); {why + '; ' if why else ''}wrote {args.out}"
        )
    else:
        _print_table(robot, res, tolerance=tolerance, scene=_scene_text(args))
    if every is not None and not args.json:
        _print_every(robot, every)
    if args.plot and not args.json:
        print(f"wrote {args.plot}")
    return 0 if bool(res.success.all()) else 1


def _print_every(robot, every, *, limit: int = 50) -> None:
    """Every solution of each pose (from ``--all``), joints in degrees (prismatic: mm)."""
    _, _, factor = _units(robot.prismatic.tolist(), robot.dof)
    for i, sols in enumerate(every[:limit]):
        print(f"pose {i}: {len(sols)} distinct solution(s) within the limits (deg; prismatic joints mm)")
        for qk in sols.tolist():
            print("  " + "  ".join(f"{v * f:10.4f}" for v, f in zip(qk, factor, strict=True)))


def _plot(robot, T, res, every, path, *, tolerance: str, world=None) -> None:
    """``--plot``: the solutions of the first :data:`PLOT_MAX_POSES` poses, their targets, and ``--all``'s as
    ghosts: at most :data:`PLOT_MAX_GHOSTS` a pose (spread evenly over its list), said in the title and in a
    ``nik: note:`` line (a 7-joint arm has a continuum of solutions: 100 ghosts were a black blob)."""
    import torch

    from nik.view import plot_arm

    n = min(len(res), PLOT_MAX_POSES)
    ghosts, found, drawn = None, 0, 0
    if every is not None:
        picked = []
        for sols in every[:n]:
            k = min(len(sols), PLOT_MAX_GHOSTS)
            picked.append(sols[torch.linspace(0, len(sols) - 1, k).round().long()] if k else sols)
            found, drawn = found + len(sols), drawn + k
        ghosts = torch.cat(picked)
    shown = f"{n} of {len(res)} poses" if n < len(res) else f"{n} pose{'s' * (n > 1)}"
    title = f"{robot.name}: {shown}, {int(res.success[:n].sum())} reached within {tolerance}"
    if drawn < found:
        title += f"\n{drawn} of {found} solutions drawn faint (at most {PLOT_MAX_GHOSTS} a pose)"
        print(
            f"nik: note: --plot draws {drawn} of the {found} solutions found (at most {PLOT_MAX_GHOSTS} a pose, "
            "spread over each pose's list; the output lists them all)",
            file=sys.stderr,
        )
    plot_arm(robot, res.q[:n], path, ghosts=ghosts, T_target=T[:n], title=title, world=world)


def _scene_text(args) -> str:
    """``", scene: FILE"`` for ``--scene`` (empty without)."""
    if getattr(args, "scene", None) is None:
        return ""
    return f", scene: {args.scene}"


def _print_table(robot, res, *, tolerance: str, scene: str = "", limit: int = 50) -> None:
    """Joints in degrees, prismatic joints in mm (each column header says which), errors in mm and degrees; a
    ``collision-free`` column where collisions were checked (``--scene``)."""
    checked = res.collision_free is not None
    names = robot.joint_names
    _, shown, factor = _units(robot.prismatic.tolist(), robot.dof)
    width = max(9, *(len(n) for n in names))
    header = [
        "#",
        *[f"{n} ({u})" for n, u in zip(names, shown, strict=True)],
        "pos err (mm)",
        "rot err (deg)",
        *(["collision-free"] if checked else []),
        "success",
    ]
    widths = [4, *[max(width + 6, 10)] * len(names), 13, 14, *([14] if checked else []), 8]
    print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    for i in range(min(len(res), limit)):
        cells = [
            str(i),
            *[f"{v * f:.4f}" for v, f in zip(res.q[i].tolist(), factor, strict=True)],
            f"{float(res.pos_err[i]) * 1e3:.3g}",
            f"{math.degrees(float(res.rot_err[i])):.3g}",
            *((["yes" if bool(res.collision_free[i]) else "NO"]) if checked else []),
            "yes" if bool(res.success[i]) else "NO",
        ]
        print("  ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True)))
    if len(res) > limit:
        print(f"... {len(res) - limit} more rows (use --out FILE.csv)")
    why = failure_summary(res)
    print(
        f"robot {robot.name}{tool_link_text(robot)}, initial guess: {res.source}{scene}; "
        f"{int(res.success.sum())} of {len(res)} reached within {tolerance}{'; ' + why if why else ''}"
    )


def _cmd_evaluate(args) -> int:
    from nik.evaluate import REFINEMENTS, EvalHooks, evaluate, markdown_table, write_report

    robot = robot_from_args(args)
    refinements = tuple(m.strip() for m in args.refinements.split(",") if m.strip())
    bad = [m for m in refinements if m not in REFINEMENTS]
    if bad:
        raise ValueError(f"--refinements: unknown method(s) {bad}; expected some of {','.join(REFINEMENTS)}")
    if args.n <= 0:
        raise ValueError(f"--n must be a positive integer, got {args.n}")
    if str(args.checkpoint).lower() not in ("auto", "none"):  # refuse a bad one in one line, before any output
        from nik.nets import load_network

        load_network(args.checkpoint, robot=robot)
    out = Path(args.out) if args.out else Path("runs") / "eval" / robot.name
    report = evaluate(
        robot,
        data=(args.data, args.split),
        checkpoint=args.checkpoint,
        n=args.n,
        refinements=refinements,
        swarm=args.swarm,
        include_pk=not args.no_pk,
        seed=args.seed,
        device=args.device,
        hooks=EvalHooks(
            progress=lambda msg: print(f"evaluating: {msg}", file=sys.stderr, flush=True),
            on_row=lambda rep: write_report(rep, out, plot=False),  # each row is kept as soon as it is made
        ),
    )
    paths = write_report(report, out)
    print(markdown_table(report))
    print(f"wrote {paths['markdown']}, {paths['json']}, {paths['plot']}")
    return 0
