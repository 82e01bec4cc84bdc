"""A picture of a timed joint path: :func:`plot_timing` (matplotlib, imported when it draws).

One row per joint: its position (left, degrees; prismatic joints mm) and velocity (right, deg/s; mm/s) against
time, sampled every millisecond from the trajectory of :func:`nik.paths.timing.time_path`, the waypoints as dots,
the joint limits and the speed limits (plus and minus) dashed. The file is written under a temporary name and
then renamed.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

__all__ = ["plot_timing"]

_LIMIT = "0.4"


def plot_timing(robot, timing, path: str | Path, *, dt: float = 1e-3, title: str | None = None, dpi: int = 110) -> Path:
    """Draw positions and velocities of ``timing`` (a :class:`nik.paths.timing.Timing` of ``robot``'s joints) against
    time and write the picture to ``path`` (format from its suffix); its folder is made. Returns the path.

    Raises ValueError when ``timing`` is not for ``robot``'s joints or matplotlib cannot write the suffix."""
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower()
    dof = robot.dof
    if timing.qd.shape[1] != dof:
        raise ValueError(f"plot_timing: the timing has {timing.qd.shape[1]} joints, {robot.name} has {dof}")
    from matplotlib.figure import Figure  # lazy: `import nik` never loads matplotlib

    prismatic = robot.prismatic.tolist()
    factor = np.array([1e3 if p else 180.0 / math.pi for p in prismatic])
    shown = ["mm" if p else "deg" for p in prismatic]
    t, q, qd, _ = timing.sample(dt)
    qw = timing.at(timing.t)[0]
    fig = Figure(figsize=(10, 1.4 * dof + 1))
    axes = fig.subplots(dof, 2, sharex=True, squeeze=False)
    lim = robot.limits.numpy()
    for j in range(dof):
        f, color = factor[j], f"C{j % 10}"
        ax_q, ax_v = axes[j]
        ax_q.plot(t, q[:, j] * f, color=color, lw=1.3)
        ax_q.plot(timing.t, qw[:, j] * f, ".", color=color, ms=3)
        for v in lim[j]:
            ax_q.axhline(v * f, color=_LIMIT, ls="--", lw=0.8)
        ax_q.set_ylabel(f"{robot.joint_names[j]}\n({shown[j]})", fontsize=7)
        ax_v.plot(t, qd[:, j] * f, color=color, lw=1.3)
        for v in (-timing.vel_limits[j], timing.vel_limits[j]):
            ax_v.axhline(v * f, color=_LIMIT, ls="--", lw=0.8)
        ax_v.set_ylabel(f"({shown[j]}/s)", fontsize=7)
        for ax in (ax_q, ax_v):
            ax.tick_params(labelsize=7)
    axes[0, 0].set_title("positions (joint limits dashed)", fontsize=8)
    axes[0, 1].set_title("velocities (speed limits dashed)", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)", fontsize=8)
    extra = f"; slowed {100 * (timing.stretch - 1):.2g} % after the check" if timing.stretch > 1 else ""
    tool = f", tool <= {timing.tool_speed * 1e3:g} mm/s" if timing.tool_speed is not None else ""
    fig.suptitle(
        title or f"{robot.name}: {len(timing.t)} waypoints in {timing.duration:.3f} s (toppra{tool}){extra}",
        fontsize=9,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        fig.savefig(tmp, dpi=dpi, format=fmt or None)
        tmp.replace(path)
    except ValueError as err:
        raise ValueError(f"plot_timing: cannot write {path.name}: {err}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return path
