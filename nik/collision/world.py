"""Obstacles in the robot's base frame: :class:`World` (spheres, boxes, capsules, point clouds as spheres).

A world is changed between solves without rebuilding anything: each ``add_*`` or :meth:`World.clear` bumps
:attr:`World.version`, and the packed arrays the distance code reads (:meth:`World.packed`) are rebuilt on the
first read after a change. Packed layout (float64, metres):

- ``spheres: (Ns, 4)``: centre x, y, z, radius (point-cloud points are spheres too);
- ``boxes: (Nb, 15)``: rotation R row by row (9), centre (3), half sizes (3); the box is ``|R^T (x - c)| <= h``;
- ``capsules: (Nc, 7)``: end points p0 (3), p1 (3), radius.

Scene files (:meth:`World.from_file`, YAML or JSON; metres unless ``unit: mm``)::

    unit:     m                    # or mm: every length below in millimetres (angles stay radians)
    spheres:  [{center: [x, y, z], radius: r}, ...]
    boxes:    [{center: [x, y, z], size: [sx, sy, sz], rpy: [r, p, y]}, ...]   # or pose: 4x4 / [x y z qw qx qy qz]
    capsules: [{p0: [x, y, z], p1: [x, y, z], radius: r}, ...]
    points:   [{xyz: [[x, y, z], ...], radius: r}, ...]

Unknown keys, missing fields, negative or zero sizes, an empty or malformed file: one-line ``ValueError``. A scene
without ``unit`` whose largest coordinate or size exceeds :data:`MM_HINT` metres (no arm reaches that far) warns
that it looks written in millimetres, as targets 100 x beyond the reach do
(:func:`nik.robots.reach.unreachable_message`).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np

from nik.collision.urdf import rpy_matrix
from nik.robots.yamlfile import load_yaml

__all__ = ["MM_HINT", "World"]

#: a scene length (coordinate or size) beyond this many metres looks written in millimetres
MM_HINT = 20.0


def _vec(value, n: int, what: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected {n} numbers, got {value!r}") from None
    if v.shape != (n,) or not np.isfinite(v).all():
        raise ValueError(f"{what}: expected {n} finite numbers, got {value!r}")
    return v


def _positive(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{what}: must be positive (metres), got {value!r}")
    return v


def _pose(value, what: str) -> np.ndarray:
    """A (4, 4) rigid transform from a (3,) centre, a (7,) x y z qw qx qy qz or a (4, 4) matrix."""
    a = np.asarray(value, dtype=np.float64)
    T = np.eye(4)
    if a.shape == (3,):
        T[:3, 3] = _vec(a, 3, what)
    elif a.shape == (7,):
        if not np.isfinite(a).all():
            raise ValueError(f"{what}: not finite")
        w, x, y, z = a[3:] / np.linalg.norm(a[3:])
        T[:3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
        T[:3, 3] = a[:3]
    elif a.shape == (4, 4):
        if not np.isfinite(a).all() or np.abs(a[:3, :3].T @ a[:3, :3] - np.eye(3)).max() > 1e-6:
            raise ValueError(f"{what}: a (4, 4) pose needs a finite orthonormal rotation")
        T = a.copy()
    else:
        raise ValueError(f"{what}: expected a centre (3,), x y z qw qx qy qz (7,) or a (4, 4) pose, got {a.shape}")
    return T


def _scaled(key: str, value, scale: float):
    """A scene item's ``value`` with its lengths times ``scale`` (``rpy`` and a pose's rotation unchanged)."""
    if scale == 1.0 or key == "rpy":
        return value
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        return value  # the add_* call names the problem
    if key == "pose" and a.shape == (4, 4):
        a[:3, 3] *= scale
    elif key == "pose":
        a[:3] *= scale
    else:
        a = a * scale
    return a


class World:
    """Obstacles in the robot's base frame (metres). Add with :meth:`add_sphere`, :meth:`add_box`,
    :meth:`add_capsule`, :meth:`add_points`; read with :meth:`packed`. See the module docstring."""

    def __init__(self):
        self._spheres: list[np.ndarray] = []
        self._boxes: list[np.ndarray] = []
        self._capsules: list[np.ndarray] = []
        #: bumped by every change; the packed arrays are rebuilt on the first read after one
        self.version = 0
        self._packed: tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None

    def __repr__(self) -> str:
        s, b, c = self.counts()
        return f"World(spheres={s}, boxes={b}, capsules={c}, version={self.version})"

    def counts(self) -> tuple[int, int, int]:
        """Numbers of spheres (point-cloud points included), boxes and capsules."""
        return sum(len(a) for a in self._spheres), len(self._boxes), len(self._capsules)

    @property
    def empty(self) -> bool:
        return sum(self.counts()) == 0

    def _changed(self) -> World:
        self.version += 1
        return self

    def add_sphere(self, center, radius: float) -> World:
        """A ball: ``center: (3,)`` metres, ``radius`` > 0 metres. Returns the world."""
        c = _vec(center, 3, "sphere center")
        self._spheres.append(np.append(c, _positive(radius, "sphere radius"))[None])
        return self._changed()

    def add_box(self, pose_or_center, size) -> World:
        """A box of edge lengths ``size: (3,)`` (> 0, metres) at ``pose_or_center``: a centre ``(3,)`` (axis-aligned),
        ``(7,)`` x y z qw qx qy qz or a ``(4, 4)`` pose. Returns the world."""
        T = _pose(pose_or_center, "box pose")
        size = _vec(size, 3, "box size")
        if not (size > 0).all():
            raise ValueError(f"box size: every edge must be positive (metres), got {size.tolist()}")
        self._boxes.append(np.concatenate([T[:3, :3].reshape(9), T[:3, 3], size / 2]))
        return self._changed()

    def add_capsule(self, p0, p1, radius: float) -> World:
        """The points within ``radius`` (> 0) of the segment ``p0 -> p1`` (``(3,)`` each, metres)."""
        a, b = _vec(p0, 3, "capsule p0"), _vec(p1, 3, "capsule p1")
        self._capsules.append(np.concatenate([a, b, [_positive(radius, "capsule radius")]]))
        return self._changed()

    def add_points(self, xyz, radius: float) -> World:
        """A point cloud ``xyz: (N, 3)`` metres, each point a ball of ``radius`` (> 0: the sensor's noise and
        spacing). Returns the world."""
        p = np.asarray(xyz, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
            raise ValueError(f"points: expected finite xyz of shape (N, 3), got shape {p.shape}")
        r = _positive(radius, "points radius")
        if len(p):
            self._spheres.append(np.concatenate([p, np.full((len(p), 1), r)], axis=1))
        return self._changed()

    def clear(self) -> World:
        """Remove every obstacle."""
        self._spheres, self._boxes, self._capsules = [], [], []
        return self._changed()

    def packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``spheres (Ns, 4)``, ``boxes (Nb, 15)``, ``capsules (Nc, 7)``: contiguous float64 (module docstring),
        rebuilt only after a change."""
        if self._packed is None or self._packed[0] != self.version:
            s = np.concatenate(self._spheres) if self._spheres else np.zeros((0, 4))
            b = np.stack(self._boxes) if self._boxes else np.zeros((0, 15))
            c = np.stack(self._capsules) if self._capsules else np.zeros((0, 7))
            self._packed = (self.version, tuple(np.ascontiguousarray(a) for a in (s, b, c)))
        return self._packed[1]

    # -- scene files ----------------------------------------------------------
    def largest_length(self) -> float:
        """The largest absolute coordinate or size of the obstacles, metres (0 for an empty world)."""
        s, b, c = self.packed()
        parts = [np.abs(s).ravel(), np.abs(b[:, 9:]).ravel(), np.abs(c).ravel()]
        return float(max((p.max() for p in parts if p.size), default=0.0))

    @classmethod
    def from_dict(cls, data, source: str = "scene") -> World:
        """A world from plain data (the scene-file schema of the module docstring)."""
        if not isinstance(data, dict) or not data:
            raise ValueError(f"{source}: expected a mapping with spheres, boxes, capsules or points; got {data!r}")
        data = dict(data)
        unit = data.pop("unit", None)
        if unit not in (None, "m", "mm"):
            raise ValueError(f"{source}: unit must be m or mm, got {unit!r}")
        world = cls._from_items(data, source, 1e-3 if unit == "mm" else 1.0)
        if unit is None and world.largest_length() > MM_HINT:
            warnings.warn(
                f"{source}: a coordinate or size of {world.largest_length():.4g} m, beyond any arm's reach "
                f"(> {MM_HINT:g} m): written in millimetres? add 'unit: mm' to the file",
                UserWarning,
                stacklevel=2,
            )
        return world

    @classmethod
    def _from_items(cls, data: dict, source: str, scale: float) -> World:
        """The obstacles of ``data`` (without ``unit``), lengths multiplied by ``scale``."""
        fields = {
            "spheres": {"center", "radius"},
            "boxes": {"center", "size", "rpy", "pose"},
            "capsules": {"p0", "p1", "radius"},
            "points": {"xyz", "radius"},
        }
        unknown = sorted(set(data) - set(fields))
        if unknown:
            raise ValueError(f"{source}: unknown key {unknown[0]!r} (expected unit, {', '.join(fields)})")
        world = cls()
        for kind, allowed in fields.items():
            items = data.get(kind) or []
            if not isinstance(items, list):
                raise ValueError(f"{source}: {kind} must be a list")
            for i, item in enumerate(items):
                where = f"{source}: {kind}[{i}]"
                if not isinstance(item, dict):
                    raise ValueError(f"{where}: expected a mapping, got {item!r}")
                bad = sorted(set(item) - allowed)
                if bad:
                    raise ValueError(f"{where}: unknown key {bad[0]!r} (expected {', '.join(sorted(allowed))})")
                try:
                    item = {k: _scaled(k, v, scale) for k, v in item.items()}
                    if kind == "spheres":
                        world.add_sphere(item["center"], item["radius"])
                    elif kind == "capsules":
                        world.add_capsule(item["p0"], item["p1"], item["radius"])
                    elif kind == "points":
                        world.add_points(item["xyz"], item["radius"])
                    else:
                        if "pose" in item and ("center" in item or "rpy" in item):
                            raise ValueError("give either pose or center (+ rpy)")
                        if "pose" in item:
                            pose = item["pose"]
                        else:
                            pose = _pose(item["center"], "box center")
                            if "rpy" in item:
                                pose[:3, :3] = rpy_matrix(*_vec(item["rpy"], 3, "box rpy"))
                        world.add_box(pose, item["size"])
                except KeyError as err:
                    raise ValueError(f"{where}: missing {err.args[0]!r}") from None
                except ValueError as err:
                    raise ValueError(f"{where}: {err}") from None
        return world

    @classmethod
    def from_file(cls, path: str | Path) -> World:
        """A world from a ``.yaml``/``.yml`` or ``.json`` scene file (module docstring)."""
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as err:
            raise ValueError(f"scene file {path}: cannot be read ({err.strerror or err})") from None
        if not text.strip():
            raise ValueError(f"scene file {path}: is empty")
        if path.suffix.lower() != ".json":
            data = load_yaml(text, f"scene file {path}")  # the error names the line and column
        else:
            try:
                data = json.loads(text)
            except json.JSONDecodeError as err:
                place = f"line {err.lineno}, column {err.colno}"
                raise ValueError(f"scene file {path}: not valid JSON: {place}: {err.msg}") from None
        return cls.from_dict(data, source=f"scene file {path}")
