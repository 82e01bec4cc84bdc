"""The arm's collision model: spheres per link and the link pairs worth checking (:func:`collision_model`).

Where the spheres come from (choices):

- a robot loaded from a URDF with ``<collision>`` geometry (meshes, boxes, cylinders, spheres, capsules): one
  body per link that has some, riding on the frame of its joint (:mod:`nik.collision.urdf`), covered by spheres
  fitted by :func:`nik.collision.fit.fit_spheres` (conservative: every surface point is inside; the overreach
  per link is reported in :attr:`CollisionModel.gaps` and :attr:`CollisionModel.volume_ratios`); the links on
  frame 0 (static relative to the base) get more spheres, and a moving link reaching more than 2 cm past its
  geometry is fitted again with more (:func:`_fit_link`);
- otherwise, a built-in arm with a shipped model (``panda``, ``ur5``, ``xarm7``: spheres fitted to their vendors'
  meshes, :mod:`nik.collision.builtin`) gets that model, unless ``radius`` is given;
- otherwise (DH / MDH / screw-axis files, or a URDF without collision geometry): a capsule of ``radius`` metres
  along each link, from one joint's origin to the next (the last to the tool point; frame 0 from the base to
  joint 1), covered exactly by spheres of radius ``sqrt(r^2 + (s/2)^2)`` spaced ``s = radius`` along it. A
  prismatic joint's travel is covered by a capsule in its frame over the whole stroke.

Which pairs are checked, as MoveIt's setup assistant decides (each left-out pair keeps its reason in
:attr:`CollisionModel.left_out`): links on the same frame (they never move relative to each other), adjacent
links (parent and child: a joint between them), the pairs MoveIt's SRDF disables (``srdf=``: a path, or found
beside the URDF, :func:`find_srdf`), then on ``samples`` seeded configurations within the limits (streamed through
the compiled rows, :func:`_pair_rows`: memory bounded whatever the spheres' count),
pairs whose spheres touch in every one ("always") and pairs never closer than ``never_clearance`` metres
("never"; ``never_clearance=None`` keeps them). :meth:`CollisionModel.with_pairs` adds or removes pairs.

Cached per robot, like the kernels: ``$XDG_CACHE_HOME/nik/collision/KEY.json`` keyed by the robot's definition
hash, the URDF's bytes and the options; a file ``NAME.collision.json`` beside the robot's file (URDF or YAML)
is used instead where present. :meth:`CollisionModel.save` / :meth:`CollisionModel.load` write and read such a
file; loading refuses a model made for another robot (definition hash) with one line.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from nik.collision.sdf import GRID_PITCH

__all__ = ["COLLISION_FORMAT", "CollisionModel", "collision_model", "link_capsule_bodies", "set_collision_model"]

#: version of the saved model's file format (the shipped models' files carry it)
COLLISION_FORMAT = 1

#: version of the fitting and the pair rules, part of the cache key (bump when they change: a cached fit is redone)
FIT_VERSION = 5


@dataclass
class CollisionModel:
    """Spheres per link (in the frame of the joint carrying the link) and the active link pairs.

    Attributes:
        robot_hash: :attr:`nik.Robot.definition_hash` of the robot it was made for.
        links: (L,) link names.
        frames: (L,) int, the robot frame carrying each link (0 = base, k = after joint k).
        centers: (S, 3) metres, sphere centres in their link's frame; spheres grouped by link.
        radii: (S,) metres.
        body_start: (L + 1,) int, link ``l``'s spheres are ``body_start[l]:body_start[l + 1]``.
        pairs: (P, 2) int, the link pairs checked (indices into ``links``, first < second).
        left_out: ``{"a|b": reason}`` for the pairs not checked (same frame, adjacent, srdf: ..., always, never,
            removed).
        parents: (L,) the nearest link with geometry above each link (URDF), or the previous capsule; None at the
            root.
        gaps: (L,) metres, how far each link's spheres overreach its geometry (module docstring).
        volume_ratios: (L,) sphere volume over geometry volume per link.
        source: ``"urdf:PATH"`` or ``"capsules"``.
        options: the options it was built with.
        grids: ``{link: SdfGrid}``, static links (frame 0) that also carry a grid of signed distances to their
            geometry in the base frame (:mod:`nik.collision.sdf`): the row of a pair with such a link is the larger
            of the spheres' and the grid's (both lower bounds of the distance). None or empty: spheres only.
    """

    robot_hash: str
    links: list[str]
    frames: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    body_start: np.ndarray
    pairs: np.ndarray
    left_out: dict = field(default_factory=dict)
    parents: list | None = None
    gaps: np.ndarray | None = None
    volume_ratios: np.ndarray | None = None
    source: str = ""
    options: dict = field(default_factory=dict)
    grids: dict | None = None

    # -- views ------------------------------------------------------------------
    @property
    def sphere_body(self) -> np.ndarray:
        """(S,) int: the link of each sphere."""
        return np.repeat(np.arange(len(self.links)), np.diff(self.body_start))

    @property
    def sphere_frame(self) -> np.ndarray:
        """(S,) int: the robot frame of each sphere."""
        return np.asarray(self.frames)[self.sphere_body]

    def spheres(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Centres ``(k, 3)`` (the link's frame, metres) and radii ``(k,)`` of one link."""
        if link not in self.links:
            raise ValueError(f"unknown link {link!r} (links: {', '.join(self.links)})")
        i = self.links.index(link)
        a, b = self.body_start[i], self.body_start[i + 1]
        return self.centers[a:b], self.radii[a:b]

    @property
    def per_link(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """``{link: (centres (k, 3), radii (k,))}``."""
        return {name: self.spheres(name) for name in self.links}

    def pair_names(self) -> list[tuple[str, str]]:
        """The active pairs as link names."""
        return [(self.links[a], self.links[b]) for a, b in self.pairs]

    def sphere_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(i, j, pair)``: every sphere pair of the active link pairs, as ``(M,)`` int arrays."""
        cached = self.__dict__.get("_sphere_pairs")
        if cached is not None and cached[0] is self.pairs:
            return cached[1]
        ii, jj, pp = [], [], []
        for p, (a, b) in enumerate(self.pairs):
            sa = np.arange(self.body_start[a], self.body_start[a + 1])
            sb = np.arange(self.body_start[b], self.body_start[b + 1])
            ii.append(np.repeat(sa, len(sb)))
            jj.append(np.tile(sb, len(sa)))
            pp.append(np.full(len(sa) * len(sb), p))
        out = tuple(np.concatenate(x).astype(np.int64) if x else np.zeros(0, np.int64) for x in (ii, jj, pp))
        self.__dict__["_sphere_pairs"] = (self.pairs, out)
        return out

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The model as the compiled kernels take it (:mod:`nik.kernels.collision`): ``spheres (S, 4)`` (centre in
        its frame, radius), ``sphere_frame (S,)`` int64, ``body_start (L + 1,)`` int64, ``pairs (P, 2)`` int64."""
        spheres = np.ascontiguousarray(np.concatenate([self.centers, self.radii[:, None]], axis=1), dtype=np.float64)
        return (
            spheres,
            np.ascontiguousarray(self.sphere_frame, dtype=np.int64),
            np.ascontiguousarray(self.body_start, dtype=np.int64),
            np.ascontiguousarray(np.asarray(self.pairs, dtype=np.int64).reshape(-1, 2)),
        )

    def grid_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The grids as the kernels take them (:class:`nik.kernels.collision.ArmSpheres`' last fields):
        ``link_grid (L,)`` int64 (-1: none; ``(0,)`` for a model without grids), ``grids (Ng, 14)`` float64
        (:meth:`nik.collision.sdf.SdfGrid.row`), ``values (N,)`` float32, the grids one after the other."""
        cached = self.__dict__.get("_grid_arrays")
        if cached is not None and cached[0] is self.grids:
            return cached[1]
        if not self.grids:
            out = (np.zeros(0, np.int64), np.zeros((0, 14)), np.zeros(0, np.float32))
        else:
            link_grid = np.full(len(self.links), -1, dtype=np.int64)
            rows, flat, start = [], [], 0
            for name, grid in self.grids.items():
                link_grid[self.links.index(name)] = len(rows)
                rows.append(grid.row(start))
                flat.append(np.ascontiguousarray(grid.values, dtype=np.float32).ravel())
                start += grid.values.size
            out = (link_grid, np.ascontiguousarray(np.stack(rows)), np.ascontiguousarray(np.concatenate(flat)))
        self.__dict__["_grid_arrays"] = (self.grids, out)
        return out

    def __repr__(self) -> str:
        return (
            f"CollisionModel({len(self.links)} links, {len(self.radii)} spheres, {len(self.pairs)} pairs, "
            f"source={self.source!r})"
        )

    # -- pairs --------------------------------------------------------------------
    def with_pairs(self, *, add=(), remove=()) -> CollisionModel:
        """A copy checking also the link pairs ``add`` and not ``remove`` (each a sequence of ``(link, link)``)."""
        current = {tuple(sorted((int(a), int(b)))) for a, b in self.pairs}
        left = dict(self.left_out)
        for names, on in ((add, True), (remove, False)):
            for a, b in names:
                for name in (a, b):
                    if name not in self.links:
                        raise ValueError(f"pair ({a!r}, {b!r}): unknown link {name!r} (links: {', '.join(self.links)})")
                if a == b:
                    raise ValueError(f"pair ({a!r}, {b!r}): a link with itself")
                key = tuple(sorted((self.links.index(a), self.links.index(b))))
                name = "|".join(self.links[k] for k in key)
                if on:
                    current.add(key)
                    left.pop(name, None)
                else:
                    current.discard(key)
                    left[name] = "removed"
        pairs = np.array(sorted(current), dtype=np.int64).reshape(-1, 2)
        copy = CollisionModel(**{**_fields(self), "pairs": pairs, "left_out": left})
        return copy

    # -- files ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "format": COLLISION_FORMAT,
            "robot_hash": self.robot_hash,
            "links": list(self.links),
            "frames": np.asarray(self.frames).tolist(),
            "centers": np.asarray(self.centers).tolist(),
            "radii": np.asarray(self.radii).tolist(),
            "body_start": np.asarray(self.body_start).tolist(),
            "pairs": np.asarray(self.pairs).tolist(),
            "left_out": dict(self.left_out),
            "parents": None if self.parents is None else list(self.parents),
            "gaps": None if self.gaps is None else np.asarray(self.gaps).tolist(),
            "volume_ratios": None if self.volume_ratios is None else np.asarray(self.volume_ratios).tolist(),
            "source": self.source,
            "options": dict(self.options),
            "grids": {name: g.to_dict() for name, g in (self.grids or {}).items()},
        }

    @classmethod
    def from_dict(cls, d: dict, source: str = "collision model") -> CollisionModel:
        try:
            if d.get("format") != COLLISION_FORMAT:
                raise ValueError(f"format {d.get('format')!r}, expected {COLLISION_FORMAT}")
            return cls(
                robot_hash=str(d["robot_hash"]),
                links=list(d["links"]),
                frames=np.asarray(d["frames"], dtype=np.int64),
                centers=np.asarray(d["centers"], dtype=np.float64).reshape(-1, 3),
                radii=np.asarray(d["radii"], dtype=np.float64),
                body_start=np.asarray(d["body_start"], dtype=np.int64),
                pairs=np.asarray(d["pairs"], dtype=np.int64).reshape(-1, 2),
                left_out=dict(d.get("left_out") or {}),
                parents=None if d.get("parents") is None else list(d["parents"]),
                gaps=None if d.get("gaps") is None else np.asarray(d["gaps"], dtype=np.float64),
                volume_ratios=None if d.get("volume_ratios") is None else np.asarray(d["volume_ratios"]),
                source=str(d.get("source", "")),
                options=dict(d.get("options") or {}),
                grids=_grids_from(d.get("grids")),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise ValueError(f"{source}: not a nik collision model ({err})") from None

    def save(self, path: str | Path) -> Path:
        """Write the model as JSON (temporary name, then rename). Returns the path."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(self.to_dict()))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path, robot=None) -> CollisionModel:
        """Read a saved model; with ``robot``, refuse one made for another robot (definition hash)."""
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise ValueError(f"collision model {path}: cannot be read ({err})") from None
        model = cls.from_dict(d, source=f"collision model {path}")
        if robot is not None and model.robot_hash != robot.definition_hash:
            raise ValueError(
                f"collision model {path}: made for robot hash {model.robot_hash}, not {robot.name!r} "
                f"(hash {robot.definition_hash})"
            )
        return model


def _fields(model: CollisionModel) -> dict:
    """The model's fields (not its cached views), for a copy."""
    return {k: v for k, v in model.__dict__.items() if not k.startswith("_")}


def _grids_from(d) -> dict | None:
    if not d:
        return None
    from nik.collision.sdf import SdfGrid

    return {str(name): SdfGrid.from_dict(g) for name, g in d.items()}


# ---------------------------------------------------------------------------
# building
# ---------------------------------------------------------------------------
def link_capsule_bodies(robot, radius) -> list:
    """Bodies (:class:`nik.collision.urdf.Body`) of capsules along the links (module docstring): their segments
    ``(m, 2, 3)`` and ``radius`` (metres; one number, or one per frame: ``dof + 1``)."""
    from nik.collision.urdf import Body

    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (robot.dof + 1,))
    if not (np.isfinite(radii).all() and (radii > 0).all()):
        raise ValueError(f"capsule radius must be positive (metres), got {np.asarray(radius).tolist()}")
    G = robot.G.numpy()
    lim = robot.limits.numpy()
    off = robot.offsets.numpy()
    bodies = []
    for k in range(robot.dof + 1):
        segments = [(np.zeros(3), G[k, :3, 3].copy())]
        if k >= 1 and bool(robot.prismatic[k - 1]):
            lo, hi = lim[k - 1] + off[k - 1]
            segments.append((np.array([0.0, 0.0, min(0.0, -hi)]), np.array([0.0, 0.0, max(0.0, -lo)])))
        bodies.append(Body(f"link{k}", k, np.array(segments), f"link{k - 1}" if k else None, float(radii[k])))
    return bodies


def _capsule_spheres(segments: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Spheres holding capsules ``segments: (m, 2, 3)`` of radius ``r``: spacing ``s = r``, radius
    ``sqrt(r^2 + (s/2)^2)`` (a point of the capsule is within ``r`` of a segment point, which is within ``s/2``
    of a sphere centre on the segment)."""
    centers = []
    for a, b in segments:
        L = float(np.linalg.norm(b - a))
        n = max(1, math.ceil(L / r)) + 1 if L > 0 else 1
        t = np.linspace(0.0, 1.0, n)[:, None]
        centers.append(a + t * (b - a))
    c = np.concatenate(centers)
    s = max((float(np.linalg.norm(b - a)) / max(1, math.ceil(float(np.linalg.norm(b - a)) / r))) for a, b in segments)
    return c, np.full(len(c), math.sqrt(r * r + (s / 2) ** 2))


def _urdf_of(robot) -> Path | None:
    src = getattr(robot, "source", None)
    if not src:
        return None
    p = Path(src)
    if p.suffix.lower() == ".urdf":
        return p if p.is_file() else None
    if p.suffix.lower() in (".yaml", ".yml") and p.is_file():
        import yaml

        with contextlib.suppress(Exception):
            data = yaml.safe_load(p.read_text())
            if isinstance(data, dict) and data.get("urdf"):
                u = Path(data["urdf"])
                u = u if u.is_absolute() else p.parent / u
                return u if u.is_file() else None
    return None


def model_source_is_urdf(robot, source) -> bool:
    """True when :func:`collision_model` fits the URDF's geometry (not capsules) for these arguments."""
    urdf = _urdf_of(robot)
    return source in (None, "urdf") and urdf is not None and _has_collision(urdf)


def _has_collision(path: Path) -> bool:
    return b"<collision" in path.read_bytes()


def _bodies_and_spheres(robot, source, radius, tolerance, max_spheres, seed, progress=None):
    urdf = _urdf_of(robot) if source in (None, "urdf") else None
    if source == "urdf" and (urdf is None or not _has_collision(urdf)):
        raise ValueError(f"robot {robot.name!r}: no URDF with <collision> geometry to fit spheres to")
    if urdf is not None and _has_collision(urdf):
        from nik.collision.urdf import urdf_bodies

        bodies = urdf_bodies(robot, urdf)
        fits = []
        for i, b in enumerate(bodies):
            if progress is not None:
                progress.say(f"fitting spheres to link {i + 1} of {len(bodies)} ({b.name})")
            fits.append(_fit_link(b, tolerance, max_spheres, seed))
        spheres = [(f.centers, f.radii) for f in fits]
        return bodies, spheres, [f.gap for f in fits], [f.volume_ratio for f in fits], f"urdf:{urdf}"
    if source not in (None, "capsules"):
        raise ValueError(f"collision source must be 'urdf', 'builtin', 'capsules' or None, got {source!r}")
    bodies = link_capsule_bodies(robot, radius)
    spheres = [_capsule_spheres(b.triangles, b.radius) for b in bodies]
    gaps = [float(r[0] - b.radius) for b, (_, r) in zip(bodies, spheres, strict=True)]
    return bodies, spheres, gaps, [float("nan")] * len(bodies), "capsules"


#: a link on a moving frame whose spheres reach farther than this past its geometry (metres) is fitted again,
#: with :data:`MORE_SPHERES` times the spheres, and the tighter fit kept
GAP_GOAL = 0.02

#: the links on frame 0 (the base's: a torso, a pedestal, a head, the other arm of a two-armed robot placed by
#: ``joint_values``) never move relative to the base, so they may carry this many times ``max_spheres``
STATIC_SPHERES = 16

#: the refit of a moving link over :data:`GAP_GOAL` has this many times the spheres (and twice the candidates)
MORE_SPHERES = 4

#: candidate centres of a fit (:func:`nik.collision.fit.fit_spheres`): a moving link's, a static link's
CANDIDATES = (800, 2000)


def _grid_bound(pitch: float) -> float:
    """:attr:`nik.collision.sdf.SdfGrid.bound` of a grid of ``pitch`` metres."""
    return float(pitch) * (math.sqrt(3) + 2 / 9)


def _fit_link(body, tolerance: float, max_spheres: int, seed: int):
    """The spheres of one URDF body (:func:`nik.collision.fit.fit_spheres`), tightened (choices): a body on frame
    0 (static relative to the base) may use :data:`STATIC_SPHERES` times ``max_spheres`` among
    ``CANDIDATES[1]`` centres (its spheres cost a check only where a moving link comes near: the broad phase skips
    the others; a torso or pedestal of large thin faces needs many); a moving body whose spheres reach more than
    :data:`GAP_GOAL` past it is fitted again with :data:`MORE_SPHERES` times the spheres and twice the candidates,
    the tighter fit kept; one ball around the whole body (:func:`nik.collision.fit.one_sphere`) replaces the fit where
    it reaches less far (a URDF ``<sphere>``, a round head). Every fit is an exact cover, so every choice stays
    conservative; a link still far over
    is named by :func:`_warn_overreach` (over :data:`OVERREACH_WARNING`). ``body``: a
    :class:`nik.collision.urdf.Body` (triangles ``(T, 3, 3)``, metres); returns its
    :class:`nik.collision.fit.SphereFit`."""
    from nik.collision.fit import fit_spheres, one_sphere

    one = one_sphere(body.triangles, seed)
    if body.frame == 0:
        budget = int(max_spheres) * STATIC_SPHERES
        fit = fit_spheres(body.triangles, tolerance=tolerance, max_spheres=budget, seed=seed, candidates=CANDIDATES[1])
        return one if one.gap < fit.gap else fit
    fit = fit_spheres(body.triangles, tolerance=tolerance, max_spheres=max_spheres, seed=seed, candidates=CANDIDATES[0])
    if fit.gap > GAP_GOAL:
        more = fit_spheres(
            body.triangles, tolerance=tolerance, max_spheres=int(max_spheres) * MORE_SPHERES, seed=seed,
            candidates=2 * CANDIDATES[0],
        )  # fmt: skip
        fit = more if more.gap < fit.gap else fit
    return one if one.gap < fit.gap else fit


def find_srdf(urdf: Path | None) -> tuple[Path | None, str]:
    """MoveIt's SRDF for a URDF, searched, and how it was found (one line; empty where there is no URDF).

    Looked at, in order: ``NAME.srdf`` beside the URDF; ``NAME.srdf`` in a ``srdf/`` folder beside it or beside
    the URDF's folder (a ROS description package: ``urdf/NAME.urdf``, ``srdf/NAME.srdf``); else the single
    ``*.srdf`` of such a folder (Baxter's ``srdf/baxter_manipulation.srdf``). A folder holding several others
    is not guessed from: None, and the line names them (pass ``srdf=PATH``)."""
    if urdf is None:
        return None, ""
    folders = [urdf.parent / "srdf", urdf.parent.parent / "srdf"]
    for cand in (urdf.with_suffix(".srdf"), *(f / f"{urdf.stem}.srdf" for f in folders)):
        if cand.is_file():
            return cand, f"SRDF {cand} (named as the URDF)"
    for folder in dict.fromkeys(folders):
        found = sorted(folder.glob("*.srdf")) if folder.is_dir() else []
        if len(found) == 1:
            return found[0], f"SRDF {found[0]} (the only one in {folder})"
        if found:
            names = ", ".join(p.name for p in found)
            return None, f"no SRDF used: {folder} holds several ({names}); pass srdf=PATH to choose one"
    return None, f"no SRDF found beside {urdf}"


def srdf_of(urdf: Path | None) -> Path | None:
    """MoveIt's SRDF for a URDF as :func:`find_srdf` searches for it; None where there is none."""
    return find_srdf(urdf)[0]


def resolve_srdf(robot, srdf, urdf: Path | None) -> Path | None:
    """The SRDF file :func:`collision_model` reads for ``srdf`` (None: the robot's own choice, ``robot.srdf`` as
    :func:`nik.load_robot` set it, default True): a path is that file (missing: a one-line ``ValueError``), True
    the one :func:`find_srdf` finds (logged at INFO on the ``nik.collision`` logger, once per robot and file;
    several candidates and none chosen: a :class:`nik.errors.CollisionModelWarning`), False none."""
    if srdf is None:
        srdf = getattr(robot, "srdf", True)
    if srdf is False or urdf is None:
        if isinstance(srdf, (str, Path)) and urdf is None:
            raise ValueError(f"robot {robot.name!r}: srdf={str(srdf)!r} applies to URDF robots (this one has none)")
        return None
    if srdf is not True:
        path = Path(srdf)
        if not path.is_file():
            raise ValueError(f"SRDF file not found: {path}")
        return path
    path, how = find_srdf(urdf)
    said = robot.__dict__.setdefault("_srdf_said", set())
    if how not in said:
        said.add(how)
        if path is None and "several" in how:
            import warnings

            from nik.errors import CollisionModelWarning

            warnings.warn(f"robot {robot.name!r}: {how}", CollisionModelWarning, stacklevel=3)
        else:
            import logging

            logging.getLogger("nik.collision").info("robot %r: %s", robot.name, how)
    return path


def srdf_disabled(path: Path) -> dict[tuple[str, str], str]:
    """``{(a, b): reason}`` of an SRDF's ``<disable_collisions link1 link2 reason>`` (names sorted per pair)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(path.read_bytes())
    except (OSError, ET.ParseError) as err:
        raise ValueError(f"{path}: not a readable SRDF ({err})") from None
    out = {}
    for el in root.iter("disable_collisions"):
        a, b = el.get("link1"), el.get("link2")
        if a and b:
            out[tuple(sorted((a, b)))] = el.get("reason") or "disabled"
    return out


#: configurations per chunk of the pair sampling (:func:`_pair_rows`)
PAIR_CHUNK = 128


def _pair_rows(robot, model: CollisionModel, Q: np.ndarray, never_clearance, progress=None):
    """The self-collision rows ``(b, P)`` of ``model``'s pairs at ``Q: (B, dof)``, yielded in chunks of
    :data:`PAIR_CHUNK` configurations: exact wherever at most ``max(never_clearance, 0)`` metres, else a lower bound
    above it (the compiled broad phase, :func:`nik.kernels.collision.collision_rows_batch`), which is all the
    "always" (below 0) and "never" (above the clearance) tests read. Memory ``O(PAIR_CHUNK * (P + L))`` whatever
    the spheres' count (no sphere-pair arrays)."""
    from nik.kernels.collision import ArmSpheres, Scene, collision_rows_batch

    G, joints = robot.chain_arrays()  # the arguments of nik.collision.compiled.kernel_arguments, no world
    no_world = Scene(np.zeros((0, 4)), np.zeros((0, 15)), np.zeros((0, 7)))
    rest = (ArmSpheres(*model.arrays(), True, *model.grid_arrays()), no_world)
    cutoff = max(0.0, float(never_clearance)) if never_clearance is not None else 0.0
    P = len(model.pairs)
    for s in range(0, len(Q), PAIR_CHUNK):
        chunk = np.ascontiguousarray(Q[s : s + PAIR_CHUNK], dtype=np.float64)
        D = np.empty((len(chunk), P + len(model.links)))
        collision_rows_batch(G, joints, chunk, *rest, cutoff, D)
        if progress is not None:
            progress.say(f"sampling {len(Q)} configurations for the link pairs: {s + len(chunk)} done")
        yield D[:, :P]


class Progress:
    """One line on stderr now and then for a long build: the first after ``after`` seconds (default
    :data:`PROGRESS_AFTER`), then at most one every ``every`` seconds, and a last one saying the time taken where
    any was printed. ``what`` names the build (``"collision model of 'baxter'"``)."""

    def __init__(self, what: str, after: float | None = None, every: float = 5.0):
        import time

        self._time = time.perf_counter
        self.what, self.after, self.every = what, PROGRESS_AFTER if after is None else after, every
        self.start, self.last, self.said = self._time(), None, False

    def say(self, doing: str) -> None:
        now = self._time()
        if now - self.start < self.after or (self.last is not None and now - self.last < self.every):
            return
        import sys

        self.last, self.said = now, True
        print(f"nik: {self.what}: {doing} ({now - self.start:.0f} s)", file=sys.stderr, flush=True)

    def done(self) -> None:
        if self.said:
            import sys

            print(f"nik: {self.what}: done in {self._time() - self.start:.0f} s", file=sys.stderr, flush=True)


#: seconds a build runs before :class:`Progress` prints its first line
PROGRESS_AFTER = 2.0


def _find_pairs(
    robot, model: CollisionModel, samples: int, never_clearance, seed: int, srdf=None, disabled=None, progress=None
):
    """Active pairs and the reasons of the others (module docstring); ``disabled``: ``{(a, b): reason}`` pairs
    an SRDF disables, given instead of its file ``srdf``. The sampled configurations are streamed in chunks
    through the compiled rows (:func:`_pair_rows`), so the memory is bounded whatever the spheres' count;
    ``progress``: a :class:`Progress` told how far it is."""

    L = len(model.links)
    names = list(model.links)
    frames = np.asarray(model.frames)
    parents = model.parents or [None] * L
    if disabled is None:
        disabled = srdf_disabled(srdf) if srdf is not None else {}
    left, candidates = {}, []
    for a in range(L):
        for b in range(a + 1, L):
            key = f"{names[a]}|{names[b]}"
            declared = disabled.get(tuple(sorted((names[a], names[b]))))
            if frames[a] == frames[b]:
                left[key] = "same frame"
            elif parents[a] == names[b] or parents[b] == names[a]:
                left[key] = "adjacent"
            elif declared is not None:
                left[key] = f"srdf: {declared}"
            else:
                candidates.append((a, b))
    model.pairs = np.array(candidates, dtype=np.int64).reshape(-1, 2)
    model.__dict__.pop("_sphere_pairs", None)
    if len(candidates) and samples > 0:
        g = torch.Generator().manual_seed(seed)
        q = robot.sample(int(samples), generator=g, dtype=torch.float64)
        always = np.ones(len(candidates), bool)
        never = np.full(len(candidates), never_clearance is not None)
        for d in _pair_rows(robot, model, q.numpy(), never_clearance, progress):
            always &= (d < 0).all(axis=0)
            if never_clearance is not None:
                never &= (d > never_clearance).all(axis=0)
        keep = []
        for p, (a, b) in enumerate(candidates):
            key = f"{names[a]}|{names[b]}"
            if always[p]:
                left[key] = "always"
            elif never[p]:
                left[key] = "never"
            else:
                keep.append((a, b))
        model.pairs = np.array(keep, dtype=np.int64).reshape(-1, 2)
        model.__dict__.pop("_sphere_pairs", None)
    model.left_out = left


_DEFAULT_KEY = json.dumps(
    {
        "source": None,
        "radius": 0.05,
        "tolerance": 0.01,
        "max_spheres": 16,
        "samples": 1000,
        "never_clearance": 0.02,
        "srdf": True,
        "seed": 0,
    },
    sort_keys=True,
)


def _cached(path: Path, robot) -> CollisionModel | None:
    if not path.is_file():
        return None
    try:
        return CollisionModel.load(path, robot)
    except ValueError:
        return None


def _store(model: CollisionModel, path: Path) -> None:
    with contextlib.suppress(OSError):
        path.parent.mkdir(parents=True, exist_ok=True)
        model.save(path)


def _static_grids(bodies, gaps, pitch, progress=None) -> dict:
    """``{link: SdfGrid}`` for the URDF bodies on frame 0 whose spheres reach farther past their geometry than a
    grid of ``pitch`` metres may fall short of it (:attr:`nik.collision.sdf.SdfGrid.bound`, its worst cell; None:
    no grids); their ``gaps`` entries become the grid's bound. Such a link keeps its spheres: a pair's row is the
    larger of the spheres' and the grid's (both lower bounds of the distance), so the grid tightens where the
    spheres reach out (large flat faces) and the spheres where they hold the surface closely."""
    from nik.collision.sdf import static_grid

    out = {}
    if pitch is None:
        return out
    bound = _grid_bound(pitch)
    for i, b in enumerate(bodies):
        if b.frame != 0 or b.radius is not None or not gaps[i] > bound:
            continue
        if progress is not None:
            progress.say(f"distance grid of the static link {b.name}")
        out[b.name] = static_grid(b.triangles, pitch)
        gaps[i] = out[b.name].bound
    return out


def _fitted(robot, source, radius, tolerance, max_spheres, seed, progress=None, grid_pitch=None) -> CollisionModel:
    """The spheres of every link (no pairs yet), and the grids of the static links (:func:`_static_grids`)."""
    found = _bodies_and_spheres(robot, source, radius, tolerance, max_spheres, seed, progress)
    bodies, spheres, gaps, ratios, src = found
    gaps = list(gaps)
    grids = _static_grids(bodies, gaps, grid_pitch, progress) if src.startswith("urdf:") else {}
    counts = [len(r) for _, r in spheres]
    return CollisionModel(
        robot_hash=robot.definition_hash,
        links=[b.name for b in bodies],
        frames=np.array([b.frame for b in bodies], dtype=np.int64),
        centers=np.concatenate([c for c, _ in spheres]).reshape(-1, 3),
        radii=np.concatenate([r for _, r in spheres]),
        body_start=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        pairs=np.zeros((0, 2), dtype=np.int64),
        parents=[b.parent for b in bodies],
        gaps=np.asarray(gaps, dtype=float),
        volume_ratios=np.asarray(ratios, dtype=float),
        source=src,
        grids=grids or None,
    )


def _cache_path(key: str) -> Path:
    from nik.kernels.cache import cache_home

    return cache_home() / "collision" / f"{key[:32]}.json"


def _beside(robot) -> Path | None:
    src = getattr(robot, "source", None)
    if not src:
        return None
    p = Path(src)
    return p.with_name(f"{p.stem}.collision.json")


def set_collision_model(robot, model: CollisionModel | None) -> None:
    """Make ``model`` (e.g. one with pairs added or removed, or loaded from a file) the one
    :func:`nik.collision.collision_model` returns for ``robot``; None restores the automatic one. A model made for
    another robot is refused (definition hash)."""
    if model is not None and model.robot_hash != robot.definition_hash:
        raise ValueError(
            f"collision model made for robot hash {model.robot_hash}, not {robot.name!r} (hash {robot.definition_hash})"
        )
    robot.__dict__["_collision_model"] = model


def collision_model(
    robot,
    *,
    source: str | None = None,
    radius=0.05,
    tolerance: float = 0.01,
    max_spheres: int = 16,
    samples: int = 1000,
    never_clearance: float | None = 0.02,
    srdf: bool | str | Path | None = None,
    seed: int = 0,
    cache: bool = True,
    grid_pitch: float | None = GRID_PITCH,
) -> CollisionModel:
    """The collision model of ``robot`` (module docstring), from a file beside the robot's, nik's cache, or built.

    Args:
        source: ``"urdf"`` (fit spheres to the URDF's collision geometry), ``"builtin"`` (the shipped model of a
            built-in arm, :mod:`nik.collision.builtin`), ``"capsules"`` (capsules along the links), or None: the
            URDF's geometry where the robot has it, else (``radius`` not given) the shipped model, else capsules
            (with a :class:`nik.errors.CollisionModelWarning` once per robot, unless ``radius`` is given).
        radius: capsule radius (metres), one or one per frame (``dof + 1``; frame 0 is the base); a value other
            than the default asks for capsules where the robot has no URDF geometry (not the shipped model).
        tolerance: sphere fitting stops once a link's spheres overreach it by at most this (metres).
        max_spheres: spheres per link: at most this many on a moving link (:data:`MORE_SPHERES` times as many
            where those reach more than :data:`GAP_GOAL` past it), :data:`STATIC_SPHERES` times as many on a link
            of frame 0 (:func:`_fit_link`).
        samples: configurations sampled to find the pairs that always / never touch (0: keep all pairs
            but the same-frame and adjacent ones).
        never_clearance: a pair never closer than this (metres) in every sample is left out; None keeps them.
        srdf: MoveIt's SRDF of a URDF robot, whose disabled link pairs are left out (reason ``"srdf: Default"``,
            ...), as MoveIt would: a path (that file), True (search beside the URDF, :func:`find_srdf`; the file
            used is logged at INFO on the ``nik.collision`` logger), False (none), or None (default: the robot's
            own, ``load_robot(..., srdf=)``, True unless given). The file used is ``model.options["srdf_file"]``.

    The joints outside the robot's chain stand where ``load_robot(..., joint_values=)`` put them (default 0, or
    the middle of their range where 0 is outside it): the links they carry are fitted there, and the model's
    cache key holds those values.
        seed: seed of the fitting and the sampling.
        cache: read and write nik's cache folder.
        grid_pitch: the static links of a URDF (frame 0: a torso, a pedestal, the rest of the robot placed by
            ``joint_values=``) whose spheres reach farther past their geometry than a grid of this pitch (metres)
            may fall short of it also get a grid of signed distances (:mod:`nik.collision.sdf`,
            :attr:`CollisionModel.grids`): their pairs' rows are the larger of the spheres' and the grid's. None:
            spheres only.
    """
    options = {
        "source": source,
        "radius": np.asarray(radius, dtype=float).tolist(),
        "tolerance": float(tolerance),
        "max_spheres": int(max_spheres),
        "samples": int(samples),
        "never_clearance": never_clearance,
        "srdf": _srdf_choice(robot, srdf),
        "seed": int(seed),
    }
    if grid_pitch != GRID_PITCH:
        options["grid_pitch"] = None if grid_pitch is None else float(grid_pitch)
    from nik.collision.urdf import placed_values

    placed = placed_values(robot)
    if placed:
        options["joint_values"] = placed
    memo = robot.__dict__.setdefault("_collision_models", {})
    memo_key = json.dumps(options, sort_keys=True)
    plain = {k: v for k, v in options.items() if k != "joint_values"}
    if (
        srdf in (None, True)
        and json.dumps({**plain, "srdf": True}, sort_keys=True) == _DEFAULT_KEY
        and robot.__dict__.get("_collision_model") is not None
    ):
        return robot.__dict__["_collision_model"]
    if memo_key in memo:
        return memo[memo_key]
    beside = _beside(robot)
    if cache and beside is not None and beside.is_file():
        model = CollisionModel.load(beside, robot)
        memo[memo_key] = model
        return model
    radii_given = options["radius"] != 0.05  # capsules of the radii given, where the robot has no URDF geometry
    if (source == "builtin" or (source is None and not radii_given)) and not model_source_is_urdf(robot, None):
        if not isinstance(options["srdf"], bool):
            raise ValueError(
                f"robot {robot.name!r}: srdf={options['srdf']!r} applies to URDF robots (this one has none)"
            )
        shipped = _builtin(robot, source, samples, never_clearance, options["srdf"], seed)
        if shipped is not None:
            memo[memo_key] = shipped
            return shipped
    urdf = _urdf_of(robot)
    fit_options = {k: options[k] for k in ("source", "radius", "tolerance", "max_spheres", "seed", "joint_values",
                                           "grid_pitch") if k in options}  # fmt: skip
    key = f"{robot.definition_hash}|{json.dumps(fit_options, sort_keys=True)}|{COLLISION_FORMAT}|fit {FIT_VERSION}"
    h = hashlib.sha256(key.encode())
    if urdf is not None:
        h.update(urdf.read_bytes())
        if model_source_is_urdf(robot, source):  # the meshes found (or not) the same way, cache warm or cold
            from nik.collision.urdf import collision_mesh_files

            for mesh in collision_mesh_files(urdf):
                h.update(f"|{mesh.resolve()}:{mesh.stat().st_size}".encode())
    fit_path = _cache_path("spheres-" + h.hexdigest())
    srdf_path = resolve_srdf(robot, options["srdf"], urdf) if model_source_is_urdf(robot, source) else None
    options["srdf_file"] = None if srdf_path is None else str(srdf_path)
    h.update(memo_key.encode())
    if srdf_path is not None:
        h.update(srdf_path.read_bytes())
    path = _cache_path(h.hexdigest())
    model = _cached(path, robot) if cache else None
    if model is None:
        progress = Progress(f"collision model of {robot.name!r}")
        spheres = _cached(fit_path, robot) if cache else None
        if spheres is None:
            spheres = _fitted(robot, source, radius, tolerance, max_spheres, seed, progress, grid_pitch)
            if cache:
                _store(spheres, fit_path)
        model = CollisionModel(**{**_fields(spheres), "options": options})
        model.__dict__.pop("_sphere_pairs", None)
        _find_pairs(robot, model, samples, never_clearance, seed, srdf_path, progress=progress)
        if cache:
            _store(model, path)
        progress.done()
    if model.source == "capsules" and source is None and not radii_given:
        _warn_capsules(robot, radius)
    _warn_overreach(robot, model)
    memo[memo_key] = model
    return model


#: a fitted link whose spheres reach farther than this past its geometry (metres) is named in a warning: sphere
#: models reach 2-3 cm past flat faces and sharp edges at the default tolerance (the panda's links 16-34 mm), so
#: this flags the links fitted badly (a torso or pedestal of a few large faces), not the usual overreach
OVERREACH_WARNING = 0.05


def _warn_overreach(robot, model: CollisionModel) -> None:
    """Say once per robot and model which fitted links overreach their geometry by more than
    :data:`OVERREACH_WARNING`, with the figures (a :class:`nik.errors.CollisionModelWarning`)."""
    if model.gaps is None or not model.source.startswith("urdf:"):
        return
    over = sorted(
        ((float(g), name) for name, g in zip(model.links, model.gaps, strict=True) if g > OVERREACH_WARNING),
        reverse=True,
    )
    said = robot.__dict__.setdefault("_overreach_said", set())
    key = (model.source, tuple(over))
    if not over or key in said:
        return
    said.add(key)
    import warnings

    from nik.errors import CollisionModelWarning

    figures = ", ".join(f"{name} {1000 * g:.0f} mm" for g, name in over)
    warnings.warn(
        f"robot {robot.name!r}: the collision spheres of {len(over)} link(s) reach more than "
        f"{1000 * OVERREACH_WARNING:.0f} mm past their meshes ({figures}): configurations near them are called "
        "colliding when the meshes are free; the mesh verdict (IKSolver's default with coal) judges answers on the "
        "meshes, and collision_model(robot, max_spheres=..., tolerance=...) or a model file tightens them",
        CollisionModelWarning,
        stacklevel=3,
    )


def _srdf_choice(robot, srdf) -> bool | str:
    """``srdf`` (None: the robot's own, ``robot.srdf``) as the model's options record it: a bool or a path."""
    if srdf is None:
        srdf = getattr(robot, "srdf", True)
    if isinstance(srdf, bool):
        return srdf
    if isinstance(srdf, (str, Path)):
        return str(srdf)
    raise ValueError(f"srdf must be True, False or a path, got {type(srdf).__name__}")


def _builtin(robot, source, samples, never_clearance, srdf, seed) -> CollisionModel | None:
    """The shipped model of a built-in arm (:mod:`nik.collision.builtin`), its pairs found again where the pair
    options are not the defaults it was shipped with; None where there is none (an error for ``"builtin"``)."""
    from nik.collision.builtin import CHECKSUMS, MODEL_DIR, builtin_model_data

    found = builtin_model_data(robot)
    if found is None:
        if source == "builtin":
            raise ValueError(
                f"robot {robot.name!r}: no shipped collision model (the built-ins with one: {', '.join(CHECKSUMS)})"
            )
        return None
    name, data = found
    model = CollisionModel.from_dict(data, source=f"shipped collision model {MODEL_DIR / name}.collision.json")
    model.robot_hash = robot.definition_hash
    model.options = {**model.options, "builtin": name}
    if robot.base is not None:  # nik's frame 0 is the world's: the base link's spheres ride on the base
        B = robot.base.numpy().astype(np.float64)
        on_base = model.sphere_frame == 0
        model.centers[on_base] = model.centers[on_base] @ B[:3, :3].T + B[:3, 3]
    if (samples, never_clearance, srdf, seed) == (1000, 0.02, True, 0):
        return model
    disabled = {
        tuple(sorted(k.split("|"))): why[len("srdf: ") :]
        for k, why in model.left_out.items()
        if srdf and why.startswith("srdf: ")
    }
    copy = CollisionModel(**{**_fields(model), "options": {**model.options, "samples": samples, "srdf": srdf}})
    copy.options.update(never_clearance=never_clearance, seed=seed)
    copy.__dict__.pop("_sphere_pairs", None)
    _find_pairs(robot, copy, samples, never_clearance, seed, disabled=disabled)
    return copy


def _warn_capsules(robot, radius) -> None:
    """Say once per robot that its collision model is capsules, an approximation, and how to give better."""
    if robot.__dict__.get("_capsules_warned"):
        return
    robot.__dict__["_capsules_warned"] = True
    import warnings

    from nik.errors import CollisionModelWarning

    r = np.asarray(radius, dtype=float)
    size = f"{1000 * float(r):.0f} mm" if r.ndim == 0 else "the given radii"
    warnings.warn(
        f"robot {robot.name!r}: no collision meshes, so its collision model is capsules of {size} along the links, "
        "an approximation that may call colliding configurations free; give radii "
        "(nik.collision.collision_model(robot, radius=[one per frame, metres]) passed to "
        "nik.collision.set_collision_model) or meshes (load the arm from a URDF with <collision> geometry, or put "
        f"a {Path(robot.source).stem if robot.source else robot.name}.collision.json beside its file)",
        CollisionModelWarning,
        stacklevel=3,
    )
