"""The independent check: a URDF's real collision meshes tested by coal (hpp-fcl's successor), an optional extra.

:class:`MeshCheck` places every link's collision geometry (:func:`nik.collision.urdf.urdf_bodies`; meshes as
they are, curved primitives by the polyhedra around them) with nik's frames and asks coal, pair by pair and
against the world's spheres, boxes and capsules, whether anything overlaps; a broad phase first (a sphere around
each link's mesh and each obstacle) leaves out the pairs too far apart to touch, so coal is asked about a few pairs
of a configuration, not every one. It shares no distance code with the sphere model, so tests and
``benchmarks/collisions.py`` compare the two verdicts. ``pip install
'nik-ik[collision-check]'`` (coal); without it, constructing one is a one-line ``ImportError``.

:func:`mesh_check` is the one the solver's mesh verdict uses (``IKSolver(mesh_verdict=)``, :mod:`nik.ik.collide`):
the meshes of the URDF named, else of the URDF the sphere model was fitted to (its ``source``, ``"urdf:PATH"``:
where a shipped model names its vendor's URDF, that one), else of the robot's own URDF; the pairs the model leaves
out by decision (same frame, adjacent, the SRDF's, always touching, removed) are left out, the ones it left out by
sampling ("never") are checked.

:func:`spheres_cover` says when the sphere model's "free" is already the meshes' "free" (every surface triangle a
fit sees lies inside one of its link's spheres: :mod:`nik.collision.fit`), so that the verdict need only ask coal
about what the spheres call colliding (:class:`nik.ik.collide.Setup`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["MeshCheck", "fitted_urdf", "mesh_check", "mesh_urdf", "spheres_cover"]


class MeshCheck:
    """Mesh-level collision verdicts for ``robot`` (loaded from the URDF ``urdf``).

    Attributes:
        urdf: the URDF the meshes come from.
        links: link names with geometry.
        frames: nik's frame of each link.
        pairs: ``(a, b)`` index pairs checked: every pair but links on the same frame, adjacent links (parent
            and child) and the ``skip`` pairs of link names (e.g. those an SRDF disables), as nik's model before
            sampling; :meth:`drop_always` removes the pairs in contact in every configuration given.
    """

    def __init__(self, robot, urdf, *, skip=()):
        try:
            import coal
        except ImportError as err:
            raise ImportError("the mesh check needs coal: pip install 'nik-ik[collision-check]'") from err
        from nik.collision.urdf import urdf_bodies

        skip = {tuple(sorted(p)) for p in skip}

        self._coal = coal
        self.robot = robot
        self.urdf = Path(urdf)
        bodies = urdf_bodies(robot, urdf)
        self.links = [b.name for b in bodies]
        self.frames = [b.frame for b in bodies]
        self._geoms, self._bounds = [], []  # each link's mesh, and a sphere around it (its frame: centre, radius)
        for b in bodies:
            v = b.triangles.reshape(-1, 3)
            f = np.arange(len(v), dtype=np.int64).reshape(-1, 3)
            m = coal.BVHModelOBBRSS()
            m.beginModel(len(f), len(v))
            m.addVertices(v)
            m.addTriangles(f)
            m.endModel()
            self._geoms.append(m)
            c = (v.min(0) + v.max(0)) / 2 if len(v) else np.zeros(3)
            self._bounds.append((c, float(np.sqrt(((v - c) ** 2).sum(1).max())) if len(v) else 0.0))
        self.pairs = [
            (a, b)
            for a in range(len(bodies))
            for b in range(a + 1, len(bodies))
            if bodies[a].frame != bodies[b].frame
            and bodies[a].parent != bodies[b].name
            and bodies[b].parent != bodies[a].name
            and tuple(sorted((bodies[a].name, bodies[b].name))) not in skip
        ]

    def _transforms(self, q):
        from nik.collision.urdf import frames_at

        F = frames_at(self.robot, np.asarray(q, dtype=np.float64))
        return [self._coal.Transform3s(F[k][:3, :3].copy(), F[k][:3, 3].copy()) for k in self.frames]

    def _broad(self, obstacles):
        """The fixed arrays of :meth:`_near` for ``obstacles`` (:meth:`_world_geoms`): the link spheres' centres in
        their frames and radii, the checked pairs' index arrays, the obstacles' centres and radii."""
        local = np.array([c for c, _ in self._bounds]).reshape(-1, 3)
        radius = np.array([r for _, r in self._bounds])
        pa = np.array([a for a, _ in self.pairs], dtype=np.int64)
        pb = np.array([b for _, b in self.pairs], dtype=np.int64)
        oc = np.array([np.asarray(ot.getTranslation()) for _, ot, _ in obstacles]).reshape(-1, 3)
        orot = np.array([np.asarray(ot.getRotation()) for _, ot, _ in obstacles]).reshape(-1, 3, 3)
        shape = np.array([_core(og) for og, _, _ in obstacles]).reshape(-1, 4)  # half extents and rounding
        moving = np.array([f > 0 for f in self.frames], dtype=bool)
        return local, radius, pa, pb, (oc, orot, shape), moving

    def _near(self, tf, broad) -> tuple[np.ndarray, list]:
        """The broad phase for one configuration placed by ``tf`` (``broad``: :meth:`_broad`): ``(pairs, links)``,
        the indices into :attr:`pairs` whose links' bounding spheres overlap and the ``(link, obstacle)`` index pairs
        whose link's bounding sphere reaches the obstacle (its exact distance from the sphere's centre: a sphere,
        a box, a capsule; the fixed base never: as nik's model): the only ones that can touch, so the only ones coal
        is asked about."""
        local, radius, pa, pb, (oc, orot, shape), moving = broad
        R = np.array([t.getRotation() for t in tf])
        centre = np.einsum("kij,kj->ki", R, local) + np.array([t.getTranslation() for t in tf])
        gap = np.sqrt(((centre[pa] - centre[pb]) ** 2).sum(1)) - radius[pa] - radius[pb]
        pairs = np.flatnonzero(gap <= 0.0)
        links = []
        if len(oc):
            gap = ball_obstacle_gap(centre[:, None, :], radius[:, None], (oc, orot, shape))  # (links, obstacles)
            links = list(zip(*np.nonzero((gap <= 0.0) & moving[:, None]), strict=True))
        return pairs, links

    def _hit(self, g1, t1, g2, t2) -> bool:
        res = self._coal.CollisionResult()
        return bool(self._coal.collide(g1, t1, g2, t2, self._coal.CollisionRequest(), res))

    def colliding_pairs(self, q) -> np.ndarray:
        """``(len(pairs),)`` bool for one configuration ``q: (dof,)``."""
        tf = self._transforms(q)
        return np.array([self._hit(self._geoms[a], tf[a], self._geoms[b], tf[b]) for a, b in self.pairs], dtype=bool)

    def drop_always(self, Q) -> list[tuple[str, str]]:
        """Stop checking the pairs in contact in every configuration of ``Q: (B, dof)``; returns their names."""
        hits = np.array([self.colliding_pairs(q) for q in Q])
        always = hits.all(axis=0) if len(hits) else np.zeros(len(self.pairs), bool)
        dropped = [(self.links[a], self.links[b]) for (a, b), x in zip(self.pairs, always, strict=True) if x]
        self.pairs = [p for p, x in zip(self.pairs, always, strict=True) if not x]
        return dropped

    def _world_geoms(self, world):
        """``[(geometry, transform, name)]`` of the world's obstacles, named as
        :func:`nik.collision.collision_names` names them (``"box 2"``)."""
        coal = self._coal
        out = []
        spheres, boxes, caps = world.packed()
        for i, s in enumerate(spheres):
            out.append((coal.Sphere(float(s[3])), coal.Transform3s(np.eye(3), s[:3].copy()), f"sphere {i}"))
        for i, b in enumerate(boxes):
            T = coal.Transform3s(b[:9].reshape(3, 3).copy(), b[9:12].copy())
            out.append((coal.Box(*(2 * b[12:15])), T, f"box {i}"))
        for i, c in enumerate(caps):
            a, e, r = c[:3], c[3:6], float(c[6])
            axis = e - a
            L = float(np.linalg.norm(axis))
            z = axis / L if L > 0 else np.array([0.0, 0.0, 1.0])
            h = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            x = np.cross(h, z)
            x /= np.linalg.norm(x)
            R = np.stack([x, np.cross(z, x), z], axis=1)
            out.append((coal.Capsule(r, L), coal.Transform3s(R, (a + e) / 2), f"capsule {i}"))
        return out

    def collides(self, Q, world=None, *, self_collision: bool = True) -> np.ndarray:
        """``(B,)`` bool for ``Q: (B, dof)``: some checked pair, or some link and an obstacle, overlap."""
        Q = np.asarray(Q, dtype=np.float64).reshape(-1, self.robot.dof)
        obstacles = self._world_geoms(world) if world is not None else []
        out = np.zeros(len(Q), dtype=bool)
        broad = self._broad(obstacles)
        for i, q in enumerate(Q):
            tf = self._transforms(q)
            pairs, links = self._near(tf, broad)
            hit = self_collision and any(self._hit(self._geoms[a], tf[a], self._geoms[b], tf[b])
                                         for a, b in (self.pairs[j] for j in pairs))  # fmt: skip
            if not hit:
                hit = any(self._hit(self._geoms[k], tf[k], *obstacles[o][:2]) for k, o in links)
            out[i] = hit
        return out

    def collision_names(self, Q, world=None, *, self_collision: bool = True) -> list[list[str] | None]:
        """Per configuration of ``Q: (B, dof)``, the sorted names of the overlapping pairs (``"a|b"``) and links and
        obstacles (``"link|box 2"``), as :func:`nik.collision.collision_names` names them; None where none."""
        Q = np.asarray(Q, dtype=np.float64).reshape(-1, self.robot.dof)
        obstacles = self._world_geoms(world) if world is not None else []
        out = []
        broad = self._broad(obstacles)
        for q in Q:
            tf = self._transforms(q)
            pairs, links = self._near(tf, broad)
            names = [f"{self.links[a]}|{self.links[b]}" for a, b in (self.pairs[j] for j in pairs) if self_collision
                     and self._hit(self._geoms[a], tf[a], self._geoms[b], tf[b])]  # fmt: skip
            names += [f"{self.links[k]}|{obstacles[o][2]}" for k, o in links
                      if self._hit(self._geoms[k], tf[k], *obstacles[o][:2])]  # fmt: skip
            out.append(sorted(names) or None)
        return out


def ball_obstacle_gap(centre: np.ndarray, radius: np.ndarray, obstacles) -> np.ndarray:
    """The exact gap between balls ``(centre (..., 3), radius (...))`` and obstacles ``(origin (..., 3), rotation
    (..., 3, 3), core (..., 4))`` (:func:`_core`), shapes broadcast together: ``|max(|R^T (c - o)| - h, 0)| - r -
    radius`` metres (negative where they overlap)."""
    origin, rot, core = obstacles
    p = np.abs(np.einsum("...ji,...j->...i", rot, centre - origin))  # the centre in the obstacle's frame
    return np.linalg.norm(np.maximum(p - core[..., :3], 0.0), axis=-1) - core[..., 3] - radius


def _core(geom) -> tuple[float, float, float, float]:
    """``(hx, hy, hz, r)``: the obstacle ``geom`` (coal's Sphere, Box or Capsule, centred on its transform) as the
    points within ``r`` of the box of half extents ``h`` in its frame, so that a point's distance to it is
    ``|max(|p| - h, 0)| - r`` (a sphere: ``h = 0``; a box: ``r = 0``; a capsule: ``h = (0, 0, half length)``);
    anything else: everywhere (``r`` infinite)."""
    name = type(geom).__name__
    if name == "Sphere":
        return 0.0, 0.0, 0.0, float(geom.radius)
    if name == "Box":
        hx, hy, hz = (float(x) for x in np.asarray(geom.halfSide).reshape(3))
        return hx, hy, hz, 0.0
    if name == "Capsule":
        return 0.0, 0.0, float(geom.halfLength), float(geom.radius)
    return 0.0, 0.0, 0.0, float("inf")


def fitted_urdf(model) -> Path | None:
    """The URDF ``model``'s spheres were fitted to, from its ``source``: ``"urdf:PATH"``, or
    ``"example-robot-data:REL"`` (a shipped model, :func:`nik.collision.builtin.erd_path`); None for any other source
    (capsules, radii given by the user) or where the file is missing."""
    source = model.source
    if source.startswith("urdf:"):
        path = Path(source[len("urdf:") :])
    elif source.startswith("example-robot-data:"):  # a shipped model (nik.collision.builtin)
        from nik.collision.builtin import erd_path

        path = erd_path(source[len("example-robot-data:") :])
    else:
        return None
    return path if path is not None and path.is_file() else None


def spheres_cover(model, mesh: MeshCheck) -> bool:
    """Whether ``model``'s spheres cover ``mesh``'s meshes on the pairs ``mesh`` checks, so that a configuration the
    spheres call free (margin 0) is free on the meshes, and coal need only judge the ones they call colliding.

    The conditions (all, checked once per pair of model and check, memoised on ``mesh``):

    - the spheres were fitted to the very file whose meshes judge: ``model.source`` (:func:`fitted_urdf`) resolves
      to ``mesh.urdf``. A fit is an exact surface cover (:mod:`nik.collision.fit`: every surface triangle of a link,
      curved primitives as the polyhedra :class:`MeshCheck` tests too, lies inside one of its spheres; the shipped
      models' centres rounded with radii grown to match), so where no two spheres of a checked pair overlap no two
      triangles do, and where no sphere reaches an obstacle no triangle does (coal tests mesh surfaces, as the
      cover promises). Another URDF (given explicitly), capsules or radii given by the user promise nothing: every
      answer is judged by coal;
    - no pair left out by sampling: no ``"never"`` in ``model.left_out`` (the meshes check those pairs, the spheres
      do not);
    - (defensive, what the first two imply for a fit of this robot) every link ``mesh`` tests is one of the model's,
      on the same frame, and every pair ``mesh`` checks is one of the model's.

    The model's ``source`` is trusted: a model file edited by hand after its fit is not detected."""
    memo = mesh.__dict__.setdefault("_covers", {})
    got = memo.get(id(model))
    if got is not None and got[0] is model:  # the model kept alive beside its answer: an id is not reused
        return got[1]
    memo[id(model)] = (model, _covers(model, mesh))
    return memo[id(model)][1]


def _covers(model, mesh: MeshCheck) -> bool:
    """:func:`spheres_cover`'s conditions, computed."""
    fitted = fitted_urdf(model)
    if fitted is None or fitted.resolve() != mesh.urdf.resolve():
        return False
    if any(why == "never" for why in model.left_out.values()):
        return False
    frame = {name: int(f) for name, f in zip(model.links, model.frames, strict=True)}
    if any(frame.get(name) != int(f) for name, f in zip(mesh.links, mesh.frames, strict=True)):
        return False
    pairs = {tuple(sorted(p)) for p in model.pair_names()}
    return all(tuple(sorted((mesh.links[a], mesh.links[b]))) in pairs for a, b in mesh.pairs)


def mesh_urdf(robot, model, urdf=None) -> Path | None:
    """The URDF whose collision meshes judge ``robot``'s answers (module docstring), or None where there is none."""
    from nik.collision.model import _has_collision, _urdf_of

    if urdf is not None:
        path = Path(urdf)
        if not path.is_file() or not _has_collision(path):
            raise ValueError(f"mesh verdict: {path} is not a URDF file with <collision> geometry")
        return path
    for path in (fitted_urdf(model), _urdf_of(robot)):
        if path is not None and path.is_file() and _has_collision(path):
            return path
    return None


def mesh_check(robot, model, urdf=None, *, required: bool = False) -> MeshCheck | None:
    """The :class:`MeshCheck` of ``robot`` with the pairs of ``model`` (module docstring), cached per robot; None
    where coal or the meshes are missing (``required``: a one-line ``ImportError`` / ``ValueError`` instead).

    A check found is also kept per model and ``urdf`` argument, so a solve with a mesh verdict does not look for the
    URDF again (resolving its path and reading its files took ~120 us a call); a missing one is looked for each
    call (coal or the meshes may be installed meanwhile)."""
    fast, fast_key = robot.__dict__.setdefault("_mesh_check_of", {}), (id(model), None if urdf is None else str(urdf))
    got = fast.get(fast_key)
    if got is not None and got[0] is model:  # the model held beside its check: its id is not reused
        return got[1]
    path = mesh_urdf(robot, model, urdf)
    if path is None:
        if required:
            raise ValueError(f"mesh verdict: robot {robot.name!r} has no URDF with collision meshes (name one)")
        return None
    skip = tuple(sorted(tuple(k.split("|")) for k, why in model.left_out.items() if why != "never"))
    key = (str(path.resolve()), skip)
    memo = robot.__dict__.setdefault("_mesh_checks", {})
    if key not in memo:
        try:
            memo[key] = MeshCheck(robot, path, skip=skip)
        except ImportError:
            if required:
                raise
            return None
    fast[fast_key] = (model, memo[key])
    return memo[key]
