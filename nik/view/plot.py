"""A picture of the arm at its solution(s): :func:`plot_arm` (matplotlib, imported when it draws).

For docs and machines without a display: each arm is the polyline of :func:`nik.view.arm.arm_points`
drawn with thick round-capped lines (capsules, seen from one side) and a dot at every joint; the target
frames as red / green / blue axes (x, y, z); other solutions of the same pose as faint arms; the obstacles of a
:class:`nik.World` (``world=``) in orange: spheres as wire balls (a large point cloud as dots), boxes as faces,
capsules as thick segments; they do not change the view's extent (a table would shrink the arm): boxes and capsules
are cut at the view's cube (matplotlib does not clip 3-D artists; a rotated box is cut corner by corner). Axes in mm.
The file is written under a temporary name and then renamed.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from nik.poses import validate_pose
from nik.view.arm import arm_points

__all__ = ["draw_obstacles", "plot_arm"]

_ARM = "#1f5fa8"
_GHOST = "#7f7f7f"
_AXES = ("#d62728", "#2ca02c", "#1f77b4")


def plot_arm(
    robot,
    q,
    path: str | Path,
    *,
    ghosts=None,
    T_target=None,
    title: str | None = None,
    dpi: int = 110,
    world=None,
) -> Path:
    """Draw the arm at ``q`` and write the picture to ``path`` (format from its suffix: ``.png``, ``.svg``, ...).

    Args:
        robot: a :class:`nik.Robot`.
        q: ``(dof,)`` or ``(B, dof)`` joint values (radians; metres for prismatic joints): B arms, drawn solid.
        path: the file to write; its folder is made.
        ghosts: optional ``(K, dof)``: more solutions (e.g. ``IKSolver.solve_all``), drawn as faint arms.
        T_target: optional ``(4, 4)`` or ``(B, 4, 4)`` target poses (metres), drawn as axes.
        title: the picture's title (default: the robot's name).
        dpi: resolution of raster formats.
        world: optional :class:`nik.World`: its obstacles are drawn (module docstring).

    Returns:
        The path written.

    Raises:
        ValueError: ``q`` or ``ghosts`` of the wrong width, a malformed target, or a suffix matplotlib cannot write.
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower()
    q = torch.as_tensor(q, dtype=torch.float64)
    if q.ndim not in (1, 2) or q.shape[-1] != robot.dof or not q.numel():
        raise ValueError(f"plot_arm: q must be (dof,) or (B, dof) with dof = {robot.dof}, got {tuple(q.shape)}")
    arms = arm_points(robot, q.reshape(-1, robot.dof)).numpy() * 1e3  # (B, dof + 2, 3) mm
    faint = None
    if ghosts is not None:
        ghosts = torch.as_tensor(ghosts, dtype=torch.float64)
        if ghosts.numel() and (ghosts.ndim != 2 or ghosts.shape[1] != robot.dof):
            raise ValueError(f"plot_arm: ghosts must be (K, {robot.dof}), got {tuple(ghosts.shape)}")
        faint = arm_points(robot, ghosts).numpy() * 1e3 if ghosts.numel() else None
    targets = None
    if T_target is not None:
        targets = validate_pose(torch.as_tensor(T_target, dtype=torch.float64).reshape(-1, 4, 4), name="T_target")
        targets = targets.numpy().copy()
        targets[:, :3, 3] *= 1e3

    from matplotlib.figure import Figure  # lazy: `import nik` never loads matplotlib

    fig = Figure(figsize=(6.4, 5.6), dpi=dpi)
    if fmt not in fig.canvas.get_supported_filetypes():
        raise ValueError(
            f"plot_arm: cannot write {path.name!r}; expected a suffix among "
            f"{', '.join(sorted(fig.canvas.get_supported_filetypes()))}"
        )
    ax = fig.add_subplot(projection="3d")
    mid, reach = _bounds(arms, faint, targets)
    if faint is not None:
        for pts in faint:
            _draw(ax, pts, color=_GHOST, alpha=0.28, width=4.0)
    for pts in arms:
        _draw(ax, pts, color=_ARM, alpha=1.0, width=7.0)
    if targets is not None:
        size = 0.12 * reach
        for T in targets:
            for k in range(3):
                end = T[:3, 3] + size * T[:3, k]
                ax.plot(*zip(T[:3, 3], end, strict=True), color=_AXES[k], linewidth=2.2)
    if world is not None and not world.empty:
        half = 0.55 * reach
        draw_obstacles(ax, world, view=(mid - half, mid + half))
    _equal_axes(ax, mid, reach)
    ax.set_title(title or robot.name)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fig.savefig(tmp, format=fmt)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


_OBSTACLE = "#e07b1a"


def draw_obstacles(ax, world, *, scale: float = 1e3, view=None) -> None:
    """The obstacles of ``world`` on a matplotlib 3-D axis, coordinates times ``scale`` (mm by default); ``view``:
    ``(lo (3,), hi (3,))`` in drawn units, the cube the boxes and capsules are cut at (module docstring)."""
    cut = (lambda p: p) if view is None else (lambda p: np.clip(p, view[0], view[1]))
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    spheres, boxes, capsules = (a * 1.0 for a in world.packed())
    if len(spheres) > 200:  # a point cloud: dots
        ax.scatter(*(spheres[:, :3] * scale).T, color=_OBSTACLE, s=4, alpha=0.6, depthshade=False)
    else:
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
        ball = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
        for c in spheres:
            x, y, z = (c[:3, None, None] + c[3] * ball) * scale
            ax.plot_wireframe(x, y, z, color=_OBSTACLE, linewidth=0.6, alpha=0.8)
    corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
    faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    for b in boxes:
        R, c, half = b[:9].reshape(3, 3), b[9:12], b[12:15]
        pts = cut((c + (corners * half) @ R.T) * scale)
        ax.add_collection3d(
            Poly3DCollection([pts[f] for f in faces], facecolor=_OBSTACLE, edgecolor="#8a4a10", alpha=0.25)
        )
    for c in capsules:
        a, b = cut(c[:3] * scale), cut(c[3:6] * scale)
        ax.plot(*zip(a, b, strict=True), color=_OBSTACLE, linewidth=max(2.0, 0.5 * c[6] * scale / 5), alpha=0.7)


def _draw(ax, pts, *, color: str, alpha: float, width: float) -> None:
    """One arm: round-capped thick segments between consecutive points (zero-length ones skipped), joint dots."""
    keep = [0] + [i for i in range(1, len(pts)) if ((pts[i] - pts[i - 1]) ** 2).sum() > 1e-12]
    pts = pts[keep]
    line = ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=color, alpha=alpha, linewidth=width)[0]
    line.set_solid_capstyle("round")
    line.set_solid_joinstyle("round")
    ax.scatter(pts[1:-1, 0], pts[1:-1, 1], pts[1:-1, 2], color="black", alpha=alpha, s=12, depthshade=False)
    ax.scatter(*pts[-1], color=color, alpha=alpha, s=30, marker="s", depthshade=False)
    ax.scatter(*pts[0], color="black", alpha=alpha, s=70, marker="^", depthshade=False)  # the base


def _bounds(arms, faint, targets) -> tuple:
    """Centre ``(3,)`` and size (mm, at least 1) of everything drawn."""
    pts = [arms.reshape(-1, 3)] + ([faint.reshape(-1, 3)] if faint is not None else [])
    if targets is not None:
        pts.append(targets[:, :3, 3])
    allp = np.concatenate(pts)
    return 0.5 * (allp.max(0) + allp.min(0)), float(max((allp.max(0) - allp.min(0)).max(), 1.0))


def _equal_axes(ax, mid, size: float) -> None:
    """Equal scales on the three axes around ``mid``, with a little margin."""
    half = 0.55 * size
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
