"""A static link's geometry as a grid of signed distances in the base frame, a lower bound of the true ones.

A link that never moves relative to the base (frame 0: a torso, a pedestal, the other arm placed by
``joint_values=``) is checked on its geometry directly: a moving sphere of centre ``x`` and radius ``r`` is apart
from it by at least ``v(x) - r``, ``v`` the trilinear interpolation of the grid (:func:`grid_values`), and
outside the grid's box by the distance to the geometry's bounding box. Spheres covering a large flat face reach
out of it by about the radius of the patch each holds; the grid does not (its bound is
:attr:`SdfGrid.bound`: 11 mm beside a flat face at the default pitch, 20 mm at worst).

Conservative by construction (choices): the surface is split into triangles with edges at most ``e = pitch / 3``
(:func:`nik.collision.fit.subdivide`), so every surface point lies within ``2 e / 3`` of a triangle's centroid (two
thirds of a median); a node's distance to the nearest centroid (a k-d tree) minus that is at most its true distance to
the surface (for the nodes within :data:`BAND` of it; farther, a distance transform of the nodes nearest the centroids
bounds it, ``pitch * sqrt(3) / 2`` lower). Inside (negative) are the nodes that a flood from the grid's border cannot
reach without crossing a node within ``pitch / 2`` of the surface, and, of those near the surface, the ones behind the
nearest triangle's outward face; an inside node stores minus its distance to the nearest centroid (at most the true
signed distance). Every node then loses ``pitch * sqrt(3) / 2``, the most that the interpolation of a 1-Lipschitz
function overshoots it inside a cell (``sum_i w_i |x - c_i|`` at the cell's centre), so ``v(x)`` is at most the true
signed distance at every ``x`` of the box. A mistaken sign (an open mesh) only lowers a value: still conservative.
"""

from __future__ import annotations

import base64
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GRID_PITCH", "SdfGrid", "grid_values", "grid_values_torch", "static_grid"]

#: default pitch of the grid (metres): about 1.2 million nodes for Baxter's torso and pedestal (5 MB float32)
GRID_PITCH = 0.01

#: the nodes within this of the surface (metres) get their distance from the nearest centroid (a k-d tree); the
#: others from a distance transform of the nodes nearest the centroids, which loses ``pitch * sqrt(3) / 2`` more
BAND = 0.06


@dataclass
class SdfGrid:
    """Signed distances on a regular grid in the base frame (metres).

    Attributes:
        origin: (3,) the first node.
        pitch: node spacing.
        values: (nx, ny, nz) float32, each at most the true signed distance minus ``pitch * sqrt(3) / 2``.
        box: (2, 3) the geometry's bounding box (lower, upper corner): outside the grid, the distance to it.
        bound: how far below the true signed distance a value within :data:`BAND` of the surface may be:
            ``pitch * sqrt(3)`` (the nodes' offset and the interpolation's; half of it beside a flat face, where the
            distance is linear) plus the sampling's ``2 e / 3``: what the model reports as the link's gap.
    """

    origin: np.ndarray
    pitch: float
    values: np.ndarray
    box: np.ndarray
    bound: float

    def to_dict(self) -> dict:
        return {
            "origin": self.origin.tolist(),
            "pitch": self.pitch,
            "shape": list(self.values.shape),
            "box": self.box.tolist(),
            "bound": self.bound,
            "values": base64.b64encode(np.ascontiguousarray(self.values, dtype="<f4").tobytes()).decode("ascii"),
        }

    @classmethod
    def from_dict(cls, d: dict) -> SdfGrid:
        values = np.frombuffer(base64.b64decode(d["values"]), dtype="<f4").reshape(tuple(d["shape"]))
        return cls(np.asarray(d["origin"], float), float(d["pitch"]), values.astype(np.float32),
                   np.asarray(d["box"], float).reshape(2, 3), float(d["bound"]))  # fmt: skip

    def row(self, start: int) -> np.ndarray:
        """``(14,)``: the grid as the kernels read it (origin, pitch, shape, ``start`` in the flat values, box)."""
        return np.array([*self.origin, self.pitch, *self.values.shape, start, *self.box[0], *self.box[1]], float)


def static_grid(triangles: np.ndarray, pitch: float = GRID_PITCH) -> SdfGrid:
    """The grid of a surface ``triangles: (T, 3, 3)`` (metres, base frame) at ``pitch`` metres (module
    docstring): the nodes span the bounding box plus two pitches each side."""
    from scipy import ndimage
    from scipy.spatial import cKDTree

    from nik.collision.fit import subdivide

    pitch = float(pitch)
    if not (math.isfinite(pitch) and pitch > 0):
        raise ValueError(f"grid pitch must be positive (metres), got {pitch}")
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    lo, hi = tri.reshape(-1, 3).min(axis=0), tri.reshape(-1, 3).max(axis=0)
    origin = lo - 2 * pitch
    shape = tuple(int(k) for k in np.ceil((hi + 2 * pitch - origin) / pitch).astype(int) + 1)
    edge = pitch / 3
    fine = subdivide(tri, edge)
    centres = fine.mean(axis=1)
    sampling = 2 * edge / 3
    half_cell = pitch * math.sqrt(3) / 2
    # the band near the surface: nodes within BAND of an occupied node (one nearest to a centroid), exact there
    occupied = np.zeros(shape, dtype=bool)
    at = np.rint((centres - origin) / pitch).astype(np.int64)
    occupied[at[:, 0], at[:, 1], at[:, 2]] = True
    apart = ndimage.distance_transform_edt(~occupied).ravel() * pitch
    band = apart <= BAND
    axes = [origin[k] + pitch * np.arange(shape[k]) for k in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    near = apart + half_cell  # beyond the band: a centroid within this (an upper bound of the distance)
    low = np.maximum(apart - half_cell - sampling, 0.0)  # ... and the distance at least this
    idx = np.zeros(len(nodes), dtype=np.int64)
    near[band], idx[band] = cKDTree(centres).query(nodes[band], workers=1)
    low[band] = np.maximum(near[band] - sampling, 0.0)
    shell = (band & (near <= pitch / 2 + sampling)).reshape(shape)  # every grid edge crossing the surface has one
    labels, _ = ndimage.label(~shell)
    border = np.unique(np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(),
                                       labels[:, :, [0, -1]].ravel()]))  # fmt: skip
    inside = ~np.isin(labels, border[border > 0]) & ~shell
    s = shell.ravel()
    t = fine[idx[s]]
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    behind = np.zeros(len(nodes), dtype=bool)
    behind[s] = np.einsum("ij,ij->i", nodes[s] - centres[idx[s]], normal) < 0
    inside |= shell & behind.reshape(shape)
    signed = np.where(inside.ravel(), -near, low)
    interp = pitch * math.sqrt(3) / 2
    values = (signed - interp).reshape(shape)
    values32 = values.astype(np.float32)
    values32 = np.where(values32 > values, np.nextafter(values32, np.float32(-np.inf)), values32)  # rounded down
    return SdfGrid(origin, pitch, values32, np.stack([lo, hi]), 2 * interp + sampling)


def grid_values(grid_rows: np.ndarray, flat: np.ndarray, k: int, points: np.ndarray) -> np.ndarray:
    """``(N,)`` the value of grid ``k`` at ``points: (N, 3)`` as the kernels compute it (numpy; the tests' reference
    for :func:`nik.kernels.collision._grid_value`): trilinear inside the nodes, the distance to the box outside."""
    import torch

    return grid_values_torch(grid_rows, flat, k, torch.as_tensor(points, dtype=torch.float64)).numpy()


def grid_values_torch(grid_rows, flat, k: int, points):
    """:func:`grid_values` in torch, differentiable in ``points: (..., 3)`` (``grid_rows (Ng, 14)``,
    ``flat (N,)`` as :meth:`nik.collision.CollisionModel.grid_arrays` gives them)."""
    import torch

    like = dict(dtype=points.dtype, device=points.device)
    row = torch.as_tensor(grid_rows[k], **like)
    origin, h = row[0:3], float(grid_rows[k][3])
    n = [int(v) for v in grid_rows[k][4:7]]
    start = int(grid_rows[k][7])
    lo, hi = row[8:11], row[11:14]
    vals = torch.as_tensor(np.asarray(flat[start : start + n[0] * n[1] * n[2]]), **like).reshape(n)
    f = (points - origin) / h
    top = torch.as_tensor([n[0] - 1, n[1] - 1, n[2] - 1], **like)
    outside = ((f < 0) | (f > top)).any(dim=-1)
    i = torch.minimum(f.detach().floor().clamp(min=0), top - 1).long()
    t = f - i.to(points.dtype)
    out = torch.zeros(points.shape[:-1], **like)
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                w = (t[..., 0] if cx else 1 - t[..., 0]) * (t[..., 1] if cy else 1 - t[..., 1])
                w = w * (t[..., 2] if cz else 1 - t[..., 2])
                ix = (i[..., 0] + cx).clamp(0, n[0] - 1)
                iy = (i[..., 1] + cy).clamp(0, n[1] - 1)
                iz = (i[..., 2] + cz).clamp(0, n[2] - 1)
                out = out + w * vals[ix, iy, iz]
    gap = torch.maximum(torch.maximum(lo - points, points - hi), torch.zeros_like(points))
    gap = torch.where(outside[..., None], gap, torch.ones_like(gap))  # no norm of 0 (its gradient) where unused
    box = torch.linalg.vector_norm(gap, dim=-1)
    return torch.where(outside, box, out)
