"""``IKSolver``: initial guess (network, closed form or multi-start) -> refinement -> result.

The solver holds the configuration of one robot's pipeline; it computes nothing itself. Each call resolves its
:class:`~nik.ik.plan.Plan` once (:meth:`IKSolver.plan`: guess source and network, LM settings and caps, restarts,
fallback, tolerances) and hands it to a backend, which runs the stages of :mod:`nik.ik.stages` as the plan says.
For a batch of B target poses, :meth:`IKSolver.solve` runs:

1. **guess**: the trained network's prediction when it has one; else, for an arm with a closed form
   (:func:`nik.analytic.family`: a spherical wrist or three parallel axes), the closed-form solution (the
   valid one nearest ``q_near``, or the one farthest inside the joint ranges); else none: the refiner
   starts from uniform configurations (the swarm from particles spread inside the limits, LM from the best
   of ``LMCfg.first_starts``);
2. **refine** the targets the guess leaves outside tolerance: by default (``refine="lm"``)
   Levenberg-Marquardt (:func:`nik.lm.lm_solve`) from the guess, restarting only the targets that still
   fail and are not provably out of reach (:mod:`nik.robots.reach`); the swarm methods (``ipso`` | ``pso``
   | ``sapso`` | ``ga``) through :func:`nik.swarm.refine` (finished by an LM polish unless ``polish=False``);
   ``refine="none"`` returns the raw guess;
3. **near**: with ``q_near`` on an arm without a closed form, a second refinement from ``q_near`` itself;
4. **more hypotheses**: LM from the other hypotheses of a multi-solution network for the targets still failing;
5. **fallback**: a second chance for the targets still failing and within reach;
6. **final check**: joint angles inside the limits, their true errors measured by FK, an honest success
   flag and ``reachable`` (False where the reach bound proves the target out of reach;
   :meth:`IKSolver.solve` warns about those, and asks about millimetres when they lie 100 x beyond).

The stages are written once; a backend computes them (:mod:`nik.ik.backends`, chosen per call by
:func:`nik.ik.backends.choose`): compiled numba kernels on numpy for CPU targets with ``refine="lm"`` (any batch
size), torch otherwise (the GPU, the swarms, ``refine="none"``). Both validate the input in one place
(:mod:`nik.ik.targets`), keep the same result contract, and name the guess that served in ``IKResult.source``.

Guess providers ``(robot, T, ...) -> q (B, dof)`` live in :mod:`nik.ik.guesses`, refiners
``(robot, T, q0) -> RefineResult`` in :mod:`nik.ik.refiners`. Units are SI (metres, radians) throughout.
"""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import torch

from nik.ik import backends, collide, every, networks, stages
from nik.ik.backends.one_pose import one_pose
from nik.ik.costs import route, solve_routed
from nik.ik.costs import solve as solve_costs
from nik.ik.plan import (
    REFINE_METHODS,
    Plan,
    check_settings,
    check_use,
    network_use,
    resolve_fallback,
    solver_plan,
    with_goal,
)
from nik.ik.result import IKResult
from nik.ik.targets import as_poses, as_q_near, check_tolerances
from nik.robots import Robot, load_robot
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["REFINE_METHODS", "IKSolver"]


class IKSolver:
    """Inverse kinematics for one robot: guess, refine, report honestly.

    Args:
        robot: a :class:`nik.Robot`, or a built-in name, YAML or URDF path for :func:`nik.load_robot`.
        checkpoint: ``"auto"`` (default): the network for this arm's definition hash without its base/tool frames
            (:attr:`nik.Robot.arm_hash`), whatever its name (else the same arm by FK, from another file or with
            another end link: :func:`nik.nets.registry.find_same_arm`): one installed in the user folder (``nik train
            --install``, :mod:`nik.nets.registry`), else the one shipped with nik (:func:`nik.models.load_pretrained`;
            on the CPU its small single-pose network where it has one), else none; on an arm with a closed form
            and ``analytic=True`` the closed form stays the guess and no network is loaded. A given or installed
            network serves on every backend before a shipped one (the precedence: :mod:`nik.ik.plan`).
            A path: an exported network (``NAME.safetensors`` with its ``NAME.json``, e.g. from ``nik train``; its
            SHA-256 is checked) or a Lightning ``.ckpt`` from ``train.py`` (or :func:`nik.models.save_checkpoint`),
            loaded safely by :func:`nik.nets.load_network`; one made for another robot definition is refused, a
            damaged file raises :class:`nik.CheckpointError` (a framed robot also takes one made for its bare arm).
            ``None``: no network. A multi-solution network
            (:mod:`nik.nets.multi`) guesses its best hypothesis by FK; targets the refinement leaves outside
            tolerance then get LM from each of its other hypotheses (before any ``fallback``);
            :meth:`solve_all` starts LM from all of them.
        refine: ``lm`` (the default: Levenberg-Marquardt from the guess, restarts only for the targets
            that fail; the fastest) | ``none`` | ``pso`` | ``sapso`` | ``ipso`` | ``ga`` (swarms, then LM polish).
        polish: finish swarm refinements with Levenberg-Marquardt (``nik.swarm.refine(polish=True)``).
        swarm_cfg: optional config of the refinement method (e.g. :class:`nik.swarm.IPSOCfg`).
        analytic: use the closed form (spherical-wrist and UR-type 6R arms) when no checkpoint is given (default True).
        device: where the network lives (``"cpu"``, ``"cuda"``); :meth:`solve` computes on the device of
            its input poses (``T.to("cuda")``) and the network's guess is moved there.
        fallback: a second chance for targets still outside tolerance after the refinement:
            ``"analytic"``, the closed-form solution nearest the first answer (closed-form arms only);
            ``"multistart"``, Levenberg-Marquardt from fresh uniform starts (with ``refine="lm"`` these
            are the LM's own restarts, drawn only for the targets that fail and are within reach);
            ``"auto"`` (or True, the default), analytic where available, else multistart;
            ``"none"`` (or False: with ``refine="lm"`` and a guess, no restarts). It is not used where it
            would repeat the first pass (no network on a closed-form arm), nor with ``refine="none"``,
            nor for targets proven out of reach. The evaluation turns it off to measure what the
            network's guess alone delivers.
        backend: ``"auto"`` (default: :func:`nik.ik.backends.choose` picks per call), ``"compiled"`` (numba
            kernels on numpy: CPU targets, ``refine="lm"`` only) or ``"torch"`` (every device and method). The
            answers meet the same contract on both; benchmarks and tests use it to compare them. On a kernel cache
            that lacks the compiled solve (a machine's first use), ``"auto"`` answers from torch while it compiles in
            a background thread, and one line on stderr says so; ``"compiled"`` (or ``NIK_COMPILE=wait``) waits for
            the compile (:mod:`nik.kernels.background`).
        world: a :class:`nik.World` of obstacles (base frame) every call avoids (``solve(world=)`` replaces it for
            one call); a world turns the collision check on, the arm against itself included.
        self_collision: None (default): checked with a world, and without one where the robot has a collision model
            attached (a ``NAME.collision.json`` beside its file, or :func:`nik.collision.set_collision_model`), not
            otherwise (a conservative sphere model calls 5-33 % of free configurations colliding); True: checked,
            the model built (fitted, cached) if needed; False: never (a world is then checked alone). Where a check
            is active, colliding answers are solved again, ``res.collision_free`` and ``res.collisions`` are set
            (:mod:`nik.ik.collide`).
        mesh_verdict: who judges ``collision_free``: ``"auto"`` (default, as ``nik solve --scene``) the robot's
            collision meshes (coal) where coal (``pip install 'nik-ik[collision-check]'``) and the robot's meshes
            are there, else the spheres; False the spheres always (the conservative model alone: faster where
            coal is installed, and refuses more); True the meshes (a one-line error without them); a URDF path:
            that URDF's meshes (:func:`nik.collision.meshcheck.mesh_check`). Where the
            sphere model was fitted to those very meshes (:func:`nik.collision.meshcheck.spheres_cover`), coal judges
            only the answers the spheres call colliding; else every answer (:mod:`nik.ik.collide`).
    """

    def __init__(
        self,
        robot: Robot | str | Path,
        checkpoint: str | Path | None = "auto",
        refine: str = "lm",
        *,
        polish: bool = True,
        swarm_cfg=None,
        analytic: bool = True,
        fallback: bool | str = "auto",
        device: str | torch.device | None = None,
        backend: str = "auto",
        world=None,
        self_collision: bool | None = None,
        mesh_verdict: bool | str | Path = "auto",
    ):
        from nik.device import resolve_device

        check_settings(backend, refine)
        self.backend, self.device = backend, resolve_device(device)
        self.robot = load_robot(robot) if not isinstance(robot, Robot) else robot
        self.refine, self.polish = refine, bool(polish)
        self.swarm_cfg = swarm_cfg
        from nik.analytic import family

        self.closed_form = bool(analytic) and family(self.robot) is not None
        self.fallback = resolve_fallback(fallback, self.closed_form, self.robot.name)
        self._net, self._net_one, self._given = networks.solver_networks(
            checkpoint, self.robot, self.device, self.closed_form
        )
        self._use_asked = None
        self._plans, self.world, self.self_collision = {}, world, collide.check_self_collision(self_collision)
        self.mesh_verdict = collide.check_mesh_verdict(mesh_verdict)

    def __setattr__(self, name: str, value) -> None:
        """A setting changed (``solver.net = ...``, ``solver.world = ...``) drops the one-pose entries made from the
        old ones (:mod:`nik.ik.backends.one_pose`)."""
        object.__setattr__(self, name, value)
        if name != "_plans":
            self.__dict__["_one"] = {}

    @property
    def net(self):
        """The network (None without one): one given (``checkpoint=PATH``, or set here) or installed serves on every
        backend; the shipped one gives way on the CPU to the arm's single-pose network (:mod:`nik.ik.plan`)."""
        return self._net

    @net.setter
    def net(self, value) -> None:
        self._net, self._given, self._net_one = value, value is not None, None

    @property
    def has_network(self) -> bool:
        """True when the solver has a network."""
        return self._net is not None

    @property
    def single_pose_net(self):
        """The small network that guesses on the CPU (recorded role ``single_pose``): the arm's shipped one with the
        shipped main one, or an installed one with an installed main one (``checkpoint="auto"``; ``nik train
        --install`` installs one where the main network does not pay for single poses); None where there is none."""
        return self._net_one

    @property
    def network_use(self) -> dict:
        """Which call types the network serves on the CPU, and why: ``{"pose": bool, "batch": bool, "pose_us": (with,
        without), "batch_us": (with, without), "wins": share, "baseline": "multistart", "how": ...}``. ``pose``:
        calls of one pose; ``batch``: calls of more. A network serves a call type where it earns its place (``wins``:
        its best hypothesis a better start than uniform ones) and is no slower there than the solver without it
        (``*_us``: microseconds of CPU per pose on seeded probes, with and without it: LM from uniform starts; for
        one pose per call the median call).
        ``how``: ``record`` (read from the network's file: ``nik train`` writes it), ``measured`` (timed in this
        process on first use, 0.12-0.18 s of CPU, kept per network), ``wins`` (set aside on wins, not timed),
        ``asked`` (set here), ``no network`` (:mod:`nik.ik.judge`). The torch backend (GPU targets, swarms)
        follows the wins verdict alone. Reading it measures where needed.

        Set ``{"pose": bool, "batch": bool}`` to decide by hand (None: decided as above)."""
        return network_use(self)

    @network_use.setter
    def network_use(self, value) -> None:
        self._use_asked = check_use(value)

    def __repr__(self) -> str:
        net, closed = self.has_network, self.closed_form
        return f"IKSolver(robot={self.robot.name!r}, network={net}, analytic={closed}, refine={self.refine!r})"

    @property
    def initial_source(self) -> str:
        """Where :meth:`solve` takes its initial guess: ``network``, ``analytic`` or ``multistart`` (the plan's
        ``source``; each result's ``source`` says which served)."""
        return self.plan().source

    def plan(self, *, backend: str = "compiled", tol_pos: float = DEFAULT_TOL_POS, tol_rot: float = DEFAULT_TOL_ROT,
             seed: int = 0, max_iters: int | None = None, poses: int | None = None) -> Plan:  # fmt: skip
        """The :class:`~nik.ik.plan.Plan` of a call on ``backend`` (``"compiled"`` | ``"torch"``) with these
        tolerances, seed and iteration cap, for a call of ``poses`` targets (1: a single pose; None: a batch; the
        network serves each on its own terms: :attr:`network_use`): resolved here, once, from the solver's settings
        (:mod:`nik.ik.plan`)."""
        return solver_plan(self, backend, tol_pos, tol_rot, seed, max_iters, "pose" if poses == 1 else "batch")

    # -- public -----------------------------------------------------------
    def initial_guess(self, T_target, *, q_near=None, seed: int = 0, representation: str | None = None) -> torch.Tensor:
        """The raw initial guess ``(B, dof)`` (network, analytic or best-of-64 uniform), inside the limits."""
        T = as_poses(T_target, representation)
        near = as_q_near(q_near, T, self.robot.dof, prismatic=self.robot.prismatic, limits=self.robot.limits)
        return stages.first_guess(self.plan(backend="torch", seed=seed), self.robot, T, q_near=near)

    def solve(
        self,
        T_target,
        tol_pos: float = DEFAULT_TOL_POS,
        tol_rot: float = DEFAULT_TOL_ROT,
        seed: int = 0,
        q_near=None,
        representation: str | None = None,
        plan: Plan | dict | None = None,
        world=None,
        bounds=None,
        q_rest=None,
        rest_weight: float = 0.1,
        costs=None,
    ) -> IKResult:
        """Joint angles that reach the target poses.

        Args:
            T_target: ``(B, 4, 4)``, ``(B, 7)`` xyz + quaternion (w, x, y, z) or ``(B, 6)`` xyz +
                roll-pitch-yaw, metres/radians (see :func:`nik.ik.targets.as_poses`; a single pose counts
                as B = 1). The computation runs in its dtype and device (non-tensor input: float64).
            tol_pos: success tolerance on the position, metres (default 1e-4: 0.1 mm).
            tol_rot: success tolerance on the geodesic rotation error, radians (default 1.745e-3: 0.1 deg;
                both from :mod:`nik.tolerances`, the tolerance every table measures).
            seed: seeds every random choice (same seed, same answer).
            q_near: ``(dof,)`` or ``(B, dof)`` current configuration, radians: among the solutions
                found, return the one nearest to it (joint motion, see :func:`nik.kernels.closed.pick`).
                Closed-form arms pick among the 8 closed-form solutions; otherwise the refinement is
                also run from ``q_near`` itself and the successful answer nearest ``q_near`` is kept.
            representation: ``"matrix"`` | ``"quat"`` (w first) | ``"quat_xyzw"`` (ROS order) | ``"rpy"``; inferred from
                the shape when None (7 numbers: ``"quat"``).
            plan: the refinement's settings, one group: a dict of :class:`~nik.ik.plan.Plan` fields changed in the
                call's own plan (``{"max_iters": 20}``: the refinement's iteration limit; default the method's
                config), or a plan of :meth:`plan` (changed with ``dataclasses.replace``) to run instead of the
                solver's own: its tolerances, seed and iteration cap then replace the arguments.
            world: a :class:`nik.World` for this call instead of the solver's (:mod:`nik.ik.collide`).
            bounds: a tolerant goal per axis of the target's tool frame (:mod:`nik.ik.bounds`: 6 half-widths x, y, z
                m, rx, ry, rz rad, ``math.inf`` = free, or ``(B, 6)``; ``"position"``, ``"axis_z"``): success means
                inside them by FK; ``res.axis_err`` the error per axis (:mod:`nik.ik.goals`). None: the tolerances.
            q_rest: a preferred posture (``(dof,)`` / ``(B, dof)`` radians, or ``"mid"``: the middle of the joint
                ranges), reached in the null space of the task without leaving the tolerance; moves the answers of
                redundant arms (7 joints, or any arm under a free axis) only; rest_weight: the share of the way to
                it each step asks (:mod:`nik.ik.goals`).
            costs: the user's cost terms (:func:`nik.costs.custom`, any :class:`nik.costs.Term`): after the pipeline,
                the call's terms (pose or bounds, limits, posture, collisions, these) are solved as one problem from
                its answer (:mod:`nik.ik.costs`); success then needs every constraint's check, ``res.unmet`` names
                what a failed target misses.

        Returns:
            :class:`IKResult` with ``(B, ...)`` fields; errors and success measured by FK on the returned ``q``
            (numpy arrays for numpy input, tensors for tensor input: :class:`IKResult`); ``collision_free`` where a
            collision check is active (success requires it).

        Raises:
            ValueError: bad poses, a negative or NaN tolerance, a malformed ``q_near``, bad bounds or ``q_rest``.

        Targets that the reach bound proves out of reach are flagged (``reachable``), get no restarts,
        and a ``UserWarning`` names them (asking about millimetres when they lie 100 x beyond the reach).
        """
        plan, max_iters, changes = _plan_changes(plan, costs is not None)
        if costs is not None:  # the built-in terms take their keyword's compiled route (nik.ik.costs.route)
            call = dict(tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, q_near=q_near, max_iters=max_iters, plan=plan,
                        representation=representation, world=world, bounds=bounds, q_rest=q_rest,
                        rest_weight=rest_weight)  # fmt: skip
            return solve_routed(self, T_target, costs, call)
        if plan is max_iters is q_near is representation is world is None and not changes:
            res = one_pose(self, T_target, tol_pos, tol_rot, seed) if bounds is q_rest is None else None
            if res is not None:  # one pose in one kernel call (nik.ik.backends.one_pose)
                return res
        check_tolerances(tol_pos, tol_rot)
        be = backends.choose(self, T_target)
        if plan is None:
            n = _count(T_target)
            plan = self.plan(backend=be.name, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, max_iters=max_iters, poses=n)
            plan = replace(plan, **changes) if changes else plan
        plan = with_goal(plan, bounds, q_rest, rest_weight)
        return solve_costs(self, be, plan, T_target, q_near, representation, world, costs)

    def solve_all(
        self,
        T_target,
        *,
        tol_pos: float = DEFAULT_TOL_POS,
        tol_rot: float = DEFAULT_TOL_ROT,
        seed: int = 0,
        n_starts: int = 256,
        dedupe_tol: float = 1e-3,
        representation: str | None = None,
        bounds=None,
        world=None,
        q_rest=None,
        rest_weight: float = 0.1,
        costs=None,
    ) -> torch.Tensor:
        """Every distinct solution found for one pose: ``(K, dof)`` radians inside the limits (K may be 0).

        Arms with a closed form (``analytic=True``): the valid closed-form solutions (at most 8; exact). Otherwise
        LM from every hypothesis of the network (each IK branch of a branch network, each head of a
        multi-head one; the guess of a plain network) and then ``n_starts`` uniform starts; the
        successful ones (within ``tol_pos`` metres / ``tol_rot`` radians) are de-duplicated
        (two solutions are the same when no joint differs by more than ``dedupe_tol`` radians,
        modulo 2 pi). With ``bounds`` (:mod:`nik.ik.goals`): on a closed-form arm with one free rotation axis the
        valid closed-form solutions over 36 free angles, else LM towards the bounds from the same starts. For a
        redundant arm (7 joints) the solutions form a continuum; K is then
        simply how many distinct samples of it the starts found.
        Cost: on the CPU the LM runs compiled from each start; panda and xarm7 with 256 starts take 50-100 ms a
        pose, one thread (``python benchmarks/solve_all.py``; about a second with the batched torch LM, the
        path of targets on a GPU). Where a collision check is active (``world``, else the solver's, and
        ``self_collision``), only the collision-free solutions (colliding ones solved again with collision rows); with
        ``q_rest`` each moved towards it in the null space, nearest first (:func:`nik.ik.collide.solve_all`). With
        ``costs`` (as :meth:`solve`), each solution solved again under the call's terms, only those meeting every
        constraint kept (:mod:`nik.ik.every`).
        """
        T = as_poses(T_target, representation)
        r = route(self, costs, T, tol_pos=tol_pos, tol_rot=tol_rot, world=world, bounds=bounds, q_rest=q_rest,
                  rest_weight=rest_weight)  # fmt: skip
        check_tolerances(r.tol_pos, r.tol_rot)
        plan = r.goal(r.solver.plan(backend="torch", tol_pos=r.tol_pos, tol_rot=r.tol_rot, seed=seed))
        Q = collide.solve_all(r.solver, plan, T, r.world, n_starts=n_starts, dedupe_tol=dedupe_tol)
        return every.with_costs(r.solver, plan, T, r.world, r.costs, Q, dedupe_tol)

    def solve_path(
        self,
        T_path,
        q_start=None,
        *,
        tol_pos: float = DEFAULT_TOL_POS,
        tol_rot: float = DEFAULT_TOL_ROT,
        seed: int = 0,
        representation: str | None = None,
        max_step: float | None = None,
        world=None,
        closed: bool | None = None,
        timing: bool | dict = False,
        vel_limits=None,
        acc_limits=None,
        bounds=None,
        q_rest=None,
        costs=None,
    ) -> IKResult:
        """One continuous joint trajectory through the waypoints of a Cartesian path (:mod:`nik.paths.solve`).

        Args:
            T_path: ``(N, 4, 4)``, ``(N, 7)`` or ``(N, 6)`` waypoints in order, metres/radians, N >= 2.
            q_start: ``(dof,)`` the joints before the path, radians: the trajectory starts nearest them. None:
                the start (IK branch, posture) that keeps the whole path continuous with the least joint motion.
            tol_pos, tol_rot: success tolerances, metres and radians (as :meth:`solve`).
            seed: seeds every random choice.
            representation: ``"matrix"`` | ``"quat"`` (w first) | ``"quat_xyzw"`` (ROS order) | ``"rpy"``; inferred from
                the shape when None (7 numbers: ``"quat"``).
            max_step: a step (largest joint motion between waypoints) above it is a reconfiguration, reported and
                warned about; radians, default :data:`nik.paths.solve.PATH_MAX_STEP` (10 degrees).
            world: a :class:`nik.World` for this call (else the solver's): a waypoint whose answer collides is
                infeasible, its ``res.path.reasons`` entry ``"colliding"``; ``res.collision_free`` per waypoint.
            closed: None: closed when the last pose equals the first (within the tolerances); then the last row
                of joints equals the first. True / False force it.
            timing: True (or a dict of :func:`nik.paths.timing.time_path` keywords) fills ``res.path.t``, ``qd``,
                ``qdd``; vel_limits, acc_limits: ``(dof,)`` its limits (default the robot's).
            bounds: a tolerant goal per waypoint (:func:`nik.ik.bounds.parse_bounds`, e.g. ``"axis_z"``).
            q_rest: ``(dof,)`` or ``"mid"``: the posture a redundant arm keeps to along the path (null space).
            costs: the user's cost terms (as :meth:`solve`; path terms too): the path found is then solved as one
                problem with them, smoothness and the ``max_step`` cap (:mod:`nik.paths.costs`).

        Returns:
            :class:`IKResult` with ``(N, ...)`` fields: ``q: (N, dof)`` the trajectory inside the limits,
            ``success`` per waypoint re-checked by FK, and ``path`` (:class:`nik.ik.PathReport`).

        Warns:
            UserWarning: naming the first waypoint out of reach, beyond a joint limit on every branch, not reached,
            or forcing a reconfiguration.
        """
        from nik.paths import costs as paths

        step = paths.PATH_MAX_STEP if max_step is None else max_step
        return paths.solve_path(
            self, T_path, q_start, tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, representation=representation,
            max_step=step, world=world, closed=closed, timing=timing, vel_limits=vel_limits, acc_limits=acc_limits,
            bounds=bounds, q_rest=q_rest, costs=costs,
        )  # fmt: skip


def _plan_changes(plan, costs: bool) -> tuple:
    """``(plan, max_iters, changes)`` of :meth:`IKSolver.solve`'s ``plan=``: a :class:`~nik.ik.plan.Plan` (or None)
    as it is, with no changes, or a dict of Plan fields as ``(None, its max_iters or None, the other fields)``; a field
    the Plan lacks is a one-line ValueError, and so is a change other than ``max_iters`` with ``costs=`` (whose plan
    :func:`nik.ik.costs.solve_routed` makes)."""
    if plan is None or isinstance(plan, Plan):
        return plan, None, {}
    if not isinstance(plan, dict):
        raise ValueError(f"plan: expected a Plan, a dict of Plan fields or None, got {type(plan).__name__}")
    names = {f.name for f in fields(Plan)}
    bad = sorted(set(plan) - names) or (sorted(set(plan) - {"max_iters"}) if costs else [])
    if bad:
        raise ValueError(
            f"plan: {bad[0]!r} is not a field the call can change (Plan fields: {', '.join(sorted(names))})"
        )
    changes = dict(plan)
    return None, changes.pop("max_iters", None), changes


def _count(T_target) -> int | None:
    """How many poses ``T_target`` holds by its shape (``(4, 4)``, ``(7,)``, ``(6,)``: one; ``(B, ...)``: B), None
    where it has no shape (the checks of :mod:`nik.ik.targets` word the error)."""
    shape = getattr(T_target, "shape", None)
    if shape is None:
        try:
            shape = np.shape(T_target)
        except Exception:  # noqa: BLE001 - ragged input: the targets' check words it
            return None
    if len(shape) <= 1 or tuple(shape) == (4, 4):
        return 1
    return int(shape[0])
