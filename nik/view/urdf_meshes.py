"""A URDF's visual geometry, placed where nik's FK puts the arm: :func:`load_urdf_visuals`.

A robot loaded from a URDF keeps only its kinematics (:mod:`nik.robots.urdf`); to draw its meshes this
module reads the file again for each link's ``<visual>`` (a mesh file, box, cylinder or sphere, with its
``<origin>`` and scale; a mesh that cannot be read, e.g. COLLADA without pycollada, falls back to the link's
``<collision>`` geometry) and walks the URDF's joint tree to pose every link: the arm's joints take the
robot's values by name, every other joint (a gripper's fingers, another arm) stands at the robot's
``joint_values`` (``load_robot(..., joint_values=)``), else at 0 (the middle of its range where 0 is outside it).

That walk is checked against :meth:`nik.Robot.fk` at two seeded configurations: nik's tool pose must be the
URDF's ``end_link`` pose, up to one constant base transform or one constant tool transform (a robot loaded
with ``base=`` or ``tool=``). Where it is not (both given, another root link), or no mesh file is there, the
caller draws capsules instead (:func:`load_urdf_visuals` returns None and says why).

``package://PKG/rest`` is looked up in the folders above the URDF (a folder named PKG, or one holding PKG);
plain paths are relative to the URDF's folder. Nothing is downloaded. Meshes are read with trimesh
(a dependency of viser, the ``view`` extra).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from nik.collision.urdf import (  # one reading of <mesh filename> and of the other joints, the collision model's
    placed_values,
    resolve_mesh_path,
    rest_value,
)
from nik.poses import rpy_to_matrix

__all__ = ["LinkVisual", "UrdfVisuals", "load_urdf_visuals", "resolve_mesh_path"]

#: FK agreement needed between the URDF walk and nik's FK (metres / rotation-matrix entries)
MATCH_TOL = 1e-5


@dataclass
class LinkVisual:
    """One visual of one link: ``vertices (V, 3)`` metres and ``faces (F, 3)`` in the link frame (its
    ``<origin>`` and scale applied), an RGB colour (0-255) and where it came from."""

    link: str
    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[int, int, int]
    source: str


@dataclass
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray  # (4, 4)
    axis: np.ndarray  # (3,) unit
    rest: float  # value when the robot does not drive it


class UrdfVisuals:
    """The visuals of a URDF's links and the pose of every link at the robot's joints.

    Attributes:
        visuals: list of :class:`LinkVisual`.
        skipped: ``"link: reason"`` for each visual that could not be read.
        base: (4, 4) placed before the URDF's root (a robot loaded with ``base=``); identity otherwise.
    """

    def __init__(self, robot, joints: list[_Joint], visuals: list[LinkVisual], skipped: list[str]):
        self.robot = robot
        self.visuals = visuals
        self.skipped = skipped
        self.base = np.eye(4)
        self._joints = joints  # parents before children
        self._index = {name: i for i, name in enumerate(robot.joint_names)}
        self._placed = placed_values(robot)

    @property
    def links(self) -> list[str]:
        """Names of the links that have a visual, each once, in tree order."""
        return list(dict.fromkeys(v.link for v in self.visuals))

    def link_poses(self, q) -> dict[str, np.ndarray]:
        """Every link's pose ``(4, 4)`` in nik's base frame (metres) at ``q: (dof,)`` (the robot's joints)."""
        q = np.asarray(torch.as_tensor(q, dtype=torch.float64).reshape(self.robot.dof))
        poses: dict[str, np.ndarray] = {}
        for j in self._joints:
            parent = poses.get(j.parent)
            if parent is None:
                parent = poses[j.parent] = self.base.copy()
            value = q[self._index[j.name]] if j.name in self._index else self._placed.get(j.name, j.rest)
            poses[j.child] = parent @ j.origin @ _motion(j, float(value))
        return poses


def _motion(j: _Joint, value: float) -> np.ndarray:
    M = np.eye(4)
    if j.kind in ("revolute", "continuous") and value:
        x, y, z = j.axis
        c, s, t = math.cos(value), math.sin(value), 1.0 - math.cos(value)
        M[:3, :3] = [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ]
    elif j.kind == "prismatic":
        M[:3, 3] = value * j.axis
    return M


def _origin(el) -> np.ndarray:
    T = np.eye(4)
    o = el.find("origin") if el is not None else None
    if o is None:
        return T
    if o.get("rpy"):
        rpy = [float(v) for v in o.get("rpy").split()]
        T[:3, :3] = rpy_to_matrix(torch.tensor(rpy, dtype=torch.float64)).numpy()
    if o.get("xyz"):
        T[:3, 3] = [float(v) for v in o.get("xyz").split()]
    return T


def _geometry(geom, urdf_dir: Path):
    """``(vertices, faces, source)`` of a ``<geometry>`` element, or ``(None, None, reason)``."""
    import trimesh

    shape = next(iter(geom), None) if geom is not None else None
    if shape is None:
        return None, None, "no geometry"
    if shape.tag == "mesh":
        name = shape.get("filename", "")
        path = resolve_mesh_path(name, urdf_dir)
        if path is None:
            return None, None, f"mesh file not found: {name}"
        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception as err:  # a format trimesh cannot read here (COLLADA needs pycollada)
            return None, None, f"{path.name}: {type(err).__name__}: {err}"
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            return None, None, f"{path.name}: no triangles"
        scale = shape.get("scale")
        v = np.asarray(mesh.vertices, dtype=np.float64) * (
            np.array([float(s) for s in scale.split()]) if scale else 1.0
        )
        return v, np.asarray(mesh.faces), str(path)
    if shape.tag == "box":
        mesh = trimesh.creation.box(extents=[float(s) for s in shape.get("size", "0 0 0").split()])
    elif shape.tag == "cylinder":
        mesh = trimesh.creation.cylinder(radius=float(shape.get("radius", 0)), height=float(shape.get("length", 0)))
    elif shape.tag == "sphere":
        mesh = trimesh.creation.icosphere(radius=float(shape.get("radius", 0)), subdivisions=2)
    else:
        return None, None, f"unknown geometry <{shape.tag}>"
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces), shape.tag


def _color(visual, materials: dict) -> tuple[int, int, int]:
    mat = visual.find("material")
    rgba = None
    if mat is not None:
        c = mat.find("color")
        rgba = c.get("rgba") if c is not None else materials.get(mat.get("name"))
    if not rgba:
        return (190, 190, 195)
    r, g, b = (float(v) for v in rgba.split()[:3])
    return (int(255 * r), int(255 * g), int(255 * b))


def _read(path: Path):
    """Joints (parents before children) and visuals of the URDF at ``path``."""
    root = ET.fromstring(path.read_bytes())
    for el in root.iter():  # drop XML namespaces
        if isinstance(el.tag, str) and "}" in el.tag:
            el.tag = el.tag.rsplit("}", 1)[1]
    materials = {}
    for m in root.findall("material"):
        c = m.find("color")
        if c is not None and m.get("name"):
            materials[m.get("name")] = c.get("rgba")
    joints = []
    for el in root.findall("joint"):
        axis = el.find("axis")
        a = np.array([float(v) for v in axis.get("xyz").split()]) if axis is not None and axis.get("xyz") else None
        a = np.array([1.0, 0.0, 0.0]) if a is None or not np.linalg.norm(a) else a / np.linalg.norm(a)
        lim = el.find("limit")
        lo = float(lim.get("lower", 0)) if lim is not None else 0.0
        hi = float(lim.get("upper", 0)) if lim is not None else 0.0
        rest = rest_value(lo, hi)
        joints.append(
            _Joint(
                el.get("name"),
                el.get("type"),
                el.find("parent").get("link"),
                el.find("child").get("link"),
                _origin(el),
                a,
                rest,
            )
        )
    by_parent: dict[str, list[_Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    children = {j.child for j in joints}
    order, todo = [], [j.parent for j in joints if j.parent not in children]
    seen = set()
    while todo:  # breadth first from the root(s): a parent's pose is known before its children's
        link = todo.pop(0)
        if link in seen:
            continue
        seen.add(link)
        for j in by_parent.get(link, []):
            order.append(j)
            todo.append(j.child)
    visuals, skipped = [], []
    for link in root.findall("link"):
        name = link.get("name")
        for visual in link.findall("visual"):
            v, f, src = _geometry(visual.find("geometry"), path.parent)
            origin = _origin(visual)
            if v is None:  # try the collision geometry of the same link
                reason = src
                col = link.find("collision")
                v, f, src = _geometry(col.find("geometry"), path.parent) if col is not None else (None, None, "")
                origin = _origin(col) if col is not None else origin
                if v is None:
                    skipped.append(f"{name}: {reason}")
                    continue
            v = v @ origin[:3, :3].T + origin[:3, 3]
            visuals.append(LinkVisual(name, v, f, _color(visual, materials), src))
    return order, visuals, skipped


def load_urdf_visuals(robot) -> tuple[UrdfVisuals | None, str]:
    """The visuals of a robot loaded from a URDF, or ``(None, why not)``.

    Returns ``(visuals, note)``: ``note`` says how many links got a mesh (or why none did).
    """
    source = getattr(robot, "source", None)
    if not source or Path(source).suffix.lower() != ".urdf" or not Path(source).is_file() or not robot.end_link:
        return None, "no URDF with meshes: links drawn as capsules between joint origins"
    try:
        import trimesh  # noqa: F401
    except ImportError:
        return None, "trimesh is not installed: links drawn as capsules"
    path = Path(source)
    try:
        joints, visuals, skipped = _read(path)
    except (ET.ParseError, AttributeError, ValueError) as err:
        return None, f"{path.name}: visuals unreadable ({err}): links drawn as capsules"
    if not visuals:
        why = f" ({skipped[0]})" if skipped else ""
        return None, f"{path.name}: no mesh to show{why}: links drawn as capsules"
    scene = UrdfVisuals(robot, joints, visuals, skipped)
    if not _align(scene):
        return None, f"{path.name}: its links do not match the robot's FK (base and tool frames?): capsules"
    note = f"{len(scene.links)} links with meshes from {path.name}"
    if skipped:
        note += f"; {len(skipped)} visuals not read ({skipped[0]})"
    return scene, note


def _align(scene: UrdfVisuals) -> bool:
    """Place the URDF walk under nik's base frame: True when nik's FK is the walk's end-link pose times at most
    one constant transform (a base before it, else a tool after it), at two seeded configurations."""
    robot = scene.robot
    q = robot.sample(2, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    T_nik = robot.fk(q).numpy()
    try:
        T_u = np.stack([scene.link_poses(qi)[robot.end_link] for qi in q])
    except KeyError:
        return False
    base = T_nik[0] @ np.linalg.inv(T_u[0])
    if np.allclose(base @ T_u[1], T_nik[1], atol=MATCH_TOL):
        scene.base = base
        return True
    tool = np.linalg.inv(T_u[0]) @ T_nik[0]
    return bool(np.allclose(T_u[1] @ tool, T_nik[1], atol=MATCH_TOL))
