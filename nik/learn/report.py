"""Does a trained network pay for itself? The figures ``nik train`` prints when it has exported one.

:func:`network_report` measures, on targets from uniform joints inside the limits (seeded):

1. the **raw network**: median and p95 of the position (mm) and rotation (deg) error of its best hypothesis
   by FK (what the JSON records as ``validation``);
2. the solver **with the network** (``IKSolver(robot, checkpoint=path)`` with the network serving every call:
   ``network_use = {"pose": True, "batch": True}``) against **no network** (``IKSolver(robot, checkpoint=None)``:
   the closed form where the arm has one, else LM from uniform starts); each row names the guess the solver's
   results report (``res.source``); success within the solver's default tolerances (0.1 mm, 0.1 deg) and
   milliseconds per target, on one batch of ``n_batch`` targets (median of ``repeats`` runs, the two solvers
   interleaved) and on ``n_one`` single poses solved one at a time (median time of one call);
3. **what the solver uses** per call type (:attr:`nik.IKSolver.network_use`, read from the record the pair's JSON
   carries: :func:`record_use`, which ``nik train`` runs after exporting): for single poses and for batches, the
   CPU time per pose with and without the network on the probes of :mod:`nik.ik.judge` and whether it serves.
   Where the file names a single-pose network beside it (``nik train`` made one), its lines follow: what
   ``IKSolver(robot)`` uses on the CPU once both are installed.

Timings depend on the machine and its load; the two solvers run in the same process, interleaved.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from nik.nets.multi import hypothesis_pose_error
from nik.solver import IKSolver
from nik.tolerances import score

__all__ = ["NetworkReport", "network_report", "record_use", "use_lines"]


@dataclass
class NetworkReport:
    """Figures of one network (module docstring). Errors in mm and degrees, times in ms per target."""

    robot: str
    raw: dict
    rows: list[dict] = field(default_factory=list)  # {"case", "solver", "success", "ms"}
    use: dict = field(default_factory=dict)  # IKSolver.network_use of the solver given the network
    single_pose: str = ""  # the single-pose network the file names beside it ("": none)
    single_pose_use: dict = field(default_factory=dict)  # its IKSolver.network_use

    def lines(self) -> list[str]:
        r = self.raw
        out = [
            f"raw network, best of {r['K']} hypotheses by FK ({r['n']} targets): position median "
            f"{r['pos_mm_median']:.2f} mm, p95 {r['pos_mm_p95']:.2f} mm; rotation median "
            f"{r['rot_deg_median']:.2f} deg, p95 {r['rot_deg_p95']:.2f} deg",
            f"{'case':<24} {'solver':<42} {'success':>8} {'ms / target':>12}",
        ]
        for row in self.rows:
            out.append(f"{row['case']:<24} {row['solver']:<42} {100 * row['success']:7.2f}% {row['ms']:12.4f}")
        out += use_lines(self.use)
        if self.single_pose:
            out.append(f"the single-pose network {self.single_pose} beside it (what IKSolver(robot) uses on the CPU "
                       "once both are installed, nik train --install):")  # fmt: skip
            out += [f"  [{self.single_pose}] {line.strip()}" for line in use_lines(self.single_pose_use)[1:]]
        return out


def use_lines(use: dict) -> list[str]:
    """The lines that say, per call type, the time with and without the network and what the solver uses
    (``use``: :attr:`nik.IKSolver.network_use`)."""
    if not use:
        return []
    from nik.ik.judge import BATCH_PROBES, MIN_WINS, POSE_PROBES

    where = {"record": "recorded in the network's JSON", "measured": "measured in this process"}.get(use["how"], "")
    out = [f"what IKSolver(robot, checkpoint=PATH) uses, per call type (nik.ik.judge{'; ' + where if where else ''}):"]
    if use["wins"] < MIN_WINS:
        out.append(
            f"  no network for single poses or batches: its best hypothesis is the better start on {use['wins']:.0%} "
            f"of the probe poses (it needs {MIN_WINS:.0%}); the times with it, for the record:"
        )
    for call, key, probes in (("single poses", "pose", f"{POSE_PROBES} poses, one call each, the median call"),
                              ("batches", "batch", f"one batch of {BATCH_PROBES}")):  # fmt: skip
        w, wo = use[f"{key}_us"]
        if math.isnan(w + wo):
            continue
        ratio = f"{wo / w:.2f}x faster" if w <= wo else f"{w / wo:.2f}x slower"
        out.append(
            f"  {call + ':':<14} {'the network' if use[key] else 'no network':<11} ({w:.1f} us a pose with the "
            f"network, {wo:.1f} us without: {ratio} with it; CPU time on {probes})"
        )
    return out


def record_use(path, robot=None) -> dict:
    """Measure whether the exported network at ``path`` (``NAME.safetensors``) pays per call type on the CPU for the
    arm it was made for (:func:`nik.ik.judge.record`: against uniform starts; 0.12-0.18 s of CPU) and write it into its
    JSON as ``network_use`` (the pair replaced whole: :func:`nik.nets.pair.write_pair_files`; the weights untouched),
    so that a solver loading it decides without measuring. ``robot``: the arm (None: the one the JSON records).
    Returns the record."""
    import json

    from nik.ik.judge import record
    from nik.nets.pair import load_pair, pair_paths, read_pair_meta, write_pair_files

    st, _ = pair_paths(path)
    net = load_pair(st, robot=robot)
    found = record(net, net.robot, IKSolver)
    meta = read_pair_meta(st)
    meta["network_use"] = found
    write_pair_files(st, st.read_bytes(), json.dumps(meta, indent=2) + "\n")
    return found


def _targets(robot, n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(int(seed))
    return robot.fk(robot.sample(int(n), generator=g, dtype=torch.float64))


def network_report(
    robot,
    checkpoint: str | Path,
    *,
    n_raw: int = 2000,
    n_batch: int = 1000,
    n_one: int = 50,
    repeats: int = 3,
    seed: int = 2026,
) -> NetworkReport:
    """Measure the network at ``checkpoint`` for ``robot`` (module docstring)."""
    from nik.nets.pair import single_pose_companion

    with_net = IKSolver(robot, checkpoint=checkpoint)
    one = single_pose_companion(checkpoint)
    use = with_net.network_use  # what the solver uses (from the pair's record where it has one)
    with_net.network_use = {"pose": True, "batch": True}  # the rows: the network serving every call
    without = IKSolver(robot, checkpoint=None)
    net = with_net.net
    T = _targets(robot, n_raw, seed)
    with torch.no_grad():
        hyp = net.hypotheses(T)
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = score(pos, rot).argmin(-1, keepdim=True)
    p, r = pos.gather(1, best)[:, 0] * 1e3, torch.rad2deg(rot.gather(1, best)[:, 0])
    raw = {
        "n": int(n_raw),
        "K": int(hyp.shape[1]),
        "pos_mm_median": float(p.median()),
        "pos_mm_p95": float(torch.quantile(p, 0.95)),
        "rot_deg_median": float(r.median()),
        "rot_deg_p95": float(torch.quantile(r, 0.95)),
    }
    report = NetworkReport(robot.name, raw, use=use)
    if one is not None:
        report.single_pose, report.single_pose_use = one.name, IKSolver(robot, checkpoint=one).network_use
    Tb = _targets(robot, n_batch, seed + 1)
    names = {"with the network": with_net, "no network": without}
    times = {k: [] for k in names}
    ok, source = {}, {}
    for solver in names.values():  # warm-up: first-call costs (kernels loaded from the cache) are not timed
        solver.solve(Tb[: min(n_batch, 64)], seed=0)
    for _ in range(repeats):
        for k, solver in names.items():
            t0 = time.perf_counter()
            res = solver.solve(Tb, seed=0)
            times[k].append(time.perf_counter() - t0)
            ok[k], source[k] = float(res.success.double().mean()), res.source  # the guess this call really used
    for k in names:
        ms = 1e3 * statistics.median(times[k]) / n_batch
        label = f"{k} (guess: {source[k]})"
        report.rows.append({"case": f"batch of {n_batch}", "solver": label, "success": ok[k], "ms": ms})
    To = _targets(robot, n_one, seed + 2)
    for solver in names.values():  # the one-pose path's first call (its kernels loaded) is not timed either
        solver.solve(To[:1], seed=0)
    one = {k: [] for k in names}
    hits = {k: 0 for k in names}
    for i in range(n_one):
        for k, solver in names.items():
            t0 = time.perf_counter()
            res = solver.solve(To[i : i + 1], seed=0)
            one[k].append(time.perf_counter() - t0)
            hits[k] += int(res.success[0])
            source[k] = res.source
    for k in names:
        ms = 1e3 * statistics.median(one[k])
        label = f"{k} (guess: {source[k]})"
        report.rows.append({"case": f"one pose ({n_one} poses)", "solver": label, "success": hits[k] / n_one, "ms": ms})
    return report
