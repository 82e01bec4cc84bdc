"""Signed distances of the arm's spheres and their Jacobians for one configuration: LM residual rows, compiled.

The model is data (:meth:`nik.collision.CollisionModel.arrays`, :meth:`nik.collision.World.packed`), passed as
two named groups after ``G, joints`` and the configuration (:func:`nik.collision.compiled.kernel_arguments` builds
them):

- ``arm`` (:class:`ArmSpheres`): ``spheres: (S, 4)`` centre in its frame and radius (metres), ``sphere_frame: (S,)``
  int64 (0 = base, k = the frame after joint k), ``body_start: (L + 1,)`` int64 (link ``l`` owns spheres
  ``body_start[l]:body_start[l+1]``), ``pairs: (P, 2)`` int64 active link pairs, ``self_on`` whether they count;
- ``scene`` (:class:`Scene`), the world: ``spheres: (Ns, 4)``, ``boxes: (Nb, 15)`` (R row by row, centre, half
  sizes), ``capsules: (Nc, 7)``.

Inside a kernel the groups are read by position (``arm[0]`` the spheres, ...), so a plain tuple in the same order
works too. ``arm``'s last three fields (defaults: none) give the static links (frame 0) that carry a grid of
signed distances (:mod:`nik.collision.sdf`): the row of a pair of such a link and another is the larger of the
spheres' row and the grid's, the smallest ``v(c_s) - r_s`` over the other link's spheres (``v`` the grid's
trilinear value, a lower bound of the distance to the static link's geometry): both are lower bounds of the
distance between the other link's spheres and the static geometry, so the larger is one too. Its Jacobian row is
the larger one's, for the grid its gradient at the minimising sphere ``dv/dx . dc_s/dq``. The spheres' minimum is
skipped where the grid's row is already at least the cutoff.

Rows (``R = P + L``): row ``p < P`` is the smallest ``|c_i - c_j| - r_i - r_j`` over the spheres of pair ``p``
(``inf`` when ``self_on`` is False); row ``P + l`` is the smallest signed distance from link ``l``'s spheres
to any obstacle (``inf`` for an empty world and for links on frame 0, the fixed base: a base standing on a
table touches it by design). The Jacobian row is that of the minimising sphere pair (or
sphere and obstacle): ``n . (dc_i/dq - dc_j/dq)``, with ``dc/dq`` column ``m`` equal to ``z_m x (c - p_m)``
(revolute) or ``z_m`` (prismatic) for the joints before the sphere's frame and 0 after.
:func:`collision_residual` turns them into LM rows ``max(0, margin - d)`` and ``-dd/dq`` where active.

A broad phase skips the sphere-by-sphere minimum of a row whose lower bound (from a bounding sphere per link,
placed with the link, and for the pairs a capsule per link, :func:`link_capsules`) is above the cutoff: ``margin``
in :func:`collision_residual` and :func:`collides_batch`, none (exact rows) in :func:`collision_distances` and
:func:`collision_distances_batch`.

The reference is :mod:`nik.collision.distance` (torch); the tests compare the two and check the Jacobians
by finite differences.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import LOWER, OFFSET, PRISMATIC, UPPER, _joint, _start

__all__ = [
    "ArmSpheres",
    "Scene",
    "blocked_poses",
    "collides_batch",
    "collides_bounded",
    "collision_distances",
    "collision_distances_batch",
    "collision_residual",
    "collision_rows_batch",
    "hand_lever",
    "link_bounds",
    "link_capsules",
    "overlaps_batch",
    "residual_bounded",
]


_NO_LINK_GRID = np.zeros(0, dtype=np.int64)
_NO_GRIDS = np.zeros((0, 14))
_NO_GRID_VALUES = np.zeros(0, dtype=np.float32)


class ArmSpheres(NamedTuple):
    """The arm's sphere model as the kernels take it (:meth:`nik.collision.CollisionModel.arrays`, then
    :meth:`nik.collision.CollisionModel.grid_arrays`: the static links checked on a distance grid)."""

    spheres: np.ndarray  #: (S, 4) centre in its frame and radius (metres)
    sphere_frame: np.ndarray  #: (S,) int64, the frame each sphere rides on (0 the base, k after joint k)
    body_start: np.ndarray  #: (L + 1,) int64, link ``l`` owns spheres ``body_start[l]:body_start[l + 1]``
    pairs: np.ndarray  #: (P, 2) int64, the link pairs checked
    self_on: bool  #: whether the pairs count (False: their rows are ``inf``)
    link_grid: np.ndarray = _NO_LINK_GRID  #: (L,) int64, the grid of each link (-1 none), or (0,): no grids
    grids: np.ndarray = _NO_GRIDS  #: (Ng, 14) origin, pitch, shape, start in ``grid_values``, box (lower, upper)
    grid_values: np.ndarray = _NO_GRID_VALUES  #: (N,) float32, the grids' values, x slowest (metres)


class Scene(NamedTuple):
    """The world's obstacles as the kernels take them (:meth:`nik.collision.World.packed`)."""

    spheres: np.ndarray  #: (Ns, 4) centre and radius (metres)
    boxes: np.ndarray  #: (Nb, 15) rotation row by row, centre, half sizes
    capsules: np.ndarray  #: (Nc, 7) the segment's two ends and the radius


@kernel
def _frames(G, joints, q, F):
    """``F (n + 1, 3, 4)``: identity, then the frame after each joint: ``F[k + 1] = F[k] G[k] J(q[k])`` (``F[0] G[0]``
    read as ``G[0]``), the products of :func:`nik.kernels.chain._times` and :func:`nik.kernels.chain._joint` written
    out in place (the same operations, so the same bits; no scratch frame to allocate, no row views to count)."""
    n = q.shape[0]
    for r in range(3):
        for k in range(4):
            F[0, r, k] = 1.0 if r == k else 0.0
    for i in range(n):
        if i == 0:
            for r in range(3):
                for k in range(4):
                    F[1, r, k] = G[0, r, k]
        else:
            for r in range(3):
                t0, t1, t2, t3 = F[i, r, 0], F[i, r, 1], F[i, r, 2], F[i, r, 3]
                F[i + 1, r, 0] = t0 * G[i, 0, 0] + t1 * G[i, 1, 0] + t2 * G[i, 2, 0]
                F[i + 1, r, 1] = t0 * G[i, 0, 1] + t1 * G[i, 1, 1] + t2 * G[i, 2, 1]
                F[i + 1, r, 2] = t0 * G[i, 0, 2] + t1 * G[i, 1, 2] + t2 * G[i, 2, 2]
                F[i + 1, r, 3] = t0 * G[i, 0, 3] + t1 * G[i, 1, 3] + t2 * G[i, 2, 3] + t3
        theta = q[i] + joints[i, OFFSET]
        if joints[i, PRISMATIC] != 0.0:
            for r in range(3):
                F[i + 1, r, 3] += F[i + 1, r, 2] * theta
        else:
            c, sn = math.cos(theta), math.sin(theta)
            for r in range(3):
                x, y = F[i + 1, r, 0], F[i + 1, r, 1]
                F[i + 1, r, 0] = x * c + y * sn
                F[i + 1, r, 1] = y * c - x * sn


@kernel
def _place(F, spheres, sphere_frame, X):
    for s in range(spheres.shape[0]):
        f = sphere_frame[s]
        for r in range(3):
            X[s, r] = F[f, r, 0] * spheres[s, 0] + F[f, r, 1] * spheres[s, 1] + F[f, r, 2] * spheres[s, 2] + F[f, r, 3]


@kernel
def _place_frame(F, spheres, sphere_frame, k, X):
    """:func:`_place` for the spheres on frame ``k`` only (a sweep moves one frame; the others stay placed)."""
    for s in range(spheres.shape[0]):
        if sphere_frame[s] != k:
            continue
        for r in range(3):
            X[s, r] = F[k, r, 0] * spheres[s, 0] + F[k, r, 1] * spheres[s, 1] + F[k, r, 2] * spheres[s, 2] + F[k, r, 3]


@kernel
def _add_point_jacobian(F, joints, frame, x, y, z, vx, vy, vz, sign, J, k):
    """``J[k, m] += sign * v . dc/dq_m`` for a point ``(x, y, z)`` riding on frame ``frame`` (row ``k`` by index, not
    a row view: a view costs two atomic reference counts)."""
    for m in range(frame):
        zx, zy, zz = F[m + 1, 0, 2], F[m + 1, 1, 2], F[m + 1, 2, 2]
        if joints[m, PRISMATIC] != 0.0:
            J[k, m] += sign * (vx * zx + vy * zy + vz * zz)
        else:
            rx, ry, rz = x - F[m + 1, 0, 3], y - F[m + 1, 1, 3], z - F[m + 1, 2, 3]
            cx, cy, cz = zy * rz - zz * ry, zz * rx - zx * rz, zx * ry - zy * rx
            J[k, m] += sign * (vx * cx + vy * cy + vz * cz)


@kernel(inline="always")
def _radial(dx, dy, dz, r, g, want):
    """Signed distance ``|d| - r`` of the offset ``d = (dx, dy, dz)`` from a point to its nearest point on a core (a
    sphere's centre, a capsule's segment), its gradient ``d / |d|`` in ``g (3,)`` where ``want`` (+z where
    ``d = 0``)."""
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    if want:
        if n > 0:
            g[0], g[1], g[2] = dx / n, dy / n, dz / n
        else:
            g[0], g[1], g[2] = 0.0, 0.0, 1.0
    return n - r


@kernel(inline="always")
def _sphere_distance(x, y, z, w, o, g, want):
    """Signed distance from the point ``(x, y, z)`` to the world's sphere ``w[o]``, its gradient in ``g (3,)``
    where ``want``."""
    return _radial(x - w[o, 0], y - w[o, 1], z - w[o, 2], w[o, 3], g, want)


@kernel(inline="always")
def _capsule_distance(x, y, z, w, o, g, want):
    """Signed distance from the point ``(x, y, z)`` to the world's capsule ``w[o]``, its gradient in ``g (3,)``
    where ``want``."""
    ax, ay, az = w[o, 0], w[o, 1], w[o, 2]
    bx, by, bz = w[o, 3] - ax, w[o, 4] - ay, w[o, 5] - az
    L2 = bx * bx + by * by + bz * bz
    t = 0.0
    if L2 > 0:
        t = ((x - ax) * bx + (y - ay) * by + (z - az) * bz) / L2
        t = min(1.0, max(0.0, t))
    return _radial(x - (ax + t * bx), y - (ay + t * by), z - (az + t * bz), w[o, 6], g, want)


@kernel(inline="always")
def _box_distance(x, y, z, w, o, g, want):
    """Signed distance from the point ``(x, y, z)`` to the world's box ``w[o]`` (exact SDF), its gradient in ``g``
    where ``want``."""
    px, py, pz = x - w[o, 9], y - w[o, 10], z - w[o, 11]  # w[o, k], not a row view w[o]: no reference count
    lx = w[o, 0] * px + w[o, 3] * py + w[o, 6] * pz  # R^T (p - c)
    ly = w[o, 1] * px + w[o, 4] * py + w[o, 7] * pz
    lz = w[o, 2] * px + w[o, 5] * py + w[o, 8] * pz
    qx, qy, qz = abs(lx) - w[o, 12], abs(ly) - w[o, 13], abs(lz) - w[o, 14]
    qmax = max(qx, max(qy, qz))
    if not want:
        if qmax > 0:
            wx, wy, wz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
            return math.sqrt(wx * wx + wy * wy + wz * wz)
        return qmax
    if qmax > 0:
        wx, wy, wz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        d = math.sqrt(wx * wx + wy * wy + wz * wz)
        gx, gy, gz = math.copysign(wx / d, lx), math.copysign(wy / d, ly), math.copysign(wz / d, lz)
    else:
        d = qmax
        gx, gy, gz = 0.0, 0.0, 0.0
        if qx >= qy and qx >= qz:
            gx = math.copysign(1.0, lx)
        elif qy >= qz:
            gy = math.copysign(1.0, ly)
        else:
            gz = math.copysign(1.0, lz)
    g[0] = w[o, 0] * gx + w[o, 1] * gy + w[o, 2] * gz
    g[1] = w[o, 3] * gx + w[o, 4] * gy + w[o, 5] * gz
    g[2] = w[o, 6] * gx + w[o, 7] * gy + w[o, 8] * gz
    return d


@kernel(inline="always")
def _obstacle_one(x, y, z, kind, o, w_spheres, w_boxes, w_capsules, g, want=False):
    """Signed distance from ``(x, y, z)`` to obstacle ``o`` of ``kind`` (0 sphere, 1 box, 2 capsule), its gradient
    in ``g`` where ``want`` (the scans skip it: computed once for the nearest)."""
    if kind == 0:
        return _sphere_distance(x, y, z, w_spheres, o, g, want)
    if kind == 1:
        return _box_distance(x, y, z, w_boxes, o, g, want)
    return _capsule_distance(x, y, z, w_capsules, o, g, want)


@kernel
def _obstacle_bound(kind, o, w_spheres, w_boxes, w_capsules, out, m):
    """``out[m] (4,)``: a sphere holding obstacle ``o`` of ``kind`` (0 sphere, 1 box, 2 capsule): centre, radius."""
    if kind == 0:
        for r in range(4):
            out[m, r] = w_spheres[o, r]
    elif kind == 1:
        b = w_boxes
        out[m, 0], out[m, 1], out[m, 2] = b[o, 9], b[o, 10], b[o, 11]
        out[m, 3] = math.sqrt(b[o, 12] * b[o, 12] + b[o, 13] * b[o, 13] + b[o, 14] * b[o, 14])
    else:
        c = w_capsules
        dx, dy, dz = c[o, 3] - c[o, 0], c[o, 4] - c[o, 1], c[o, 5] - c[o, 2]
        out[m, 0], out[m, 1] = 0.5 * (c[o, 0] + c[o, 3]), 0.5 * (c[o, 1] + c[o, 4])
        out[m, 2] = 0.5 * (c[o, 2] + c[o, 5])
        out[m, 3] = 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz) + c[o, 6]


@kernel
def link_bounds(spheres, body_start, bounds):
    """``bounds (L, 4)``: each link's bounding sphere in its own frame (the mean of its centres, and the radius
    reaching every one of its spheres; radius -1 for a link without spheres). A link rides on one frame, so the
    bound placed with that frame holds the placed spheres (a rigid motion keeps distances)."""
    for link in range(body_start.shape[0] - 1):
        s0, s1 = body_start[link], body_start[link + 1]
        for r in range(4):
            bounds[link, r] = 0.0
        if s1 <= s0:
            bounds[link, 3] = -1.0
            continue
        for s in range(s0, s1):
            for r in range(3):
                bounds[link, r] += spheres[s, r]
        for r in range(3):
            bounds[link, r] /= s1 - s0
        for s in range(s0, s1):
            dx, dy, dz = (
                spheres[s, 0] - bounds[link, 0],
                spheres[s, 1] - bounds[link, 1],
                spheres[s, 2] - bounds[link, 2],
            )
            bounds[link, 3] = max(bounds[link, 3], math.sqrt(dx * dx + dy * dy + dz * dz) + spheres[s, 3])


@kernel
def link_capsules(spheres, body_start, caps):
    """``caps (L, 7)``: each link's capsule in its own frame, a segment ``caps[l, 0:3]``-``caps[l, 3:6]`` along the
    principal axis of its centres (power iteration on their scatter) and the radius ``caps[l, 6]`` reaching every
    one of its spheres, plus 1 um for the rounding of the tests that read it (radius -1 for a link without
    spheres). Any axis gives a capsule that holds the link (the radius is measured); the principal one the thinnest
    of those tried. Tighter than :func:`link_bounds`' sphere for an elongated link (panda: radius 2-11 cm against
    4-19 cm)."""
    for link in range(body_start.shape[0] - 1):
        s0, s1 = body_start[link], body_start[link + 1]
        if s1 <= s0:
            for r in range(6):
                caps[link, r] = 0.0
            caps[link, 6] = -1.0
            continue
        mx, my, mz = 0.0, 0.0, 0.0
        for s in range(s0, s1):
            mx, my, mz = mx + spheres[s, 0], my + spheres[s, 1], mz + spheres[s, 2]
        mx, my, mz = mx / (s1 - s0), my / (s1 - s0), mz / (s1 - s0)
        ux, uy, uz = 0.577, 0.578, 0.576
        for _ in range(8):  # power iteration: u <- C u / |C u|, C the scatter of the centres
            vx, vy, vz = 0.0, 0.0, 0.0
            for s in range(s0, s1):
                dx, dy, dz = spheres[s, 0] - mx, spheres[s, 1] - my, spheres[s, 2] - mz
                k = dx * ux + dy * uy + dz * uz
                vx, vy, vz = vx + k * dx, vy + k * dy, vz + k * dz
            nv = math.sqrt(vx * vx + vy * vy + vz * vz)
            if nv == 0.0:
                break
            ux, uy, uz = vx / nv, vy / nv, vz / nv
        lo, hi = np.inf, -np.inf
        for s in range(s0, s1):
            t = (spheres[s, 0] - mx) * ux + (spheres[s, 1] - my) * uy + (spheres[s, 2] - mz) * uz
            lo, hi = min(lo, t), max(hi, t)
        caps[link, 0], caps[link, 1], caps[link, 2] = mx + lo * ux, my + lo * uy, mz + lo * uz
        caps[link, 3], caps[link, 4], caps[link, 5] = mx + hi * ux, my + hi * uy, mz + hi * uz
        rad = 0.0
        for s in range(s0, s1):
            near = _point_segment(spheres[s, 0], spheres[s, 1], spheres[s, 2], caps[link, 0], caps[link, 1],
                                  caps[link, 2], caps[link, 3], caps[link, 4], caps[link, 5])  # fmt: skip
            rad = max(rad, near + spheres[s, 3])
        caps[link, 6] = rad + 1e-6


@kernel(inline="always")
def _point_segment(px, py, pz, ax, ay, az, bx, by, bz):
    """Distance from the point ``p`` to the segment ``a``-``b`` (metres)."""
    dx, dy, dz = bx - ax, by - ay, bz - az
    L2 = dx * dx + dy * dy + dz * dz
    t = 0.0
    if L2 > 0:
        t = min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / L2))
    ex, ey, ez = px - (ax + t * dx), py - (ay + t * dy), pz - (az + t * dz)
    return math.sqrt(ex * ex + ey * ey + ez * ez)


@kernel(inline="always")
def _segment_segment(p1x, p1y, p1z, q1x, q1y, q1z, p2x, p2y, p2z, q2x, q2y, q2z):
    """Distance between the segments ``p1``-``q1`` and ``p2``-``q2`` (metres): the closest points of the clamped
    parameters (Ericson, Real-Time Collision Detection 5.1.9); within rounding of the true distance (the capsules'
    1 um covers it)."""
    d1x, d1y, d1z = q1x - p1x, q1y - p1y, q1z - p1z
    d2x, d2y, d2z = q2x - p2x, q2y - p2y, q2z - p2z
    rx, ry, rz = p1x - p2x, p1y - p2y, p1z - p2z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    s, t = 0.0, 0.0
    if a <= 1e-18 and e <= 1e-18:
        s, t = 0.0, 0.0
    elif a <= 1e-18:
        t = min(1.0, max(0.0, f / e))
    else:
        c = d1x * rx + d1y * ry + d1z * rz
        if e <= 1e-18:
            s = min(1.0, max(0.0, -c / a))
        else:
            b = d1x * d2x + d1y * d2y + d1z * d2z
            den = a * e - b * b
            if den > 0:
                s = min(1.0, max(0.0, (b * f - c * e) / den))
            t = (b * s + f) / e
            if t < 0:
                t = 0.0
                s = min(1.0, max(0.0, -c / a))
            elif t > 1:
                t = 1.0
                s = min(1.0, max(0.0, (b - c) / a))
    ex = p1x + d1x * s - (p2x + d2x * t)
    ey = p1y + d1y * s - (p2y + d2y * t)
    ez = p1z + d1z * s - (p2z + d2z * t)
    return math.sqrt(ex * ex + ey * ey + ez * ez)


@kernel(inline="always")
def _grid_of(arm, link):
    """The grid checking link ``link`` (:class:`ArmSpheres`' ``link_grid``), -1 for none."""
    link_grid = arm[5]
    if link < link_grid.shape[0]:
        return link_grid[link]
    return -1


@kernel(inline="always")
def _grid_box_gap(grids, k, x, y, z, box):
    """How far ``(x, y, z)`` lies outside grid ``k``'s nodes (``box`` False) or its geometry's bounding box
    (``box`` True), metres (0 within)."""
    dx, dy, dz = 0.0, 0.0, 0.0
    if box:
        lx, ly, lz, hx, hy, hz = grids[k, 8], grids[k, 9], grids[k, 10], grids[k, 11], grids[k, 12], grids[k, 13]
    else:
        h = grids[k, 3]
        lx, ly, lz = grids[k, 0], grids[k, 1], grids[k, 2]
        hx, hy, hz = lx + h * (grids[k, 4] - 1), ly + h * (grids[k, 5] - 1), lz + h * (grids[k, 6] - 1)
    dx = max(lx - x, max(x - hx, 0.0))
    dy = max(ly - y, max(y - hy, 0.0))
    dz = max(lz - z, max(z - hz, 0.0))
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@kernel(inline="always")
def _grid_value(grids, values, k, x, y, z, g, want):
    """The value of grid ``k`` at ``(x, y, z)`` (:mod:`nik.collision.sdf`: at most the signed distance to the
    static link's geometry, metres): trilinear between its nodes, the distance to the geometry's bounding box
    outside them; its gradient in ``g (3,)`` where ``want``."""
    h = grids[k, 3]
    nx, ny, nz = int(grids[k, 4]), int(grids[k, 5]), int(grids[k, 6])
    fx, fy, fz = (x - grids[k, 0]) / h, (y - grids[k, 1]) / h, (z - grids[k, 2]) / h
    if fx < 0.0 or fy < 0.0 or fz < 0.0 or fx > nx - 1 or fy > ny - 1 or fz > nz - 1:
        lx, ly, lz, hx, hy, hz = grids[k, 8], grids[k, 9], grids[k, 10], grids[k, 11], grids[k, 12], grids[k, 13]
        dx, dy, dz = max(lx - x, max(x - hx, 0.0)), max(ly - y, max(y - hy, 0.0)), max(lz - z, max(z - hz, 0.0))
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if want:
            gx = dx if x > hx else -dx
            gy = dy if y > hy else -dy
            gz = dz if z > hz else -dz
            g[0], g[1], g[2] = gx / d, gy / d, gz / d
        return d
    i, j, m = min(int(fx), nx - 2), min(int(fy), ny - 2), min(int(fz), nz - 2)
    tx, ty, tz = fx - i, fy - j, fz - m
    b = int(grids[k, 7]) + (i * ny + j) * nz + m
    sx, sy = ny * nz, nz
    v000, v001 = float(values[b]), float(values[b + 1])
    v010, v011 = float(values[b + sy]), float(values[b + sy + 1])
    v100, v101 = float(values[b + sx]), float(values[b + sx + 1])
    v110, v111 = float(values[b + sx + sy]), float(values[b + sx + sy + 1])
    c00, c01 = v000 + (v001 - v000) * tz, v010 + (v011 - v010) * tz
    c10, c11 = v100 + (v101 - v100) * tz, v110 + (v111 - v110) * tz
    c0, c1 = c00 + (c01 - c00) * ty, c10 + (c11 - c10) * ty
    if want:
        g[0] = (c1 - c0) / h
        g[1] = ((1 - tx) * (c01 - c00) + tx * (c11 - c10)) / h
        a0 = (1 - ty) * (v001 - v000) + ty * (v011 - v010)
        a1 = (1 - ty) * (v101 - v100) + ty * (v111 - v110)
        g[2] = ((1 - tx) * a0 + tx * a1) / h
    return c0 + (c1 - c0) * tx


@kernel
def _grid_row(X, arm, k, mover, below, g):
    """``(best, s)``: the smallest ``v(c_s) - r_s`` over the placed spheres ``X`` of link ``mover`` against grid
    ``k`` (:func:`_grid_value`) and the sphere giving it; returned as soon as it is below ``below``."""
    spheres, body_start, grids, values = arm[0], arm[2], arm[6], arm[7]
    best, bs = np.inf, -1
    for s in range(body_start[mover], body_start[mover + 1]):
        dist = _grid_value(grids, values, k, X[s, 0], X[s, 1], X[s, 2], g, False) - spheres[s, 3]
        if dist < best:
            best, bs = dist, s
            if best < below:
                return best, bs
    return best, bs


@kernel(inline="always")
def _place_link(F, spheres, sphere_frame, body_start, link, X, placed):
    """The world positions of link ``link``'s spheres in ``X``, once per evaluation (``placed[link]``)."""
    if placed[link]:
        return
    placed[link] = True
    for s in range(body_start[link], body_start[link + 1]):
        f = sphere_frame[s]
        for r in range(3):
            X[s, r] = F[f, r, 0] * spheres[s, 0] + F[f, r, 1] * spheres[s, 1] + F[f, r, 2] * spheres[s, 2] + F[f, r, 3]


@kernel
def rows_work(n, arm, scene, capsules=True):
    """``(wf, wi)``: the scratch of :func:`_rows_in` for a chain of ``n`` joints, the model and the world (float64
    and int64, 1-D), allocated once by a caller that evaluates many configurations (an LM, a batch) rather than on
    every evaluation (13 small arrays: about 1 us of a 5-10 us evaluation). It also holds each link's capsule
    (:func:`link_capsules`, computed here once: the scratch belongs to this model; ~1 us, so ``capsules`` False for
    a caller that evaluates one configuration: the pairs' broad phase then stops at the links' spheres)."""
    spheres, body_start = arm[0], arm[2]
    w_spheres, w_boxes, w_capsules = scene
    S, L = spheres.shape[0], body_start.shape[0] - 1
    No = w_spheres.shape[0] + w_boxes.shape[0] + w_capsules.shape[0]
    a = (n + 1) * 12 + 3 * S + 3 * L + 4 * No + 6
    wf = np.empty(a + 13 * L)
    caps = wf[a : a + 7 * L].reshape((L, 7))  # the model's: read by _rows_in, never written
    if capsules:
        link_capsules(spheres, body_start, caps)
    else:
        caps[:, :] = -2.0  # none: radius -2
    return wf, np.empty(5 * No + S + L, dtype=np.int64)


@kernel
def _rows(G, joints, q, arm, scene, d, J, want_jacobian, cutoff, bounds, stop):
    """:func:`_rows_in` with its scratch allocated here (:func:`rows_work`)."""
    work = rows_work(q.shape[0], arm, scene, False)
    return _rows_in(G, joints, q, arm, scene, d, J, want_jacobian, cutoff, bounds, stop, work)


@kernel
def _rows_in(G, joints, q, arm, scene, d, J, want_jacobian, cutoff, bounds, stop, work):
    """The rows (module docstring) with the broad phase: ``d[k]`` is exact wherever it is at most ``cutoff``, else
    a lower bound above ``cutoff`` (Jacobian row 0). ``bounds (L, 4)``: :func:`link_bounds`. ``stop``: return at the
    first row below ``cutoff`` (the rows after it are left unset). Returns whether a row is below ``cutoff``.
    ``work``: the scratch ``(wf, wi)`` of :func:`rows_work`.

    The broad phase, each test a lower bound of the distances it skips (a signed distance is 1-Lipschitz, so a
    bounding sphere's distance minus its radius bounds every sphere inside it): a pair of links whose bounding
    spheres are apart by more than ``cutoff`` is that bound, then likewise their capsules (where the scratch holds
    them: :func:`rows_work`); else a sphere of one link farther than ``cutoff`` from the other link's capsule (or
    bounding sphere) is skipped; a link and an obstacle whose bound is above ``cutoff``
    likewise. A row is the smallest of its exact distances and its skipped bounds, so below ``cutoff`` it equals
    the all-pairs minimum (the minimising pair is never skipped)."""
    spheres, sphere_frame, body_start, pairs, self_on = arm[0], arm[1], arm[2], arm[3], arm[4]
    w_spheres, w_boxes, w_capsules = scene
    wf, wi = work
    n = q.shape[0]
    S = spheres.shape[0]
    P = pairs.shape[0]
    L = body_start.shape[0] - 1
    No = w_spheres.shape[0] + w_boxes.shape[0] + w_capsules.shape[0]
    # the scratch (rows_work), sliced: frames, placed spheres, the links' and the obstacles' bounding spheres
    a = (n + 1) * 12
    F = wf[0:a].reshape((n + 1, 3, 4))
    X = wf[a : a + 3 * S].reshape((S, 3))
    a += 3 * S
    Bc = wf[a : a + 3 * L].reshape((L, 3))  # each link's bounding sphere, placed
    a += 3 * L
    Ob = wf[a : a + 4 * No].reshape((No, 4))  # each obstacle's bounding sphere: the first test of a link against it
    a += 4 * No
    g = wf[a : a + 3]
    gb = wf[a + 3 : a + 6]
    a += 6
    Cap = wf[a : a + 7 * L].reshape((L, 7))  # each link's capsule in its frame (rows_work)
    Cp = wf[a + 7 * L : a + 13 * L].reshape((L, 6))  # ... placed, for the pairs that need it
    kinds, which, all_kinds = wi[0:No], wi[No : 2 * No], wi[2 * No : 3 * No]
    near_at, all_which = wi[3 * No : 4 * No], wi[4 * No : 5 * No]
    keep, placed = wi[5 * No : 5 * No + S], wi[5 * No + S : 5 * No + S + L]
    for link in range(L):
        placed[link] = 0
    _frames(G, joints, q, F)
    for link in range(L):
        if bounds[link, 3] >= 0:
            f = sphere_frame[body_start[link]]
            for r in range(3):
                Bc[link, r] = F[f, r, 0] * bounds[link, 0] + F[f, r, 1] * bounds[link, 1] + F[f, r, 2] * bounds[link, 2]
                Bc[link, r] += F[f, r, 3]
    if want_jacobian:
        for r in range(P + L):
            for m in range(n):
                J[r, m] = 0.0
    for r in range(3):
        gb[r] = 0.0
    hit = False
    # the world first: a link and an obstacle are the likelier overlap, and the cheaper test
    m = 0
    for kind, count in ((0, w_spheres.shape[0]), (2, w_capsules.shape[0]), (1, w_boxes.shape[0])):
        for o in range(count):
            all_kinds[m], all_which[m] = kind, o
            _obstacle_bound(kind, o, w_spheres, w_boxes, w_capsules, Ob, m)
            m += 1
    for link in range(L):
        s0, s1 = body_start[link], body_start[link + 1]
        if s1 <= s0 or sphere_frame[s0] == 0 or No == 0:
            d[P + link] = np.inf  # the base's links never move: their contacts with the world are the user's set-up
            continue
        lower = np.inf  # the smallest bound of the obstacles skipped
        m = 0
        for t in range(No):
            kind, o = all_kinds[t], all_which[t]
            dx, dy, dz = Bc[link, 0] - Ob[t, 0], Bc[link, 1] - Ob[t, 1], Bc[link, 2] - Ob[t, 2]
            bound = math.sqrt(dx * dx + dy * dy + dz * dz) - Ob[t, 3] - bounds[link, 3]
            if bound <= cutoff and kind == 1:  # the bounding spheres within reach: the obstacle's own distance
                bound = _box_distance(Bc[link, 0], Bc[link, 1], Bc[link, 2], w_boxes, o, g, False) - bounds[link, 3]
            elif bound <= cutoff and kind == 2:
                x, y, z = Bc[link, 0], Bc[link, 1], Bc[link, 2]
                bound = _capsule_distance(x, y, z, w_capsules, o, g, False) - bounds[link, 3]
            if bound > cutoff:
                lower = min(lower, bound)
            else:
                kinds[m], which[m], near_at[m] = kind, o, t
                m += 1
        best, bs, bk = np.inf, -1, -1
        if m > 0:
            _place_link(F, spheres, sphere_frame, body_start, link, X, placed)
            for s in range(s0, s1):
                for k in range(m):
                    if kinds[k] != 0:  # the obstacle's bounding sphere first: skipped where it cannot matter
                        t = near_at[k]
                        dx, dy, dz = X[s, 0] - Ob[t, 0], X[s, 1] - Ob[t, 1], X[s, 2] - Ob[t, 2]
                        bound = math.sqrt(dx * dx + dy * dy + dz * dz) - Ob[t, 3] - spheres[s, 3]
                        if bound >= best:
                            continue
                        if bound > cutoff:
                            lower = min(lower, bound)
                            continue
                    dist = _obstacle_one(X[s, 0], X[s, 1], X[s, 2], kinds[k], which[k], w_spheres, w_boxes,
                                         w_capsules, g) - spheres[s, 3]  # fmt: skip
                    if dist < best:
                        best, bs, bk = dist, s, k
                        if stop and best < cutoff:
                            d[P + link] = best
                            return True
        d[P + link] = min(best, lower)
        if want_jacobian and bs >= 0 and best <= lower:
            _obstacle_one(X[bs, 0], X[bs, 1], X[bs, 2], kinds[bk], which[bk], w_spheres, w_boxes, w_capsules, gb, True)
            _add_point_jacobian(
                F, joints, sphere_frame[bs], X[bs, 0], X[bs, 1], X[bs, 2], gb[0], gb[1], gb[2], 1.0, J, P + link
            )
        if d[P + link] < cutoff:
            hit = True
            if stop:
                return True
    for p in range(P):
        if not self_on:
            d[p] = np.inf
            continue
        a, b = pairs[p, 0], pairs[p, 1]
        if bounds[a, 3] < 0 or bounds[b, 3] < 0:
            d[p] = np.inf
            continue
        gd, gs, k = -np.inf, -1, -1  # the grid's row of a static link on its grid: the pair's row is the larger
        ka, kb = _grid_of(arm, a), _grid_of(arm, b)
        if ka >= 0 or kb >= 0:  # (both are lower bounds of the distance): the spheres only where the grid's is low
            k, mover = (ka, b) if ka >= 0 else (kb, a)
            x, y, z = Bc[mover, 0], Bc[mover, 1], Bc[mover, 2]
            if _grid_box_gap(arm[6], k, x, y, z, False) > bounds[mover, 3]:  # all outside the nodes: the box's
                gd = _grid_box_gap(arm[6], k, x, y, z, True) - bounds[mover, 3]
            if gd <= cutoff:
                _place_link(F, spheres, sphere_frame, body_start, mover, X, placed)
                gd, gs = _grid_row(X, arm, k, mover, -np.inf, g)
            if gd >= cutoff:
                d[p] = gd
                if want_jacobian and gs >= 0:
                    _grid_value(arm[6], arm[7], k, X[gs, 0], X[gs, 1], X[gs, 2], gb, True)
                    _add_point_jacobian(F, joints, sphere_frame[gs], X[gs, 0], X[gs, 1], X[gs, 2], gb[0], gb[1],
                                        gb[2], 1.0, J, p)  # fmt: skip
                continue
        dx, dy, dz = Bc[a, 0] - Bc[b, 0], Bc[a, 1] - Bc[b, 1], Bc[a, 2] - Bc[b, 2]
        lower = math.sqrt(dx * dx + dy * dy + dz * dz) - bounds[a, 3] - bounds[b, 3]
        best, bi, bj = np.inf, -1, -1
        caps = Cap[a, 6] > -1.5 and Cap[b, 6] > -1.5
        if lower <= cutoff and caps:  # the links' capsules (rows_work), tighter than their spheres
            for k in (a, b):
                f = sphere_frame[body_start[k]]
                for e in range(2):
                    for r in range(3):
                        Cp[k, 3 * e + r] = (F[f, r, 0] * Cap[k, 3 * e] + F[f, r, 1] * Cap[k, 3 * e + 1]
                                            + F[f, r, 2] * Cap[k, 3 * e + 2] + F[f, r, 3])  # fmt: skip
            lower = _segment_segment(Cp[a, 0], Cp[a, 1], Cp[a, 2], Cp[a, 3], Cp[a, 4], Cp[a, 5], Cp[b, 0], Cp[b, 1],
                                     Cp[b, 2], Cp[b, 3], Cp[b, 4], Cp[b, 5]) - Cap[a, 6] - Cap[b, 6]  # fmt: skip
        if lower <= cutoff:
            lower = np.inf
            _place_link(F, spheres, sphere_frame, body_start, a, X, placed)
            _place_link(F, spheres, sphere_frame, body_start, b, X, placed)
            m = 0
            for j in range(body_start[b], body_start[b + 1]):  # link b's spheres within reach of link a
                if caps:
                    near = _point_segment(X[j, 0], X[j, 1], X[j, 2], Cp[a, 0], Cp[a, 1], Cp[a, 2], Cp[a, 3], Cp[a, 4],
                                          Cp[a, 5]) - spheres[j, 3] - Cap[a, 6]  # fmt: skip
                else:
                    dx, dy, dz = X[j, 0] - Bc[a, 0], X[j, 1] - Bc[a, 1], X[j, 2] - Bc[a, 2]
                    near = math.sqrt(dx * dx + dy * dy + dz * dz) - spheres[j, 3] - bounds[a, 3]
                if near > cutoff:  # sphere j is farther than cutoff from every sphere of link a
                    lower = min(lower, near)
                else:
                    keep[m] = j
                    m += 1
            for i in range(body_start[a], body_start[a + 1]):
                if m == 0:
                    break
                if caps:
                    near = _point_segment(X[i, 0], X[i, 1], X[i, 2], Cp[b, 0], Cp[b, 1], Cp[b, 2], Cp[b, 3], Cp[b, 4],
                                          Cp[b, 5]) - spheres[i, 3] - Cap[b, 6]  # fmt: skip
                else:
                    dx, dy, dz = X[i, 0] - Bc[b, 0], X[i, 1] - Bc[b, 1], X[i, 2] - Bc[b, 2]
                    near = math.sqrt(dx * dx + dy * dy + dz * dz) - spheres[i, 3] - bounds[b, 3]
                if near > cutoff:  # sphere i is farther than cutoff from every sphere of link b
                    lower = min(lower, near)
                    continue
                for t in range(m):
                    j = keep[t]
                    reach = best + spheres[i, 3] + spheres[j, 3]  # nearer than this beats the best so far
                    dx, dy, dz = X[i, 0] - X[j, 0], X[i, 1] - X[j, 1], X[i, 2] - X[j, 2]
                    sq = dx * dx + dy * dy + dz * dz
                    if reach > 0 and sq < reach * reach:
                        best, bi, bj = math.sqrt(sq) - spheres[i, 3] - spheres[j, 3], i, j
                        if stop and best < cutoff:
                            d[p] = max(best, gd)
                            return True
        d[p] = min(best, lower)
        if k >= 0 and gd > d[p]:
            d[p] = gd
            if want_jacobian and gs >= 0:
                _grid_value(arm[6], arm[7], k, X[gs, 0], X[gs, 1], X[gs, 2], gb, True)
                _add_point_jacobian(F, joints, sphere_frame[gs], X[gs, 0], X[gs, 1], X[gs, 2], gb[0], gb[1], gb[2],
                                    1.0, J, p)  # fmt: skip
        elif want_jacobian and bi >= 0 and best <= lower:
            dx, dy, dz = X[bi, 0] - X[bj, 0], X[bi, 1] - X[bj, 1], X[bi, 2] - X[bj, 2]
            nn = math.sqrt(dx * dx + dy * dy + dz * dz)
            if nn > 0:
                vx, vy, vz = dx / nn, dy / nn, dz / nn
                _add_point_jacobian(F, joints, sphere_frame[bi], X[bi, 0], X[bi, 1], X[bi, 2], vx, vy, vz, 1.0, J, p)
                _add_point_jacobian(F, joints, sphere_frame[bj], X[bj, 0], X[bj, 1], X[bj, 2], vx, vy, vz, -1.0, J, p)
        if d[p] < cutoff:
            hit = True
            if stop:
                return True
    return hit


@kernel
def collision_distances(G, joints, q, arm, scene, d, J):
    """Rows ``d (P + L,)`` (metres) and their Jacobian ``J (P + L, n)`` for ``q: (n,)`` (module docstring)."""
    bounds = np.empty((arm[2].shape[0] - 1, 4))
    link_bounds(arm[0], arm[2], bounds)
    _rows(G, joints, q, arm, scene, d, J, True, np.inf, bounds, False)


@kernel
def collision_residual(G, joints, q, arm, scene, margin, r, Jr):
    """LM rows ``r = max(0, margin - d)`` ``(P + L,)`` and ``Jr = dr/dq`` ``(P + L, n)`` for ``q: (n,)``; returns
    the smallest distance ``d`` where it is at most ``margin`` (metres), else a lower bound above ``margin``
    (``inf`` when there is nothing to check). Rows the broad phase puts farther than ``margin`` are not computed
    sphere by sphere (their residual is 0 either way)."""
    bounds = np.empty((arm[2].shape[0] - 1, 4))
    link_bounds(arm[0], arm[2], bounds)
    return residual_bounded(G, joints, q, arm, scene, margin, r, Jr, bounds)


@kernel
def residual_bounded(G, joints, q, arm, scene, margin, r, Jr, bounds):
    """:func:`collision_residual` with the links' bounds ``(L, 4)`` of :func:`link_bounds` given (computed once by
    a caller that evaluates many configurations of one model)."""
    work = rows_work(q.shape[0], arm, scene, False)
    return residual_in(G, joints, q, arm, scene, margin, r, Jr, bounds, work)


@kernel
def residual_in(G, joints, q, arm, scene, margin, r, Jr, bounds, work):
    """:func:`residual_bounded` with its scratch ``work`` given (:func:`rows_work`, once per call of the LM of
    :mod:`nik.kernels.collision_lm`)."""
    _rows_in(G, joints, q, arm, scene, r, Jr, True, margin, bounds, False, work)
    smallest = np.inf
    for k in range(r.shape[0]):
        dist = r[k]
        smallest = min(smallest, dist)
        if margin - dist > 0:
            r[k] = margin - dist
            for m in range(Jr.shape[1]):
                Jr[k, m] = -Jr[k, m]
        else:
            r[k] = 0.0
            for m in range(Jr.shape[1]):
                Jr[k, m] = 0.0
    return smallest


@kernel
def collides_bounded(G, joints, q, arm, scene, margin, d, bounds):
    """Whether some row of ``q: (n,)`` is below ``margin`` (metres), stopping at the first such row, no Jacobian;
    ``d (P + L,)`` scratch, ``bounds (L, 4)``: :func:`link_bounds` (the test of :func:`collides_batch`, for one
    configuration)."""
    work = rows_work(q.shape[0], arm, scene, False)
    return collides_in(G, joints, q, arm, scene, margin, d, bounds, work)


@kernel
def collides_in(G, joints, q, arm, scene, margin, d, bounds, work):
    """:func:`collides_bounded` with its scratch ``work`` given (:func:`rows_work`)."""
    J = np.empty((0, q.shape[0]))
    return _rows_in(G, joints, q, arm, scene, d, J, False, margin, bounds, True, work)


@kernel
def collision_distances_batch(G, joints, Q, arm, scene, D):
    """Rows ``D (B, P + L)`` for ``Q: (B, n)``, exact (every sphere pair), no Jacobian."""
    collision_rows_batch(G, joints, Q, arm, scene, np.inf, D)


@kernel
def collision_rows_batch(G, joints, Q, arm, scene, cutoff, D):
    """Rows ``D (B, P + L)`` for ``Q: (B, n)`` through the broad phase of ``cutoff`` (metres): each row equal to
    the exact one (:func:`collision_distances_batch`) wherever either is at most ``cutoff``, else a lower bound
    above ``cutoff`` (what the tests compare)."""
    J = np.empty((0, Q.shape[1]))
    bounds = np.empty((arm[2].shape[0] - 1, 4))
    link_bounds(arm[0], arm[2], bounds)
    work = rows_work(Q.shape[1], arm, scene)
    for b in range(Q.shape[0]):
        _rows_in(G, joints, Q[b], arm, scene, D[b], J, False, cutoff, bounds, False, work)


@kernel
def collides_batch(G, joints, Q, arm, scene, margin, out):
    """``out (B,)`` bool: some row of ``Q[b]`` is below ``margin`` (metres); each configuration stops at its first
    such row."""
    spheres, body_start, pairs = arm[0], arm[2], arm[3]
    R = pairs.shape[0] + body_start.shape[0] - 1
    d = np.empty(R)
    J = np.empty((0, Q.shape[1]))
    bounds = np.empty((body_start.shape[0] - 1, 4))
    link_bounds(spheres, body_start, bounds)
    work = rows_work(Q.shape[1], arm, scene)
    for b in range(Q.shape[0]):
        out[b] = _rows_in(G, joints, Q[b], arm, scene, d, J, False, margin, bounds, True, work)


@kernel
def _link_bound(F, bounds, sphere_frame, body_start, link, c):
    """``c (3,)``: link ``link``'s bounding sphere (:func:`link_bounds`) placed by the frames ``F``; returns its
    radius (-1 for a link without spheres)."""
    if bounds[link, 3] < 0:
        return -1.0
    f = sphere_frame[body_start[link]]
    for r in range(3):
        c[r] = F[f, r, 0] * bounds[link, 0] + F[f, r, 1] * bounds[link, 1] + F[f, r, 2] * bounds[link, 2] + F[f, r, 3]
    return bounds[link, 3]


@kernel
def _link_world(X, F, bounds, arm, scene, link, g, c, cut, below):
    """The smallest row of link ``link`` against the world: exact where at most ``cut``, else a lower bound above it
    (an obstacle farther than ``cut`` from the link's bounding sphere is that bound: a signed distance is
    1-Lipschitz); returned as soon as it is below ``below``."""
    spheres, sphere_frame, body_start = arm[0], arm[1], arm[2]
    w_spheres, w_boxes, w_capsules = scene
    s0, s1 = body_start[link], body_start[link + 1]
    rad = _link_bound(F, bounds, sphere_frame, body_start, link, c)
    best = np.inf
    for kind, count in ((0, w_spheres.shape[0]), (2, w_capsules.shape[0]), (1, w_boxes.shape[0])):
        for o in range(count):
            lower = _obstacle_one(c[0], c[1], c[2], kind, o, w_spheres, w_boxes, w_capsules, g) - rad
            if lower > cut:
                best = min(best, lower)
                continue
            for s in range(s0, s1):
                dist = _obstacle_one(X[s, 0], X[s, 1], X[s, 2], kind, o, w_spheres, w_boxes, w_capsules, g)
                best = min(best, dist - spheres[s, 3])
                if best < below:
                    return best
    return best


@kernel
def _pair_row(X, F, bounds, arm, a, b, c, cb, cut, below):
    """The row of links ``a`` and ``b``: exact where at most ``cut``, else a lower bound above it (their bounding
    spheres' distance); returned as soon as it is below ``below``."""
    spheres, sphere_frame, body_start = arm[0], arm[1], arm[2]
    gd = -np.inf
    ka, kb = _grid_of(arm, a), _grid_of(arm, b)
    if ka >= 0 or kb >= 0:  # a static link on its distance grid: the larger of its row and the spheres' (_rows_in)
        k, mover = (ka, b) if ka >= 0 else (kb, a)
        rm = _link_bound(F, bounds, sphere_frame, body_start, mover, c)
        if _grid_box_gap(arm[6], k, c[0], c[1], c[2], False) > rm:
            gd = _grid_box_gap(arm[6], k, c[0], c[1], c[2], True) - rm
            if gd > cut:
                return gd
        gd = _grid_row(X, arm, k, mover, -np.inf, cb)[0]
        if gd > cut:
            return gd
        if gd >= below:
            below = -np.inf  # the pair's row is at least the grid's: the spheres' exact minimum decides
    ra = _link_bound(F, bounds, sphere_frame, body_start, a, c)
    rb = _link_bound(F, bounds, sphere_frame, body_start, b, cb)
    dx, dy, dz = c[0] - cb[0], c[1] - cb[1], c[2] - cb[2]
    lower = math.sqrt(dx * dx + dy * dy + dz * dz) - ra - rb
    if lower > cut:
        return max(lower, gd)
    best = np.inf
    for i in range(body_start[a], body_start[a + 1]):
        for j in range(body_start[b], body_start[b + 1]):
            dx, dy, dz = X[i, 0] - X[j, 0], X[i, 1] - X[j, 1], X[i, 2] - X[j, 2]
            best = min(best, math.sqrt(dx * dx + dy * dy + dz * dz) - spheres[i, 3] - spheres[j, 3])
            if best < below:
                return max(best, gd)
    return max(best, gd)


@kernel
def _fixed_rows(X, F, bounds, arm, scene, on, g, cut):
    """The smallest row among those whose links all have ``on[frame]`` (placed in ``X``, frames ``F``, the links'
    bounds ``bounds``): pairs with both links on such frames, and such links (not on frame 0) against the world;
    exact where at most ``cut``, else a lower bound above it."""
    sphere_frame, body_start, pairs, self_on = arm[1], arm[2], arm[3], arm[4]
    L = body_start.shape[0] - 1
    best = np.inf
    c, cb = np.empty(3), np.empty(3)
    for link in range(L):
        s0, s1 = body_start[link], body_start[link + 1]
        if s1 <= s0 or not on[sphere_frame[s0]] or sphere_frame[s0] == 0:
            continue
        best = min(best, _link_world(X, F, bounds, arm, scene, link, g, c, cut, -np.inf))
    if self_on:
        for p in range(pairs.shape[0]):
            a, b = pairs[p, 0], pairs[p, 1]
            if body_start[a] == body_start[a + 1] or body_start[b] == body_start[b + 1]:
                continue
            if not (on[sphere_frame[body_start[a]]] and on[sphere_frame[body_start[b]]]):
                continue
            best = min(best, _pair_row(X, F, bounds, arm, a, b, c, cb, cut, -np.inf))
    return best


@kernel
def _sweep_rows(X, F, bounds, arm, scene, k, n, g, below):
    """The smallest row of the links on frame ``k`` (placed in ``X``, frames ``F``, the links' bounds ``bounds``):
    against the world, and against the links on frames 0, ``k`` and ``n``; exact where at most ``below``, else a
    lower bound above it; returned as soon as one is below ``below`` (then an upper bound of it)."""
    sphere_frame, body_start, pairs, self_on = arm[1], arm[2], arm[3], arm[4]
    L = body_start.shape[0] - 1
    best = np.inf
    c, cb = np.empty(3), np.empty(3)
    for link in range(L):
        s0, s1 = body_start[link], body_start[link + 1]
        if s1 <= s0 or sphere_frame[s0] != k:
            continue
        best = min(best, _link_world(X, F, bounds, arm, scene, link, g, c, below, below))
        if best < below:
            return best
    if self_on:
        for p in range(pairs.shape[0]):
            a, b = pairs[p, 0], pairs[p, 1]
            if body_start[a] == body_start[a + 1] or body_start[b] == body_start[b + 1]:
                continue
            fa, fb = sphere_frame[body_start[a]], sphere_frame[body_start[b]]
            if not ((fa == k and (fb == 0 or fb == k or fb == n)) or (fb == k and (fa == 0 or fa == k or fa == n))):
                continue
            best = min(best, _pair_row(X, F, bounds, arm, a, b, c, cb, below, below))
            if best < below:
                return best
    return best


@kernel
def _rigid_inverse_times(A, M, out):
    """``out (3, 4) = A @ M^-1`` for rigid ``A (3, 4)`` and ``M (3, 4)`` (their top rows)."""
    for r in range(3):
        for c in range(3):
            out[r, c] = A[r, 0] * M[c, 0] + A[r, 1] * M[c, 1] + A[r, 2] * M[c, 2]
    for r in range(3):
        out[r, 3] = A[r, 3] - (out[r, 0] * M[0, 3] + out[r, 1] * M[1, 3] + out[r, 2] * M[2, 3])


@kernel
def hand_lever(G, spheres, sphere_frame):
    """The farthest a sphere centre on the last frame (``n = G.shape[0] - 1``, the tool's: it rides with the pose)
    lies from the tool point ``G[n][:3, 3]`` (metres; 0 with none there): a pose within ``tol_rot`` of a target moves
    such a sphere by at most ``tol_pos + tol_rot * lever``. Read by the blocked-pose proof's fixed rows
    (:func:`nik.collision.compiled.blocked_targets`) and the collision LM's finishing step."""
    n = G.shape[0] - 1
    lever = 0.0
    for k in range(spheres.shape[0]):
        if sphere_frame[k] == n:
            x, y, z = spheres[k, 0] - G[n, 0, 3], spheres[k, 1] - G[n, 1, 3], spheres[k, 2] - G[n, 2, 3]
            lever = max(lever, math.sqrt(x * x + y * y + z * z))
    return lever


@kernel
def _lever(spheres, sphere_frame, k, M, prismatic):
    """The farthest a sphere centre on frame ``k`` lies from the axis of the joint that turns it (the z axis of
    ``M (3, 4)`` in frame ``k``'s coordinates): what a sphere moves per radian; 1 for a prismatic joint."""
    rho = 0.0
    for s in range(spheres.shape[0]):
        if sphere_frame[s] != k:
            continue
        if prismatic:
            return 1.0
        vx, vy, vz = spheres[s, 0] - M[0, 3], spheres[s, 1] - M[1, 3], spheres[s, 2] - M[2, 3]
        along = vx * M[0, 2] + vy * M[1, 2] + vz * M[2, 2]
        rho = max(rho, math.sqrt(max(vx * vx + vy * vy + vz * vz - along * along, 0.0)))
    return rho


@kernel
def _piece_blocked(G, joints, arm, scene, work, swept, x, half):
    """Whether every value of joint ``j`` within ``half`` of ``x`` leaves the links on frame ``k`` colliding for every
    configuration within ``slack`` of the pose (``swept = (sweep, j, k, n, rho, slack, depth)``, :func:`blocked_poses`'s
    sweep ``sweep``: 0 the first joint, 1 the last). A piece is blocked where the row at its centre is below
    ``-(rho * half + slack)`` (a sphere moves at most ``rho`` per unit of the joint); else, unless that row is at least
    ``-slack`` or the piece is ``depth`` halvings deep, its two halves are judged the same way. ``work = (F, X, lb, g,
    Tj, stack)``: the frames and placed spheres of the pose, the links' bounds, scratch (``stack (depth + 2, 2)``)."""
    spheres, sphere_frame = arm[0], arm[1]
    F, X, lb, g, Tj, stack = work
    sweep, j, k, n, rho, slack, depth = swept
    top = 0
    stack[0, 0], stack[0, 1] = x, half
    while top >= 0:
        c, w = stack[top, 0], stack[top, 1]
        top -= 1
        prismatic = joints[j, PRISMATIC] != 0.0
        if sweep == 0:  # F[1] = G[0] J(q1)
            _start(Tj, G[0])
            _joint(Tj, prismatic, c + joints[j, OFFSET])
            for r in range(3):
                for col in range(4):
                    F[1, r, col] = Tj[r, col]
        else:  # F[n - 1] = F[n] (G[n - 1] J(qn))^-1
            _start(Tj, G[n - 1])
            _joint(Tj, prismatic, c + joints[j, OFFSET])
            _rigid_inverse_times(F[n], Tj, F[n - 1])
        _place_frame(F, spheres, sphere_frame, k, X)  # frames 0 and n stay placed
        reach = rho * w + slack  # a row at least -reach here may be free somewhere in the piece
        worst = _sweep_rows(X, F, lb, arm, scene, k, n, g, -reach)
        if worst < -reach:
            continue
        if worst >= -slack or w <= half / 2.0**depth * 1.5:  # may be free here, or as fine as allowed
            return False
        stack[top + 1, 0], stack[top + 1, 1] = c - w / 2, w / 2
        stack[top + 2, 0], stack[top + 2, 1] = c + w / 2, w / 2
        top += 2
    return True


@kernel
def blocked_poses(G, joints, T, arm, scene, slack, samples, depth, out):
    """``out (B,)`` bool: no configuration whose tool pose is within ``slack`` of ``T[b] (4, 4)`` is free, proven
    by the rows the pose fixes (metres; ``slack`` bounds how far a sphere on the last two frames moves between two
    such configurations: the position tolerance plus the rotation tolerance times the sphere's lever).

    The links on the last frame (the frame after the last joint: a hand, its fingers) ride with the tool, the links
    on frame 0 never move: their rows against each other and the world's against the former are fixed by the pose
    (blocked where the smallest is below ``-slack``). Then two sweeps over one joint each, on ``samples`` values of
    its range: the links on frame 1 move with the first joint alone, the links on frame ``n - 1`` with the pose and
    the last joint alone; their rows against the world and the links on frames 0, their own and ``n`` are swept
    (blocked where, for every value, the smallest row plus what a sphere moves between two values and ``slack`` is
    below 0). Never True for a pose that has a free configuration within the tolerances.

    Each value stands for the piece of the range around it (half a step each side); a piece whose row is not low
    enough to block it all is halved, up to ``depth`` times (the two halves judged at their centres with half the
    motion), rather than ending the sweep: a pose whose swept link collides at every value but by less than the
    motion over one step is proven on a finer step only where it needs one (:func:`_piece_blocked`). The sweep ends
    (not proven) at once where a value's row is at least ``-slack`` (a configuration there may be free), or where a
    piece ``depth`` halvings deep is still open; ``depth`` 0 is the plain sweep."""
    spheres, sphere_frame, body_start = arm[0], arm[1], arm[2]
    n = joints.shape[0]
    S = spheres.shape[0]
    F = np.zeros((n + 1, 3, 4))
    X = np.zeros((S, 3))
    on = np.zeros(n + 1, dtype=np.bool_)
    g = np.empty(3)
    lb = np.empty((body_start.shape[0] - 1, 4))  # the links' bounding spheres: rows far above the cut skipped
    link_bounds(spheres, body_start, lb)
    Tj = np.empty((3, 4))
    Gn = np.empty((3, 4))
    _start(Gn, G[n])
    M0 = np.empty((3, 4))  # the first joint turns frame 1 about its own z axis (M0 = identity in its coordinates)
    _start(M0, np.eye(4))
    Mw = np.empty((3, 4))  # the last joint turns frame n - 1 about the z axis of G[n - 1]
    _start(Mw, G[n - 1])
    sweeps = 2 if n >= 3 else (1 if n == 2 else 0)
    stack = np.empty((depth + 2, 2))  # the open pieces of one value's halving (centre, half width), depth first
    for b in range(T.shape[0]):
        out[b] = False
        for r in range(3):
            for c in range(4):
                F[0, r, c] = 1.0 if r == c else 0.0
        _rigid_inverse_times(T[b], Gn, F[n])  # F[n] = T G[n]^-1
        for i in range(n + 1):
            on[i] = i == 0 or i == n
        _place(F, spheres, sphere_frame, X)  # only the spheres on frames 0 and n are read
        if _fixed_rows(X, F, lb, arm, scene, on, g, -slack) < -slack:
            out[b] = True
            continue
        if samples < 2:
            continue
        for sweep in range(sweeps):
            j = 0 if sweep == 0 else n - 1  # the joint swept
            k = 1 if sweep == 0 else n - 1  # the frame it moves
            prismatic = joints[j, PRISMATIC] != 0.0
            rho = _lever(spheres, sphere_frame, k, M0 if sweep == 0 else Mw, prismatic)
            lo, hi = joints[j, LOWER], joints[j, UPPER]
            span = hi - lo if prismatic else min(hi - lo, 2.0 * math.pi)
            h = span / (samples - 1)
            blocked = True
            for i in range(samples):
                x = lo + ((i * 7919) % samples) * h  # a stride through the range: a free value is met early
                swept = (sweep, j, k, n, rho, slack, depth)
                if not _piece_blocked(G, joints, arm, scene, (F, X, lb, g, Tj, stack), swept, x, h / 2):
                    blocked = False
                    break
            if blocked:
                out[b] = True
                break


@kernel
def overlaps_batch(G, joints, Q, arm, scene, pair_hit, world_hit):
    """What overlaps (distance below 0) in each ``Q[b] (n,)``: ``pair_hit (B, P)`` bool, the pairs (False where
    ``self_on`` is False); ``world_hit (B, L, No)`` bool, link ``l`` and obstacle ``o`` (numbered spheres, boxes,
    capsules, as :meth:`nik.collision.World.packed`; False for the links on frame 0). The names of
    :func:`nik.collision.collision_names`, compiled; the same broad phase (cutoff 0) as the check."""
    spheres, sphere_frame, body_start, pairs = arm[0], arm[1], arm[2], arm[3]
    w_spheres, w_boxes, w_capsules = scene
    n = Q.shape[1]
    S, P, L = spheres.shape[0], pairs.shape[0], body_start.shape[0] - 1
    Ns, Nb = w_spheres.shape[0], w_boxes.shape[0]
    bounds = np.empty((L, 4))
    link_bounds(spheres, body_start, bounds)
    d = np.empty(P + L)
    J = np.empty((0, n))
    F = np.empty((n + 1, 3, 4))
    X = np.empty((S, 3))
    g = np.empty(3)
    for b in range(Q.shape[0]):
        _rows(G, joints, Q[b], arm, scene, d, J, False, 0.0, bounds, False)
        for p in range(P):
            pair_hit[b, p] = d[p] < 0.0
        world_hit[b, :, :] = False
        _frames(G, joints, Q[b], F)
        placed = False
        for link in range(L):
            s0, s1 = body_start[link], body_start[link + 1]
            if s1 <= s0 or sphere_frame[s0] == 0 or not d[P + link] < 0.0:
                continue
            if not placed:
                _place(F, spheres, sphere_frame, X)
                placed = True
            for kind, count, first in ((0, Ns, 0), (1, Nb, Ns), (2, w_capsules.shape[0], Ns + Nb)):
                for o in range(count):
                    for s in range(s0, s1):
                        dist = _obstacle_one(X[s, 0], X[s, 1], X[s, 2], kind, o, w_spheres, w_boxes, w_capsules, g)
                        if dist - spheres[s, 3] < 0.0:
                            world_hit[b, link, first + o] = True
                            break
