"""URDF collision geometry as triangles that contain it: boxes exactly, curved primitives by polyhedra around them.

:func:`box_triangles`, :func:`cylinder_triangles`, :func:`sphere_triangles`, :func:`capsule_triangles` give
``(T, 3, 3)`` triangles (metres) of a closed surface that holds the primitive (a polygon *around* the circle:
its inradius is the radius), so spheres that hold these triangles hold the primitive (:mod:`nik.collision.fit`).
:func:`mesh_triangles` reads a mesh file through trimesh (the ``collision-check`` extra, with pycollada for
COLLADA ``.dae``); a file it cannot read is a one-line :class:`ValueError` naming the file and what to install.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["box_triangles", "capsule_triangles", "cylinder_triangles", "mesh_triangles", "sphere_triangles"]

_SECTIONS = 32  # polygon sides around a circle (numpy only: no convex-hull library needed)


def _outward(tri: np.ndarray, center) -> np.ndarray:
    """Triangles of a convex surface turned to face away from ``center`` (for the volume of :mod:`.fit`)."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", n, tri.mean(axis=1) - np.asarray(center, dtype=float)) < 0
    tri[flip] = tri[flip][:, ::-1]
    return tri


def _band(lower: np.ndarray, upper: np.ndarray) -> list[np.ndarray]:
    """Triangles between two rings of equally many points (planar quads split in two)."""
    nxt = np.roll(np.arange(len(lower)), -1)
    return [np.stack([lower, lower[nxt], upper[nxt]], 1), np.stack([lower, upper[nxt], upper], 1)]


def _fan(pole: np.ndarray, ring: np.ndarray) -> np.ndarray:
    nxt = np.roll(np.arange(len(ring)), -1)
    return np.stack([np.broadcast_to(pole, ring.shape), ring, ring[nxt]], 1)


def box_triangles(size) -> np.ndarray:
    """The 12 triangles of a box of edge lengths ``size: (3,)`` centred at the origin."""
    h = np.asarray(size, dtype=np.float64).reshape(3) / 2
    c = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float) * h
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tri = np.array([[c[a], c[b], c[d]] for a, b, cc, d in quads] + [[c[b], c[cc], c[d]] for a, b, cc, d in quads])
    return _outward(tri, np.zeros(3))


def _ring(radius: float, z: float) -> np.ndarray:
    a = 2 * math.pi * np.arange(_SECTIONS) / _SECTIONS
    return np.stack([radius * np.cos(a), radius * np.sin(a), np.full(_SECTIONS, z)], axis=1)


def cylinder_triangles(radius: float, length: float) -> np.ndarray:
    """A prism around a cylinder along z (centred at the origin, as in URDF): a polygon whose inradius is the
    radius, and flat caps."""
    out = radius / math.cos(math.pi / _SECTIONS)
    lo, hi = _ring(out, -length / 2), _ring(out, length / 2)
    parts = [*_band(lo, hi), _fan(np.array([0.0, 0.0, -length / 2]), lo), _fan(np.array([0.0, 0.0, length / 2]), hi)]
    return _outward(np.concatenate(parts), np.zeros(3))


_RINGS = 12  # latitude bands of the polyhedra around balls (even: one ring on the equator)


def _ball_rings(radius: float) -> tuple[list[np.ndarray], float]:
    """Rings of a UV polyhedron around a ball of ``radius`` at the origin (poles excluded) and the scale applied:
    every face plane lies at least ``radius`` from the centre (its faces are planar quads and triangles, so it
    is convex and contains the ball)."""
    rings = []
    for i in range(1, _RINGS):
        phi = math.pi * i / _RINGS
        rings.append(_ring(math.sin(phi), math.cos(phi)))
    unit = [np.array([0.0, 0.0, 1.0]), *rings, np.array([0.0, 0.0, -1.0])]
    tri = np.concatenate(
        [_fan(unit[0], unit[1])]
        + [t for i in range(1, _RINGS - 1) for t in _band(unit[i + 1], unit[i])]
        + [_fan(unit[-1], unit[-2])]
    )
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    inner = float(np.abs(np.einsum("ij,ij->i", n, tri[:, 0])).min())
    return [r * (radius / inner) for r in rings], radius / inner


def sphere_triangles(radius: float) -> np.ndarray:
    """A polyhedron around a ball of ``radius`` at the origin."""
    rings, scale = _ball_rings(radius)
    top, bottom = np.array([0.0, 0.0, scale]), np.array([0.0, 0.0, -scale])
    parts = [_fan(top, rings[0]), *[t for i in range(len(rings) - 1) for t in _band(rings[i + 1], rings[i])]]
    parts.append(_fan(bottom, rings[-1]))
    return _outward(np.concatenate(parts), np.zeros(3))


def capsule_triangles(radius: float, length: float) -> np.ndarray:
    """A polyhedron around a capsule along z (segment from ``-length/2`` to ``length/2``, as URDF's capsule): the
    polyhedron around a ball cut at its equator, the halves moved to the segment's ends and joined by a prism."""
    rings, scale = _ball_rings(radius)
    half = _RINGS // 2  # rings[half - 1] is the equator
    up = [r + [0.0, 0.0, length / 2] for r in rings[:half]]
    down = [r - [0.0, 0.0, length / 2] for r in rings[half - 1 :]]
    chain = up + down
    parts = [_fan(np.array([0.0, 0.0, scale + length / 2]), chain[0])]
    parts += [t for i in range(len(chain) - 1) for t in _band(chain[i + 1], chain[i])]
    parts.append(_fan(np.array([0.0, 0.0, -scale - length / 2]), chain[-1]))
    return _outward(np.concatenate(parts), np.zeros(3))


#: the package trimesh needs for a mesh format (by file suffix) beyond STL, OBJ, PLY and OFF, which it reads alone
MESH_READERS = {".dae": "pycollada", ".zae": "pycollada", ".3mf": "networkx and lxml", ".glb": "", ".gltf": ""}

#: what to install for the collision extra (trimesh, pycollada, coal)
INSTALL_HINT = "pip install 'nik-ik[collision-check]'"


def mesh_triangles(path: str | Path, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    """The triangles ``(T, 3, 3)`` of a mesh file (STL, OBJ, PLY, DAE with pycollada, ...), scaled per axis.

    Read by trimesh (the ``collision-check`` extra, which installs pycollada for COLLADA ``.dae``); a file that
    cannot be read is a one-line :class:`ValueError` naming it, and, where a reader package is missing, the
    package and :data:`INSTALL_HINT`."""
    try:
        import trimesh
    except ImportError as err:
        raise ValueError(f"cannot read mesh {path}: trimesh is not installed ({INSTALL_HINT})") from err
    try:
        mesh = trimesh.load(str(path), force="mesh")
        tri = np.asarray(mesh.triangles, dtype=np.float64)
    except ImportError as err:  # a reader's package (pycollada for .dae) is missing
        package = MESH_READERS.get(Path(path).suffix.lower()) or getattr(err, "name", None) or "its reader"
        raise ValueError(
            f"cannot read mesh {path}: its format needs {package}, which is not installed ({INSTALL_HINT})"
        ) from None
    except Exception as err:  # noqa: BLE001 - trimesh raises many kinds
        text = " ".join(str(err).split())
        raise ValueError(f"cannot read mesh {path}: {type(err).__name__}: {text} ({INSTALL_HINT} reads "
                         "STL, OBJ, PLY and COLLADA .dae)") from None  # fmt: skip
    if tri.size == 0 or not np.isfinite(tri).all():
        raise ValueError(f"cannot read mesh {path}: no finite triangles")
    return tri * np.asarray(scale, dtype=np.float64).reshape(1, 1, 3)
