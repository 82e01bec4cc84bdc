"""A URDF's ``<collision>`` geometry, per link, as triangles in the frame of the robot's joint that carries it.

nik's FK knows frames, not links: frame ``k`` (``k = 1..dof``) is ``G_0 J_1 G_1 ... G_{k-1} J_k`` of the normal form
(:mod:`nik.kinematics`), frame 0 the robot's base frame. A URDF link rides on the frame of the last arm joint
above it in the tree (links above the first arm joint ride on frame 0). Joints that are not the arm's (a gripper's,
the other arm of a two-armed robot, a head) are placed at the robot's :attr:`joint_values` (``load_robot(...,
joint_values=)``), else at :func:`rest_value` (0, or the middle of the range where 0 is outside it), as ``nik
view`` draws them. Its geometry in that frame is fixed, and found by
one walk of the tree at q = 0: for the child link ``C_k`` of arm joint ``k`` (axis frame ``P_k``, see
:func:`nik.robots.model.axis_frame`), frame ``k`` is ``B @ U_{C_k}(q) @ P_k`` with ``U`` the URDF walk and ``B``
a constant (the robot's base frame, a ``root_link`` other than the URDF's root); the walk is checked against
:meth:`nik.Robot.fk`-style frames at two seeded configurations, so a URDF that is not this robot's is refused
with one line.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nik.collision.shapes import (
    box_triangles,
    capsule_triangles,
    cylinder_triangles,
    mesh_triangles,
    sphere_triangles,
)

__all__ = [
    "Body",
    "collision_mesh_files",
    "frames_at",
    "mesh_places",
    "resolve_mesh_path",
    "rest_value",
    "rpy_matrix",
    "urdf_bodies",
]

#: agreement needed between the URDF walk and nik's frames (metres and rotation-matrix entries)
MATCH_TOL = 1e-5


@dataclass
class Body:
    """One collision body: a URDF link's (or a link capsule's) geometry, rigid in frame ``frame``.

    Attributes:
        name: link name.
        frame: index of the robot's frame carrying it (0 = base, k = after joint k).
        triangles: (T, 3, 3) metres, in that frame, a closed surface holding the geometry; for a capsule body
            (``radius`` set) its segments ``(m, 2, 3)`` instead.
        parent: the nearest link above it with geometry (None for the root); for capsules the previous one.
        radius: the capsules' radius (metres), or None for a surface.
    """

    name: str
    frame: int
    triangles: np.ndarray
    parent: str | None = None
    radius: float | None = None


def mesh_places(filename: str, urdf_dir: Path) -> list[Path]:
    """Every place a URDF's ``<mesh filename>`` may be, in the order looked: for ``package://PKG/rest`` the folders
    above the URDF (a folder named PKG, or one holding PKG), then ``$ROS_PACKAGE_PATH`` (as the folders above),
    ``$AMENT_PREFIX_PATH`` / ``$CMAKE_PREFIX_PATH`` and this Python's prefixes (``PREFIX/share/PKG/rest``; pip's
    robot-description wheels, e.g. example-robot-data, install there or under ``site-packages/cmeel.prefix``);
    ``file://PATH`` that path; a plain path relative to the URDF's folder. The same places whatever nik's cache
    holds, so a copied URDF finds its meshes (or not) the same way every time."""
    import os
    import site
    import sys

    if filename.startswith("file://"):
        return [Path(filename[len("file://") :])]
    if not filename.startswith("package://"):
        p = Path(filename)
        return [p if p.is_absolute() else urdf_dir / p]
    package, _, rest = filename[len("package://") :].partition("/")
    places = []
    folders = [urdf_dir, *urdf_dir.parents]
    folders += [Path(d) for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    for folder in folders:
        places += [folder / rest] if folder.name == package else []
        places.append(folder / package / rest)
    prefixes = [
        Path(d)
        for v in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH")
        for d in os.environ.get(v, "").split(os.pathsep)
        if d
    ]
    prefixes += [Path(sys.prefix), *(Path(d) / "cmeel.prefix" for d in site.getsitepackages())]
    places += [prefix / "share" / package / rest for prefix in prefixes]
    return list(dict.fromkeys(places))


def resolve_mesh_path(filename: str, urdf_dir: Path) -> Path | None:
    """The file a URDF's ``<mesh filename>`` names: the first of :func:`mesh_places` that exists, or None."""
    return next((p for p in mesh_places(filename, urdf_dir) if p.is_file()), None)


def mesh_not_found(filename: str, urdf_dir: Path, where: str) -> ValueError:
    """The one-line error of a mesh found nowhere, naming every place looked."""
    looked = ", ".join(str(p) for p in mesh_places(filename, urdf_dir))
    return ValueError(f"{where}: mesh file not found: {filename} (looked in: {looked})")


def collision_mesh_files(path: Path) -> list[Path]:
    """The files of the URDF ``path``'s ``<collision>`` meshes, resolved (:func:`resolve_mesh_path`); a missing one
    is a one-line ``ValueError`` naming every place looked (:func:`mesh_not_found`)."""
    links, _ = _read(Path(path))
    out = []
    for name, link in links.items():
        for i, col in enumerate(link.findall("collision")):
            for mesh in col.iter("mesh"):
                filename = mesh.get("filename", "")
                found = resolve_mesh_path(filename, Path(path).parent)
                if found is None:
                    raise mesh_not_found(filename, Path(path).parent, f"{Path(path).name}: link {name!r} collision {i}")
                out.append(found)
    return out


def _floats(text: str | None, n: int, default: float, where: str) -> np.ndarray:
    if text is None:
        return np.full(n, default)
    try:
        v = np.array([float(x) for x in text.split()])
    except ValueError:
        raise ValueError(f"{where}: expected {n} numbers, got {text!r}") from None
    if v.size != n or not np.isfinite(v).all():
        raise ValueError(f"{where}: expected {n} finite numbers, got {text!r}")
    return v


def rpy_matrix(r, p, y) -> np.ndarray:
    """The URDF rotation ``Rz(y) Ry(p) Rx(r)`` (radians), 3x3."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _origin(el, where: str) -> np.ndarray:
    T = np.eye(4)
    o = el.find("origin") if el is not None else None
    if o is not None:
        T[:3, :3] = rpy_matrix(*_floats(o.get("rpy"), 3, 0.0, f"{where} origin rpy"))
        T[:3, 3] = _floats(o.get("xyz"), 3, 0.0, f"{where} origin xyz")
    return T


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    x, y, z = axis
    c, s, t = math.cos(angle), math.sin(angle), 1 - math.cos(angle)
    R = np.eye(4)
    R[:3, :3] = [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
    return R


def _geometry_triangles(geom, urdf_dir: Path, where: str) -> np.ndarray:
    shape = next(iter(geom), None) if geom is not None else None
    if shape is None:
        raise ValueError(f"{where}: <geometry> has no shape")
    tag = shape.tag.rsplit("}", 1)[-1]
    if tag == "mesh":
        name = shape.get("filename", "")
        path = resolve_mesh_path(name, urdf_dir)
        if path is None:
            raise mesh_not_found(name, urdf_dir, where)
        return mesh_triangles(path, _floats(shape.get("scale"), 3, 1.0, f"{where} mesh scale"))
    if tag == "box":
        size = _floats(shape.get("size"), 3, float("nan"), f"{where} box size")
        if (size <= 0).any():
            raise ValueError(f"{where}: box size must be positive, got {size.tolist()}")
        return box_triangles(size)
    r = float(_floats(shape.get("radius"), 1, float("nan"), f"{where} {tag} radius")[0])
    if not r > 0:
        raise ValueError(f"{where}: {tag} radius must be positive, got {r}")
    if tag == "sphere":
        return sphere_triangles(r)
    length = float(_floats(shape.get("length"), 1, float("nan"), f"{where} {tag} length")[0])
    if not length >= 0:
        raise ValueError(f"{where}: {tag} length must be >= 0, got {length}")
    if tag == "cylinder":
        return cylinder_triangles(r, length)
    if tag == "capsule":
        return capsule_triangles(r, length)
    raise ValueError(f"{where}: unknown geometry <{tag}> (expected mesh, box, cylinder, sphere, capsule)")


def rest_value(lower: float, upper: float) -> float:
    """Where a joint the robot does not drive stands by default: 0, or the middle of its range ``[lower, upper]``
    where 0 is outside it (a joint without a range, ``lower >= upper``: 0)."""
    if lower >= upper or lower <= 0.0 <= upper:
        return 0.0
    return 0.5 * (lower + upper)


def placed_values(robot) -> dict[str, float]:
    """``{joint: value}`` given for the joints outside ``robot``'s chain (``load_robot(..., joint_values=)``)."""
    return dict(getattr(robot, "joint_values", None) or {})


@dataclass
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    rest: float


def _read(path: Path):
    try:
        root = ET.fromstring(path.read_bytes())
    except (OSError, ET.ParseError) as err:
        raise ValueError(f"{path}: not a readable URDF ({err})") from None
    for el in root.iter():  # drop namespaces
        if isinstance(el.tag, str):
            el.tag = el.tag.rsplit("}", 1)[-1]
    joints = []
    for j in root.findall("joint"):
        name = j.get("name", "")
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise ValueError(f"{path}: joint {name!r} lacks <parent> or <child>")
        axis = _floats(j.find("axis").get("xyz") if j.find("axis") is not None else None, 3, 0.0, name)
        axis = np.array([1.0, 0.0, 0.0]) if not axis.any() else axis / np.linalg.norm(axis)
        lim = j.find("limit")
        lo = float(lim.get("lower", 0.0)) if lim is not None else 0.0
        hi = float(lim.get("upper", 0.0)) if lim is not None else 0.0
        rest = rest_value(lo, hi)
        joints.append(
            _Joint(name, j.get("type", "fixed"), parent.get("link"), child.get("link"), _origin(j, name), axis, rest)
        )
    links = {link.get("name"): link for link in root.findall("link")}
    return links, joints


def frames_at(robot, q: np.ndarray) -> np.ndarray:
    """``(dof + 1, 4, 4)``: frame 0 (identity, the base frame) and frames 1..dof of the normal form at ``q: (dof,)``."""
    G = robot.G.numpy()
    off = robot.offsets.numpy()
    pr = robot.prismatic.numpy()
    out = np.empty((robot.dof + 1, 4, 4))
    out[0] = np.eye(4)
    T = G[0].copy()
    for i in range(robot.dof):
        J = np.eye(4)
        v = q[i] + off[i]
        if pr[i]:
            J[2, 3] = v
        else:
            c, s = math.cos(v), math.sin(v)
            J[:2, :2] = [[c, -s], [s, c]]
        T = T @ J
        out[i + 1] = T
        T = T @ G[i + 1]
    return out


def urdf_bodies(robot, path: str | Path) -> list[Body]:
    """The collision bodies of the URDF ``path`` for ``robot`` (loaded from that URDF): one per link with
    ``<collision>`` geometry (all its ``<collision>`` elements together), in the frame that carries it."""
    from nik.robots.model import axis_frame

    path = Path(path)
    links, joints = _read(path)
    by_child = {j.child: j for j in joints}
    children: dict[str, list[_Joint]] = {}
    for j in joints:
        children.setdefault(j.parent, []).append(j)
    roots = [name for name in links if name not in by_child]
    if len(roots) != 1:
        raise ValueError(f"{path}: expected one root link, found {roots}")
    index = {name: k + 1 for k, name in enumerate(robot.joint_names)}
    placed = placed_values(robot)
    missing = [n for n in robot.joint_names if n not in {j.name for j in joints}]
    if missing:
        raise ValueError(f"{path}: is not this robot's URDF (no joint {missing[0]!r})")

    def walk(q):
        """World pose of every link (URDF root = identity) and the arm frame each rides on."""
        pose, frame = {roots[0]: np.eye(4)}, {roots[0]: 0}
        todo = [roots[0]]
        while todo:
            link = todo.pop()
            for j in children.get(link, []):
                T = pose[link] @ j.origin
                if j.kind in ("revolute", "continuous", "prismatic"):
                    v = q[index[j.name] - 1] if j.name in index else placed.get(j.name, j.rest)
                    if j.kind == "prismatic":
                        M = np.eye(4)
                        M[:3, 3] = j.axis * v
                        T = T @ M
                    else:
                        T = T @ _axis_rotation(j.axis, v)
                pose[j.child] = T
                frame[j.child] = index.get(j.name, frame[link])
                todo.append(j.child)
        return pose, frame

    joint_of = {j.name: j for j in joints}
    child_of = {k: joint_of[name].child for name, k in index.items()}
    P = {k: axis_frame(joint_of[name].axis) for name, k in index.items()}
    rng = np.random.default_rng(0)
    B = None
    for trial in range(3):
        lim = robot.limits.numpy()
        q = np.zeros(robot.dof) if trial == 0 else rng.uniform(lim[:, 0], lim[:, 1])
        q = np.clip(q, lim[:, 0], lim[:, 1])
        pose, frame = walk(q)
        F = frames_at(robot, q)
        for k in range(1, robot.dof + 1):
            Bk = F[k] @ np.linalg.inv(pose[child_of[k]] @ P[k])
            if B is None:
                B = Bk
            elif np.abs(Bk - B).max() > MATCH_TOL:
                raise ValueError(
                    f"{path}: its links do not move as this robot's frames (joint {robot.joint_names[k - 1]!r}); "
                    "is it the URDF the robot was loaded from?"
                )
        if trial == 0:
            pose0, frame0, F0 = pose, frame, F
    bodies = []
    for name, link in links.items():
        tris = []
        for i, col in enumerate(link.findall("collision")):
            where = f"{path.name}: link {name!r} collision {i}"
            T = _origin(col, where)
            t = _geometry_triangles(col.find("geometry"), path.parent, where)
            tris.append(t @ T[:3, :3].T + T[:3, 3])
        if not tris or name not in pose0:
            continue
        k = frame0[name]
        X = np.linalg.inv(F0[k]) @ B @ pose0[name]  # link frame -> frame k (constant)
        tri = np.concatenate(tris)
        bodies.append(Body(name, k, tri @ X[:3, :3].T + X[:3, 3]))
    with_geometry = {b.name for b in bodies}
    for b in bodies:  # the nearest link above with geometry (MoveIt's adjacency skips links without any)
        up = by_child[b.name].parent if b.name in by_child else None
        while up is not None and up not in with_geometry:
            up = by_child[up].parent if up in by_child else None
        b.parent = up
    return bodies
