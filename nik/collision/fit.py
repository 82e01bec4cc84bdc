"""Conservative spheres around one rigid body: :func:`fit_spheres` (triangles in, centres and radii out).

The guarantee is exact, not sampled: a ball is convex, so a triangle whose three corners lie inside a ball lies
inside it entirely. The body's surface is cut into small triangles (no edge longer than ``max_edge``) and every
triangle is *assigned* to one sphere whose radius reaches all three of its corners; the union of the spheres
therefore holds every surface point of the geometry (and, for a closed surface, the whole solid: a point inside
that no sphere held would have a ray to infinity crossing the surface outside every sphere, which cannot be).
Curved primitives are first replaced by polyhedra that contain them (:mod:`nik.collision.shapes`), so the same
argument covers them.

How the spheres are placed (choices): ``K`` centres by k-means (seeded) on points inside the body's convex hull,
which slices long links along their length; triangles go to the sphere that needs the least radius for them; then
a few rounds of (centre = approximate smallest ball around its triangles' corners, Badoiu-Clarkson) and
(reassign each triangle to the sphere that holds it with the most room). ``K`` grows from 1 until the spheres
overreach the geometry by at most ``tolerance`` metres, or ``max_spheres`` is reached.

Overreach (:class:`SphereFit`): ``gap`` is the largest distance from a point of the union's boundary to the
geometry's surface (metres, measured on 96 points per sphere against the subdivided surface's corners), and
``volume_ratio`` the union's volume over the geometry's (Monte Carlo, seeded; the convex hull's volume where the
surface is not closed).

Only numpy here; :mod:`nik.collision.shapes` turns URDF geometry (and meshes, through trimesh) into triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SPHERE_PENALTY", "SphereFit", "fit_spheres", "subdivide"]

#: Where no sphere count meets the tolerance, the count kept is the one with the smallest
#: ``volume_ratio + SPHERE_PENALTY * count``: one more sphere must shrink the union by 2 % of the body's volume.
SPHERE_PENALTY = 0.02


@dataclass
class SphereFit:
    """Spheres around one body, in the body's frame.

    Attributes:
        centers: (K, 3) metres.
        radii: (K,) metres.
        gap: largest distance from the union's boundary to the geometry's surface (metres): the overreach.
        volume_ratio: union volume / geometry volume (>= 1 up to Monte Carlo noise).
    """

    centers: np.ndarray
    radii: np.ndarray
    gap: float
    volume_ratio: float


def subdivide(triangles: np.ndarray, max_edge: float) -> np.ndarray:
    """``triangles: (T, 3, 3)`` split (each into four, repeatedly) until no edge is longer than ``max_edge``."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    out = []
    for _ in range(40):
        edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
        small = edges <= max_edge
        out.append(tri[small])
        tri = tri[~small]
        if not len(tri):
            break
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        tri = np.concatenate(
            [np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], axis=0
        )
    out.append(tri)
    return np.concatenate(out, axis=0)


def _hull_planes(points: np.ndarray) -> np.ndarray | None:
    """Half-spaces ``(F, 4)`` (unit normal, offset: inside where ``n . x <= d``) of the convex hull, or None."""
    try:
        from scipy.spatial import ConvexHull

        hull = ConvexHull(points)
    except Exception:  # noqa: BLE001 - flat or degenerate geometry, or no scipy: bounding box only
        return None
    eq = hull.equations  # n . x + off <= 0 inside
    return np.concatenate([eq[:, :3], -eq[:, 3:4]], axis=1)


def _inside_points(corners: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    planes = _hull_planes(corners)
    pts = rng.uniform(lo, hi, size=(4 * n, 3))
    if planes is not None:
        pts = pts[(pts @ planes[:, :3].T <= planes[:, 3] + 1e-12).all(axis=1)]
    if len(pts) < 8:  # flat geometry: the corners themselves
        pts = corners
    return pts[:n]


def _kmeans(points: np.ndarray, k: int, rng: np.random.Generator, iters: int = 25) -> np.ndarray:
    centers = [points[rng.integers(len(points))]]
    for _ in range(1, k):  # k-means++
        d2 = np.min(((points[:, None] - np.array(centers)[None]) ** 2).sum(-1), axis=1)
        total = d2.sum()
        centers.append(
            points[rng.choice(len(points), p=d2 / total)] if total > 0 else points[rng.integers(len(points))]
        )
    c = np.array(centers)
    for _ in range(iters):
        lab = np.argmin(((points[:, None] - c[None]) ** 2).sum(-1), axis=1)
        for j in range(k):
            sel = points[lab == j]
            if len(sel):
                c[j] = sel.mean(axis=0)
    return c


def _reach(tri: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """``(T, K)``: the radius sphere ``k`` needs to hold triangle ``t`` (its farthest corner)."""
    return np.linalg.norm(tri[:, :, None, :] - centers[None, None], axis=3).max(axis=1)


def _assign(tri, centers, iters):
    """Each triangle to the centre nearest its centroid (a Voronoi cell of the surface per sphere); radius = the
    farthest corner of its triangles. Then each centre moves to the approximate smallest ball around its cell's
    corners where that makes the union smaller (sum of r^3). Returns centres and radii (empty cells dropped)."""
    K = len(centers)
    mid = tri.mean(axis=1)
    lab = np.argmin(((mid[:, None] - centers[None]) ** 2).sum(-1), axis=1)
    rows = np.arange(len(tri))

    def radii_of(c):
        r = np.zeros(K)
        np.maximum.at(r, lab, _reach(tri, c)[rows, lab])
        return r

    radii = radii_of(centers)
    moved = centers.copy()
    for j in range(K):  # centre = approximate smallest ball around its cell's corners (Badoiu-Clarkson)
        pts = np.unique(tri[lab == j].reshape(-1, 3), axis=0)
        if not len(pts):
            continue
        c = moved[j].copy()
        for i in range(iters):
            far = pts[np.argmax(((pts - c) ** 2).sum(-1))]
            c += (far - c) / (i + 2)
        moved[j] = c
    r_moved = radii_of(moved)
    if (r_moved**3).sum() < (radii**3).sum():
        centers, radii = moved, r_moved
    keep = radii > 0
    return centers[keep], radii[keep]


def _fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


def _gap(centers, radii, surface: np.ndarray) -> float:
    """Largest distance from a boundary point of the union of spheres to the nearest surface point."""
    pts = (centers[:, None] + radii[:, None, None] * _fibonacci(96)[None]).reshape(-1, 3)
    inside = (np.linalg.norm(pts[:, None] - centers[None], axis=2) < radii[None] - 1e-9).any(axis=1)
    pts = pts[~inside]
    if not len(pts):
        return 0.0
    best = np.full(len(pts), np.inf)
    for s in range(0, len(surface), 2048):
        chunk = surface[s : s + 2048]
        best = np.minimum(best, np.sqrt(((pts[:, None] - chunk[None]) ** 2).sum(-1)).min(axis=1))
    return float(best.max())


def _volume_ratio(centers, radii, volume: float, rng) -> float:
    if volume <= 0:
        return float("nan")
    lo, hi = (centers - radii[:, None]).min(axis=0), (centers + radii[:, None]).max(axis=0)
    pts = rng.uniform(lo, hi, size=(20000, 3))
    inside = np.zeros(len(pts), dtype=bool)
    for c, r in zip(centers, radii, strict=True):
        inside |= ((pts - c) ** 2).sum(-1) <= r * r
    return float(inside.mean() * np.prod(hi - lo) / volume)


def _volume(tri: np.ndarray) -> float:
    """Volume enclosed by a closed, consistently oriented triangle surface (divergence theorem); the convex
    hull's where that is not plausible (not between 0.3 and 1 times the hull's)."""
    v = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)
    try:
        from scipy.spatial import ConvexHull

        hull = float(ConvexHull(tri.reshape(-1, 3)).volume)
    except Exception:  # noqa: BLE001 - flat geometry
        return max(v, 0.0)
    return v if 0.3 * hull <= v <= hull * (1 + 1e-9) else hull  # an open or inconsistently oriented surface


def fit_spheres(
    triangles: np.ndarray,
    *,
    tolerance: float = 0.01,
    max_spheres: int = 12,
    max_edge: float | None = None,
    volume: float | None = None,
    seed: int = 0,
) -> SphereFit:
    """Spheres whose union holds every point of the surface ``triangles: (T, 3, 3)`` (metres, body frame).

    Args:
        tolerance: stop adding spheres once they overreach the surface by at most this (metres).
        max_spheres: at most this many spheres.
        max_edge: triangles are split until no edge is longer (default: the body's largest extent / 10,
            at least 2 mm).
        volume: the geometry's volume (m^3) for the reported ratio; default from the triangles.
        seed: k-means and Monte Carlo seed.
    """
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    if not len(tri) or not np.isfinite(tri).all():
        raise ValueError("fit_spheres: expected finite triangles (T, 3, 3) with T >= 1")
    corners = tri.reshape(-1, 3)
    extent = float((corners.max(axis=0) - corners.min(axis=0)).max())
    edge = max(extent / 10.0, 0.002) if max_edge is None else float(max_edge)
    fine = subdivide(tri, edge) if extent > 0 else tri
    surface = np.unique(fine.reshape(-1, 3).round(9), axis=0)
    if len(surface) > 4000:
        surface = surface[np.random.default_rng(seed).choice(len(surface), 4000, replace=False)]
    volume = _volume(tri) if volume is None else float(volume)
    rng = np.random.default_rng(seed)
    inside = _inside_points(corners, 3000, rng)
    best = None
    counts = [k for k in (1, 2, 3, 4, 6, 8, 10, 12, 16, 20, 24, 32) if k < max_spheres] + [int(max_spheres)]
    for k in counts:
        centers = _kmeans(inside, min(k, len(inside)), np.random.default_rng(seed + k))
        c, r = _assign(fine, centers, iters=30)
        gap = _gap(c, r, surface)
        ratio = _volume_ratio(c, r, volume, np.random.default_rng(seed))
        score = ratio + SPHERE_PENALTY * len(r)
        if best is None or score < best[0]:
            best = (score, c, r, gap, ratio)
        if gap <= tolerance:
            break
    _, c, r, gap, ratio = best
    return SphereFit(c, r, gap, ratio)
