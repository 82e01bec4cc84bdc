"""``nik view``: argument parsing only; the page is :class:`nik.view.Viewer` (viser, the ``view`` extra)."""

from __future__ import annotations

import sys

from nik.cli.common import add_root_link_argument
from nik.cli.scene import add_scene_argument, world_from_args
from nik.cli.solve import read_poses_csv

__all__ = ["register"]


def register(sub) -> None:
    v = sub.add_parser(
        "view",
        help="the arm at its IK solution in a browser page: drag the target, see every solution, play a path",
        description="Serve a page (viser) showing ROBOT at the solution of a target pose: URDF meshes where the "
        "mesh files are there, else capsules between the joint origins. Drag the target with the mouse: the arm "
        "follows (one solve per move, from the current joints) and the panel shows success, the errors (mm, deg) "
        "and the joint angles (deg); every solution of the pose is drawn faint. --poses: a slider over the poses of "
        "a CSV; --path: the waypoints of a CSV solved in order and played back. Runs until Ctrl-C. Needs the "
        "optional extra: pip install 'nik-ik[view]'.",
    )
    v.add_argument("robot", metavar="ROBOT", help="built-in robot name, YAML robot file or URDF")
    v.add_argument("--end-link", default=None, metavar="LINK", help="URDF: the tool link")
    add_root_link_argument(v)
    v.add_argument(
        "--checkpoint",
        default="auto",
        help="network for the guess: auto (default, as nik solve), none, or NAME.safetensors / a .ckpt",
    )
    src = v.add_mutually_exclusive_group()
    src.add_argument("--poses", metavar="FILE.csv", help="poses to choose from (header x,y,z,qw,qx,qy,qz)")
    src.add_argument("--path", metavar="FILE.csv", help="waypoints of a path to play back (same columns)")
    v.add_argument("--unit", choices=["m", "mm"], default="m", help="unit of the CSV positions (default m)")
    v.add_argument("--port", type=int, default=8080, help="TCP port (default 8080; 0: any free port)")
    v.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    v.add_argument("--seed", type=int, default=0, help="random seed of the solver and the first pose (default 0)")
    add_scene_argument(v)
    v.set_defaults(func=_cmd_view)


def _cmd_view(args) -> int:
    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port must be in 0..65535, got {args.port}")
    from nik.view import VIEW_EXTRA_MESSAGE, Viewer, ViewerCfg, viser_available

    if not viser_available():  # before any work: one line, exit 2
        print(VIEW_EXTRA_MESSAGE, file=sys.stderr)
        return 2
    from nik.cli.common import robot_from_args, tool_link_text
    from nik.ik import as_poses
    from nik.solver import IKSolver

    def targets(file):
        if file is None:
            return None
        xyzq = read_poses_csv(file)
        if args.unit == "mm":
            xyzq[:, :3] *= 1e-3
        return as_poses(xyzq, "quat", name=str(file))

    robot = robot_from_args(args)
    poses, path = targets(args.poses), targets(args.path)
    checkpoint = None if str(args.checkpoint).lower() == "none" else args.checkpoint
    solver = IKSolver(robot, checkpoint=checkpoint, world=world_from_args(args))
    viewer = Viewer(solver, cfg=ViewerCfg(host=args.host, port=args.port, seed=args.seed), poses=poses, path=path)
    print(f"nik view: {robot.name}{tool_link_text(robot)} at {viewer.url} (Ctrl-C stops)", flush=True)
    try:
        viewer.serve_forever()  # stops the server on the way out
    except KeyboardInterrupt:  # Ctrl-C is how a page is closed: not an error
        pass
    return 0
