"""Conservative spheres around one rigid body: :func:`fit_spheres` (triangles in, centres and radii out).

The guarantee is exact, not sampled: a ball is convex, so a triangle whose three corners lie inside a ball lies
inside it entirely. The body's surface is cut into small triangles (no edge longer than ``max_edge``) and every
triangle is *assigned* to one sphere whose radius reaches all three of its corners; the union of the spheres
therefore holds every surface point of the geometry. (The inside is held where the spheres reach it, which the
candidates below, centred inside, usually do; an obstacle wholly inside a link and touching none of its surface
is the one case a surface cover cannot promise, as for checkers that test mesh surfaces.) Curved primitives
are first replaced by polyhedra that contain them (:mod:`nik.collision.shapes`), so the same argument covers
them.

How the spheres are placed (choices): candidate centres are seeded points inside the body's convex hull (and
on its surface), each with the radius that reaches ``tolerance`` past its nearest surface point (so a sphere
bulges out of a flat or convex face by about ``tolerance``); a greedy set cover picks the candidate that holds the
most triangles not yet held until all are (a triangle no candidate holds goes to the chosen sphere that grows
least for it), and each radius then shrinks to the farthest corner of its own triangles. Where that needs more
than ``max_spheres``, the reach grows by half and the cover is redone.

Optimisation (``refine`` rounds, :func:`refine_cover`): alternately every triangle goes to the sphere that holds
it with the most room (so no radius grows), and every sphere moves to the centre of the smallest ball around the
corners of its triangles (a small convex programme on their hull's vertices, scipy's SLSQP) with the radius of its
farthest corner; spheres left without triangles go. Every step keeps each triangle's three corners inside its
sphere, so the cover stays exact whatever the optimiser returns; radii never grow from one round to the next.

Overreach (:class:`SphereFit`): ``gap`` is the largest distance from a point of the union's boundary to the
geometry's surface (metres, measured on 96 points per sphere against the subdivided surface's corners), and
``volume_ratio`` the union's volume over the geometry's (Monte Carlo, seeded; the convex hull's volume where the
surface is not closed).

numpy, and scipy's convex hull where installed (for the candidate centres and the volume; the bounding box
without it); :mod:`nik.collision.shapes` turns URDF geometry (and meshes, through trimesh) into triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SphereFit", "fit_spheres", "refine_cover", "subdivide"]


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
    """``triangles: (T, 3, 3)`` split in two at the middle of their longest edge, repeatedly, until no edge is
    longer than ``max_edge`` (long slivers become a row of pieces, not a grid)."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    out = []
    for _ in range(64):
        lengths = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2)  # edge k: corner k -> corner k + 1
        small = lengths.max(axis=1) <= max_edge
        out.append(tri[small])
        tri, lengths = tri[~small], lengths[~small]
        if not len(tri):
            break
        k = np.argmax(lengths, axis=1)
        rows = np.arange(len(tri))
        a, b, c = tri[rows, k], tri[rows, (k + 1) % 3], tri[rows, (k + 2) % 3]
        m = (a + b) / 2
        tri = np.concatenate([np.stack([a, m, c], axis=1), np.stack([m, b, c], axis=1)])
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


def _greedy_cover(corners, faces, inside, depth, reach, max_spheres):
    """Spheres ``(centres, radii)`` holding every triangle ``corners[faces]``: candidates ``inside`` with radius
    ``depth + reach``; greedily the one holding the most triangles not yet held; triangles no candidate holds go
    to the chosen sphere that grows least for them; then each radius shrinks to its own triangles' farthest
    corner. None when more than ``max_spheres`` are needed."""
    radii = depth + reach
    held_v = np.empty((len(inside), len(corners)), dtype=bool)
    sq = (corners**2).sum(-1)
    for s in range(0, len(inside), 256):
        c = inside[s : s + 256]
        d2 = (c**2).sum(-1)[:, None] - 2.0 * c @ corners.T + sq[None]  # float64: well below the sizes here
        held_v[s : s + 256] = d2 <= (radii[s : s + 256, None] ** 2) * (1 - 1e-9)
    held = held_v[:, faces].all(axis=2)  # (C, T)
    counts = held.astype(np.float32)
    open_ = np.ones(faces.shape[0], dtype=bool)
    chosen = []
    while open_.any():
        gain = counts @ open_.astype(np.float32)  # triangles each candidate would newly hold (exact below 2^24)
        best = int(np.argmax(gain))
        if gain[best] == 0:
            break
        chosen.append(best)
        open_ &= ~held[best]
        if len(chosen) > max_spheres:
            return None
    if not chosen:
        chosen = [int(np.argmax(depth))]
    centers = inside[chosen].copy()
    tri = corners[faces]
    need = np.linalg.norm(tri[:, :, None, :] - centers[None, None], axis=3).max(axis=1)  # (T, K)
    # each triangle to a chosen sphere that holds it (the one that holds it with most room), else the one
    # needing the least radius for it
    room = need - radii[chosen][None]
    lab = np.argmin(room, axis=1)
    out = np.zeros(len(chosen))
    np.maximum.at(out, lab, need[np.arange(len(tri)), lab])
    keep = out > 0
    remap = np.cumsum(keep) - 1
    return centers[keep], out[keep], remap[lab]


def _smallest_ball_centre(points: np.ndarray, start: np.ndarray) -> np.ndarray:
    """The centre of (about) the smallest ball holding ``points: (n, 3)``: SLSQP on their hull's vertices from
    ``start``; ``start`` where the optimiser fails or does no better (the caller recomputes the radius exactly)."""
    pts = points
    if len(pts) > 4:
        try:
            from scipy.spatial import ConvexHull

            pts = points[ConvexHull(points).vertices]
        except Exception:  # noqa: BLE001 - flat or degenerate: every point
            pts = points
    try:
        from scipy.optimize import minimize
    except ImportError:
        return start

    def worst(c):
        return float(((pts - c) ** 2).sum(-1).max())

    x0 = np.concatenate([start, [worst(start)]])
    res = minimize(
        lambda x: x[3],
        x0,
        jac=lambda x: np.array([0.0, 0.0, 0.0, 1.0]),
        constraints=[
            {
                "type": "ineq",
                "fun": lambda x: x[3] - ((pts - x[:3]) ** 2).sum(-1),
                "jac": lambda x: np.concatenate([2.0 * (pts - x[:3]), np.ones((len(pts), 1))], axis=1),
            }
        ],
        method="SLSQP",
        options={"maxiter": 100, "ftol": 1e-12},
    )
    c = np.asarray(res.x[:3], dtype=np.float64)
    return c if np.isfinite(c).all() and worst(c) < worst(start) else start


def refine_cover(corners, faces, centers, radii, labels, rounds: int):
    """``rounds`` of the optimisation in the module docstring on the cover ``centers (K, 3), radii (K,)`` of the
    triangles ``corners[faces]`` (``labels (T,)``: each triangle's sphere). Returns ``(centers, radii)``."""
    tri = corners[faces]
    c, r, lab = np.asarray(centers, float).copy(), np.asarray(radii, float).copy(), np.asarray(labels).copy()
    for _ in range(int(rounds)):
        need = np.linalg.norm(tri[:, :, None, :] - c[None, None], axis=3).max(axis=1)  # (T, K)
        lab = np.argmin(need - r[None], axis=1)  # the sphere holding it with the most room: no radius grows
        used = np.unique(lab)
        new_c, new_r = [], []
        for k in used:
            pts = np.unique(faces[lab == k].ravel())
            ck = _smallest_ball_centre(corners[pts], c[k])
            new_c.append(ck)
            new_r.append(float(np.linalg.norm(corners[pts] - ck, axis=1).max()))
        remap = np.full(len(c), -1)
        remap[used] = np.arange(len(used))
        c, r, lab = np.array(new_c), np.array(new_r), remap[lab]
    need = np.linalg.norm(tri[:, :, None, :] - c[None, None], axis=3).max(axis=1)
    lab = np.argmin(need - r[None], axis=1)
    out = np.zeros(len(c))
    np.maximum.at(out, lab, need[np.arange(len(tri)), lab])  # exact radii for the final assignment
    keep = out > 0
    return c[keep], out[keep]


def fit_spheres(
    triangles: np.ndarray,
    *,
    tolerance: float = 0.01,
    max_spheres: int = 16,
    max_edge: float | None = None,
    volume: float | None = None,
    seed: int = 0,
    refine: int = 0,
    candidates: int = 800,
) -> SphereFit:
    """Spheres whose union holds every point of the surface ``triangles: (T, 3, 3)`` (metres, body frame).

    Args:
        tolerance: the overreach aimed at (metres): candidate spheres reach this far past the nearest surface
            point; grown by half (and so on) until ``max_spheres`` suffice.
        max_spheres: at most this many spheres.
        max_edge: triangles are split until no edge is longer (default: twice ``tolerance``, at least the body's
            largest extent / 20).
        volume: the geometry's volume (m^3) for the reported ratio; default from the triangles.
        seed: seed of the candidate centres and of the Monte Carlo volume.
        refine: rounds of the optimisation (module docstring; 0: the greedy cover as it is).
        candidates: candidate centres drawn inside the hull (plus a tenth as many surface corners).
    """
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    if not len(tri) or not np.isfinite(tri).all():
        raise ValueError("fit_spheres: expected finite triangles (T, 3, 3) with T >= 1")
    flat = tri.reshape(-1, 3)
    extent = float((flat.max(axis=0) - flat.min(axis=0)).max())
    edge = max(2.0 * float(tolerance), extent / 20.0, 1e-4) if max_edge is None else float(max_edge)
    fine = subdivide(tri, edge) if extent > 0 else tri
    corners, faces = np.unique(fine.reshape(-1, 3).round(12), axis=0, return_inverse=True)
    faces = faces.reshape(-1, 3)
    volume = _volume(tri) if volume is None else float(volume)
    rng = np.random.default_rng(seed)
    n_in = int(candidates)
    inside = np.concatenate([_inside_points(flat, n_in, rng), corners[rng.choice(len(corners), max(1, n_in // 10))]])
    sq = (corners**2).sum(-1)
    d2 = (inside**2).sum(-1)[:, None] - 2.0 * inside @ corners.T + sq[None]
    depth = np.sqrt(np.maximum(d2.min(axis=1), 0.0))
    reach = max(float(tolerance), 1e-4)
    found = None
    while found is None:
        found = _greedy_cover(corners, faces, inside, depth, reach, int(max_spheres))
        reach *= 1.5
    c, r, lab = found
    if refine > 0:
        c, r = refine_cover(corners, faces, c, r, lab, refine)
    surface = corners if len(corners) <= 4000 else corners[rng.choice(len(corners), 4000, replace=False)]
    return SphereFit(c, r, _gap(c, r, surface), _volume_ratio(c, r, volume, np.random.default_rng(seed)))
