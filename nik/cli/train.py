"""``nik train`` (a network for an arm) and ``nik compare``: argument parsing only; the work is in
:mod:`nik.learn.recipe` and :mod:`nik.learn.compare`, imported when the command runs (Lightning is heavy).

The full LightningCLI stays ``python train.py fit --config configs/train/<method>.yaml``.
"""

from __future__ import annotations

import json
import shlex
import sys

from nik.cli.common import add_root_link_argument, notes_as_lines

__all__ = ["register"]


def register(sub) -> None:
    from nik.learn.cli import build_parser

    t = sub.add_parser(
        "train",
        help="train a network for an arm and export it (ROBOT: built-in name, YAML or URDF)",
        description="Train a multi-solution network for ROBOT (a built-in name, a YAML robot file or a URDF with "
        "--end-link) within a wall-clock budget, on fresh forward-kinematics samples at every step (or --data), "
        "export it as NAME.safetensors + NAME.json (SHA-256 recorded) and print its evaluation: raw error (mm, deg) "
        "and network + LM against no network, on a batch and on single poses. The kind is chosen from the arm: "
        "one head per IK branch where nik labels the branches (PUMA- and UR-type 6R arms), else K heads. "
        "Progress goes to stderr; the run lives in RUNS/NAME/ (last.ckpt, history.csv, curve.png, report.txt).",
    )
    t.add_argument("robot", metavar="ROBOT", help="built-in robot name, YAML robot file or URDF")
    t.add_argument("--end-link", default=None, help="URDF: the tool link (default: the end of the longest chain)")
    add_root_link_argument(t)
    t.add_argument("--minutes", type=float, default=20.0, help="training wall-clock budget in minutes (default 20)")
    t.add_argument("--data", default=None, help="dataset folder (nik generate); default: fresh FK samples every step")
    t.add_argument(
        "--out", default=None, help="NAME.safetensors to write (+ NAME.json); default RUNS/NAME/NAME.safetensors"
    )
    t.add_argument(
        "--install",
        action="store_true",
        help="also copy the network to the user folder ($NIK_HOME/networks, else ~/.local/share/nik/networks), "
        "where IKSolver(robot) and nik solve find it for this arm (matched by its definition, not its name; "
        "on an arm with a closed form the closed form stays the default: the output says how to use the network)",
    )
    t.add_argument("--resume", action="store_true", help="continue RUNS/NAME/last.ckpt (the budget counts both parts)")
    t.add_argument("--name", default=None, help="run and file name (default: the robot's name)")
    t.add_argument("--runs", default="runs", help="folder of the runs (default runs)")
    t.add_argument(
        "--kind", choices=["auto", "branch_heads", "multihead"], default="auto", help="network kind (default auto)"
    )
    t.add_argument("--hidden", type=int, nargs="+", default=None, help="hidden layer sizes (default 256 256 256 256)")
    t.add_argument("--heads", type=int, default=8, help="hypotheses of a multi-head network (default 8)")
    t.add_argument(
        "--single-pose",
        action="store_true",
        help="a small network (default hidden 64 64) that the solver uses on the CPU (its compiled "
        "backend), next to the main network of the arm (recorded role single_pose)",
    )
    t.add_argument(
        "--single-pose-share",
        type=float,
        default=0.2,
        metavar="F",
        help="share of the budget for a small single-pose network, trained after the main one only where the main "
        "one makes single poses slower on the CPU; saved beside it as NAME_one and named in its JSON (default 0.2; "
        "0: never)",
    )
    t.add_argument("--batch-size", type=int, default=1024, help="samples per step (default 1024)")
    t.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate at the start (default 1e-3, cosine)")
    t.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    t.add_argument("--max-steps", type=int, default=None, help="also stop after this many steps")
    t.add_argument("--val-n", type=int, default=5000, help="validation samples (default 5000)")
    t.add_argument("--steps-per-epoch", type=int, default=200, help="steps between validations (default 200)")
    t.add_argument("--eval-batch", type=int, default=1000, help="targets of the batch evaluation (default 1000)")
    t.add_argument("--eval-one", type=int, default=50, help="single poses of the one-pose evaluation (default 50)")
    t.add_argument("--no-eval", action="store_true", help="skip the evaluation after training")
    t.add_argument("--threads", type=int, default=None, metavar="N", help="torch threads (default: torch's setting)")
    t.set_defaults(func=_cmd_train)

    p = sub.add_parser(
        "compare",
        help="compare the training methods (bp, adam, lbfgs, de, de_bp) on one dataset and budget; names a winner",
        description="Train every method on the same dataset and split under the same budget (--steps: "
        "reproducible; --budget: wall-clock seconds, kept inside the steps) with several seeds, for paper C's "
        "6-8-6 net and the realistic default, and evaluate each on the test split. Writes a Markdown table "
        "(what each run ran, what stopped it, DE's subset size) with a verdict per metric (the best method, "
        "its margin against the spread over the seeds, whether the ranking is established), CSVs and a plot of "
        "validation loss against wall-clock time (docs/training.md).",
    )
    build_parser(p)
    p.set_defaults(func=_cmd_compare)


def _cmd_train(args) -> int:
    from nik.learn.recipe import DEFAULT_HIDDEN, SINGLE_POSE_HIDDEN, TrainCfg, train_network

    cfg = TrainCfg(
        robot=args.robot,
        end_link=args.end_link,
        root_link=args.root_link,
        minutes=args.minutes,
        data=args.data,
        out=args.out,
        name=args.name,
        runs=args.runs,
        install=args.install,
        resume=args.resume,
        kind=args.kind,
        hidden=tuple(args.hidden) if args.hidden else (SINGLE_POSE_HIDDEN if args.single_pose else DEFAULT_HIDDEN),
        heads=args.heads,
        single_pose=args.single_pose,
        single_pose_share=args.single_pose_share,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        max_steps=args.max_steps,
        val_n=args.val_n,
        steps_per_epoch=args.steps_per_epoch,
        evaluate=not args.no_eval,
        eval_batch=args.eval_batch,
        eval_one=args.eval_one,
        command=shlex.join(getattr(args, "invocation", None) or ["nik", *sys.argv[1:]]),
    )
    with notes_as_lines():  # the default tool link of a URDF and the like: one line each, as they come
        res = train_network(cfg)
    print(
        f"trained {res.kind} network for {res.wall_s / 60:.1f} min ({res.steps} steps, {res.samples / 1e6:.2f} M "
        f"samples); wrote {res.out} and {res.out.with_suffix('.json')}"
    )
    if res.single_pose is not None:
        print(f"{res.single_pose_note}: wrote {res.single_pose} (installed with it, it guesses on the CPU)")
    if res.installed is not None:
        print(f"installed as {res.installed}" + (" (its single-pose network beside it)" if res.single_pose else ""))
        for line in res.usage:
            print(f"  {line}")
    else:
        print(
            f"not installed: `nik networks install {shlex.quote(str(res.out))}` (or --install) makes nik.IKSolver "
            f"and nik solve find it for this arm; without it: "
            f"nik.IKSolver({_arm_expression(args)}, checkpoint={json.dumps(str(res.out))})"
        )
    if res.report is not None:
        print("evaluation (position mm, rotation deg; success within 0.1 mm / 0.1 deg; CPU, this process):")
        for line in res.report.lines():
            print("  " + line)
    return 0


def _arm_expression(args) -> str:
    """The Python that loads the trained arm again (:func:`nik.learn.usage.robot_expression`), else ``ARM``."""
    import warnings

    from nik.learn.usage import robot_expression
    from nik.robots import load_robot

    with warnings.catch_warnings():  # its notes were printed when training began
        warnings.simplefilter("ignore")
        robot = load_robot(args.robot, end_link=args.end_link, root_link=args.root_link)
    return robot_expression(robot, args.robot, args.end_link, root_link=args.root_link) or "ARM"


def _cmd_compare(args) -> int:
    from nik.learn.compare import compare

    compare(args)
    return 0
