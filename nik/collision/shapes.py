"""URDF collision geometry as triangles that contain it: boxes exactly, curved primitives by polyhedra around them.

:func:`box_triangles`, :func:`cylinder_triangles`, :func:`sphere_triangles`, :func:`capsule_triangles` give
``(T, 3, 3)`` triangles (metres) of a closed surface that holds the primitive (a polygon *around* the circle:
its inradius is the radius), so spheres that hold these triangles hold the primitive (:mod:`nik.collision.fit`).
:func:`mesh_triangles` reads a mesh file through trimesh (the ``view`` or ``collision-check`` extra); a file it
cannot read is a one-line :class:`ValueError`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["box_triangles", "capsule_triangles", "cylinder_triangles", "mesh_triangles", "sphere_triangles"]

_SECTIONS = 32  # polygon sides around a circle


def _hull_triangles(points: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    return points[hull.simplices]


def box_triangles(size) -> np.ndarray:
    """The 12 triangles of a box of edge lengths ``size: (3,)`` centred at the origin."""
    h = np.asarray(size, dtype=np.float64).reshape(3) / 2
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float) * h
    return _hull_triangles(corners)


def _ring(radius: float, z: float) -> np.ndarray:
    out = radius / math.cos(math.pi / _SECTIONS)  # circumscribed: the polygon's inradius is ``radius``
    a = 2 * math.pi * np.arange(_SECTIONS) / _SECTIONS
    return np.stack([out * np.cos(a), out * np.sin(a), np.full(_SECTIONS, z)], axis=1)


def cylinder_triangles(radius: float, length: float) -> np.ndarray:
    """A prism around a cylinder along z (centred at the origin, as in URDF)."""
    return _hull_triangles(np.concatenate([_ring(radius, -length / 2), _ring(radius, length / 2)]))


def _ball_points(radius: float, center=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Corners of a polyhedron around a ball: rings of a circumscribed UV sphere, scaled so that every face
    plane lies at least ``radius`` from the centre."""
    rings = 12
    pts = [np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])]
    for i in range(1, rings):
        phi = math.pi * i / rings
        a = 2 * math.pi * (np.arange(_SECTIONS) + 0.5 * (i % 2)) / _SECTIONS
        pts.append(
            np.stack([math.sin(phi) * np.cos(a), math.sin(phi) * np.sin(a), np.full(_SECTIONS, math.cos(phi))], 1)
        )
    unit = np.concatenate(pts)
    from scipy.spatial import ConvexHull

    inner = -ConvexHull(unit).equations[:, 3].max()  # the face plane nearest the centre
    return np.asarray(center, dtype=float) + unit * (radius / inner)


def sphere_triangles(radius: float) -> np.ndarray:
    """A polyhedron around a ball of ``radius`` at the origin."""
    return _hull_triangles(_ball_points(radius))


def capsule_triangles(radius: float, length: float) -> np.ndarray:
    """A polyhedron around a capsule along z (segment from ``-length/2`` to ``length/2``, as URDF's capsule):
    the convex hull of the polyhedra around its two end balls."""
    return _hull_triangles(
        np.concatenate([_ball_points(radius, (0, 0, -length / 2)), _ball_points(radius, (0, 0, length / 2))])
    )


def mesh_triangles(path: str | Path, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    """The triangles ``(T, 3, 3)`` of a mesh file (STL, OBJ, PLY, DAE with pycollada, ...), scaled per axis."""
    try:
        import trimesh
    except ImportError as err:
        raise ValueError(
            f"cannot read mesh {path}: trimesh is not installed (pip install 'nik[collision-check]')"
        ) from err
    try:
        mesh = trimesh.load(str(path), force="mesh")
        tri = np.asarray(mesh.triangles, dtype=np.float64)
    except Exception as err:  # noqa: BLE001 - trimesh raises many kinds
        raise ValueError(f"cannot read mesh {path}: {type(err).__name__}: {err}") from None
    if tri.size == 0 or not np.isfinite(tri).all():
        raise ValueError(f"cannot read mesh {path}: no finite triangles")
    return tri * np.asarray(scale, dtype=np.float64).reshape(1, 1, 3)
