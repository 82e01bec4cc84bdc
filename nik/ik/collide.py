"""The collision stage of :class:`nik.IKSolver`: which collision model a call uses, and collision-free answers.

**When collisions are checked** (``IKSolver(robot, world=None, self_collision=None)``, per call ``solve(world=)``):

- a ``world`` (on the solver or per call, even an empty one) turns the check on, **the arm against itself
  included**: ``collision_free`` means free of the world and of the arm (the model is built if needed: fitted to
  the URDF's collision geometry, or capsules along the links; cached, :func:`nik.collision.collision_model`);
  ``self_collision=False`` checks the world only;
- without a world, ``self_collision=None`` (the default) checks the arm against itself where the robot **has a
  collision model attached**: a ``NAME.collision.json`` beside its URDF / YAML file or one set by the user
  (:func:`nik.collision.set_collision_model`); otherwise nothing is checked; ``True``: checked; ``False``: never.

Why not on by default for every arm without a world: a sphere model is conservative (every surface point inside;
it overreaches by 1.5-3.5 cm), so it calls 5-33 % of the panda's free configurations colliding
(docs/collisions.md). Turned on silently, it would make random reachable targets fail that the same call solves
today, and fit a model (seconds) inside a solve. A world or an attached model is a decision the user made.

**What the stage does** (:func:`resolve`, after the main pipeline, both backends): every answer is checked
(:func:`nik.kernels.collision.collides_batch`, margin 0); the ones that collide (within reach) are solved again by
LM with collision rows (:mod:`nik.kernels.collision_lm`): from the answer (it keeps a path or ``q_near`` on its
branch), then the network's other hypotheses or the closed form's other branches that are free, nearest the pose
first (colliding ones dropped before any iteration), then uniform restarts drawn collision-free. A target whose
pose alone proves every answer colliding (:func:`nik.collision.compiled.blocked_targets`: the hand against the
world or the base, the first and the last joint's links swept over their range) is not solved again (it would
fail after the whole restart budget); with the meshes judging, or a tolerant goal (``bounds``: no pose is fixed),
it is. The torch backend runs the same compiled kernel on the CPU (the answers go there and back).

**The verdict** ``res.collision_free``: the sphere check of the returned ``q`` (margin 0): conservative, so an
answer called free is free on the meshes (docs/collisions.md measures it); ``success`` requires it. With a mesh
verdict (``IKSolver(mesh_verdict=)``: ``"auto"`` where coal is installed and the robot has collision meshes,
True (required), a URDF path, False: the default) the meshes judge instead (:func:`nik.collision.meshcheck.mesh_check`,
coal): every answer is checked on them, and only those colliding on the meshes are solved again, so a
conservative sphere model never turns a free answer into a failure (the spheres steer, the meshes judge; it costs
one coal check per answer, 0.6-2.7 ms on the panda). ``res.collisions`` names what overlaps in each colliding
answer (``"linkA|linkB"``, ``"link|box 2"``; :func:`nik.collision.collision_names`).

Choices (:class:`CollideCfg`): margin 5 mm (the rows push the spheres that far apart, the verdict needs 0), weight
1 (a millimetre of penetration costs as much as a millimetre of pose error), 30 iterations per start,
:attr:`CollideCfg.restarts` uniform starts, each the collision-free draw nearest the pose among
:attr:`CollideCfg.tries`. A solver takes other settings as ``solver.collide_cfg = CollideCfg(...)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

__all__ = [
    "CollideCfg",
    "Setup",
    "after_solve",
    "attached_model",
    "free_solutions",
    "has_attached",
    "path_waypoints",
    "resolve",
    "setup",
]


@dataclass(frozen=True)
class CollideCfg:
    """Settings of the collision stage (module docstring): ``margin`` metres, ``weight`` of the collision rows,
    ``iters`` / ``stall_iters`` per start, ``restarts`` uniform starts per target, ``tries`` draws per start."""

    margin: float = 0.005
    weight: float = 1.0
    iters: int = 30
    stall_iters: int = 5
    restarts: int = 16
    tries: int = 16


@dataclass(frozen=True)
class Setup:
    """The collision check of one call: the arm's ``model``, the ``world`` (None: self only), ``self_on`` and the
    ``mesh`` check that judges (a :class:`nik.collision.meshcheck.MeshCheck`; None: the spheres judge)."""

    model: object
    world: object
    self_on: bool
    mesh: object = None

    def colliding(self, robot, q: np.ndarray) -> np.ndarray:
        """``(B,)`` bool, the verdict for ``q: (B, dof)``: the meshes' where they judge, else the spheres'."""
        if self.mesh is not None:
            return self.mesh.collides(q, self.world, self_collision=self.self_on)
        from nik.kernels.collision import collides_batch

        (G, joints), rest = self.arguments(robot)
        hit = np.empty(len(q), dtype=bool)
        collides_batch(G, joints, np.ascontiguousarray(q, dtype=np.float64), *rest, 0.0, hit)
        return hit

    def names(self, robot, q: np.ndarray) -> list:
        """What overlaps in each of ``q: (B, dof)`` (:func:`nik.collision.collision_names`), by the verdict's check."""
        if self.mesh is not None:
            return self.mesh.collision_names(q, self.world, self_collision=self.self_on)
        from nik.collision.compiled import collision_names_compiled

        return collision_names_compiled(robot, q, self.world, model=self.model, self_collision=self.self_on)

    def arguments(self, robot):
        """``(G, joints), rest``: :func:`nik.collision.compiled.kernel_arguments`."""
        from nik.collision.compiled import kernel_arguments

        return kernel_arguments(robot, self.model, self.world, self_collision=self.self_on)


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


def after_solve(solver, backend, plan, T_target, q_near, representation, world):
    """:meth:`nik.IKSolver.solve` on ``backend``, then :func:`resolve` where a check is active (the call's
    ``world``, else the solver's); without one the backend's result itself (``collision_free`` None)."""
    res = backend.solve(solver.robot, plan, T_target, q_near, representation)
    s = setup(solver.robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None:
        return res
    from nik.ik.targets import as_poses

    return resolve(solver.robot, plan, as_poses(T_target, representation), res, s, getattr(solver, "collide_cfg", None))


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
    return Setup(model, world, self_on, mesh)


def _numpy(x) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


def _like(x: np.ndarray, ref):
    """``x`` as the kind of ``ref`` (a tensor of its dtype and device, or a numpy array of its dtype)."""
    if isinstance(ref, torch.Tensor):
        return torch.from_numpy(np.ascontiguousarray(x)).to(device=ref.device, dtype=ref.dtype)
    return np.asarray(x, dtype=np.asarray(ref).dtype)


def _starts(robot, plan, T: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(starts (k, H, n), n_starts (k,))``: the answer, then the closed form's valid branches (closed-form arms)
    or the network's hypotheses."""
    from nik.ik.model import model_of

    k, n = q.shape
    extra = np.zeros((k, 0, n))
    count = np.zeros(k, dtype=np.int64)
    model = model_of(robot, plan.lm_cfg)
    if model.closed is not None:
        sols, valid = model.closed_solutions(T)
        order = np.argsort(~valid, axis=1, kind="stable")  # valid branches first
        extra = np.take_along_axis(sols, order[:, :, None], axis=1)
        count = valid.sum(1).astype(np.int64)
    elif plan.net is not None and hasattr(plan.net, "hypotheses"):
        Tn = model.arm_targets(T) if plan.net_in_arm_frame else T
        with torch.no_grad():
            extra = _numpy(plan.net.hypotheses(torch.from_numpy(np.ascontiguousarray(Tn)))).astype(np.float64)
        count = np.full(k, extra.shape[1], dtype=np.int64)
    starts = np.ascontiguousarray(np.concatenate([q[:, None, :], extra], axis=1))
    return starts, count + 1


def resolve(robot, plan, T: torch.Tensor, res, s: Setup, cfg: CollideCfg | None = None):
    """``res`` with colliding answers solved again and ``collision_free`` set (module docstring); ``T: (B, 4, 4)``
    the validated targets, ``res`` of either kind (numpy or tensors: the result keeps its kind)."""
    from nik.ik.model import model_of
    from nik.kernels.collision_lm import collision_lm
    from nik.kernels.lm import CLASSIC, ITERS, STALL_ITERS, seed_state

    cfg = cfg or CollideCfg()
    (G, joints), rest = s.arguments(robot)
    q = np.ascontiguousarray(_numpy(res.q), dtype=np.float64)
    B = q.shape[0]
    hit = s.colliding(robot, q)
    reach = np.ones(B, dtype=bool) if res.reachable is None else _numpy(res.reachable).astype(bool)
    idx = np.nonzero(hit & reach)[0]
    if idx.size and s.mesh is None and getattr(plan, "bounds", None) is None:
        # a pose whose own rows collide has no free answer: not solved again (a tolerant goal fixes no pose)
        from nik.collision.compiled import blocked_targets

        T_hit = _numpy(T)[idx]
        idx = idx[
            ~blocked_targets(robot, s.model, s.world, T_hit, plan.tol_pos, plan.tol_rot, self_collision=s.self_on)
        ]
    success = _numpy(res.success).astype(bool).copy()
    pos, rot, it = (_numpy(x).copy() for x in (res.pos_err, res.rot_err, res.iterations))
    if idx.size:
        Tn = np.ascontiguousarray(_numpy(T)[idx], dtype=np.float64)
        starts, n_starts = _starts(robot, plan, Tn, q[idx])
        tol_pos, tol_rot = plan.stage_tolerances(T.dtype == torch.float32)
        opts, iopts = model_of(robot, plan.lm_cfg).lm.options(tol_pos, tol_rot)
        iopts = iopts.copy()
        iopts[ITERS], iopts[STALL_ITERS] = cfg.iters, cfg.stall_iters
        k, n = idx.size, q.shape[1]
        bounds, modes = np.zeros((k, 6)), np.full(k, CLASSIC, dtype=np.int64)
        restarts = np.full(k, cfg.restarts, dtype=np.int64)
        qk, free, done = np.empty((k, n)), np.empty(k, dtype=bool), np.empty(k, dtype=bool)
        itk, pk, rk = np.empty(k, dtype=np.int64), np.empty(k), np.empty(k)
        collision_lm(G, joints, Tn, starts, n_starts, bounds, modes, opts, iopts, restarts, cfg.tries,
                     seed_state(plan.seed), *rest, cfg.margin, cfg.weight, qk, free, done, itk, pk, rk)  # fmt: skip
        q[idx], pos[idx], rot[idx], it[idx] = qk, pk, rk, it[idx] + itk
        success[idx] = (pk <= plan.tol_pos) & (rk <= plan.tol_rot)
        hit[idx] = s.colliding(robot, q[idx])  # the verdict of the new answers (the others' stands)
    free = ~hit
    out = type(res)(**{**res.__dict__})
    out.q, out.pos_err, out.rot_err = _like(q, res.q), _like(pos, res.pos_err), _like(rot, res.rot_err)
    out.iterations, out.success = _like(it, res.iterations), _like(success & free, res.success)
    out.collision_free = _like(free, res.success)
    out.collisions = [None] * B
    for i, names in zip(np.nonzero(hit)[0], s.names(robot, q[hit]), strict=True):
        out.collisions[i] = names or []  # [] only where the verdict's margin 0 and the names' rounding differ
    return out


def path_waypoints(solver, q: np.ndarray, world, success: np.ndarray):
    """For :func:`nik.paths.solve.solve_path`: ``(success & free, free, reasons)`` for the trajectory ``q: (N, dof)``
    under the call's check (``world``, else the solver's; the rule of :func:`setup`): ``free (N,)`` bool and
    ``reasons`` (N strings, ``"colliding"`` where the answer collides, else ``""``); without a check
    ``(success, None, ["", ...])``."""
    s = setup(solver.robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None:
        return success, None, [""] * len(success)
    hit = s.colliding(solver.robot, q)
    return success & ~hit, ~hit, ["colliding" if h else "" for h in hit]


def free_solutions(solver, Q: torch.Tensor) -> torch.Tensor:
    """The rows of ``Q: (K, dof)`` that are collision-free under the solver's check (all without one)."""
    robot = solver.robot
    s = setup(robot, solver.world, solver.self_collision, solver.mesh_verdict)
    if s is None or Q.shape[0] == 0:
        return Q
    hit = s.colliding(robot, _numpy(Q))
    return Q[torch.from_numpy(~hit).to(Q.device)]
