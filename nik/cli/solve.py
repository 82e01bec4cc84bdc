"""``nik solve`` and ``nik evaluate``: argument parsing and printing; the work is in :mod:`nik.solver`
and :mod:`nik.evaluate`."""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path

__all__ = ["register", "read_poses_csv", "write_solutions_csv"]

POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
REFINE_CHOICES = ("none", "pso", "sapso", "ipso", "ga", "lm")


def register(sub) -> None:
    s = sub.add_parser(
        "solve",
        help="solve inverse kinematics for one pose or a CSV of poses",
        description="Joint angles reaching the given tool poses: the closed form (PUMA-like arms), else the "
        "network shipped with nik for the robot (or --checkpoint), else a multi-start; then the --refine method "
        "to tolerance. Prints joint angles in degrees, the position error in mm, the rotation error in degrees and "
        "the success flag. Exit status: 0 when "
        "every pose was reached within tolerance, 1 when some was not, 2 on an error.",
    )
    s.add_argument("--robot", required=True, help="built-in robot name or robot file (YAML/URDF)")
    s.add_argument(
        "--checkpoint",
        default="auto",
        help="trained network (.ckpt) for the initial guess; 'auto' (default): the network shipped with nik for "
        "this robot, if any (not used where the closed form applies); 'none': no network",
    )
    s.add_argument("--refine", choices=REFINE_CHOICES, default="ipso", help="refinement method (default ipso)")
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--pose",
        nargs=7,
        type=float,
        metavar=("X", "Y", "Z", "QW", "QX", "QY", "QZ"),
        help="one pose: position (metres, or --unit mm) and unit quaternion (w, x, y, z)",
    )
    src.add_argument("--poses", metavar="FILE.csv", help="CSV with header x,y,z,qw,qx,qy,qz (one pose per row)")
    s.add_argument("--unit", choices=["m", "mm"], default="m", help="unit of the input positions (default m)")
    s.add_argument("--out", metavar="FILE.csv", help="write the solutions as CSV (header included)")
    s.add_argument("--json", action="store_true", help="print JSON (radians and degrees, errors in SI and mm/deg)")
    s.add_argument("--tol-mm", type=float, default=0.1, help="position tolerance in mm (default 0.1)")
    s.add_argument(
        "--tol-deg",
        type=float,
        default=math.degrees(1e-3),
        help="rotation tolerance in degrees (default 0.0573 = 1e-3 rad)",
    )
    s.add_argument(
        "--q-near",
        nargs="+",
        type=float,
        metavar="DEG",
        help="current joint angles in degrees: return the solution nearest to them",
    )
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.add_argument("--max-iters", type=int, default=None, help="iteration limit of the refinement")
    s.set_defaults(func=_cmd_solve)

    e = sub.add_parser(
        "evaluate",
        help="evaluate network, refinements, swarm, closed form and pytorch-kinematics on a test split",
        description="Solve the test poses of a dataset with every pipeline and write a Markdown table "
        "(success at 1 mm / 1 deg and 0.1 mm / 0.1 deg, error percentiles, joints outside limits, time per "
        "target), a JSON copy and an error histogram (PNG).",
    )
    e.add_argument("--robot", required=True, help="built-in robot name or robot file (YAML/URDF)")
    e.add_argument(
        "--checkpoint", default=None, help="trained network (.ckpt); without it the network rows are left out"
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
    e.set_defaults(func=_cmd_evaluate)


# ---------------------------------------------------------------------------
# CSV
# ---------------------------------------------------------------------------
def read_poses_csv(path: str | Path):
    """``(B, 7)`` float64 tensor from a CSV with header ``x,y,z,qw,qx,qy,qz`` (any column order,
    extra columns ignored). Errors name the file, line and column."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"poses file not found: {path}")
    with path.open(newline="") as fh:
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
        for line, rec in enumerate(reader, start=2):
            if not rec or all(not v.strip() for v in rec):
                continue
            vals = []
            for c, name in zip(cols, POSE_COLUMNS, strict=True):
                try:
                    vals.append(float(rec[c]))
                except (IndexError, ValueError):
                    got = rec[c] if c < len(rec) else "nothing"
                    raise ValueError(f"{path} line {line}: column {name!r} must be a number, got {got!r}") from None
            rows.append(vals)
    if not rows:
        raise ValueError(f"{path}: no poses after the header")
    return torch.tensor(rows, dtype=torch.float64)


def write_solutions_csv(path: str | Path, joint_names, result) -> None:
    """Write one row per target: ``index``, joints in radians and degrees, errors (mm, deg), success, iterations."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "index",
                *[f"{j}_rad" for j in joint_names],
                *[f"{j}_deg" for j in joint_names],
                "pos_err_mm",
                "rot_err_deg",
                "success",
                "iterations",
            ]
        )
        for i in range(len(result)):
            q = result.q[i].tolist()
            w.writerow(
                [
                    i,
                    *[f"{v:.12g}" for v in q],
                    *[f"{math.degrees(v):.10g}" for v in q],
                    f"{float(result.pos_err[i]) * 1e3:.6g}",
                    f"{math.degrees(float(result.rot_err[i])):.6g}",
                    int(bool(result.success[i])),
                    int(result.iterations[i]),
                ]
            )


# ---------------------------------------------------------------------------
# Commands
# ---------------------------------------------------------------------------
def _cmd_solve(args) -> int:
    import torch

    from nik.robots import load_robot
    from nik.solver import IKSolver, as_poses

    robot = load_robot(args.robot)
    if args.pose is not None:
        poses = torch.tensor([args.pose], dtype=torch.float64)
    else:
        poses = read_poses_csv(args.poses)
    if args.unit == "mm":
        poses[:, :3] *= 1e-3
    if args.tol_mm <= 0 or args.tol_deg <= 0:
        raise ValueError(f"--tol-mm and --tol-deg must be > 0, got {args.tol_mm} and {args.tol_deg}")
    q_near = None
    if args.q_near is not None:
        if len(args.q_near) != robot.dof:
            raise ValueError(f"--q-near: {robot.name} has {robot.dof} joints, got {len(args.q_near)} angles")
        q_near = torch.tensor([math.radians(v) for v in args.q_near], dtype=torch.float64)
    T = as_poses(poses, "quat", name="--pose" if args.pose is not None else str(args.poses))
    checkpoint = None if str(args.checkpoint).lower() == "none" else args.checkpoint
    solver = IKSolver(robot, checkpoint=checkpoint, refine=args.refine)
    res = solver.solve(
        T,
        tol_pos=args.tol_mm * 1e-3,
        tol_rot=math.radians(args.tol_deg),
        seed=args.seed,
        q_near=q_near,
        max_iters=args.max_iters,
    )
    if args.out:
        write_solutions_csv(args.out, robot.joint_names, res)
    if args.json:
        results = []
        for i in range(len(res)):
            q = res.q[i].tolist()
            results.append(
                {
                    "index": i,
                    "q_rad": q,
                    "q_deg": [math.degrees(v) for v in q],
                    "pos_err_m": float(res.pos_err[i]),
                    "pos_err_mm": float(res.pos_err[i]) * 1e3,
                    "rot_err_rad": float(res.rot_err[i]),
                    "rot_err_deg": math.degrees(float(res.rot_err[i])),
                    "success": bool(res.success[i]),
                    "iterations": int(res.iterations[i]),
                }
            )
        print(
            json.dumps(
                {
                    "robot": robot.name,
                    "joint_names": robot.joint_names,
                    "refine": args.refine,
                    "initial_guess": res.source,
                    "tol_mm": args.tol_mm,
                    "tol_deg": args.tol_deg,
                    "results": results,
                    **({"out": str(args.out)} if args.out else {}),
                },
                indent=2,
            )
        )
    elif args.out:
        ok = int(res.success.sum())
        print(
            f"solved {ok} of {len(res)} poses within {args.tol_mm:g} mm / {args.tol_deg:g} deg "
            f"({robot.name}, guess: {res.source}, refine: {args.refine}); wrote {args.out}"
        )
    else:
        _print_table(robot, res)
    return 0 if bool(res.success.all()) else 1


def _print_table(robot, res, *, limit: int = 50) -> None:
    names = robot.joint_names
    width = max(9, *(len(n) for n in names))
    header = ["#", *[f"{n} (deg)" for n in names], "pos err (mm)", "rot err (deg)", "success"]
    widths = [4, *[max(width + 6, 10)] * len(names), 13, 14, 8]
    print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    for i in range(min(len(res), limit)):
        cells = [
            str(i),
            *[f"{math.degrees(v):.4f}" for v in res.q[i].tolist()],
            f"{float(res.pos_err[i]) * 1e3:.3g}",
            f"{math.degrees(float(res.rot_err[i])):.3g}",
            "yes" if bool(res.success[i]) else "NO",
        ]
        print("  ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True)))
    if len(res) > limit:
        print(f"... {len(res) - limit} more rows (use --out FILE.csv)")
    print(f"robot {robot.name}, initial guess: {res.source}; {int(res.success.sum())} of {len(res)} reached")


def _cmd_evaluate(args) -> int:
    from nik.evaluate import REFINEMENTS, evaluate, markdown_table, write_report
    from nik.robots import load_robot

    robot = load_robot(args.robot)
    refinements = tuple(m.strip() for m in args.refinements.split(",") if m.strip())
    bad = [m for m in refinements if m not in REFINEMENTS]
    if bad:
        raise ValueError(f"--refinements: unknown method(s) {bad}; expected some of {','.join(REFINEMENTS)}")
    if args.n <= 0:
        raise ValueError(f"--n must be a positive integer, got {args.n}")
    report = evaluate(
        robot,
        data=args.data,
        checkpoint=args.checkpoint,
        n=args.n,
        split=args.split,
        refinements=refinements,
        swarm=args.swarm,
        include_pk=not args.no_pk,
        seed=args.seed,
        progress=lambda msg: print(f"evaluating: {msg}", file=sys.stderr, flush=True),
    )
    out = Path(args.out) if args.out else Path("runs") / "eval" / robot.name
    paths = write_report(report, out)
    print(markdown_table(report))
    print(f"wrote {paths['markdown']}, {paths['json']}, {paths['histogram']}")
    return 0
