"""End-to-end evaluation on a dataset's held-out test split: the table users compare.

:func:`evaluate` solves the same test poses with every pipeline and measures each the same
way (FK of the returned joints against the target): the default pipeline (``IKSolver(robot)``, what
users run), LM multistart without a network, the network alone, the network plus each refinement,
the uniform-init swarm (no network), the closed form (PUMA-like arms) and pytorch-kinematics'
``PseudoInverseIK`` as a peer. Each row is timed after a warm-up call, once the kernels have compiled (a first
run waits for their background compile, :mod:`nik.kernels.background`, and says so in a note), and says the guess
that really served it, and where the solver set its network aside, that it did and what guessed instead.
:func:`write_report` writes the Markdown table, a JSON copy and a cumulative error plot.

The evaluation room: it may import every room below it (robots, data, nets, analytic, ik, learn); only the
cli imports it.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from nik.poses import matrix_to_rpy, pose_error, rpy_to_matrix
from nik.robots import Robot, load_robot
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT, score

__all__ = [
    "EvalHooks",
    "EvalRow",
    "EvalReport",
    "evaluate",
    "markdown_table",
    "plot_errors",
    "robot_to_urdf",
    "write_report",
]

#: Refinement methods evaluated after the network, in table order.
REFINEMENTS = ("lm", "pso", "sapso", "ipso", "ga")
#: Targets of the warm-up call before each timed one: the same pipeline on the first of the test poses, so that no
#: row carries one-time costs (compiled kernels loaded, caches filled, first allocations). Batches above
#: 10,000 poses may take another path than the warm-up (the compiled one stops there: ``nik.ik.lean``).
WARMUP_TARGETS = 16


@dataclass(frozen=True)
class EvalHooks:
    """What :func:`evaluate` tells as it runs: ``progress(message)`` before each row, ``on_row(report)`` after each
    row is added (the CLI writes the table there); None: nothing."""

    progress: object = None
    on_row: object = None


@dataclass
class EvalRow:
    """One pipeline's results on the test poses. Errors in mm and degrees (human-facing)."""

    method: str
    n: int
    success_1mm_1deg: float  # fraction within 1 mm and 1 degree
    success_01mm_01deg: float  # fraction within 0.1 mm and 0.1 degree
    pos_mm: dict  # percentiles p50, p95, p99, max of the position error, mm
    rot_deg: dict  # the same for the geodesic rotation error, degrees
    outside_limits: int  # number of returned joint vectors with a joint outside its limits
    ms_per_target: float  # wall time of the batched call divided by n, milliseconds
    note: str = ""


@dataclass
class EvalReport:
    """All rows plus the raw errors (for the plot) and what was left out and why."""

    robot: str
    data: str
    n: int
    rows: list[EvalRow] = field(default_factory=list)
    errors: dict = field(default_factory=dict)  # method -> (pos_mm ndarray, rot_deg ndarray)
    notes: list[str] = field(default_factory=list)
    device: str = "cpu"
    threads: int = 1
    end_link: str | None = None  # the tool link of a URDF arm
    network: str = ""  # the network of the network rows: "shipped network for NAME", a path, or "" (none)


def _row(method: str, robot: Robot, T: torch.Tensor, q: torch.Tensor, seconds: float, note: str = "") -> tuple:
    q = q.to(T.dtype)
    pos, rot = pose_error(T, robot.fk(q))
    pos_mm = (pos * 1e3).cpu().numpy()
    rot_deg = np.degrees(rot.cpu().numpy())

    def pct(a):
        return {
            "p50": float(np.percentile(a, 50)),
            "p95": float(np.percentile(a, 95)),
            "p99": float(np.percentile(a, 99)),
            "max": float(a.max()),
        }

    n = int(T.shape[0])
    row = EvalRow(
        method=method,
        n=n,
        success_1mm_1deg=float(((pos_mm <= 1.0) & (rot_deg <= 1.0)).mean()),
        success_01mm_01deg=float(((pos_mm <= 0.1) & (rot_deg <= 0.1)).mean()),
        pos_mm=pct(pos_mm),
        rot_deg=pct(rot_deg),
        outside_limits=int((~robot.within_limits(q)).sum()),
        ms_per_target=1e3 * seconds / max(n, 1),
        note=note,
    )
    return row, (pos_mm, rot_deg)


def _timed(fn, device: torch.device | None = None):
    sync = torch.cuda.synchronize if device is not None and device.type == "cuda" else (lambda: None)
    sync()
    t0 = time.perf_counter()
    out = fn()
    sync()
    return out, time.perf_counter() - t0


# ---------------------------------------------------------------------------
# pytorch-kinematics peer
# ---------------------------------------------------------------------------
def robot_to_urdf(robot: Robot) -> tuple[str, str]:
    """A URDF string with the same FK as ``robot`` (from its normal form), and its end link name.

    Joint ``i`` sits at origin ``G_{i-1} Rz(offset_i)`` (prismatic: ``G_{i-1} Tz(offset_i)``) of its
    parent link and turns about (slides along) z; a fixed joint with origin ``G_n`` carries the tool link.
    A URDF arm's rotations, parsed through float32, are orthonormal to about 1e-7 only: each is written as
    the nearest rotation, so the FK agrees to about 1e-7 there (exactly for arms defined by parameters).

    Raises:
        RuntimeError: a transform has no roll-pitch-yaw form that reproduces it (not seen on any arm).
    """
    G, off = robot.G.numpy(), robot.offsets.numpy()
    lim = robot.limits.numpy()
    prismatic = robot.prismatic.tolist()

    def origin(M: np.ndarray) -> str:
        rpy = matrix_to_rpy(torch.as_tensor(M[:3, :3])).numpy()
        xyz = M[:3, 3]
        xyz_s, rpy_s = " ".join(f"{v:.17g}" for v in xyz), " ".join(f"{v:.17g}" for v in rpy)
        return f'<origin xyz="{xyz_s}" rpy="{rpy_s}"/>'

    def rz(t: float) -> np.ndarray:
        M = np.eye(4)
        M[:2, :2] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
        return M

    def tz(d: float) -> np.ndarray:
        M = np.eye(4)
        M[2, 3] = d
        return M

    def rx(t: float) -> np.ndarray:
        M = np.eye(4)
        M[1:3, 1:3] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
        return M

    def rpy_safe(M: np.ndarray) -> list[np.ndarray]:
        """``M`` as a product of one or two transforms whose roll-pitch-yaw round-trips exactly
        (pitch = +-90 deg loses roll and yaw)."""
        generic = rz(0.3) @ rx(0.7)
        M = M.copy()
        U, _, Vt = np.linalg.svd(M[:3, :3])
        M[:3, :3] = U @ Vt  # the nearest rotation (float32-parsed URDF origins are off by ~1e-7)
        for pre in (None, rx(math.pi / 2), rx(-math.pi / 2), generic):
            parts_ = [M] if pre is None else [M @ np.linalg.inv(pre), pre]
            ok = True
            for P in parts_:
                R = torch.as_tensor(P[:3, :3])
                back = rpy_to_matrix(matrix_to_rpy(R)).numpy()
                ok &= bool(np.abs(back - P[:3, :3]).max() < 1e-12)
            if ok:
                return parts_
        raise RuntimeError("robot_to_urdf: no roll-pitch-yaw form found")

    parts = [f'<robot name="{robot.name}">', '<link name="link0"/>']
    for i in range(robot.dof):
        first, *rest = rpy_safe(G[i] @ (tz(off[i]) if prismatic[i] else rz(off[i])))
        parent = f"link{i}"
        if rest:  # an intermediate fixed frame
            parts.append(f'<link name="link{i}_fixed"/>')
            parts.append(
                f'<joint name="fixed{i}" type="fixed"><parent link="link{i}"/><child link="link{i}_fixed"/>'
                f"{origin(first)}</joint>"
            )
            parent, first = f"link{i}_fixed", rest[0]
        parts.append(f'<link name="link{i + 1}"/>')
        parts.append(
            f'<joint name="{robot.joint_names[i]}" type="{"prismatic" if prismatic[i] else "revolute"}">'
            f'<parent link="{parent}"/><child link="link{i + 1}"/>'
            f'{origin(first)}<axis xyz="0 0 1"/>'
            f'<limit lower="{lim[i, 0]:.17g}" upper="{lim[i, 1]:.17g}" effort="1" velocity="1"/></joint>'
        )
    tool_parts = rpy_safe(G[robot.dof])
    parent = f"link{robot.dof}"
    for k, P in enumerate(tool_parts):
        child = "tool" if k == len(tool_parts) - 1 else "tool_fixed"
        parts.append(f'<link name="{child}"/>')
        parts.append(
            f'<joint name="{child}_joint" type="fixed"><parent link="{parent}"/><child link="{child}"/>'
            f"{origin(P)}</joint>"
        )
        parent = child
    parts.append("</robot>")
    return "\n".join(parts), "tool"


def _pk_solve(
    robot: Robot,
    T: torch.Tensor,
    *,
    tol_pos: float,
    tol_rot: float,
    seed: int,
    retries: int = 10,
    max_iterations: int = 50,
) -> tuple[torch.Tensor, float, str]:
    """pytorch-kinematics ``PseudoInverseIK`` on ``T: (B, 4, 4)``: the best retry per target and the seconds."""
    import pytorch_kinematics as pk  # the peer baseline, only on this code path

    from nik.robots.urdf import build_pk_chain

    text, end = robot_to_urdf(robot)
    chain = build_pk_chain(text, end).to(dtype=T.dtype, device=T.device)
    # the chain must reproduce nik's FK, else the comparison is meaningless
    qc = robot.sample(16, generator=torch.Generator().manual_seed(0), dtype=T.dtype, device=T.device)
    ref = robot.fk(qc)
    got = chain.forward_kinematics(qc).get_matrix()
    if float((ref - got).abs().max()) > 1e-6:  # pytorch-kinematics parses origins in float32 (about 1e-8 m)
        raise RuntimeError(f"generated URDF does not reproduce the FK of {robot.name!r}")
    torch.manual_seed(seed)  # pk draws its retry configurations from the global generator
    ik = pk.PseudoInverseIK(
        chain,
        pos_tolerance=tol_pos,
        rot_tolerance=tol_rot,
        num_retries=retries,
        max_iterations=max_iterations,
        joint_limits=robot.limits.to(device=T.device, dtype=T.dtype),
        early_stopping_any_converged=True,
    )
    ik.solve(pk.Transform3d(matrix=T[:WARMUP_TARGETS]))  # a warm-up call, as every row has
    torch.manual_seed(seed)
    target = pk.Transform3d(matrix=T)
    sol, seconds = _timed(lambda: ik.solve(target), T.device)
    err = score(sol.err_pos, sol.err_rot)  # (B, retries)
    idx = err.argmin(-1)
    q = torch.gather(sol.solutions, 1, idx[:, None, None].expand(-1, 1, robot.dof)).squeeze(1)
    note = f"PseudoInverseIK, {retries} retries, {max_iterations} iterations"
    return q, seconds, note


# ---------------------------------------------------------------------------
# The evaluation
# ---------------------------------------------------------------------------
def _set_aside(solver, robot: Robot, source: str) -> str:
    """``"network set aside: ..."`` where ``solver`` has a network but another guess served (``source``): the solver
    judged it no better a start than uniform configurations (:mod:`nik.ik.judge`, figures quoted) and solved as
    without it; ``""`` where the network guessed or there is none."""
    net = getattr(solver, "net", None)
    if net is None or source == "network":
        return ""
    instead = {"analytic": "the closed form", "multistart": "uniform starts"}.get(source, source)
    why = "by the solver"
    try:
        from nik.ik.judge import verdict
        from nik.ik.plan import in_arm_frame

        v = verdict(net, robot.arm if in_arm_frame(robot, net) else robot)
        if not v.earns:
            why = (
                f"by the solver: no better a start than uniform configurations (the better start on {v.wins:.0%} of "
                f"{v.probes} probe poses)"
            )
    except (ImportError, AttributeError, TypeError, ValueError):  # the figures only; the fact stands without them
        pass
    return f"network set aside {why}; {instead} guessed instead"


def _network_rows_solver(robot: Robot, checkpoint, report: EvalReport) -> dict | None:
    """The :class:`IKSolver` keywords of the network rows, or None (said in a note) when there is no network.

    ``checkpoint``: ``"auto"``, the network ``IKSolver(robot)`` finds for this robot's definition hash (one installed
    in the user folder, else the one shipped: :func:`nik.nets.registry.find_network`; used here on arms with a
    closed form too, where the solver's default keeps the closed form); ``None`` or ``"none"``, no network; else
    a path.
    """
    from nik.nets.registry import SHIPPED_DIR, find_network

    word = checkpoint.lower() if isinstance(checkpoint, str) else None
    if checkpoint is None or word == "none":
        report.notes.append("no network (checkpoint none): the network rows are missing")
        return None
    if word == "auto":
        path = find_network(robot)
        if path is None:
            report.notes.append(
                f"no network shipped with nik or installed for {robot.name} (definition hash "
                f"{robot.definition_hash}): the network rows are missing"
            )
            return None
        where = "shipped" if path.parent.resolve() == SHIPPED_DIR.resolve() else "installed"
        report.network = f"{where} network for {robot.name}'s definition hash, {path}"
        return {"checkpoint": "auto", "analytic": False}
    report.network = str(checkpoint)
    return {"checkpoint": checkpoint}


def evaluate(
    robot: Robot | str | Path,
    *,
    data: str | Path | tuple,
    checkpoint: str | Path | None = None,
    n: int = 1000,
    refinements: tuple[str, ...] = REFINEMENTS,
    swarm: str = "ipso",
    include_pk: bool = True,
    tol_pos: float = DEFAULT_TOL_POS,
    tol_rot: float = DEFAULT_TOL_ROT,
    seed: int = 0,
    device: str | torch.device = "cpu",
    hooks: EvalHooks | None = None,
) -> EvalReport:
    """Evaluate every pipeline on the first ``n`` poses of a dataset's test split (or another one).

    Args:
        robot: the arm (object, built-in name or file); the dataset and checkpoint must match it.
        data: dataset directory (``nik generate``), evaluated on its ``"test"`` split; or ``(directory, split)`` for
            another split (``"train"``, ``"val"``).
        checkpoint: the network of the network rows: ``"auto"``, the one installed or shipped with nik for this
            robot's definition hash (as ``IKSolver(robot)`` finds it); a path to a trained network; ``None`` /
            ``"none"``: no network rows (a note says why). The rows "default pipeline" (``IKSolver(robot)``,
            whatever it finds) and "LM multistart, no network" are there whatever it is; the rows that say "no
            network" (LM multistart, uniform-init swarm, closed form) use none whatever is installed.
        n: number of test poses.
        refinements: methods run after the network (``lm``, ``pso``, ``sapso``, ``ipso``, ``ga``).
        swarm: the uniform-init swarm row's method (no network).
        include_pk: add pytorch-kinematics' ``PseudoInverseIK`` as a peer.
        tol_pos, tol_rot: tolerances the refinements stop at (metres, radians).
        hooks: :class:`EvalHooks`, the callables told as the evaluation runs: ``progress(message)`` before each
            row, ``on_row(report)`` after each row is added (the CLI writes the table
            there, so rows already computed survive a failure in a later one).
        device: where every pipeline computes (``"cpu"``, ``"cuda"``); timings synchronise the GPU.

    Every row is timed after a warm-up call of the same pipeline on the first :data:`WARMUP_TARGETS` poses; where that
    call started the kernels' compile in the background (a cold cache), the evaluation waits for it and warms up once
    more, so no row carries the compile (a note says how long it waited). Its note starts with the guess that really
    served (``guess network | analytic | multistart``: the result's ``source``, not the solver's configuration), then,
    where the solver had a network and another guess served, ``network set aside ...`` and what guessed instead.

    Returns:
        :class:`EvalReport`.
    """
    from nik.data import load_dataset
    from nik.device import resolve_device
    from nik.solver import IKSolver

    dev = resolve_device(device)
    robot = load_robot(robot) if not isinstance(robot, Robot) else robot
    if not isinstance(data, str | Path) and not (isinstance(data, tuple | list) and len(data) == 2):
        raise ValueError(f"data: expected a dataset directory or (directory, split), got {data!r:.80}")
    data, split = (data, "test") if isinstance(data, str | Path) else data
    ds = load_dataset(data, robot=robot)
    part = ds.split(split)
    if len(part) == 0:
        raise ValueError(f"{data}: the {split!r} split is empty")
    n = min(int(n), len(part))
    T = part.pose[:n].to(device=dev, dtype=torch.float64).clone()
    report = EvalReport(
        robot=robot.name,
        data=str(data),
        n=n,
        threads=torch.get_num_threads(),
        device=str(dev),
        end_link=robot.end_link,
    )
    hooks = hooks or EvalHooks()
    say = hooks.progress or (lambda msg: None)
    on_row = hooks.on_row

    def add(method: str, q: torch.Tensor, seconds: float, note: str = "") -> None:
        row, errs = _row(method, robot, T, q, seconds, note)
        report.rows.append(row)
        report.errors[method] = errs
        if on_row is not None:
            on_row(report)

    compile_wait = [0.0]  # seconds the warm-up calls waited for the kernels' first compile

    def warm_up(solver, kw) -> None:
        """The warm-up call on the first targets (one-time costs: kernels, caches, first allocations). Where it started
        the kernels' compile in the background (:mod:`nik.kernels.background`: the call was answered by torch), wait
        for the compile to end and call again, so that the timed call runs the compiled kernels, not torch beside a
        compiling thread (a first run's rows were up to 200x slower than a rerun's)."""
        from nik.kernels import background

        head = T[: min(n, WARMUP_TARGETS)]
        solver.solve(head, **kw)
        t0 = time.perf_counter()
        if background.BUSY and background.wait():
            compile_wait[0] += time.perf_counter() - t0
            solver.solve(head, **kw)  # now on the compiled kernels

    def solve_row(method: str, solver, note=None) -> None:
        """Time ``solver.solve(T)`` after a warm-up call on the first targets (and after the kernels' compile); the
        note starts with the guess that really served (``res.source``), then, where the solver has a network that
        did not guess, that it was set aside (:func:`_set_aside`), then ``note`` (a string, or a function of the
        result)."""
        kw = {"tol_pos": tol_pos, "tol_rot": tol_rot, "seed": seed}
        warm_up(solver, kw)
        res, sec = _timed(lambda: solver.solve(T, **kw), dev)
        extra = note(res) if callable(note) else note
        parts = [f"guess {res.source}", _set_aside(solver, robot, res.source), extra]
        add(method, res.q, sec, "; ".join(p for p in parts if p))

    say("default pipeline")
    solver = IKSolver(robot, device=dev)
    solve_row("default pipeline", solver, f"IKSolver(robot): refine lm, fallback {solver.fallback}")
    say("LM multistart, no network")
    solve_row(
        "LM multistart, no network",
        IKSolver(robot, checkpoint=None, analytic=False, device=dev),
        "IKSolver(robot, checkpoint=None, analytic=False): LM from uniform starts, restarts where it fails",
    )
    net_kw = _network_rows_solver(robot, checkpoint, report)
    if net_kw is not None:
        say("network")
        solve_row("network", IKSolver(robot, **net_kw, device=dev, refine="none"), "no refinement")
        for method in refinements:
            say(f"network + {method}")
            polish = " + LM polish" if method != "lm" else ""
            solve_row(
                f"network + {method}",
                IKSolver(robot, **net_kw, device=dev, refine=method, fallback=False),
                lambda res, polish=polish: f"mean {res.iterations.float().mean():.1f} iterations{polish}",
            )
        say("network + lm + LM restarts")
        solve_row(
            "network + lm + LM restarts",
            IKSolver(robot, **net_kw, device=dev, refine="lm", fallback="multistart"),
            "targets LM misses from the guess restart from uniform starts (fallback multistart, not the closed form)",
        )
    if swarm == "lm":
        report.notes.append("uniform-init lm is the row 'LM multistart, no network'")
    else:
        say(f"uniform-init {swarm}")
        solve_row(
            f"uniform-init {swarm}",
            IKSolver(robot, checkpoint=None, refine=swarm, analytic=False, fallback="none", device=dev),
            lambda res: f"no network; mean {float(res.iterations.float().mean()):.1f} iterations + LM polish",
        )
    from nik.analytic import family

    if family(robot) is not None:
        say("analytic")
        solve_row(
            "analytic (closed form)",
            IKSolver(robot, checkpoint=None, refine="none", device=dev),
            "all 8 solutions, FK-verified; the most central valid one",
        )
    else:
        report.notes.append(
            f"{robot.name} has no closed form (no spherical wrist, no three parallel axes): no closed-form row"
        )
    if include_pk:
        say("pytorch-kinematics")
        try:
            q, sec, note = _pk_solve(robot, T, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed)
            add("pytorch-kinematics", q, sec, note)
        except Exception as err:  # a peer that cannot be built or run costs its row, never the others
            why = " ".join(f"{type(err).__name__}: {err}".split())
            report.notes.append(f"pytorch-kinematics row skipped: {why}")
    waited = (
        f"this run waited {compile_wait[0]:.1f} s for the kernels' first compile before timing"
        if compile_wait[0] > 0
        else "the kernels were compiled before timing"
    )
    report.notes.append(
        f"every row is timed after a warm-up call of its solver on the first {min(n, WARMUP_TARGETS)} poses, once "
        f"the kernels have compiled ({waited}): no row carries one-time costs"
    )
    return report


# ---------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------
def _fmt(x: float) -> str:
    if x == 0:
        return "0"
    if abs(x) >= 100:
        return f"{x:.0f}"
    if abs(x) >= 0.01:
        return f"{x:.3g}"
    return f"{x:.1e}"


def _threads(n: int) -> str:
    return f"{n} thread" if n == 1 else f"{n} threads"


def markdown_table(report: EvalReport) -> str:
    """The report as a Markdown table (errors in mm and degrees, success in percent)."""
    tool = f" (tool link `{report.end_link}`)" if report.end_link else ""
    net = f" Network rows: {report.network}." if report.network else ""
    lines = [
        f"Robot `{report.robot}`{tool}, {report.n} poses of the test split of `{report.data}`, "
        f"CPU ({_threads(report.threads)}), float64.{net}",
        "",
        "| method | success 1 mm / 1 deg | success 0.1 mm / 0.1 deg | position error mm (p50 / p95 / p99 / max) "
        "| rotation error deg (p50 / p95 / p99 / max) | joints outside limits | ms / target | note |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in report.rows:
        pos = " / ".join(_fmt(r.pos_mm[k]) for k in ("p50", "p95", "p99", "max"))
        rot = " / ".join(_fmt(r.rot_deg[k]) for k in ("p50", "p95", "p99", "max"))
        lines.append(
            f"| {r.method} | {100 * r.success_1mm_1deg:.2f} % | {100 * r.success_01mm_01deg:.2f} % | {pos} | {rot} "
            f"| {r.outside_limits} | {r.ms_per_target:.3f} | {r.note} |"
        )
    for note in report.notes:
        lines.append(f"\nNote: {note}.")
    return "\n".join(lines) + "\n"


#: Line styles and markers of the cumulative plot. The colour cycles every 10 lines; the marker steps one further
#: at each round of colours, so no two of the first 100 lines share colour and marker (the line style cycles on
#: its own), and a line lying on another still shows its markers.
_LINESTYLES = ("-", "--", "-.", ":")
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">")


def line_style(i: int, n: int, colours: list[str]) -> dict:
    """Matplotlib style of the ``i``-th of ``n`` lines: its colour, marker and line style. Colour ``i`` and marker
    ``i + i // len(colours)`` (each modulo its count) never repeat together for ``len(colours) * len(_MARKERS)``
    lines (100 with matplotlib's 10 colours); markers are staggered so that lines on top of each other show
    theirs at different places."""
    return {
        "color": colours[i % len(colours)],
        "linestyle": _LINESTYLES[i % len(_LINESTYLES)],
        "marker": _MARKERS[(i + i // len(colours)) % len(_MARKERS)],
        "markevery": (0.03 + 0.15 * i / max(n, 1), 1 / 6),
        "markersize": 5,
        "linewidth": 1.4,
    }


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def plot_errors(report: EvalReport, path: str | Path) -> Path:
    """Cumulative error plot: for each method the percentage of targets whose position error (mm, left)
    and rotation error (deg, right) is at most x, x on a log axis. Every method has its own colour, line
    style and marker (markers staggered along the line), so a line that lies on another stays visible.
    Errors below 1e-12 are drawn at 1e-12. Returns ``path`` (written to a temporary name, then renamed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    floor = 1e-12
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), sharey=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    methods = list(report.errors)
    for i, method in enumerate(methods):
        style = {**line_style(i, len(methods), colours), "drawstyle": "steps-post", "label": method}
        for ax, vals in zip(axes, report.errors[method], strict=True):
            v = np.sort(np.maximum(np.asarray(vals, dtype=float), floor))
            if v.size == 0:
                continue
            y = 100.0 * np.arange(1, v.size + 1) / v.size
            ax.plot(v, y, **style)
    for ax, what, unit in zip(axes, ("position", "rotation"), ("mm", "deg"), strict=True):
        ax.set_xscale("log")
        ax.set_xlim(floor / 2, None)
        ax.set_ylim(0, 101)
        ax.set_xlabel(f"{what} error ({unit}), log scale; below 1e-12 drawn at 1e-12")
        ax.axvline(0.1, color="k", linestyle=":", linewidth=1)
        ax.axvline(1.0, color="0.6", linestyle=":", linewidth=1)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_ylabel("targets with error <= x (%)")
    axes[1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    fig.suptitle(
        f"{report.robot}: cumulative IK errors on {report.n} test poses (dotted: 0.1 and 1 mm / deg; higher and "
        "further left is better)",
        fontsize=10,
    )
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return path


def write_report(report: EvalReport, out: str | Path, *, plot: bool = True) -> dict[str, Path]:
    """Write ``evaluation.md``, ``evaluation.json`` and (``plot``) ``errors.png`` (:func:`plot_errors`) into ``out``.

    Returns the paths under ``markdown``, ``json`` and ``plot`` (also under ``histogram``, its former name).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"markdown": out / "evaluation.md", "json": out / "evaluation.json", "plot": out / "errors.png"}
    paths["histogram"] = paths["plot"]
    _write_atomic(paths["markdown"], markdown_table(report))
    data = {k: v for k, v in asdict(report).items() if k != "errors"}
    _write_atomic(paths["json"], json.dumps(data, indent=2))
    if plot:
        plot_errors(report, paths["plot"])
    return paths
