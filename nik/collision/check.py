"""The collision check of a robot: signed distances, LM residual rows and verdicts, with the robot's own model by
default (:func:`nik.collision.collision_model`), built on the pure distances of :mod:`nik.collision.distance`.

- :func:`signed_distances`: ``(B, P + L)``, the active pairs' distances then each link's distance to the world:
  the rows of :func:`collision_residual` ``max(0, margin - d)``, one LM residual per row (a pair or a link; the row
  count does not depend on the world);
- :func:`collides`: ``(B,)`` bool, some row below ``margin`` (``margin=0``: touching counts as free, overlapping
  as colliding); :func:`colliding_links`: ``(B, L)`` bool, which links take part (for drawing them in colour);
- :func:`collision_names`: per configuration, the names of what overlaps (``"linkA|linkB"`` for the arm against
  itself, ``"link|box 2"`` for a link against the world's obstacle of that kind and index in :meth:`World.packed`;
  a point cloud's points are spheres), or None where nothing does: why an answer is called colliding.
"""

from __future__ import annotations

import numpy as np
import torch

from nik.collision.distance import _box_sdf, _capsule_dist, self_distances, sphere_centers, world_distances
from nik.collision.model import collision_model

__all__ = ["colliding_links", "collides", "collision_names", "collision_residual", "signed_distances"]

#: the world's obstacle kinds, in the order of :meth:`nik.World.packed`
OBSTACLE_KINDS = ("sphere", "box", "capsule")


def signed_distances(robot, q: torch.Tensor, world=None, *, model=None, self_collision: bool = True) -> torch.Tensor:
    """``(B, P + L)`` metres for ``q: (B, dof)``: the active pairs' distances (inf for each when
    ``self_collision=False``), then each link's distance to ``world``. ``model`` defaults to
    ``collision_model(robot)``."""
    model = collision_model(robot) if model is None else model
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
    model = collision_model(robot) if model is None else model
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
    model = collision_model(robot) if model is None else model
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


def collision_names(robot, q, world=None, *, model=None, self_collision: bool = True) -> list[list[str] | None]:
    """Per configuration of ``q: (B, dof)``, the sorted names of what overlaps (module docstring: ``"a|b"`` for an
    active pair of links, ``"link|box 2"`` for a link and an obstacle), or None where nothing does (margin 0)."""
    model = collision_model(robot) if model is None else model
    qt = torch.as_tensor(np.asarray(q.detach() if isinstance(q, torch.Tensor) else q), dtype=torch.float64)
    qt = qt.reshape(-1, robot.dof)
    with torch.no_grad():
        c = sphere_centers(model, robot, qt)  # (B, S, 3)
        hits = [[] for _ in range(len(qt))]
        if self_collision:
            for b, p in zip(*np.nonzero((self_distances(model, c) < 0).numpy()), strict=True):
                a, e = model.pairs[p]
                hits[b].append(f"{model.links[a]}|{model.links[e]}")
        if world is not None:
            r = torch.as_tensor(model.radii, dtype=torch.float64)[:, None]
            moving = torch.as_tensor(model.sphere_frame != 0)[:, None]  # the fixed base is not tested (as the check)
            spheres, boxes, caps = (torch.as_tensor(a) for a in world.packed())
            per_kind = (
                torch.cdist(c, spheres[None, :, :3].expand(len(c), -1, -1)) - spheres[:, 3],
                _box_sdf(c, boxes),
                _capsule_dist(c, caps),
            )
            for kind, d in zip(OBSTACLE_KINDS, per_kind, strict=True):
                for b, s, k in zip(*np.nonzero(((d - r < 0) & moving).numpy()), strict=True):
                    hits[b].append(f"{model.links[model.sphere_body[s]]}|{kind} {k}")
    return [sorted(set(h)) or None for h in hits]
