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
LM with collision rows (:mod:`nik.kernels.collision_lm`): first from the answer alone (it keeps a path or ``q_near``
on its branch, and ends most targets); then, from that pass's answer, the network's other hypotheses or the closed
form's other branches that are free, nearest the pose first (colliding ones dropped before any iteration), then
uniform restarts drawn collision-free. A target left by the first pass whose pose alone proves every answer
colliding (:func:`nik.collision.compiled.blocked_targets`: the hand against the world or the base, the first and the
last joint's links swept over their range) is not solved on (it would fail after the whole restart budget); with the
meshes judging where the spheres do not cover them (below), or a tolerant goal (``bounds``: no pose is fixed), it
is. Where the re-solve ends off the goal, once more from its answer with the rows at margin 0 (:func:`_solve_free`).
The torch backend runs the same compiled kernel on the CPU (the answers go there and back).

**Constraints compose**: every mix of ``bounds=``, ``q_rest=``, a world and self-collision, in
:meth:`~nik.IKSolver.solve` and :meth:`~nik.IKSolver.solve_all`, on both backends:

- the re-solve keeps the call's goal: the collision LM's pose rows are the bounded residual with its dead zones
  (:mod:`nik.kernels.lm`'s, the one the goal stages use), not the full pose;
- the posture: with a check active, the main pipeline runs without ``q_rest`` and :func:`resolve` applies it after
  the re-solve, before the verdict (:func:`rest_free`: null-space steps that never leave the goal, and never end in
  a collision: the longest free prefix of the steps is kept), to every successful answer, re-solved or not;
- every answer that changed is judged again on its final ``q`` (as returned) by each term's check: the pose within
  the tolerances, or ``axis_err`` (recomputed) inside the bounds; the joint limits (the kernels keep them); the
  collision verdict;
- :meth:`~nik.IKSolver.solve_all` (:func:`solve_all`): colliding solutions solved again from themselves, plus one
  from uniform free starts, the free ones moved towards ``q_rest``, nearest first (:func:`all_solutions`).

Measured (``python benchmarks/compose.py``: panda, xarm7, ur5 in a clutter, targets from configurations free of it):
each mix within 1 point of the same mix without the world (benchmarks/results/compose.txt).

**The verdict** ``res.collision_free``: the sphere check of the returned ``q`` (margin 0): conservative, so an
answer called free is free on the meshes (docs/collisions.md measures it); ``success`` requires it. With a mesh
verdict (``IKSolver(mesh_verdict=)``: ``"auto"``, the default, where coal is installed and the robot has collision
meshes; True (required); a URDF path; False: the spheres always) the meshes judge instead
(:func:`nik.collision.meshcheck.mesh_check`, coal), in one of two ways, chosen once per call by
:func:`nik.collision.meshcheck.spheres_cover` (:attr:`Setup.covered`):

- **the spheres cover the meshes**: the model was fitted to the very URDF whose meshes judge (its ``source``) and
  checks every pair they check (no pair left out by sampling, ``"never"``): the built-in panda, ur5 and xarm7 with
  example-robot-data installed, and an arm whose model nik fitted to its URDF where the sampling left no pair out. A
  fit is an exact surface cover (:mod:`nik.collision.fit`), so an answer the spheres call free is free on the
  meshes, and coal need only judge what they call colliding: the stage runs as without a verdict (the spheres
  steer: the answers they call colliding are solved again, the blocked-pose proof spares the restarts), then coal
  judges the answers the spheres still call colliding; where a re-solved answer fails (off the goal, or colliding
  on the meshes) but the call's own answer met the goal and is free on the meshes, the own answer is returned (a
  conservative sphere model must never turn a free answer into a failure). The price of the choice: an own answer
  free on the meshes that the spheres call colliding is solved again like any other (it may move, or change branch),
  and kept only where the spheres find no free answer. Measured (built-in panda, a table and 10 obstacles, 1,000
  targets, scene seeds 0-2, ``benchmarks/collision_speed.py --builtin --mesh-verdict``, docs/collisions.md):
  success 99.8 / 99.9 / 99.8 % (the spheres judging: 99.8 / 99.7 / 98.9 %, no target lost against them), 0 answers
  called free that collide on the meshes, 21 / 24 / 35 us a target against 19 / 21 / 26 with the spheres judging
  (coal asked about 3 / 4 / 16 configurations of the call's 1,000 answers);
- **otherwise** (another URDF named, capsules, radii given, a pair left out by sampling) the spheres promise nothing
  about the meshes: every answer is checked on them and only those colliding there are solved again, without the
  blocked-pose proof (it does not bind the meshes); one coal check per answer (0.6-2.7 ms on the panda).

``res.collisions`` names what overlaps in each colliding answer (``"linkA|linkB"``, ``"link|box 2"``;
:func:`nik.collision.collision_names`), by the verdict's check.

Choices (:class:`CollideCfg`): margin 5 mm (the rows push the spheres that far apart, the verdict needs 0), weight
1 (a millimetre of penetration costs as much as a millimetre of pose error), 30 iterations per start,
:attr:`CollideCfg.restarts` uniform starts, each the collision-free draw nearest the pose among
:attr:`CollideCfg.tries`; a start at the pose whose hand overlaps by less than the tolerance can move it is first
finished inside the tolerance (:attr:`CollideCfg.finish` iterations, :mod:`nik.kernels.collision_lm`). A solver takes
other settings as ``solver.collide_cfg = CollideCfg(...)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nik.ik.goals import preference, prefers

__all__ = [
    "CollideCfg",
    "Setup",
    "after_solve",
    "attached_model",
    "all_solutions",
    "free_solutions",
    "has_attached",
    "path_waypoints",
    "resolve",
    "rest_free",
    "setup",
    "solve_all",
]


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
    fraction of it (the answer and the restarts / the other given starts; 0: off).

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
    ``world``, else the solver's); without one the backend's result itself (``collision_free`` None). With a check,
    the posture (``plan.q_rest``) is left to :func:`resolve` (after the collision re-solve, before the verdict)."""
    s = setup(solver.robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None:
        return backend.solve(solver.robot, plan, T_target, q_near, representation)
    from dataclasses import replace

    from nik.ik.targets import as_poses

    first = plan if plan.q_rest is None and not plan.manipulability else replace(plan, q_rest=None, manipulability=0.0)
    res = backend.solve(solver.robot, first, T_target, q_near, representation)
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


def _starts(robot, plan, T: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(starts (k, H, n), n_starts (k,))``: the answer, then the closed form's valid branches (closed-form arms)
    or the network's hypotheses."""
    from nik.ik.backends.compiled import PACKED_MAX_BATCH
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
        packed = model.packed(plan.net) if k <= PACKED_MAX_BATCH else None
        if packed is not None:  # the compiled forward pass (11 panda poses: 0.16 ms, torch's 1.5 ms)
            T64 = np.ascontiguousarray(T, dtype=np.float64)
            extra = packed.ranked_hypotheses(model.G, model.joints, T64, plan.tol_pos, plan.tol_rot,
                                             Tin=np.ascontiguousarray(Tn, dtype=np.float64))[0]  # fmt: skip
        else:
            with torch.no_grad():
                extra = _numpy(plan.net.hypotheses(torch.from_numpy(np.ascontiguousarray(Tn)))).astype(np.float64)
        count = np.full(k, extra.shape[1], dtype=np.int64)
    starts = np.ascontiguousarray(np.concatenate([q[:, None, :], extra], axis=1))
    return starts, count + 1


def _goal(robot, plan, B: int, float32: bool):
    """``(model, half (B, 6), modes (B,), opts, iopts)`` of the call's pose term for the compiled kernels: the
    bounded goal (bounds times the float32 margin for float32 targets) or the classic one (``modes == CLASSIC``,
    the stage tolerances in ``opts``)."""
    from nik.ik.goals import _modes_half
    from nik.ik.model import model_of

    model = model_of(robot, plan.lm_cfg)
    half, modes = _modes_half(plan, B, plan.float32_margin if float32 else 1.0)
    opts, iopts = model.lm.options(*plan.stage_tolerances(float32))
    if plan.manipulability > 0.0:  # read by the posture step only (nik.ik.goals.preference)
        from nik.kernels.lm import MANIPULABILITY

        opts = opts.copy()
        opts[MANIPULABILITY] = plan.manipulability
    return model, np.ascontiguousarray(half), np.ascontiguousarray(modes), opts, iopts


def _judge(model, plan, T: np.ndarray, q: np.ndarray):
    """``(ok, pos, rot, d)`` of ``q: (k, n)`` against ``T: (k, 4, 4)`` by FK: the pose within the asked tolerances,
    or (with ``plan.bounds``) every axis of ``d (k, 6)`` (:func:`nik.kernels.lm.bounded_errors`) inside the asked
    bounds; ``d`` None without bounds."""
    from nik.kernels import lm

    k = q.shape[0]
    pos, rot = np.empty(k), np.empty(k)
    lm.pose_errors(model.G, model.joints, T, q, pos, rot)
    if plan.bounds is None:
        return (pos <= plan.tol_pos) & (rot <= plan.tol_rot), pos, rot, None
    half, modes = plan.bounds.expand(k), plan.bounds.modes(k)
    d = np.empty((k, 6))
    lm.bounded_errors(model.G, model.joints, T, q, modes, d)
    return (np.abs(d) <= half).all(1), pos, rot, d


def rest_free(robot, s: Setup | None, goal, T: np.ndarray, q: np.ndarray, ok, q_rest, weight: float, push=None):
    """``(k,)`` bool, which rows moved: ``q: (k, n)`` in place, where ``ok (k,)``, moved towards ``q_rest: (k, n)`` in
    the null space of the pose term ``goal`` (:func:`_goal`; :func:`nik.kernels.driver.rest_posture`: never leaving
    the goal) **without leaving collision-free** under ``s`` (None: no check). An answer whose posture steps end
    colliding takes the nearer ``q_rest`` of: the longest collision-free prefix of the same steps
    (:data:`nik.ik.goals.REST_ITERS` steps, then half as many, ... down to one; the steps are deterministic, so ``i``
    steps are the first ``i`` of the longer run), and ``push(rows, q_end)`` (the collision LM from the colliding end:
    ``(q, done)``; :func:`_pusher`), moved on towards ``q_rest`` the same way, where that is done, free and nearer
    ``q_rest`` than the answer was; else it stays where it was."""
    from nik.ik.goals import REST_DAMPING, REST_ITERS
    from nik.kernels import driver

    model, half, modes, opts, _ = goal
    q0 = q.copy()  # s None: no collision check (the posture alone)
    todo = np.flatnonzero(ok)
    iters = REST_ITERS
    pushed, q_push = np.zeros(0, dtype=np.int64), None
    while todo.size and iters >= 1:
        qt = np.ascontiguousarray(q0[todo])
        k = todo.size
        driver.rest_posture((model.G, model.joints), np.ascontiguousarray(T[todo]), qt, (half[todo], modes[todo]),
                            opts, (np.ascontiguousarray(q_rest[todo]), float(weight), iters, REST_DAMPING),
                            np.ones(k, dtype=bool), (np.empty(k), np.empty(k), np.empty((k, 6))))  # fmt: skip
        moved = (qt != q0[todo]).any(1)
        hit = np.zeros(k, dtype=bool)
        if s is not None and moved.any():
            hit[moved] = s.colliding(robot, qt[moved])
        keep = ~hit
        q[todo[keep]] = qt[keep]
        if iters == REST_ITERS and push is not None and hit.any():
            pushed = todo[hit]
            q_push, done = push(pushed, np.ascontiguousarray(qt[hit]))
            done &= ~s.colliding(robot, q_push)
            pushed, q_push = pushed[done], q_push[done]
        todo, iters = todo[hit], iters // 2
    if pushed.size:  # the pushed end, moved on towards q_rest, where nearer it than the prefix (and the answer)
        mask = np.zeros(q.shape[0], dtype=bool)
        mask[pushed] = True
        qp = q.copy()
        qp[pushed] = q_push
        rest_free(robot, s, goal, T, qp, mask, q_rest, weight)
        near = ((qp[pushed] - q_rest[pushed]) ** 2).sum(1) < ((q[pushed] - q_rest[pushed]) ** 2).sum(1)
        q[pushed[near]] = qp[pushed[near]]
    return (q != q0).any(1)


def _pusher(robot, s: Setup, plan, cfg: CollideCfg, goal, T: np.ndarray):
    """``push(rows, q) -> (q', done)`` for :func:`rest_free`: the collision LM (:func:`_solve_free`) for targets
    ``T[rows]`` under rows ``rows`` of ``goal`` from ``q: (m, n)``, no restarts."""

    def push(rows, q):
        model, half, modes, opts, iopts = goal
        m = rows.size
        g = (model, half[rows], modes[rows], opts, iopts)
        qp, done, _ = _solve_free(robot, s, plan, cfg, g, T[rows], q[:, None], np.ones(m), np.zeros(m))
        return qp, done

    return push


def _collision_solve(robot, s: Setup, plan, cfg: CollideCfg, goal, T, starts, n_starts, restarts, margin: float):
    """:func:`nik.kernels.collision_lm.collision_lm` for targets ``T: (k, 4, 4)`` with the call's pose term ``goal``
    (:func:`_goal`; rows ``k`` of it) from ``starts: (k, H, n)`` (``n_starts (k,)`` of them) and ``restarts (k,)``
    uniform ones, the collision rows' reach ``margin``; returns ``(q (k, n), done (k,), iterations (k,))``."""
    from nik.kernels.collision_lm import collision_lm
    from nik.kernels.lm import ITERS, STALL_ITERS, seed_state

    _, half, modes, opts, iopts = goal
    (G, joints), rest = s.arguments(robot)
    iopts = iopts.copy()
    iopts[ITERS], iopts[STALL_ITERS] = cfg.iters, cfg.stall_iters
    k, n = starts.shape[0], starts.shape[2]
    q, free, done = np.empty((k, n)), np.empty(k, dtype=bool), np.empty(k, dtype=bool)
    it, pos, rot = np.empty(k, dtype=np.int64), np.empty(k), np.empty(k)
    collision_lm(G, joints, np.ascontiguousarray(T), np.ascontiguousarray(starts), np.asarray(n_starts, dtype=np.int64),
                 np.ascontiguousarray(half[:k]), np.ascontiguousarray(modes[:k]), opts, iopts,
                 np.asarray(restarts, dtype=np.int64), cfg.tries, cfg.patience, seed_state(plan.seed), *rest, margin,
                 cfg.weight, cfg.finish, cfg.descents, cfg.converged, q, free, done, it, pos, rot,
                 cfg.converged_given)  # fmt: skip
    return q, done, it


def _solve_free(robot, s: Setup, plan, cfg: CollideCfg, goal, T, starts, n_starts, restarts):
    """:func:`_collision_solve` with :attr:`CollideCfg.margin`, then, where that is not done, LM once more from its
    answer with the rows pushing only where spheres overlap (margin 0, the verdict's): the margin rows may hold an
    answer off a goal that lies nearer an obstacle than the margin (a free compromise millimetres off the pose;
    measured: 2 of 300 panda targets from free configurations in a clutter, 1 of 300 xarm7). Returns
    ``(q (k, n), done (k,), iterations (k,))``."""
    q, done, it = _collision_solve(robot, s, plan, cfg, goal, T, starts, n_starts, restarts, cfg.margin)
    miss = np.flatnonzero(~done)
    if miss.size:
        model, half, modes, opts, iopts = goal
        mgoal = (model, half[miss], modes[miss], opts, iopts)
        qm, dm, itm = _collision_solve(robot, s, plan, cfg, mgoal, T[miss], q[miss, None], np.ones(miss.size),
                                       np.zeros(miss.size), 0.0)  # fmt: skip
        q[miss[dm]], done[miss[dm]] = qm[dm], True
        it[miss] += itm
    return q, done, it


def resolve(robot, plan, T: torch.Tensor, res, s: Setup, cfg: CollideCfg | None = None):
    """``res`` with colliding answers solved again and ``collision_free`` set (module docstring); ``T: (B, 4, 4)``
    the validated targets, ``res`` of either kind (numpy or tensors: the result keeps its kind).

    Every term of the call composes: the re-solve keeps the call's goal (``plan.bounds``: the bounded residual with
    its dead zones in the collision LM's pose rows, else the classic one); with ``plan.q_rest`` every successful
    answer then moves towards the posture by :func:`rest_free` (inside the goal, never into a collision); an
    answer that changed is judged again on its final ``q`` (as returned: float32 answers rounded and clamped into
    the float32 limits) by each term's check: the goal (``pos_err``/``rot_err``, or ``axis_err`` inside the
    bounds), the joint limits (kept by the kernels) and the collision verdict."""
    cfg = cfg or CollideCfg()
    q = np.ascontiguousarray(_numpy(res.q), dtype=np.float64)
    B = q.shape[0]
    Tnp = np.ascontiguousarray(_numpy(T), dtype=np.float64)
    float32 = _numpy(res.q).dtype == np.float32
    goal = _goal(robot, plan, B, float32)
    model, half, modes, opts, iopts = goal
    hit = s.steering(robot, q)  # the spheres, unless the meshes judge without their cover (today's flow)
    reach = np.ones(B, dtype=bool) if res.reachable is None else _numpy(res.reachable).astype(bool)
    idx = np.nonzero(hit & reach)[0]
    success = _numpy(res.success).astype(bool).copy()
    q_own, own_ok, done = q.copy(), success.copy(), np.zeros(0, dtype=bool)  # the call's own answers
    pos, rot, it = (_numpy(x).copy() for x in (res.pos_err, res.rot_err, res.iterations))
    axis = None if res.axis_err is None else _numpy(res.axis_err).copy()
    changed = np.zeros(B, dtype=bool)
    if idx.size:
        Tn = np.ascontiguousarray(Tnp[idx])
        k = idx.size
        kgoal = (model, half[idx], modes[idx], opts, iopts)
        first = q[idx]
        if prefers(plan):  # the first start moved towards q_rest first (the re-solve lands nearer it)
            qr, weight, _ = preference(robot, plan, B, None)
            rest_free(robot, None, kgoal, Tn, first, success[idx], qr[idx], weight)
        # from the answer alone first: it ends most targets (44 of 55 on the panda's scene), without the
        # hypotheses, the blocked-pose proof or the restarts, which only the rest get
        # (the margin-0 pass of :func:`_solve_free` waits for the second pass: measured, it costs more there than
        # it saves)
        qk, done, itk = _collision_solve(
            robot, s, plan, cfg, kgoal, Tn, first[:, None], np.ones(k), np.zeros(k), cfg.margin
        )
        miss = np.flatnonzero(~done)
        if miss.size and (s.mesh is None or s.covered) and getattr(plan, "bounds", None) is None:
            # a pose whose own rows collide has no free answer: not solved on (a tolerant goal fixes no pose)
            from nik.collision.compiled import blocked_targets

            T_miss = _numpy(T)[idx[miss]]
            miss = miss[
                ~blocked_targets(robot, s.model, s.world, T_miss, plan.tol_pos, plan.tol_rot, self_collision=s.self_on)
            ]
        if miss.size:  # from the first pass's answer, the hypotheses or branches, the uniform restarts
            Tm = np.ascontiguousarray(Tn[miss])
            starts, n_starts = _starts(robot, plan, Tm, qk[miss])
            mgoal = (model, half[idx[miss]], modes[idx[miss]], opts, iopts)
            qm, dm, itm = _solve_free(
                robot, s, plan, cfg, mgoal, Tm, starts, n_starts, np.full(miss.size, cfg.restarts)
            )
            qk[miss], done[miss], itk[miss] = qm, dm, itk[miss] + itm
        q[idx], it[idx] = qk, it[idx] + itk
        hit[idx] = s.steering(robot, qk)  # the check of the new answers (the others' stands)
        success[idx] = done & ~hit[idx]
        changed[idx] = True
    if s.mesh is not None and s.covered:  # the meshes judge what the spheres still call colliding
        _meshes_judge(robot, s, q, hit, success, changed, idx, done, q_own, own_ok)
    if prefers(plan):
        ok = success & ~hit
        (qr, weight, _), push = preference(robot, plan, B, None), _pusher(robot, s, plan, cfg, goal, Tnp)
        changed |= rest_free(robot, s, goal, Tnp, q, ok, qr, weight, push)
    if changed.any():
        if float32:  # rounded and clamped into the float32 limits, as the answer is returned, then judged
            q[changed] = np.clip(q[changed].astype(np.float32), model.lo32, model.hi32)
        ok, pk, rk, dk = _judge(model, plan, np.ascontiguousarray(Tnp[changed]), np.ascontiguousarray(q[changed]))
        pos[changed], rot[changed], success[changed] = pk, rk, ok
        if axis is not None and dk is not None:
            axis[changed] = dk
    free = ~hit
    out = type(res)(**{**res.__dict__})
    out.q, out.pos_err, out.rot_err = _like(q, res.q), _like(pos, res.pos_err), _like(rot, res.rot_err)
    out.iterations, out.success = _like(it, res.iterations), _like(success & free, res.success)
    if axis is not None:
        out.axis_err = _like(axis, res.axis_err)
    out.collision_free = _like(free, res.success)
    out.collisions = [None] * B
    for i, names in zip(np.nonzero(hit)[0], s.names(robot, q[hit]), strict=True):
        out.collisions[i] = names or []  # [] only where the verdict's margin 0 and the names' rounding differ
    return out


def _meshes_judge(robot, s: Setup, q, hit, success, changed, idx, done, q_own, own_ok) -> None:
    """:func:`resolve`'s verdict where the spheres cover the meshes (:attr:`Setup.covered`), in place: the meshes
    judge the answers ``q`` the spheres call colliding (``hit``: the others are free on the meshes); a re-solved
    answer (rows ``idx``, ``done`` where it met the goal) that fails, where the call's own answer ``q_own`` met the
    goal (``own_ok``) and is free on the meshes, gives way to it, unchanged (``changed`` off: its errors stand): a
    conservative sphere model must never turn a free answer into a failure. The re-solve steered by the spheres
    (the answers they call colliding solved again, the blocked-pose proof sparing the restarts), so both the
    re-solved answers still colliding and the own answers asked about are ones the spheres call colliding: coal is
    asked about nothing else."""
    hit[:] = s.judge(robot, q, hit)
    if not idx.size:
        return
    success[idx] = done & ~hit[idx]
    back = idx[~success[idx] & own_ok[idx]]
    if back.size:
        own = back[~s.mesh.collides(q_own[back], s.world, self_collision=s.self_on)]
        q[own], hit[own], success[own], changed[own] = q_own[own], False, True, False


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


def solve_all(solver, plan, T: torch.Tensor, world=None, *, n_starts: int = 256, dedupe_tol: float = 1e-3):
    """:meth:`nik.IKSolver.solve_all` for the one pose ``T: (1, 4, 4)`` (validated) under ``plan`` (its goal and
    posture): the search of :func:`nik.ik.stages.all_solutions`, then :func:`all_solutions` (world and posture)."""
    from nik.ik import stages
    from nik.ik.backends import torch_backend
    from nik.robots.reach import within_reach

    if T.shape[0] != 1:
        raise ValueError(f"solve_all: expected one pose, got {T.shape[0]}")
    robot = solver.robot
    job = stages.Job(torch_backend(), robot, T, within_reach(robot, T), None, plan.tol_pos, plan.tol_rot, T.dtype,
                     plan.tol_pos, plan.tol_rot)  # fmt: skip
    Q = stages.all_solutions(plan, job, closed_form=solver.closed_form, n_starts=n_starts, dedupe_tol=dedupe_tol)
    return all_solutions(solver, plan, T, Q, world, dedupe_tol)


def all_solutions(solver, plan, T: torch.Tensor, Q: torch.Tensor, world=None, dedupe_tol: float = 1e-3):
    """:meth:`nik.IKSolver.solve_all`'s terms after the search: ``Q: (K, dof)`` the solutions found for the one pose
    ``T: (1, 4, 4)`` (within the goal, without a world), returned as ``(K', dof)`` of ``Q``'s kind.

    Where a check is active (the call's ``world``, else the solver's; the rule of :func:`setup`), a colliding solution
    is solved again by the collision LM from itself (the call's goal kept; no restarts: a solution that stays colliding
    is dropped), and one more row from collision-free uniform starts (:attr:`CollideCfg.restarts`) adds a free
    solution where every one found collides; under the classic goal these are then driven to rounding level (the
    collision LM at margin 0, kept where the position error is not larger), as the search's survivors are, so that a
    branch found twice meets in the de-duplication; only the free ones that meet the goal are kept. With ``plan.q_rest``
    each solution moves towards the posture in the null space (:func:`rest_free`: inside the goal, never into a
    collision), and the solutions come nearest ``q_rest`` first. De-duplicated again at ``dedupe_tol``."""
    from nik.ik.guesses import dedupe

    robot = solver.robot
    s = setup(robot, solver.world if world is None else world, solver.self_collision, solver.mesh_verdict)
    if s is None and not prefers(plan):
        return Q
    q = np.ascontiguousarray(_numpy(Q), dtype=np.float64).reshape(-1, robot.dof)
    Tq = np.ascontiguousarray(np.repeat(_numpy(T).astype(np.float64).reshape(1, 4, 4), q.shape[0] + 1, axis=0))
    float32 = Q.dtype == torch.float32
    if s is not None:
        cfg = getattr(solver, "collide_cfg", None) or CollideCfg()
        hit = s.colliding(robot, q) if q.shape[0] else np.zeros(0, dtype=bool)
        k = int(hit.sum()) + 1
        starts = np.zeros((k, 1, robot.dof))
        starts[:-1, 0] = q[hit]
        n_starts, restarts = np.ones(k), np.zeros(k)
        n_starts[-1], restarts[-1] = 0, cfg.restarts
        goal = _goal(robot, plan, k, float32)
        qk = _solve_free(robot, s, plan, cfg, goal, Tq[:k], starts, n_starts, restarts)[0]
        if plan.bounds is None:  # to rounding level, as the search's survivors (the branches meet in dedupe)
            tight = np.finfo(np.float64).eps ** 0.75
            model, half, modes, _, iopts = goal
            polish = (model, half, modes, model.lm.options(tight, tight)[0], iopts)
            qp = _collision_solve(robot, s, plan, cfg, polish, Tq[:k], qk[:, None], np.ones(k), np.zeros(k), 0.0)[0]
            better = _judge(model, plan, Tq[:k], qp)[1] <= _judge(model, plan, Tq[:k], qk)[1]
            qk[better] = qp[better]
        q = np.concatenate([q[~hit], qk])
        q = q[~s.colliding(robot, q)]
    model = _goal(robot, plan, 1, float32)[0]
    if float32:
        q = np.clip(q.astype(np.float32), model.lo32, model.hi32).astype(np.float64)
    Tk = np.ascontiguousarray(Tq[:1].repeat(q.shape[0], axis=0))
    ok = _judge(model, plan, Tk, q)[0]
    q = np.ascontiguousarray(q[ok])
    Tk = np.ascontiguousarray(Tk[ok])
    if prefers(plan) and q.shape[0]:
        qr, weight, _ = preference(robot, plan, q.shape[0], None)
        goal = _goal(robot, plan, q.shape[0], float32)
        push = None if s is None else _pusher(robot, s, plan, cfg, goal, Tk)
        rest_free(robot, s, goal, Tk, q, np.ones(q.shape[0], dtype=bool), qr, weight, push)
        if float32:
            q = np.clip(q.astype(np.float32), model.lo32, model.hi32).astype(np.float64)
        keep = _judge(model, plan, Tk, q)[0]
        q, qr = np.ascontiguousarray(q[keep]), qr[keep]
        if plan.q_rest is not None:  # nearest q_rest first, else the highest manipulability first
            q = q[np.argsort(((q - qr) ** 2).sum(1), kind="stable")]
        else:
            from nik.costs.manipulability import manipulability

            q = q[np.argsort(manipulability(robot).compiled(q)[0][:, 0], kind="stable")]
    out = torch.from_numpy(np.ascontiguousarray(q)).to(dtype=Q.dtype, device=Q.device)
    return dedupe(out, tol=dedupe_tol, prismatic=robot.prismatic)
