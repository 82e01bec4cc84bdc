"""Which collision check a call of the collision stage uses (:func:`setup`: the arm's model, the world, the
self-collision rule, the meshes that judge) and the stage's settings (:class:`CollideCfg`); the package
docstring (:mod:`nik.ik.collide`) says the rules."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class CollideCfg:
    """Settings of the collision stage (:mod:`nik.kernels.collision_lm` says how each is used).

    ``margin`` (m): the clearance the collision rows ask for; ``weight``: of the collision rows against the pose
    rows; ``iters`` / ``stall_iters``: per start (a start ends after ``stall_iters`` iterations in a row that lower
    its sum by less than 0.1 %); ``restarts``: uniform starts per target; ``tries``: draws per start (the free draw
    nearest the pose is kept); ``patience``: end a target's uniform restarts after that many in a row that do not
    lower its best sum by 1 % (0: off); ``finish``: iterations of the finishing step (a start at the pose that
    overlaps by less than the tolerance can move the hand within it; 0: off); ``descents``: the uniform restarts
    the collision LM runs from, ranked by their starting sum (further ones only where nearly free; <= 0: all);
    ``converged`` / ``converged_given``: a descent ends at a kept step that lowers its sum by less than that
    fraction of it (the answer and the restarts / the other given starts; 0: off); ``mesh_steer``: where the
    meshes judge and the spheres' re-solve found no free answer, solve on with the mesh rows
    (:mod:`nik.ik.collide.mesh_step`).

    The defaults were chosen on the built-in panda's scenes (``benchmarks/collision_speed.py``,
    ``benchmarks/collision_lm_ab.py``): each saves iterations without losing a target there. Fewer ``restarts``
    trade success on the hardest targets for time; a tighter ``stall_iters`` (3) or ``converged`` (3e-3) saves
    more iterations but moves some re-solved answers to another local minimum."""

    margin: float = 0.005
    weight: float = 1.0
    iters: int = 30
    stall_iters: int = 4
    restarts: int = 16
    tries: int = 16
    patience: int = 0
    finish: int = 10
    descents: int = 4
    converged: float = 2e-3
    converged_given: float = 2e-2
    mesh_steer: bool = True


@dataclass(frozen=True)
class Setup:
    """The collision check of one call: the arm's ``model``, the ``world`` (None: self only), ``self_on``, the
    ``mesh`` check that judges (a :class:`nik.collision.meshcheck.MeshCheck`; None: the spheres judge) and
    ``covered``: the spheres cover those meshes on the pairs they check
    (:func:`nik.collision.meshcheck.spheres_cover`), so a configuration the spheres call free is free on the meshes
    and coal judges only the ones they call colliding."""

    model: object
    world: object
    self_on: bool
    mesh: object = None
    covered: bool = False

    def spheres(self, robot, q: np.ndarray) -> np.ndarray:
        """``(B,)`` bool, the sphere check of ``q: (B, dof)`` (:func:`nik.kernels.collision.collides_batch`, margin
        0), whoever judges."""
        from nik.kernels.collision import collides_batch

        (G, joints), rest = self.arguments(robot)
        hit = np.empty(len(q), dtype=bool)
        collides_batch(G, joints, np.ascontiguousarray(q, dtype=np.float64), *rest, 0.0, hit)
        return hit

    def steering(self, robot, q: np.ndarray) -> np.ndarray:
        """``(B,)`` bool, the check :func:`resolve` solves again by: the spheres', unless the meshes judge and the
        spheres do not cover them (then the meshes': only what collides on them is solved again)."""
        if self.mesh is not None and not self.covered:
            return self.mesh.collides(q, self.world, self_collision=self.self_on)
        return self.spheres(robot, q)

    def judge(self, robot, q: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """``(B,)`` bool, the verdict for ``q: (B, dof)`` given ``hit``, :meth:`steering`'s for it: the meshes' on
        the rows ``hit`` calls colliding where the spheres cover them (the others are free on the meshes), else
        ``hit`` itself (a copy)."""
        hit = np.array(hit, dtype=bool)
        if self.mesh is not None and self.covered and hit.any():
            hit[hit] = self.mesh.collides(np.asarray(q)[hit], self.world, self_collision=self.self_on)
        return hit

    def colliding(self, robot, q: np.ndarray) -> np.ndarray:
        """``(B,)`` bool, the verdict for ``q: (B, dof)``: the meshes' where they judge (coal asked only about the
        configurations the spheres call colliding where the spheres cover the meshes), else the spheres'."""
        return self.judge(robot, q, self.steering(robot, q))

    def names(self, robot, q: np.ndarray) -> list:
        """What overlaps in each of ``q: (B, dof)`` (:func:`nik.collision.collision_names`), by the verdict's check
        (where the spheres cover the meshes, coal names only the rows the spheres call colliding; the rest None)."""
        if self.mesh is None:
            from nik.collision.compiled import collision_names_compiled

            return collision_names_compiled(robot, q, self.world, model=self.model, self_collision=self.self_on)
        q = np.asarray(q, dtype=np.float64).reshape(-1, robot.dof)
        rows = np.flatnonzero(self.spheres(robot, q)) if self.covered else np.arange(len(q))
        out = [None] * len(q)
        if rows.size:
            for i, names in zip(rows, self.mesh.collision_names(q[rows], self.world, self_collision=self.self_on),
                                strict=True):  # fmt: skip
                out[i] = names
        return out

    def arguments(self, robot):
        """``(G, joints), rest``: :func:`nik.collision.compiled.kernel_arguments`, built once per call's check (the
        stage asks for them at each step: 20-50 us a time) and again only after the world changed."""
        from nik.collision.compiled import kernel_arguments

        version = None if self.world is None else self.world.version
        got = self.__dict__.get("_arguments")  # a frozen dataclass: the memo lives in the instance's dict
        if got is None or got[0] is not robot or got[1] != version:
            got = (robot, version, kernel_arguments(robot, self.model, self.world, self_collision=self.self_on))
            self.__dict__["_arguments"] = got
        return got[2]


def attached_model(robot):
    """The collision model attached to ``robot`` (set by the user, or a ``NAME.collision.json`` beside its file),
    else None; never fits one. The file beside the robot's is looked for once per robot (not on every solve: a
    file system call costs more than a pose); one written later is attached by
    :func:`nik.collision.set_collision_model` or by loading the robot again."""
    model = robot.__dict__.get("_collision_model")
    if model is not None:
        return model
    found = robot.__dict__.get("_collision_beside")
    if found is None:
        from nik.collision.model import _beside

        beside = _beside(robot)
        found = robot.__dict__["_collision_beside"] = beside is not None and beside.is_file()
    if not found:
        return None
    from nik.collision.model import collision_model

    return collision_model(robot)


def has_attached(robot) -> bool:
    """Whether ``robot`` has a collision model attached (:func:`attached_model`), told without loading it."""
    d = robot.__dict__
    if d.get("_collision_model") is not None:
        return True
    found = d.get("_collision_beside")
    return attached_model(robot) is not None if found is None else found


def check_self_collision(value):
    """``value`` when it is None, True or False (one line otherwise)."""
    if value is not None and not isinstance(value, bool):
        raise ValueError(f"IKSolver: self_collision must be None, True or False, got {value!r}")
    return value


def check_mesh_verdict(value):
    """``value`` when it is True, False, ``"auto"`` or a URDF path (one line otherwise)."""
    from pathlib import Path

    if isinstance(value, bool) or value == "auto" or isinstance(value, str | Path) and Path(value).suffix == ".urdf":
        return value
    raise ValueError(f"IKSolver: mesh_verdict must be True, False, 'auto' or a URDF path, got {value!r}")


def setup(robot, world, self_collision, mesh_verdict=False) -> Setup | None:
    """The collision check of a call (module docstring), or None when nothing is checked."""
    if world is not None:
        from nik.collision import World

        if not isinstance(world, World):
            raise ValueError(f"IKSolver: world must be a nik.World, got {type(world).__name__}")
    model = attached_model(robot) if self_collision is None else None
    self_on = (model is not None or world is not None) if self_collision is None else bool(self_collision)
    if not self_on and (world is None or world.empty):
        return None
    if model is None:
        from nik.collision.model import collision_model

        model = collision_model(robot)
    mesh = None
    if mesh_verdict is not False:
        from nik.collision.meshcheck import mesh_check

        urdf = None if isinstance(mesh_verdict, bool) or mesh_verdict == "auto" else mesh_verdict
        mesh = mesh_check(robot, model, urdf, required=mesh_verdict != "auto")
    if mesh is None:
        return Setup(model, world, self_on)
    from nik.collision.meshcheck import spheres_cover

    return Setup(model, world, self_on, mesh, spheres_cover(model, mesh))


def _numpy(x) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


def _like(x: np.ndarray, ref):
    """``x`` as the kind of ``ref`` (a tensor of its dtype and device, or a numpy array of its dtype)."""
    if isinstance(ref, torch.Tensor):
        return torch.from_numpy(np.ascontiguousarray(x)).to(device=ref.device, dtype=ref.dtype)
    return np.asarray(x, dtype=np.asarray(ref).dtype)
