"""Signed distances of the arm's spheres, batched and differentiable (torch): the reference of the compiled kernels.

For ``q: (B, dof)`` the spheres of a :class:`nik.collision.CollisionModel` are placed by FK of the robot's frames
(:func:`link_frames`), and

- :func:`self_distances` gives, per active link pair, the smallest ``|c_i - c_j| - r_i - r_j`` over their spheres:
  ``(B, P)``, negative where they overlap;
- :func:`world_distances` gives, per link, the smallest signed distance from its spheres to the world's spheres,
  boxes and capsules: ``(B, L)`` (``inf`` for an empty world);

each for a model given explicitly; :mod:`nik.collision.check` puts them together for a robot's own model.

Gradients flow to ``q`` through the minimum's arguments (torch's ``amin`` scatter splits ties evenly). The
compiled kernels (:mod:`nik.kernels.collision`) compute the same rows and their Jacobians; the tests compare them.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["link_frames", "self_distances", "sphere_centers", "world_distances"]


def link_frames(robot, q: torch.Tensor) -> torch.Tensor:
    """``(B, dof + 1, 3, 4)``: frame 0 (the base frame, identity) and the frames after each joint, for
    ``q: (B, dof)`` (radians; metres for prismatic joints), in q's dtype and device."""
    B, n = q.shape
    G = robot.G.to(q.device, q.dtype)
    off = robot.offsets.to(q.device, q.dtype)
    pr = robot.prismatic.tolist()
    eye = torch.eye(4, dtype=q.dtype, device=q.device)[:3].expand(B, 3, 4)
    T = G[0, :3].expand(B, 3, 4)
    out = [eye]
    theta = q + off
    for i in range(n):
        t = theta[:, i : i + 1]
        if pr[i]:
            T = torch.stack([T[..., 0], T[..., 1], T[..., 2], T[..., 3] + T[..., 2] * t], dim=-1)
        else:
            c, s = torch.cos(t), torch.sin(t)
            T = torch.stack([T[..., 0] * c + T[..., 1] * s, T[..., 1] * c - T[..., 0] * s, T[..., 2], T[..., 3]], -1)
        out.append(T)
        T = T @ G[i + 1]
    return torch.stack(out, dim=1)


def sphere_centers(model, robot, q: torch.Tensor) -> torch.Tensor:
    """``(B, S, 3)`` sphere centres in the base frame for ``q: (B, dof)``."""
    F = link_frames(robot, q)[:, torch.as_tensor(model.sphere_frame, device=q.device)]  # (B, S, 3, 4)
    c = torch.as_tensor(model.centers, dtype=q.dtype, device=q.device)
    return (F[..., :3] @ c[..., None])[..., 0] + F[..., 3]


def _segment_min(values: torch.Tensor, index: np.ndarray, count: int) -> torch.Tensor:
    """``(B, count)``: per group the minimum of ``values: (B, M)`` (``index: (M,)`` group ids); inf for none."""
    out = torch.full((values.shape[0], count), float("inf"), dtype=values.dtype, device=values.device)
    if values.shape[1] == 0:
        return out
    idx = torch.as_tensor(index, device=values.device).expand(values.shape[0], -1)
    return out.scatter_reduce(1, idx, values, reduce="amin", include_self=False)


def self_distances(model, centers: torch.Tensor) -> torch.Tensor:
    """``(B, P)``: per active pair of ``model.pairs``, the smallest signed distance between their spheres; for a
    pair with a static link that has a grid (:attr:`nik.collision.CollisionModel.grids`), the larger of that and
    the smallest ``v(c) - r`` over the other link's spheres (:func:`nik.collision.sdf.grid_values_torch`): both are
    lower bounds of the distance to the static link's geometry."""
    i, j, pid = model.sphere_pairs()
    r = torch.as_tensor(model.radii, dtype=centers.dtype, device=centers.device)
    link_grid, grid_rows, flat = model.grid_arrays()
    on_grid = np.zeros(len(model.pairs), dtype=bool)
    if len(link_grid) and len(model.pairs):
        on_grid = (link_grid[model.pairs[:, 0]] >= 0) | (link_grid[model.pairs[:, 1]] >= 0)
    ii, jj = torch.as_tensor(i, device=centers.device), torch.as_tensor(j, device=centers.device)
    d = torch.linalg.vector_norm(centers[:, ii] - centers[:, jj], dim=-1) - r[ii] - r[jj]
    out = _segment_min(d, pid, len(model.pairs))
    if on_grid.any():
        from nik.collision.sdf import grid_values_torch

        cols = []
        for p in range(len(model.pairs)):
            if not on_grid[p]:
                cols.append(out[:, p])
                continue
            a, b = (int(x) for x in model.pairs[p])
            k, mover = (link_grid[a], b) if link_grid[a] >= 0 else (link_grid[b], a)
            s = slice(int(model.body_start[mover]), int(model.body_start[mover + 1]))
            v = grid_values_torch(grid_rows, flat, int(k), centers[:, s]) - r[s]
            cols.append(torch.maximum(v.amin(dim=1), out[:, p]) if v.shape[1] else out[:, p])
        out = torch.stack(cols, dim=1)
    return out


def _box_sdf(p: torch.Tensor, boxes: torch.Tensor) -> torch.Tensor:
    """``(B, S, Nb)`` signed distance of points ``p: (B, S, 3)`` to boxes ``(Nb, 15)``."""
    R = boxes[:, :9].reshape(-1, 3, 3)
    local = torch.einsum("nji,bsnj->bsni", R, p[:, :, None, :] - boxes[:, 9:12])  # R^T (p - c)
    qd = local.abs() - boxes[:, 12:15]
    outside = torch.linalg.vector_norm(qd.clamp(min=0), dim=-1)
    inside = qd.max(dim=-1).values.clamp(max=0)
    return outside + inside


def _capsule_dist(p: torch.Tensor, caps: torch.Tensor) -> torch.Tensor:
    a, b, r = caps[:, 0:3], caps[:, 3:6], caps[:, 6]
    ab = b - a
    L2 = (ab * ab).sum(-1).clamp(min=1e-300)
    t = (((p[:, :, None, :] - a) * ab).sum(-1) / L2).clamp(0, 1)
    closest = a + t[..., None] * ab
    return torch.linalg.vector_norm(p[:, :, None, :] - closest, dim=-1) - r


def world_distances(model, world, centers: torch.Tensor) -> torch.Tensor:
    """``(B, L)``: per link, the smallest signed distance from its spheres to the world's obstacles (inf for an
    empty world, and for the links on frame 0: the fixed base touches the table it stands on by design)."""
    like = dict(dtype=centers.dtype, device=centers.device)
    rad = torch.as_tensor(model.radii, **like)
    best = torch.full(centers.shape[:2], float("inf"), **like)
    if world is not None:
        spheres, boxes, caps = (torch.as_tensor(a, **like) for a in world.packed())
        if len(spheres):
            d = torch.cdist(centers, spheres[None, :, :3].expand(centers.shape[0], -1, -1)) - spheres[:, 3]
            best = torch.minimum(best, d.min(dim=-1).values)
        if len(boxes):
            best = torch.minimum(best, _box_sdf(centers, boxes).min(dim=-1).values)
        if len(caps):
            best = torch.minimum(best, _capsule_dist(centers, caps).min(dim=-1).values)
    best = torch.where(torch.as_tensor(model.sphere_frame == 0, device=best.device), float("inf"), best - rad)
    return _segment_min(best, model.sphere_body, len(model.links))
