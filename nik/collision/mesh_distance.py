"""Signed distances between a robot's collision meshes, with the nearest points, as LM rows (coal).

:class:`MeshDistance` turns the pairs a :class:`nik.collision.meshcheck.MeshCheck` tests (the arm against itself,
the pairs the model leaves out by decision, such as the SRDF's, left out; every moving link against each obstacle
of a world) into rows ``r = max(0, margin - d)`` metres with their Jacobian, for the collision stage's mesh step
(:mod:`nik.ik.collide`) and the term :func:`nik.costs.mesh.mesh_collision`:

- ``d``: coal's distance between the two meshes (BVH, surface triangles) where they are apart, with its nearest
  (witness) points ``p_a``, ``p_b``; where they touch or overlap (a BVH pair reports 0), the signed distance of
  the links' convex hulls (GJK / EPA: negative, the penetration depth, with its normal), which contain the meshes,
  so the row keeps pushing while the meshes overlap;
- ``J = n^T (J_p(a, p_a) - J_p(b, p_b))``, ``n`` the unit normal from ``p_a`` to ``p_b`` and ``J_p(link, p)`` the
  point Jacobian of ``p`` moving with the link (``z_i x (p - o_i)`` for the revolute joints before it, ``z_i`` for
  the prismatic ones; an obstacle does not move): the derivative of ``margin - d`` with the nearest points held.

A pair whose bounding spheres (each link's mesh inside one sphere) lie more than ``margin`` apart is not asked
about: its row is 0 (the distance reported is that lower bound). Of the others, coal's collision query with a
security margin (``margin``) says which meshes come that near (about 10 us a pair); only those are asked for the
distance and nearest points (about 300 us a pair of meshes; the others report ``margin`` as their lower bound).
A configuration of a 7-joint arm in a small scene takes about 0.1-1 ms, a few ms where many pairs touch.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MeshDistance"]


class MeshDistance:
    """The rows of the pairs ``check`` tests (module docstring), for ``world`` (a :class:`nik.World` or None) and
    the arm against itself where ``self_collision``.

    Attributes:
        rows: ``(M,)`` pairs ``(a, b)`` of link indices of ``check``, ``b = -1 - o`` for obstacle ``o``.
        names: ``(M,)`` the rows' names, ``"linkA|linkB"`` or ``"link|box 2"`` (as
            :func:`nik.collision.collision_names` names them).
    """

    def __init__(self, check, world=None, *, self_collision: bool = True):
        coal = check._coal
        self.check, self.robot, self._coal = check, check.robot, coal
        self._hulls, self._bound = [], []
        for k, g in enumerate(check._geoms):
            if not hasattr(g, "vertices"):  # a primitive (convex already): its own bounding sphere and hull
                g.computeLocalAABB()
                self._bound.append((np.asarray(g.aabb_center, dtype=np.float64), float(g.aabb_radius)))
                self._hulls.append(g)
                continue
            self._bound.append(check._bounds[k])  # the mesh check's sphere around the mesh (computed once there)
            self._hulls.append(None)  # built when a pair of this link first overlaps (:meth:`_hull`)
        self._obstacles = []
        for geom, tf, name in check._world_geoms(world) if world is not None else []:
            half = _half_size(geom)
            self._obstacles.append((geom, tf, name, np.asarray(tf.getTranslation(), dtype=np.float64), half))
        self.rows = [(a, b) for a, b in check.pairs] if self_collision else []
        self.rows += [(k, -1 - o) for k in range(len(check._geoms)) if check.frames[k] > 0
                      for o in range(len(self._obstacles))]  # fmt: skip
        other = [*check.links, *reversed([o[2] for o in self._obstacles])]  # b < 0 indexes from the end
        self.names = [f"{check.links[a]}|{other[b]}" for a, b in self.rows]

    def __len__(self) -> int:
        return len(self.rows)

    def rows_at(self, Q, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(r (B, M), J (B, M, dof), d (B, M))`` for ``Q: (B, dof)``: the rows ``max(0, margin - d)`` metres,
        their Jacobian and the distances ``d`` (metres, negative where the hulls overlap; for a pair not asked
        about, a lower bound: the bounding spheres' gap (a link's sphere and the obstacle's own shape), or ``margin``
        where coal finds the meshes no nearer)."""
        from nik.collision.meshcheck import _core, ball_obstacle_gap
        from nik.collision.urdf import frames_at

        Q = np.asarray(Q, dtype=np.float64).reshape(-1, self.robot.dof)
        B, M, n = len(Q), len(self.rows), self.robot.dof
        r, J, d = np.zeros((B, M)), np.zeros((B, M, n)), np.zeros((B, M))
        prismatic = self.robot.prismatic.numpy().astype(bool)
        a_idx = np.array([a for a, _ in self.rows], dtype=np.int64)
        b_idx = np.array([b for _, b in self.rows], dtype=np.int64)
        local = np.array([c for c, _ in self._bound]).reshape(-1, 3)
        radius = np.array([rad for _, rad in self._bound] + [o[4] for o in reversed(self._obstacles)])
        fixed = np.array([o[3] for o in reversed(self._obstacles)]).reshape(-1, 3)  # b < 0 indexes from the end
        reach = margin + 2e-9  # a pair coal finds farther than this: rowless, and free by the check (d > 1e-9)
        obs = np.flatnonzero(b_idx < 0)  # the rows of a link against an obstacle, and each obstacle's frame and shape
        placed = [self._obstacles[-1 - b][1] for b in b_idx[obs]]
        ocentre = np.array([np.asarray(t.getTranslation()) for t in placed]).reshape(-1, 3)
        orot = np.array([np.asarray(t.getRotation()) for t in placed]).reshape(-1, 3, 3)
        core = np.array([_core(self._obstacles[-1 - b][0]) for b in b_idx[obs]]).reshape(-1, 4)
        for i, q in enumerate(Q):
            F = frames_at(self.robot, q)
            tf = self.check._transforms(q)
            R = np.array([np.asarray(t.getRotation()) for t in tf])
            t = np.array([np.asarray(t.getTranslation()) for t in tf])
            centres = np.concatenate([np.einsum("kij,kj->ki", R, local) + t, fixed])
            d[i] = np.linalg.norm(centres[a_idx] - centres[b_idx], axis=1) - radius[a_idx] - radius[b_idx]
            if obs.size:  # a link against an obstacle: its sphere's exact gap to the obstacle
                d[i, obs] = ball_obstacle_gap(centres[a_idx[obs]], radius[a_idx[obs]], (ocentre, orot, core))
            for m in np.flatnonzero(d[i] <= margin):  # the bounding spheres within the margin: coal asked
                a, b = self.rows[m]
                if not self._near(tf, a, b, reach):  # farther than the margin: no row (d: that lower bound)
                    d[i, m] = max(d[i, m], reach)
                    continue
                dist, pa, pb, normal = self._pair(tf, a, b)
                d[i, m] = dist
                if dist >= margin or pa is None:
                    continue
                r[i, m] = margin - dist
                row = normal @ _point_jacobian(F, self.check.frames[a], pa, prismatic)
                if b >= 0:
                    row = row - normal @ _point_jacobian(F, self.check.frames[b], pb, prismatic)
                J[i, m] = row
        return r, J, d

    def _hull(self, k: int):
        """The convex hull of link ``k``'s mesh (a primitive is its own), built on first use (Qhull: about 10-50 ms a
        link) and kept on its geometry for every later :class:`MeshDistance` of the same mesh check."""
        hull = self._hulls[k]
        if hull is None:
            g = self.check._geoms[k]
            if g.convex is None:
                g.buildConvexHull(False, "Qt")
            hull = self._hulls[k] = g.convex
        return hull

    def _geometry(self, tf, b: int):
        """``(geometry, transform)`` of row side ``b`` (a link placed by ``tf``, or obstacle ``-1 - b``)."""
        return (self.check._geoms[b], tf[b]) if b >= 0 else self._obstacles[-1 - b][:2]

    def _near(self, tf, a: int, b: int, reach: float) -> bool:
        """Whether the meshes of row ``(a, b)`` placed by ``tf`` come within ``reach`` metres: coal's collision
        query with that security margin (a BVH overlap test, about 10 us a pair of meshes, against about 300 us for
        the distance with its nearest points), so the distance is asked only of the pairs that need a row."""
        coal = self._coal
        req = coal.CollisionRequest()
        req.security_margin = reach
        gb, tb = self._geometry(tf, b)
        return bool(coal.collide(self.check._geoms[a], tf[a], gb, tb, req, coal.CollisionResult()))

    def _pair(self, tf, a: int, b: int):
        """``(d, p_a, p_b, n)`` of row ``(a, b)`` (``b < 0``: obstacle ``-1 - b``) placed by ``tf``; the points and
        ``n`` None where coal gives no normal (``d`` <= 0 then)."""
        coal = self._coal
        ta = tf[a]
        if b >= 0:
            gb, tb, hb = self.check._geoms[b], tf[b], self._hull(b)
        else:
            gb, tb = self._obstacles[-1 - b][:2]
            hb = gb
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        dist = coal.distance(self.check._geoms[a], ta, gb, tb, req, res)
        pa, pb = np.array(res.getNearestPoint1()), np.array(res.getNearestPoint2())
        gap = float(np.linalg.norm(pb - pa))
        if dist > 1e-9 and gap > 1e-12:
            return float(dist), pa, pb, (pb - pa) / gap
        req.enable_signed_distance = True
        res = coal.DistanceResult()
        dist = coal.distance(self._hull(a), ta, hb, tb, req, res)
        normal = np.array(res.normal, dtype=np.float64)
        norm = float(np.linalg.norm(normal))
        if not np.isfinite(dist) or norm < 1e-12:
            return min(float(dist), 0.0) if np.isfinite(dist) else 0.0, None, None, None
        return float(min(dist, 0.0)), np.array(res.getNearestPoint1()), np.array(res.getNearestPoint2()), normal / norm


def _half_size(geom) -> float:
    """The radius of a sphere around the obstacle ``geom`` (coal's Sphere, Box or Capsule) about its centre."""
    name = type(geom).__name__
    if name == "Sphere":
        return float(geom.radius)
    if name == "Box":
        return float(np.linalg.norm(geom.halfSide))
    if name == "Capsule":
        return float(geom.halfLength + geom.radius)
    return float("inf")


def _point_jacobian(F: np.ndarray, frame: int, p: np.ndarray, prismatic: np.ndarray) -> np.ndarray:
    """``(3, dof)``: the velocity of the point ``p`` (base frame, metres) fixed to frame ``frame`` of ``F``
    (:func:`nik.collision.urdf.frames_at`: frame ``i + 1`` turns about its own z with joint ``i``) per unit of each
    joint's speed; 0 for the joints after the frame."""
    dof = len(F) - 1
    k = min(int(frame), dof)
    out = np.zeros((3, dof))
    if k:
        z, v = F[1 : k + 1, :3, 2], p - F[1 : k + 1, :3, 3]  # (k, 3) axes and lever arms
        cols = np.stack([z[:, 1] * v[:, 2] - z[:, 2] * v[:, 1], z[:, 2] * v[:, 0] - z[:, 0] * v[:, 2],
                         z[:, 0] * v[:, 1] - z[:, 1] * v[:, 0]])  # fmt: skip
        out[:, :k] = np.where(prismatic[:k], z.T, cols)
    return out
