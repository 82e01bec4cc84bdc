"""``nik generate`` and ``nik data info``: argument parsing only; the work is in :mod:`nik.data`."""

from __future__ import annotations

import argparse
import math

from nik.cli.common import add_robot_arguments, robot_from_args, tool_link_text

__all__ = ["register", "format_info"]


def _positive_int(text: str) -> int:
    try:
        value = int(text.replace("_", ""))
    except ValueError:
        try:
            value = float(text)  # 1e6
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
        if not value.is_integer():
            raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
        value = int(value)
    return value


def register(sub) -> None:
    g = sub.add_parser(
        "generate",
        help="generate a dataset of (joint vector, pose) pairs",
        description="Sample joint vectors, compute their poses by FK and write data/NAME/ (q.npy, pose.npy, "
        "branch.npy, meta.json). Reproducible: the same arguments give identical arrays.",
    )
    add_robot_arguments(g)
    g.add_argument("--n", required=True, type=_positive_int, help="number of samples (e.g. 1000000 or 1e6)")
    g.add_argument("--out", required=True, help="dataset directory to create, e.g. data/kuka_kr_1m")
    g.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    g.add_argument("--overwrite", action="store_true", help="replace an existing dataset at --out")
    g.add_argument(
        "--sampler", choices=["uniform", "sobol"], default="uniform", help="uniform iid (default) or scrambled Sobol"
    )
    g.add_argument(
        "--ranges",
        default="limits",
        help="'limits' (default) or a YAML file {angles: deg|rad, ranges: [[lo, hi], ...]}",
    )
    g.add_argument("--val-fraction", type=float, default=0.1, help="validation split fraction (default 0.1)")
    g.add_argument("--test-fraction", type=float, default=0.1, help="test split fraction (default 0.1)")
    g.add_argument("--dtype", choices=["float32", "float64"], default="float64", help="storage dtype (default float64)")
    g.add_argument("--device", default="cpu", help="device for FK: cpu (default) or cuda")
    g.add_argument(
        "--branch",
        type=int,
        default=None,
        metavar="K",
        help="keep only IK branch K (0..7: shoulder + 2 elbow + 4 wrist); PUMA-type arms only",
    )
    g.add_argument("--chunk-size", type=_positive_int, default=None, help="samples per chunk (memory bound)")
    g.add_argument(
        "--fk",
        choices=["auto", "eager", "compiled"],
        default="auto",
        help="FK kernel: torch.compile'd or eager; auto (default) compiles for n >= 10,000,000",
    )
    g.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads for the maths (default 1; writing runs in one more thread)",
    )
    g.add_argument(
        "--shard",
        default=None,
        metavar="I/N",
        help="write only shard I (0..N-1) of N of this dataset (whole blocks of 65,536 samples); "
        "join the N shards with nik data merge",
    )
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    g.set_defaults(func=_cmd_generate)

    d = sub.add_parser("data", help="inspect datasets", description="Inspect datasets written by nik generate.")
    dsub = d.add_subparsers(dest="data_command", metavar="SUBCOMMAND")
    info = dsub.add_parser("info", help="print a dataset's metadata and statistics")
    info.add_argument("path", help="dataset directory, e.g. data/kuka_kr_1m")
    info.add_argument("--no-verify", action="store_true", help="skip the checksum verification")
    info.set_defaults(func=_cmd_info)
    merge = dsub.add_parser(
        "merge",
        help="join the shards of nik generate --shard I/N into one dataset",
        description="Join shard directories (nik generate ... --shard I/N, made anywhere) into one dataset, "
        "identical to the one nik generate writes without --shard. Checks that the shards belong together, "
        "that each appears once and none is missing, and their checksums.",
    )
    merge.add_argument("out", help="dataset directory to create, e.g. data/kuka_kr_1m")
    merge.add_argument("shards", nargs="+", metavar="SHARD_DIR", help="the N shard directories, in any order")
    merge.add_argument("--overwrite", action="store_true", help="replace an existing dataset at OUT")
    merge.add_argument("--no-verify", action="store_true", help="skip the shards' checksum verification")
    merge.set_defaults(func=_cmd_merge)
    d.set_defaults(func=lambda args: (d.print_help(), 2)[1])


def _cmd_generate(args) -> int:
    import time

    from nik.data import DEFAULT_CHUNK, Compute, Sampling, generate_dataset

    if args.n <= 0:
        raise ValueError(f"--n must be a positive integer, got {args.n}")
    robot = robot_from_args(args)
    shard = None
    if args.shard is not None:
        from nik.data import parse_shard

        shard = parse_shard(args.shard)
    t0 = time.perf_counter()
    out = generate_dataset(
        robot,
        args.n,
        args.out,
        seed=args.seed,
        dtype=args.dtype,
        branch=args.branch,
        overwrite=args.overwrite,
        progress=None if not args.no_progress else False,
        shard=shard,
        sampling=Sampling(
            sampler=args.sampler, ranges=args.ranges, val_fraction=args.val_fraction, test_fraction=args.test_fraction
        ),
        compute=Compute(
            device=args.device,
            chunk_size=args.chunk_size or DEFAULT_CHUNK,
            compiled={"auto": "auto", "eager": False, "compiled": True}[args.fk],
            threads=args.threads,
        ),
    )
    dt = time.perf_counter() - t0
    if shard is not None:
        from nik.data import read_meta

        a, b = read_meta(out)["shard"]["rows"]
        rows = f"rows {a}..{b - 1} of {args.n}" if b > a else f"empty: {args.n} samples fill fewer blocks than shards"
        what = f"shard {shard[0]}/{shard[1]} ({rows}) of {robot.name}{tool_link_text(robot)} samples"
        print(f"wrote {what} to {out} in {dt:.1f} s ({(b - a) / dt:,.0f} samples/s)")
        return 0
    what = f"{args.n} samples of {robot.name}{tool_link_text(robot)}"
    print(f"wrote {what} to {out} in {dt:.1f} s ({args.n / dt:,.0f} samples/s)")
    return 0


def _end_text(rob: dict) -> str:
    """The arm's end as ``nik generate`` names it (:func:`nik.cli.common.tool_link_text`: ``, flange panda_link8 on
    panda_link7`` or ``, tool link NAME, tool frame at ...``), from a dataset's ``meta["robot"]``: its definition and
    the flange recorded beside it (datasets made before that record the end link only)."""
    import torch

    from nik.robots import Robot

    try:
        robot = Robot.from_definition(rob["definition"])
    except Exception:  # noqa: BLE001 - only the words of one line: the stored end link
        end = (rob.get("definition") or {}).get("end_link")
        return f", tool link {end}" if end else ""
    flange = rob.get("flange")
    if isinstance(flange, dict) and flange.get("link"):
        robot.flange_link, robot.flange = flange["link"], torch.tensor(flange["frame"], dtype=torch.float64)
    text = tool_link_text(robot)
    return f", {text[2:-1]}" if text else ""


def format_info(ds) -> str:
    """The text ``nik data info`` prints for a loaded dataset."""
    import numpy as np

    from nik.data import branch_name

    m = ds.meta
    rob = m["robot"]
    lines = [
        f"dataset    {ds.path}",
        f"robot      {rob['name']} (definition {rob['definition_hash']}, {m['dof']} joints{_end_text(rob)})",
        f"samples    {m['n']:,}  (train {m['split_sizes']['train']:,}, val {m['split_sizes']['val']:,}, "
        f"test {m['split_sizes']['test']:,}; contiguous ranges {m['splits']})",
        f"sampler    {m['sampler']}, seed {m['seed']}, ranges: {m['ranges']['source']}",
        f"dtype      {m['dtype']} (FK in {m['fk']['dtype']} on {m['fk']['device']})",
        f"created    {m['created']} with nik {m['nik_version']}",
        "checksums  " + ", ".join(f"{k} sha256:{v['sha256'][:12]}" for k, v in m["files"].items()),
    ]
    names = rob["definition"].get("joint_names") or [f"joint{i + 1}" for i in range(m["dof"])]
    q = np.asarray(ds.q)
    pos = np.asarray(ds.pose[:, :3, 3])
    qmin, qmax = _chunked_minmax(q)
    pmin, pmax = _chunked_minmax(pos)
    rng = np.asarray(m["ranges"]["radians"])
    prismatic = rob["definition"].get("prismatic") or [False] * m["dof"]
    lines.append("")
    if any(prismatic):  # slides in mm, said in a last column
        head = f"{'joint':<12}{'min':>12}{'max':>12}{'range lo':>16}{'range hi':>16}  unit"
    else:
        head = f"{'joint':<12}{'min (deg)':>12}{'max (deg)':>12}{'range lo (deg)':>16}{'range hi (deg)':>16}"
    lines.append(head)
    for i, name in enumerate(names):
        f = 1e3 if prismatic[i] else 180.0 / math.pi
        lines.append(
            f"{name:<12}{qmin[i] * f:>12.3f}{qmax[i] * f:>12.3f}{rng[i, 0] * f:>16.3f}{rng[i, 1] * f:>16.3f}"
            + (f"  {'mm' if prismatic[i] else 'deg'}" if any(prismatic) else "")
        )
    lines.append("")
    lines.append(f"{'workspace':<12}{'min (mm)':>12}{'max (mm)':>12}{'extent (mm)':>14}")
    for i, ax in enumerate("xyz"):
        lines.append(f"{ax:<12}{pmin[i] * 1e3:>12.1f}{pmax[i] * 1e3:>12.1f}{(pmax[i] - pmin[i]) * 1e3:>14.1f}")
    reach = _chunked_max_norm(pos)
    lines.append(f"{'max |p|':<12}{'':>12}{reach * 1e3:>12.1f}")
    if m.get("branch"):
        b = m["branch"]
        lines.append("")
        filt = (
            "all branches"
            if b["filter"] is None
            else f"only branch {b['filter']} ({branch_name(b['filter'])}), {b['candidates']:,} candidates drawn"
        )
        lines.append(f"IK branch labels (shoulder + 2 elbow + 4 wrist): {filt}")
        total = max(1, sum(b["counts"]))
        for k, c in enumerate(b["counts"]):
            if c:
                lines.append(f"  {k}  {branch_name(k):<16}{c:>12,}  {100 * c / total:6.2f} %")
    return "\n".join(lines)


def _chunked_minmax(a, chunk: int = 1 << 20):
    import numpy as np

    lo = np.full(a.shape[1], np.inf)
    hi = np.full(a.shape[1], -np.inf)
    for i in range(0, a.shape[0], chunk):
        part = np.asarray(a[i : i + chunk], dtype=np.float64)
        lo = np.minimum(lo, part.min(0))
        hi = np.maximum(hi, part.max(0))
    return lo, hi


def _chunked_max_norm(a, chunk: int = 1 << 20) -> float:
    import numpy as np

    best = 0.0
    for i in range(0, a.shape[0], chunk):
        part = np.asarray(a[i : i + chunk], dtype=np.float64)
        best = max(best, float(np.sqrt((part**2).sum(1)).max()))
    return best


def _cmd_merge(args) -> int:
    from nik.data import merge_shards, read_meta

    out = merge_shards(args.out, args.shards, overwrite=args.overwrite, verify=not args.no_verify)
    n = read_meta(out)["n"]
    print(f"merged {len(args.shards)} shards into {out} ({n} samples)")
    return 0


def _cmd_info(args) -> int:
    from nik.data import load_dataset

    ds = load_dataset(args.path, verify=not args.no_verify)
    print(format_info(ds))
    return 0
