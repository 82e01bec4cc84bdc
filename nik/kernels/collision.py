"""Signed distances of the arm's spheres and their Jacobians for one configuration: LM residual rows, compiled.

The model is data (:meth:`nik.collision.CollisionModel.arrays`, :meth:`nik.collision.World.packed`):

- ``spheres: (S, 4)`` centre in its frame and radius (metres), ``sphere_frame: (S,)`` int64 (0 = base, k = the
  frame after joint k), ``body_start: (L + 1,)`` int64 (link ``l`` owns spheres ``body_start[l]:body_start[l+1]``),
  ``pairs: (P, 2)`` int64 active link pairs;
- the world: ``w_spheres: (Ns, 4)``, ``w_boxes: (Nb, 15)`` (R row by row, centre, half sizes),
  ``w_capsules: (Nc, 7)``.

Rows (``R = P + L``): row ``p < P`` is the smallest ``|c_i - c_j| - r_i - r_j`` over the spheres of pair ``p``
(``inf`` when ``self_on`` is False); row ``P + l`` is the smallest signed distance from link ``l``'s spheres
to any obstacle (``inf`` for an empty world and for links on frame 0, the fixed base: a base standing on a
table touches it by design). The Jacobian row is that of the minimising sphere pair (or
sphere and obstacle): ``n . (dc_i/dq - dc_j/dq)``, with ``dc/dq`` column ``m`` equal to ``z_m x (c - p_m)``
(revolute) or ``z_m`` (prismatic) for the joints before the sphere's frame and 0 after.
:func:`collision_residual` turns them into LM rows ``max(0, margin - d)`` and ``-dd/dq`` where active.

A broad phase skips the sphere-by-sphere minimum of a row whose lower bound (from a bounding sphere per link,
placed with the link) is above the cutoff: ``margin`` in :func:`collision_residual` and :func:`collides_batch`,
none (exact rows) in :func:`collision_distances` and :func:`collision_distances_batch`.

The reference is :mod:`nik.collision.distance` (torch); the tests compare the two and check the Jacobians
by finite differences.
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel
from nik.kernels.chain import OFFSET, PRISMATIC, _joint, _start, _times

__all__ = ["collides_batch", "collision_distances", "collision_distances_batch", "collision_residual"]


@kernel
def _frames(G, joints, q, F):
    """``F (n + 1, 3, 4)``: identity, then the frame after each joint."""
    n = q.shape[0]
    for r in range(3):
        for k in range(4):
            F[0, r, k] = 1.0 if r == k else 0.0
    T = np.empty((3, 4))
    _start(T, G[0])
    for i in range(n):
        _joint(T, joints[i, PRISMATIC] != 0.0, q[i] + joints[i, OFFSET])
        for r in range(3):
            for k in range(4):
                F[i + 1, r, k] = T[r, k]
        _times(T, G[i + 1])


@kernel
def _place(F, spheres, sphere_frame, X):
    for s in range(spheres.shape[0]):
        f = sphere_frame[s]
        for r in range(3):
            X[s, r] = F[f, r, 0] * spheres[s, 0] + F[f, r, 1] * spheres[s, 1] + F[f, r, 2] * spheres[s, 2] + F[f, r, 3]


@kernel
def _add_point_jacobian(F, joints, frame, x, y, z, vx, vy, vz, sign, row):
    """``row[m] += sign * v . dc/dq_m`` for a point ``(x, y, z)`` riding on frame ``frame``."""
    for m in range(frame):
        zx, zy, zz = F[m + 1, 0, 2], F[m + 1, 1, 2], F[m + 1, 2, 2]
        if joints[m, PRISMATIC] != 0.0:
            row[m] += sign * (vx * zx + vy * zy + vz * zz)
        else:
            rx, ry, rz = x - F[m + 1, 0, 3], y - F[m + 1, 1, 3], z - F[m + 1, 2, 3]
            cx, cy, cz = zy * rz - zz * ry, zz * rx - zx * rz, zx * ry - zy * rx
            row[m] += sign * (vx * cx + vy * cy + vz * cz)


@kernel
def _obstacle(x, y, z, w_spheres, w_boxes, w_capsules, g):
    """Smallest signed distance from the point ``(x, y, z)`` to the obstacles, and its gradient in ``g (3,)``."""
    best = np.inf
    for o in range(w_spheres.shape[0]):
        dx, dy, dz = x - w_spheres[o, 0], y - w_spheres[o, 1], z - w_spheres[o, 2]
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        d = n - w_spheres[o, 3]
        if d < best:
            best = d
            if n > 0:
                g[0], g[1], g[2] = dx / n, dy / n, dz / n
            else:
                g[0], g[1], g[2] = 0.0, 0.0, 1.0
    for o in range(w_capsules.shape[0]):
        ax, ay, az = w_capsules[o, 0], w_capsules[o, 1], w_capsules[o, 2]
        bx, by, bz = w_capsules[o, 3] - ax, w_capsules[o, 4] - ay, w_capsules[o, 5] - az
        L2 = bx * bx + by * by + bz * bz
        t = 0.0
        if L2 > 0:
            t = ((x - ax) * bx + (y - ay) * by + (z - az) * bz) / L2
            t = min(1.0, max(0.0, t))
        dx, dy, dz = x - (ax + t * bx), y - (ay + t * by), z - (az + t * bz)
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        d = n - w_capsules[o, 6]
        if d < best:
            best = d
            if n > 0:
                g[0], g[1], g[2] = dx / n, dy / n, dz / n
            else:
                g[0], g[1], g[2] = 0.0, 0.0, 1.0
    for o in range(w_boxes.shape[0]):
        b = w_boxes[o]
        px, py, pz = x - b[9], y - b[10], z - b[11]
        lx = b[0] * px + b[3] * py + b[6] * pz  # R^T (p - c)
        ly = b[1] * px + b[4] * py + b[7] * pz
        lz = b[2] * px + b[5] * py + b[8] * pz
        qx, qy, qz = abs(lx) - b[12], abs(ly) - b[13], abs(lz) - b[14]
        qmax = max(qx, max(qy, qz))
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
        if d < best:
            best = d
            g[0] = b[0] * gx + b[1] * gy + b[2] * gz
            g[1] = b[3] * gx + b[4] * gy + b[5] * gz
            g[2] = b[6] * gx + b[7] * gy + b[8] * gz
    return best


@kernel
def _rows(
    G,
    joints,
    q,
    spheres,
    sphere_frame,
    body_start,
    pairs,
    w_spheres,
    w_boxes,
    w_capsules,
    self_on,
    d,
    J,
    want_jacobian,
    cutoff,
):
    """The rows (module docstring). Broad phase: a row whose lower bound from the links' bounding spheres exceeds
    ``cutoff`` is that bound (Jacobian row 0) instead of the exact minimum."""
    n = q.shape[0]
    S = spheres.shape[0]
    P = pairs.shape[0]
    L = body_start.shape[0] - 1
    F = np.empty((n + 1, 3, 4))
    X = np.empty((S, 3))
    _frames(G, joints, q, F)
    _place(F, spheres, sphere_frame, X)
    Bc = np.zeros((L, 3))  # each link's bounding sphere: the mean of its centres, reaching all its spheres
    Br = np.zeros(L)
    for link in range(L):
        s0, s1 = body_start[link], body_start[link + 1]
        if s1 > s0:
            for s in range(s0, s1):
                for r in range(3):
                    Bc[link, r] += X[s, r]
            for r in range(3):
                Bc[link, r] /= s1 - s0
            for s in range(s0, s1):
                dx, dy, dz = X[s, 0] - Bc[link, 0], X[s, 1] - Bc[link, 1], X[s, 2] - Bc[link, 2]
                Br[link] = max(Br[link], math.sqrt(dx * dx + dy * dy + dz * dz) + spheres[s, 3])
    if want_jacobian:
        for r in range(P + L):
            for m in range(n):
                J[r, m] = 0.0
    for p in range(P):
        best, bi, bj = np.inf, -1, -1
        if self_on:
            a, b = pairs[p, 0], pairs[p, 1]
            dx, dy, dz = Bc[a, 0] - Bc[b, 0], Bc[a, 1] - Bc[b, 1], Bc[a, 2] - Bc[b, 2]
            bound = math.sqrt(dx * dx + dy * dy + dz * dz) - Br[a] - Br[b]
            if bound > cutoff:
                d[p] = bound
                continue
            for i in range(body_start[a], body_start[a + 1]):
                for j in range(body_start[b], body_start[b + 1]):
                    dx, dy, dz = X[i, 0] - X[j, 0], X[i, 1] - X[j, 1], X[i, 2] - X[j, 2]
                    dist = math.sqrt(dx * dx + dy * dy + dz * dz) - spheres[i, 3] - spheres[j, 3]
                    if dist < best:
                        best, bi, bj = dist, i, j
        d[p] = best
        if want_jacobian and bi >= 0:
            dx, dy, dz = X[bi, 0] - X[bj, 0], X[bi, 1] - X[bj, 1], X[bi, 2] - X[bj, 2]
            nn = math.sqrt(dx * dx + dy * dy + dz * dz)
            if nn > 0:
                vx, vy, vz = dx / nn, dy / nn, dz / nn
                _add_point_jacobian(F, joints, sphere_frame[bi], X[bi, 0], X[bi, 1], X[bi, 2], vx, vy, vz, 1.0, J[p])
                _add_point_jacobian(F, joints, sphere_frame[bj], X[bj, 0], X[bj, 1], X[bj, 2], vx, vy, vz, -1.0, J[p])
    g = np.empty(3)
    gb = np.zeros(3)
    for link in range(L):
        best, bs = np.inf, -1
        if body_start[link] < body_start[link + 1] and sphere_frame[body_start[link]] == 0:
            d[P + link] = np.inf  # the base's links never move: their contacts with the world are the user's set-up
            continue
        bound = _obstacle(Bc[link, 0], Bc[link, 1], Bc[link, 2], w_spheres, w_boxes, w_capsules, g) - Br[link]
        if bound > cutoff:  # signed distances are 1-Lipschitz: no sphere of the link is nearer than this
            d[P + link] = bound
            continue
        for s in range(body_start[link], body_start[link + 1]):
            dist = _obstacle(X[s, 0], X[s, 1], X[s, 2], w_spheres, w_boxes, w_capsules, g) - spheres[s, 3]
            if dist < best:
                best, bs = dist, s
                gb[0], gb[1], gb[2] = g[0], g[1], g[2]
        d[P + link] = best
        if want_jacobian and bs >= 0 and best < np.inf:
            _add_point_jacobian(
                F, joints, sphere_frame[bs], X[bs, 0], X[bs, 1], X[bs, 2], gb[0], gb[1], gb[2], 1.0, J[P + link]
            )


@kernel
def collision_distances(
    G, joints, q, spheres, sphere_frame, body_start, pairs, w_spheres, w_boxes, w_capsules, self_on, d, J
):
    """Rows ``d (P + L,)`` (metres) and their Jacobian ``J (P + L, n)`` for ``q: (n,)`` (module docstring)."""
    _rows(
        G,
        joints,
        q,
        spheres,
        sphere_frame,
        body_start,
        pairs,
        w_spheres,
        w_boxes,
        w_capsules,
        self_on,
        d,
        J,
        True,
        np.inf,
    )


@kernel
def collision_residual(
    G, joints, q, spheres, sphere_frame, body_start, pairs, w_spheres, w_boxes, w_capsules, self_on, margin, r, Jr
):
    """LM rows ``r = max(0, margin - d)`` ``(P + L,)`` and ``Jr = dr/dq`` ``(P + L, n)`` for ``q: (n,)``; returns
    the smallest distance ``d`` where it is at most ``margin`` (metres), else a lower bound above ``margin``
    (``inf`` when there is nothing to check). Rows whose links' bounding spheres are farther than ``margin``
    apart are not computed sphere by sphere (their residual is 0 either way)."""
    _rows(
        G,
        joints,
        q,
        spheres,
        sphere_frame,
        body_start,
        pairs,
        w_spheres,
        w_boxes,
        w_capsules,
        self_on,
        r,
        Jr,
        True,
        margin,
    )
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
def collision_distances_batch(
    G, joints, Q, spheres, sphere_frame, body_start, pairs, w_spheres, w_boxes, w_capsules, self_on, D
):
    """Rows ``D (B, P + L)`` for ``Q: (B, n)``, no Jacobian."""
    J = np.empty((0, Q.shape[1]))
    for b in range(Q.shape[0]):
        _rows(
            G,
            joints,
            Q[b],
            spheres,
            sphere_frame,
            body_start,
            pairs,
            w_spheres,
            w_boxes,
            w_capsules,
            self_on,
            D[b],
            J,
            False,
            np.inf,
        )


@kernel
def collides_batch(
    G, joints, Q, spheres, sphere_frame, body_start, pairs, w_spheres, w_boxes, w_capsules, self_on, margin, out
):
    """``out (B,)`` bool: some row of ``Q[b]`` is below ``margin`` (metres)."""
    R = pairs.shape[0] + body_start.shape[0] - 1
    d = np.empty(R)
    J = np.empty((0, Q.shape[1]))
    for b in range(Q.shape[0]):
        _rows(
            G,
            joints,
            Q[b],
            spheres,
            sphere_frame,
            body_start,
            pairs,
            w_spheres,
            w_boxes,
            w_capsules,
            self_on,
            d,
            J,
            False,
            margin,
        )
        hit = False
        for k in range(R):
            if d[k] < margin:
                hit = True
                break
        out[b] = hit
