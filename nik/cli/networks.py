"""``nik networks``: list the installed and shipped networks, install an exported pair, remove an installed one.

Argument parsing and printing only; the work is in :mod:`nik.nets.registry` (and :mod:`nik.learn.usage` for the
lines that say how to solve with a network once it is installed).
"""

from __future__ import annotations

__all__ = ["register"]


def register(sub) -> None:
    p = sub.add_parser(
        "networks",
        help="list the installed and shipped networks (default), install an exported pair, remove an installed one",
        description="Networks live in two folders: the user folder ($NIK_HOME/networks, else "
        "~/.local/share/nik/networks) and the one shipped inside nik. IKSolver(robot) takes the first whose "
        "recorded robot hash is the arm's definition hash (the user folder first; the name does not matter); on an "
        "arm with a closed form the closed form stays the default guess (checkpoint=PATH uses the network).",
    )
    acts = p.add_subparsers(dest="action", metavar="ACTION")
    acts.add_parser("list", help="the installed and shipped networks: arm, robot hash, kind, recorded error, file")
    i = acts.add_parser(
        "install",
        help="copy an exported pair (NAME.safetensors + NAME.json) into the user folder, checked first",
        description="Check the pair (format, SHA-256 of the weights, robot definition, architecture: a damaged or "
        "foreign file is refused) and copy both files into the user folder.",
    )
    i.add_argument("pair", metavar="PAIR.safetensors", help="the .safetensors (or .json) of an exported pair")
    i.add_argument("--name", default=None, help="installed file name (default: the recorded robot name)")
    r = acts.add_parser("remove", help="delete an installed network (a shipped one cannot be removed)")
    r.add_argument("name", metavar="NAME", help="the installed network's name (as nik networks list shows it)")
    p.set_defaults(func=_cmd_networks)


def _error(info) -> str:
    if info.pos_mm is None or info.rot_deg is None:
        return "not recorded"
    return f"{info.pos_mm:.2f} mm / {info.rot_deg:.2f} deg"


def _cmd_list() -> int:
    from nik.nets.registry import SHIPPED_DIR, list_networks, user_dir

    rows = [("name", "arm", "robot hash", "kind", "recorded error (median)", "where", "file")]
    for n in list_networks():
        kind = n.kind if not n.problem else f"unreadable: {n.problem}"
        rows.append((n.name, n.robot, n.robot_hash or "?", kind, _error(n), n.where, str(n.path)))
    print(f"user folder: {user_dir()}; shipped: {SHIPPED_DIR}")
    if len(rows) == 1:
        print("no networks")
        return 0
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]) - 1)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=False)) + "  " + row[-1])
    return 0


def _cmd_install(pair: str, name: str | None) -> int:
    from nik.learn.usage import network_usage, recorded_source
    from nik.nets.pair import read_pair_meta
    from nik.nets.registry import install
    from nik.robots import Robot

    installed = install(pair, name=name)  # checked in full first (load_pair)
    meta = read_pair_meta(installed)
    robot = Robot.from_definition(meta["robot_definition"])
    print(f"installed {installed} (arm {robot.name}, robot hash {robot.definition_hash})")
    source, end_link = recorded_source(meta)  # the arm file of the recorded nik train command, where it is here
    for line in network_usage(robot, installed, source=source, end_link=end_link):
        print(f"  {line}")
    return 0


def _cmd_networks(args) -> int:
    action = args.action or "list"
    if action == "install":
        return _cmd_install(args.pair, args.name)
    if action == "remove":
        from nik.nets.registry import remove

        for path in remove(args.name):
            print(f"removed {path}")
        return 0
    return _cmd_list()
