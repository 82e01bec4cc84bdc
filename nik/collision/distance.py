"""Signed distances of the arm's spheres, batched and differentiable (torch): the reference of the compiled kernels.

For ``q: (B, dof)`` the spheres of a :class:`nik.collision.CollisionModel` are placed by FK of the robot's frames
(:func:`link_frames`), and

- :func:`self_distances` gives, per active link pair, the smallest ``|c_i - c_j| - r_i - r_j`` over their spheres:
  ``(B, P)``, negative where they overlap;
- :func:`world_distances` gives, per link, the smallest signed distance from its spheres to the world's spheres,
  boxes and capsules: ``(B, L)`` (``inf`` for an empty world);
- :func:`signed_distances` both, ``(B, P + L)``: the rows of :func:`collision_residual`
  ``max(0, margin - d)``, one LM residual per row (a pair or a link; the row count does not depend on the world);
- :func:`collides`: ``(B,)`` bool, some row below ``margin`` (``margin=0``: touching counts as free, overlapping
  as colliding); :func:`colliding_links`: ``(B, L)`` bool, which links take part (for drawing them in colour).

Gradients flow to ``q`` through the minimum's arguments (torch's ``amin`` scatter splits ties evenly). The
compiled kernels (:mod:`nik.kernels.collision`) compute the same rows and their Jacobians; the tests compare them.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = [
    "colliding_links",
    "collides",
    "collision_residual",
    "link_frames",
    "self_distances",
    "signed_distances",
    "sphere_centers",
    "world_distances",
]


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
    """``(B, P)``: per active pair of ``model.pairs``, the smallest signed distance between their spheres."""
    i, j, pid = model.sphere_pairs()
    r = torch.as_tensor(model.radii, dtype=centers.dtype, device=centers.device)
    ii, jj = torch.as_tensor(i, device=centers.device), torch.as_tensor(j, device=centers.device)
    d = torch.linalg.vector_norm(centers[:, ii] - centers[:, jj], dim=-1) - r[ii] - r[jj]
    return _segment_min(d, pid, len(model.pairs))


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


def signed_distances(robot, q: torch.Tensor, world=None, *, model=None, self_collision: bool = True) -> torch.Tensor:
    """``(B, P + L)`` metres for ``q: (B, dof)``: the active pairs' distances (inf for each when
    ``self_collision=False``), then each link's distance to ``world``. ``model`` defaults to
    ``robot.collision_spheres()``."""
    model = robot.collision_spheres() if model is None else model
    c = sphere_centers(model, robot, q)
    selfd = self_distances(model, c)
    if not self_collision:
        selfd = torch.full_like(selfd, float("inf"))
    return torch.cat([selfd, world_distances(model, world, c)], dim=1)


def collision_residual(
    robot, q: torch.Tensor, world=None, *, margin: float = 0.0, model=None, self_collision: bool = True
) -> torch.Tensor:
    """``(B, P + L)``: ``max(0, margin - d)`` of :func:`signed_distances`, the LM residual rows (metres)."""
    d = signed_distances(robot, q, world, model=model, self_collision=self_collision)
    return torch.clamp(margin - d, min=0.0)


def collides(
    robot, q, world=None, *, margin: float = 0.0, model=None, self_collision: bool = True, compiled: bool = True
):
    """``(B,)`` bool: some active pair or some link is closer than ``margin`` (metres; 0: overlapping) for
    ``q: (B, dof)`` or ``(dof,)`` (numpy in, numpy out; torch in, torch out). ``compiled``: the numba kernel
    (:mod:`nik.kernels.collision`) for CPU input; else (or on another device) the torch path."""
    as_numpy = not isinstance(q, torch.Tensor)
    model = robot.collision_spheres() if model is None else model
    if compiled and (as_numpy or q.device.type == "cpu"):
        from nik.collision.compiled import kernel_arguments
        from nik.kernels.collision import collides_batch

        Q = np.ascontiguousarray(np.asarray(q.detach() if not as_numpy else q, dtype=np.float64).reshape(-1, robot.dof))
        (G, joints), rest = kernel_arguments(robot, model, world, self_collision=self_collision)
        out = np.empty(len(Q), dtype=np.bool_)
        collides_batch(G, joints, Q, *rest, float(margin), out)
        return out if as_numpy else torch.from_numpy(out)
    qt = torch.as_tensor(q, dtype=torch.float64).reshape(-1, robot.dof)
    with torch.no_grad():
        d = signed_distances(robot, qt, world, model=model, self_collision=self_collision)
    hit = (d < margin).any(dim=1)
    return hit.numpy() if as_numpy else hit


def colliding_links(
    robot, q, world=None, *, margin: float = 0.0, model=None, self_collision: bool = True
) -> np.ndarray:
    """``(B, L)`` bool for ``q: (B, dof)``: link ``l`` is in a pair closer than ``margin`` or closer than ``margin``
    to the world (the links of ``model.links``; what a viewer draws in another colour)."""
    model = robot.collision_spheres() if model is None else model
    qt = torch.as_tensor(np.asarray(q.detach() if isinstance(q, torch.Tensor) else q), dtype=torch.float64)
    qt = qt.reshape(-1, robot.dof)
    with torch.no_grad():
        d = signed_distances(robot, qt, world, model=model, self_collision=self_collision).numpy()
    P = len(model.pairs)
    hit = d[:, P:] < margin
    for p, (a, b) in enumerate(np.asarray(model.pairs).reshape(-1, 2)):
        close = d[:, p] < margin
        hit[:, a] |= close
        hit[:, b] |= close
    return hit
