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

A sphere whose centre is inside at depth ``d`` (distance to the surface) with radius at most ``d + reach`` lies
within ``reach`` of the geometry, so the cover's overreach is bounded by the reach where the candidates are good
and the cover needs no fallback. ``medial=True`` adds the best such centres: points of the medial axis (the
centres of the largest balls inside, one touching each surface corner, :func:`_medial_candidates`) and points
part-way to them, for which a sphere of radius ``d + reach`` holds the most surface per unit of overreach (a
cylinder's axis, a plate's mid-plane).

The refinement (``refine=N`` rounds, the built-ins' shipped models; choices): the greedy cover is carried onto
the surface split finer (``fine_edge``, a third of ``max_edge`` by default: a sub-triangle lies inside its
triangle, so the cover still holds it) and optimised continuously against the mesh. The quantity minimised is
the bound above: a ball centred inside at depth ``d`` (the distance to the nearest surface point) with radius
``r`` leaves the body by at most ``r - d`` (a point outside is reached through the surface). Each round (a) moves
every centre to the point minimising ``max |c - p| - d(c)`` over the corners ``p`` of its own triangles (a
compass search, 14 directions, the step halved where none improves; depth from a KD-tree of surface probes
with outward normals, so a centre that leaves the body is charged for it), (b) gives every triangle to the
sphere that needs the least overreach to hold it, then to the one that holds it with the most room, and sets
each radius to its triangles' farthest corner, and (c) while under ``max_spheres`` splits the spheres reaching
out most (their triangles halved across their principal axis). Every iterate is an exact cover (each triangle
assigned, each radius reaching its triangles' corners: the guarantee above, not a sampled one, so no safety
margin for sampling density is needed); the one with the least area-weighted ``r - d`` over the surface is
kept. The depths only steer the search: an error in them makes the fit looser, never smaller than the cover.

Overreach (:class:`SphereFit`): ``gap`` is the largest distance from a point of the union's boundary to the
geometry's surface (metres, measured on 96 points per sphere against the subdivided surface's corners), and
``volume_ratio`` the union's volume over the geometry's (Monte Carlo, seeded; the convex hull's volume where the
surface is not closed).

numpy, and scipy's convex hull where installed (for the candidate centres and the volume; the bounding box
without it; the refinement needs scipy's KD-tree); :mod:`nik.collision.shapes` turns URDF geometry (and meshes,
through trimesh) into triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SphereFit", "fit_spheres", "one_sphere", "subdivide"]


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


def one_sphere(triangles: np.ndarray, seed: int = 0, edge: float = 0.005) -> SphereFit:
    """One ball around the whole closed surface ``triangles: (T, 3, 3)``: centred at the middle of its bounding box,
    through its farthest corner, so an exact cover (every corner inside, hence the convex hull and the surface).
    For a URDF ``<sphere>`` (a polyhedron around the ball) it reaches only the polyhedron's own slack past the
    surface, where a cover of many spheres overreaches its large faces. The gap is measured on the surface
    subdivided to ``edge`` metres."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    corners = tri.reshape(-1, 3)
    c = (corners.min(axis=0) + corners.max(axis=0)) / 2
    r = float(np.sqrt(((corners - c) ** 2).sum(axis=1).max())) * (1 + 1e-12)
    centers, radii = c[None], np.array([r])
    surface = subdivide(tri, edge).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    return SphereFit(centers, radii, _gap(centers, radii, surface), _volume_ratio(centers, radii, _volume(tri), rng))


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
    try:
        from scipy.spatial import cKDTree

        return float(cKDTree(surface).query(pts)[0].max())
    except ImportError:
        pass
    best = np.full(len(pts), np.inf)
    for s in range(0, len(surface), 256):  # (P, 256, 3) at a time
        chunk = surface[s : s + 256]
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


def _inside_only(candidates, n_in, tri, flat, edge, volume, seed) -> np.ndarray:
    """``candidates`` with the first ``n_in`` (drawn in the convex hull) that lie outside a closed, non-convex body
    replaced by points inside it (drawn from a generator of its own, ``seed + 1``); the others as they are.

    A centre outside the body at distance ``e`` from it, with a radius reaching the surface, leaves the body by
    about ``2 e``: such centres made the greedy cover hold a pedestal's legs with one ball between them (470 mm
    past the mesh). The inside is told by the nearest surface probe's outward normal (:func:`_signed_depth`), so
    only where the surface looks closed and consistently oriented (its enclosed volume between 0.1 and 1 times its
    convex hull's) and scipy is there; a convex body keeps every candidate (and its
    fit). The cover's guarantee does not depend on where candidates are."""
    if n_in <= 0 or volume <= 0:
        return candidates
    try:
        from scipy.spatial import ConvexHull

        hull = float(ConvexHull(flat).volume)
    except Exception:  # noqa: BLE001 - flat geometry or no scipy
        return candidates
    enclosed = abs(float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0))
    if not 0.1 * hull <= enclosed <= hull * (1 - 1e-3):  # open, inconsistent, or convex: nothing to do
        return candidates
    probes = _probes(tri, edge / 2.0)
    drawn = candidates[:n_in]
    out = _signed_depth(drawn, probes) < 0
    if not out.any():
        return candidates
    more = _inside_points(flat, 4 * n_in, np.random.default_rng(seed + 1))
    more = more[_signed_depth(more, probes) > 0][: int(out.sum())]
    return np.concatenate([drawn[~out], more, candidates[n_in:]])


def _face_reach(corners, faces, inside) -> np.ndarray | None:
    """``(C, T)`` float32: the distance from each candidate centre ``inside`` to the farthest corner of each triangle
    (the radius a candidate needs to hold it), computed once for every reach the cover tries; None where it would
    take more than :data:`FACE_REACH_ENTRIES` entries (the cover then compares corner by corner each time). float32
    only steers the greedy choice: the radii are recomputed in float64 from the triangles each sphere is given."""
    if len(inside) * len(faces) > FACE_REACH_ENTRIES:
        return None
    out = np.empty((len(inside), len(faces)), dtype=np.float32)
    sq = (corners**2).sum(-1)
    for s in range(0, len(inside), 128):
        c = inside[s : s + 128]
        d = np.sqrt(np.maximum((c**2).sum(-1)[:, None] - 2.0 * c @ corners.T + sq[None], 0.0)).astype(np.float32)
        out[s : s + 128] = np.maximum(np.maximum(d[:, faces[:, 0]], d[:, faces[:, 1]]), d[:, faces[:, 2]])
    return out


#: the most entries (candidates x triangles, float32) :func:`_face_reach` keeps: 64 M, 256 MB
FACE_REACH_ENTRIES = 64 * 2**20


def _greedy_cover(corners, faces, inside, depth, reach, max_spheres, face_reach=None):
    """Spheres ``(centres, radii)`` holding every triangle ``corners[faces]``: candidates ``inside`` with radius
    ``depth + reach``; greedily the one holding the most triangles not yet held; triangles no candidate holds go
    to the chosen sphere that grows least for them; then each radius shrinks to its own triangles' farthest
    corner. None when more than ``max_spheres`` are needed. ``face_reach``: :func:`_face_reach`, when computed."""
    radii = depth + reach
    if face_reach is not None:
        held = face_reach <= (radii[:, None] * (1 - 1e-6)).astype(np.float32)  # (C, T)
    else:
        held_v = np.empty((len(inside), len(corners)), dtype=bool)
        sq = (corners**2).sum(-1)
        for s in range(0, len(inside), 256):
            c = inside[s : s + 256]
            d2 = (c**2).sum(-1)[:, None] - 2.0 * c @ corners.T + sq[None]  # float64: well below the sizes here
            held_v[s : s + 256] = d2 <= (radii[s : s + 256, None] ** 2) * (1 - 1e-9)
        held = held_v[:, faces[:, 0]] & held_v[:, faces[:, 1]] & held_v[:, faces[:, 2]]  # (C, T)
    gain = held.sum(axis=1)  # triangles each candidate would newly hold, kept up to date as triangles are held
    open_ = np.ones(faces.shape[0], dtype=bool)
    chosen = []
    while open_.any():
        best = int(np.argmax(gain))
        if gain[best] == 0:
            break
        chosen.append(best)
        newly = held[best] & open_
        open_ &= ~newly
        gain -= held[:, newly].sum(axis=1)  # each triangle leaves the gains once: C x T in all
        if len(chosen) > max_spheres:
            return None
    if not chosen:
        chosen = [int(np.argmax(depth))]
    centers = inside[chosen].copy()
    need = _need(corners, faces, centers)  # (T, K), float64
    # each triangle to a chosen sphere that holds it (the one that holds it with most room), else the one
    # needing the least radius for it
    room = need - radii[chosen][None]
    lab = np.argmin(room, axis=1)
    out = np.zeros(len(chosen))
    np.maximum.at(out, lab, need[np.arange(len(faces)), lab])
    keep = out > 0
    remap = np.cumsum(keep) - 1
    return centers[keep], out[keep], remap[lab]


def _probes(tri: np.ndarray, edge: float):
    """Surface probes for the signed depth: centroids of ``tri`` split to ``edge`` with their outward normals
    (orientation from the enclosed volume's sign), and a KD-tree over them (scipy)."""
    from scipy.spatial import cKDTree

    fine = subdivide(tri, edge)
    cen = fine.mean(axis=1)
    fn = np.cross(fine[:, 1] - fine[:, 0], fine[:, 2] - fine[:, 0])
    if float(np.einsum("ij,ij->i", fine[:, 0], fn).sum()) < 0:  # inward-facing: flip
        fn = -fn
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    return cKDTree(cen), cen, fn


def _signed_depth(x: np.ndarray, probes) -> np.ndarray:
    """Distance from ``x: (..., 3)`` to the nearest probe, positive inside (against its normal), negative out."""
    tree, cen, fn = probes
    d, i = tree.query(x)
    inside = np.einsum("...k,...k->...", fn[i], cen[i] - x) >= 0
    return np.where(inside, d, -d)


def _need(corners: np.ndarray, faces: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """``(T, K)``: the radius sphere ``k`` needs to hold triangle ``t`` (its farthest corner)."""
    out = np.empty((len(faces), len(centers)))
    for s in range(0, len(centers), 16):
        dv = np.sqrt(((corners[:, None, :] - centers[None, s : s + 16]) ** 2).sum(-1))  # (V, k)
        out[:, s : s + 16] = dv[faces].max(axis=1)
    return out


def _hull_vertices(p: np.ndarray) -> np.ndarray:
    """The points of ``p: (N, 3)`` on its convex hull (the farthest point from anywhere is one of them)."""
    if len(p) < 16:
        return p
    try:
        from scipy.spatial import ConvexHull

        return p[ConvexHull(p).vertices]
    except Exception:  # noqa: BLE001 - flat patch
        return p


_DIRECTIONS = np.concatenate(
    [np.eye(3), -np.eye(3), np.array(np.meshgrid(*[[-1.0, 1.0]] * 3)).reshape(3, -1).T / 3**0.5]
)


def _best_centres(c0: np.ndarray, patches: list, probes, steps: int = 60) -> np.ndarray:
    """Centres ``(K, 3)`` minimising, each for its patch of points, ``max |c - p| - depth(c)``: the bound on how
    far the ball holding the patch reaches out of the body (a ball centred inside at depth ``d`` with radius
    ``r`` leaves it by at most ``r - d``). A compass search from ``c0`` (14 directions, the step halved where
    none improves), all spheres at once (one KD-tree query a step); an empty patch keeps its centre."""
    hulls = [_hull_vertices(p) if len(p) else None for p in patches]
    c = np.asarray(c0, dtype=np.float64).copy()
    K, D = len(c), len(_DIRECTIONS)

    def far(k, x):  # (n, 3) -> (n,)
        return np.sqrt(((x[:, None, :] - hulls[k][None]) ** 2).sum(-1)).max(axis=1)

    live = np.array([h is not None for h in hulls])
    cost = np.full(K, np.inf)
    step = np.zeros(K)
    depth = _signed_depth(c, probes)
    for k in np.nonzero(live)[0]:
        r = far(k, c[k : k + 1])[0]
        cost[k], step[k] = r - depth[k], max(0.25 * r, 1e-3)
    for _ in range(steps):
        live &= step > 2e-5
        idx = np.nonzero(live)[0]
        if not len(idx):
            break
        trial = c[idx, None, :] + step[idx, None, None] * _DIRECTIONS[None]  # (n, D, 3)
        dep = _signed_depth(trial.reshape(-1, 3), probes).reshape(len(idx), D)
        for j, k in enumerate(idx):
            tc = far(k, trial[j]) - dep[j]
            b = int(np.argmin(tc))
            if tc[b] < cost[k] - 1e-9:
                c[k], cost[k] = trial[j, b], tc[b]
            else:
                step[k] *= 0.5
    return c


def _radii(need: np.ndarray, lab: np.ndarray, k: int) -> np.ndarray:
    r = np.zeros(k)
    np.maximum.at(r, lab, need[np.arange(len(lab)), lab])
    return r


def _refine(corners, faces, centers, radii, probes, iters: int, max_spheres: int):
    """Continuous refinement of a cover (module docstring): alternately each sphere's centre moved to the best
    one for its triangles (:func:`_best_centres`) and each triangle given to the sphere that holds it with the
    least overreach; the sphere reaching out most split in two while under ``max_spheres``. Every triangle stays
    assigned and every radius is its triangles' farthest corner, so every iterate is a cover; the one with the
    least area-weighted overreach bound is returned ``(centres, radii)``."""
    tri = corners[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    c = np.asarray(centers, dtype=np.float64).copy()
    need = _need(corners, faces, c)
    held = need <= np.asarray(radii)[None] * (1 + 1e-12)
    lab = np.where(held.any(axis=1), np.argmax(np.where(held, -need, -np.inf), axis=1), np.argmin(need, axis=1))
    best = None
    for it in range(iters + 1):
        if it:  # centre step, then the sphere reaching out most split while under budget
            c = _best_centres(c, [corners[np.unique(faces[lab == k])] for k in range(len(c))], probes)
            depth = _signed_depth(c, probes)
            over = _radii(need, lab, len(c)) - depth
            last = max(1, iters - 3)  # splits until 3 rounds before the end, then the cover settles
            splits = -(-(max_spheres - len(c)) // (last - it + 1)) if it <= last else 0
            split = []
            for k in np.argsort(-over)[: max(0, splits)]:
                m = np.nonzero(lab == k)[0]
                if len(m) > 1:
                    mid = tri[m].mean(axis=1)
                    axis = np.linalg.svd(mid - mid.mean(axis=0), full_matrices=False)[2][0]
                    side = (mid - mid.mean(axis=0)) @ axis > 0
                    lab[m[side]] = len(c)
                    c = np.vstack([c, c[k]])
                    split += [k, len(c) - 1]
            if split:
                c[split] = _best_centres(c[split], [corners[np.unique(faces[lab == j])] for j in split], probes)
            need = _need(corners, faces, c)
            depth = _signed_depth(c, probes)
            lab = np.argmin(need - depth[None], axis=1)  # the least overreach for each triangle
        for _ in range(8):  # then shrink: each triangle to the sphere that holds it with most room
            r = _radii(need, lab, len(c))
            new = np.argmax(np.where(need <= r[None], r[None] - need, -np.inf), axis=1)
            if (new == lab).all():
                break
            lab = new
        r = _radii(need, lab, len(c))
        keep = r > 0
        depth = _signed_depth(c, probes)
        score = float(area @ (r - depth)[lab]) / float(area.sum())
        if best is None or score < best[0]:
            best = (score, c[keep].copy(), r[keep].copy())
        c, lab = c[keep], (np.cumsum(keep) - 1)[lab]
        need = need[:, keep]
    return best[1], best[2]


def _medial_candidates(corners: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Centres of the largest balls inside the surface touching each corner (the shrinking-ball estimate of the
    medial axis): corner ``p`` with outward normal ``n`` (area-weighted face normals; the orientation taken from
    the enclosed volume's sign) gets ``p - r n`` with ``r`` the smallest ``|p - q|^2 / (2 n . (p - q))`` over the
    corners ``q`` with ``n . (p - q) > 0``; also at 0.35 and 0.7 of that depth (thin parts). ``(3 V, 3)``
    (:func:`fit_spheres` keeps a seeded ``3 * candidates`` of them)."""
    tri = corners[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # area-weighted (x2)
    if float(np.einsum("ij,ij->i", tri[:, 0], fn).sum()) < 0:  # inward-facing: flip
        fn = -fn
    n = np.zeros_like(corners)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    extent = float((corners.max(axis=0) - corners.min(axis=0)).max())
    r = np.full(len(corners), extent / 2)
    for s in range(0, len(corners), 512):
        p, m = corners[s : s + 512], n[s : s + 512]
        d = p[:, None] - corners[None]  # (b, V, 3)
        num = (d**2).sum(-1)
        den = 2.0 * np.einsum("bvk,bk->bv", d, m)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where((den > 1e-12) & (num > 1e-18), num / den, np.inf)
        r[s : s + 512] = np.minimum(r[s : s + 512], ratio.min(axis=1))
    return np.concatenate([corners - (t * r)[:, None] * n for t in (1.0, 0.7, 0.35)])


def fit_spheres(
    triangles: np.ndarray,
    *,
    tolerance: float = 0.01,
    max_spheres: int = 16,
    max_edge: float | None = None,
    volume: float | None = None,
    seed: int = 0,
    medial: bool = False,
    candidates: int = 800,
    refine: int = 0,
    fine_edge: float | None = None,
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
        medial: add the medial-axis candidates (module docstring): tighter, slower (nik's shipped models).
        candidates: candidate centres drawn inside the hull (plus a tenth as many surface corners).
        refine: rounds of the continuous refinement (module docstring; 0: the greedy cover as it is); it may
            split spheres up to ``max_spheres``.
        fine_edge: the refinement holds triangles split to this edge (default a third of ``max_edge``).
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
    if medial:
        med = _medial_candidates(corners, faces)
        inside = np.concatenate([inside, med[rng.choice(len(med), min(len(med), 3 * n_in), replace=False)]])
    inside = _inside_only(inside, n_in, tri, flat, edge, volume, seed)
    sq = (corners**2).sum(-1)
    depth = np.empty(len(inside))
    for s in range(0, len(inside), 256):  # chunked: (256, V) at a time
        c = inside[s : s + 256]
        depth[s : s + 256] = np.sqrt(np.maximum(((c**2).sum(-1)[:, None] - 2.0 * c @ corners.T + sq[None]).min(1), 0))
    reach = max(float(tolerance), 1e-4)
    found = None
    face_reach = _face_reach(corners, faces, inside)
    while found is None:
        found = _greedy_cover(corners, faces, inside, depth, reach, int(max_spheres), face_reach)
        reach *= 1.5
    c, r, _ = found
    if refine > 0:
        fe = edge / 3.0 if fine_edge is None else float(fine_edge)
        fine = subdivide(tri, fe) if extent > 0 else tri
        corners, faces = np.unique(fine.reshape(-1, 3).round(12), axis=0, return_inverse=True)
        faces = faces.reshape(-1, 3)
        c, r = _refine(corners, faces, c, r, _probes(tri, fe), int(refine), int(max_spheres))
    surface = corners if len(corners) <= 4000 else corners[rng.choice(len(corners), 4000, replace=False)]
    return SphereFit(c, r, _gap(c, r, surface), _volume_ratio(c, r, volume, np.random.default_rng(seed)))
