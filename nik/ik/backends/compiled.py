"""The compiled backend: the stages' work on float64 numpy arrays through the numba kernels of :mod:`nik.kernels`.

For one pose the torch pipeline spends about a millisecond in per-operation overhead, not arithmetic; here a call
is validated (:func:`~nik.ik.targets.pose_array`) and then runs every stage of its plan in one kernel call
(:func:`nik.kernels.driver.solve`, :meth:`CompiledBackend.solve`), which calls the stage kernels below in the order
of :func:`nik.ik.stages.run`; those stages, run one by one over the same kernels, remain the staged path (a network
the kernels do not pack, more than :data:`PACKED_MAX_BATCH` poses with a network) and the reference the driver is
tested against. Every per-robot fact (chain arrays, limits, reach bound,
closed-form constants, the compiled LM, packed networks) comes from the robot's model (:mod:`nik.ik.model`),
looked up once per call:

- the checks of :mod:`nik.ik.targets` (:func:`~nik.ik.targets.pose_array`) and the reach bound
  (:func:`nik.kernels.poses.reach_flags`);
- the network's hypotheses: for up to :data:`PACKED_MAX_BATCH` poses the packed network's compiled forward pass
  (:mod:`nik.nets.compiled`; the plan's network: :mod:`nik.ik.plan`), for more
  the torch forward pass (one batched float32 matmul per layer); every hypothesis ranked by compiled FK, the forward
  pass, the ranking and the tolerance check in one kernel call (:func:`nik.kernels.seeded.ranked_hypotheses`);
- Levenberg-Marquardt (:class:`nik.lm.compiled.CompiledLM`, the solver's :class:`~nik.lm.LMCfg`): from a guess,
  from several starts in turn (:meth:`~nik.lm.compiled.CompiledLM.solve_starts`), or from uniform starts with the
  batched LM's restart budget;
- the closed forms (:mod:`nik.kernels.closed`: the 8 solutions of ``nik.analytic.solve``, the one chosen as
  ``nik.ik.guesses.analytic_guess`` chooses it); an arm that fits its family only within a tolerance gets the
  ideal arm's closed form checked at :data:`~nik.ik.model.APPROXIMATE_CHECK_TOL`, polished by LM where it misses
  the solver's tolerance (the one policy of :mod:`nik.ik.model`).

Answers come back as an :class:`~nik.ik.result.IKResult` in the targets' dtype: float32 targets are solved in
float64 to the plan's float32 tolerance (:meth:`nik.ik.plan.Plan.stage_tolerances`), rounded, clamped into the
float32 limits and measured again.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import torch

from nik.ik.backends.base import Job, Refined
from nik.ik.guesses import LIMIT_ROUNDING
from nik.ik.model import APPROXIMATE_CHECK_TOL, CLOSED_FORM_TOL, model_of
from nik.ik.result import IKResult
from nik.ik.targets import pose_array, q_near_array
from nik.kernels import background as _bg
from nik.robots.reach import REACH_SLACK

__all__ = ["APPROXIMATE_CHECK_TOL", "CLOSED_FORM_TOL", "PACKED_MAX_BATCH", "CompiledBackend", "as_float32"]
#: Most poses whose hypotheses the packed network's compiled forward pass computes; above, torch's batched
#: forward pass (float32 matmuls) is cheaper per pose. Measured with panda's and xarm7's single-pose networks
#: (whole solver, one thread, CPU us per target; kernel / torch): 16 poses 26 / 73, 100 poses 20 / 28,
#: 1,000 poses 19 / 15: the crossover lies between 100 and 1,000.
PACKED_MAX_BATCH = 256


_KERNELS = None


def _kernels():
    """The kernels this backend calls, imported on first use (``import nik`` does not import numba)."""
    global _KERNELS
    if _KERNELS is None:
        from types import SimpleNamespace

        from nik.kernels import closed, driver, lm, seeded
        from nik.lm.compiled import _seed

        _KERNELS = SimpleNamespace(
            solve=driver.solve,
            klm=lm,
            seed=_seed,
            rank=seeded.rank,
            merge=seeded.merge,
            closed_guess=closed.guess,
            pose_errors=lm.pose_errors,
            turns_toward=lm.turns_toward,
        )
    return _KERNELS


_SOURCE = {"network": 0, "analytic": 1, "multistart": 2}  # nik.kernels.driver.SOURCE_*
_FALLBACK = {"none": 0, "analytic": 1, "multistart": 2}  # nik.kernels.driver.FALLBACK_*


@dataclass(frozen=True)
class _Absent:
    """The arrays of a packed network where there is none (the driver reads none of them)."""

    flat: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float32))
    layout: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    activation: int = 0
    in_mean: np.ndarray = field(default_factory=lambda: np.zeros(0))
    in_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    out_center: np.ndarray = field(default_factory=lambda: np.zeros(0))
    out_half: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prismatic: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.bool_))
    heads: int = 0


_NO_NET = _Absent()
_NO_CLOSED = np.zeros(0)


class CompiledBackend:
    """The compiled backend (see the module docstring and :mod:`nik.ik.backends` for the interface)."""

    name = "compiled"

    def __init__(self, defer: bool = True):
        #: answer from torch while the driver's first compile runs in the background (``backend="auto"``; see
        #: :meth:`solve`); False: compile on the caller's thread (``backend="compiled"``, ``NIK_COMPILE=wait``)
        self.defer = defer
        self._looked = not defer  # whether the first call looked at the cache (background.cold)
        self._compiled = set()  # (plan, dtype, q_near given) whose driver runs without compiling

    # -- arrays ------------------------------------------------------------------
    nonzero = staticmethod(np.flatnonzero)

    @staticmethod
    def arange(n: int, like=None):
        return np.arange(n)

    @staticmethod
    def copy(x):
        return x.copy()

    @staticmethod
    def rows(x, idx):
        """``x[idx]`` (``idx``: sorted indices from :meth:`nonzero`, or None for every row); no copy when they are
        all the rows."""
        return x if idx is None or idx.shape[0] == x.shape[0] else x[idx]

    @staticmethod
    def put(dst, idx, src) -> None:
        dst[idx] = src

    @staticmethod
    def norm(x):
        return np.sqrt((x * x).sum(-1))

    @staticmethod
    def zeros_long(n: int, like=None):
        return np.zeros(n, dtype=np.int64)

    @staticmethod
    def turns_toward(job: Job, q):
        """``q`` with its wrapping joints moved by whole turns towards ``job.q_near`` (a copy)."""
        q = q.copy()
        _kernels().turns_toward(job.model.joints, q, job.q_near)
        return q

    @staticmethod
    def merge(answers, job: Job, idx, res: Refined, strict: bool) -> int:
        """:meth:`nik.ik.stages.Answers.merge` in one kernel call; returns how many targets still fail."""
        return _kernels().merge(
            (answers.q, answers.pos_err, answers.rot_err, answers.iterations, answers.ok(job)), idx,
            (res.q, res.pos_err, res.rot_err, res.iterations), strict, job.tol_pos, job.tol_rot,
        )  # fmt: skip

    # -- the job -------------------------------------------------------------------
    def job(self, robot, plan, T_target, q_near, representation, *, reach: bool = True, stacklevel: int = 2) -> Job:
        """The validated targets of one call; ``reach=False`` leaves the reach flags to the driver (:meth:`solve`)."""
        T, dtype = pose_array(T_target, representation)
        model = model_of(robot, plan.lm_cfg)
        if reach:
            reachable, every = model.reach(T)
            if not every:
                warnings.warn(model.unreachable_message(T, reachable), UserWarning, stacklevel=stacklevel)
        else:
            reachable = np.empty(T.shape[0], dtype=bool)
        near = None if q_near is None else q_near_array(q_near, T.shape[0], robot)
        tol_pos, tol_rot = plan.stage_tolerances(dtype == torch.float32)
        return Job(
            self, robot, T, reachable, near, tol_pos, tol_rot, dtype, plan.tol_pos, plan.tol_rot, model,
            numpy_out=isinstance(T_target, np.ndarray),
        )  # fmt: skip

    # -- the whole plan in one kernel call -------------------------------------------------------------------------
    def solve(self, robot, plan, T_target, q_near, representation) -> IKResult:
        """The plan on the targets: validated (:meth:`job`), then every stage in one call of
        :func:`nik.kernels.driver.solve` (the same stages on the same kernels as :func:`nik.ik.stages.run`, the same
        answers, reach flags included); the staged path where the driver does not apply (a network the kernels do
        not pack, or more than :data:`PACKED_MAX_BATCH` poses with a network). A tolerant goal (``plan.bounds``) runs
        the goal stages of :mod:`nik.ik.goals` (:func:`nik.kernels.driver.solve_bounded`)."""
        if plan.bounds is not None:
            from nik.ik import goals

            return goals.solve_compiled(self, robot, plan, T_target, q_near, representation)
        if not self._looked:  # the first call of the process: nothing compiled on this machine yet?
            self._looked = True
            if _bg.cold(_kernels().solve):
                _bg.begin()  # the checks and the model on torch, no kernel compiled on this thread
        try:
            job = self.job(robot, plan, T_target, q_near, representation, reach=False)
        except Exception:
            _bg.end_if_idle()  # bad input on the first call: BUSY set above is not left behind
            raise
        model = job.model
        packed = None
        if plan.source == "network":
            packed = model.packed(plan.net) if job.size <= PACKED_MAX_BATCH else None
            if packed is None:
                from nik.ik import stages

                _bg.end_if_idle()  # the staged path compiles its kernels on this thread, as it always did
                job.reachable, every = model.reach(job.T)
                if not every:
                    warnings.warn(model.unreachable_message(job.T, job.reachable), UserWarning, stacklevel=3)
                return stages.run(plan, job)
        res = self._driver(plan, job, packed)
        if isinstance(res, tuple):  # the driver is not compiled for this plan: torch answers meanwhile
            return self._meanwhile(res, robot, plan, T_target, q_near, representation)
        return res

    @staticmethod
    def _meanwhile(pending, robot, plan, T_target, q_near, representation) -> IKResult:
        """The call answered by the torch backend (the same stages, tolerances and success contract) while the driver
        compiles in a background thread, started after this answer (``pending``: what it compiles; module
        :mod:`nik.kernels.background`)."""
        from nik.ik.backends.torch import TorchBackend

        try:
            return TorchBackend().solve(robot, plan, T_target, q_near, representation)
        finally:
            _bg.compile_later(*pending)

    def driver_args(self, plan, model, dtype, packed) -> tuple:
        """What :func:`nik.kernels.driver.solve` takes from ``plan`` and ``model`` for answers in ``dtype`` (with the
        ``packed`` network, or None): four tuples around the call's own arrays, gathered once per plan and dtype and
        kept on the model (:meth:`_driver`, :mod:`nik.ik.backends.one_pose`)."""
        key = (plan, dtype)
        static = model.driver_args.get(key)
        if static is None:  # what the driver takes from the plan and the model, gathered once per plan
            k = _kernels()
            lm = model.lm
            tol_pos, tol_rot = plan.stage_tolerances(dtype == torch.float32)
            opts, iopts = lm.options(tol_pos, tol_rot, plan.max_iters)
            _, iopts_multi = lm.options(tol_pos, tol_rot, plan.max_iters, multistart=True)
            p = packed or _NO_NET
            closed = model.closed if model.closed is not None else _NO_CLOSED
            check = model.closed_check[dtype] if model.closed_check is not None else 0.0
            static = (
                (model.G, model.joints),
                (model.center, model.radius, REACH_SLACK, _SOURCE[plan.source], p.flat, p.layout, p.activation,
                 p.in_mean, p.in_std, p.out_center, p.out_half, p.prismatic, p.heads),
                (closed, check, LIMIT_ROUNDING),
                (opts, iopts, iopts_multi, lm.budget, k.seed(k.klm, plan.seed), plan.restarts, plan.hypotheses,
                 plan.near, _FALLBACK[plan.fallback], tol_pos, tol_rot),
            )  # fmt: skip
            if len(model.driver_args) > 64:
                model.driver_args.clear()
            model.driver_args[key] = static
        return static

    def _driver(self, plan, job: Job, packed) -> IKResult | tuple:
        """The plan in one call of :func:`nik.kernels.driver.solve`. Where ``self.defer`` and the driver's machine
        code for these argument types is neither loaded nor cached (:func:`nik.kernels.background.ready`, asked once
        per plan and dtype until it is), the compile is announced and ``(kernel, args, also)`` returned instead: what
        :meth:`_meanwhile` compiles (``also``: the pose checks of :meth:`job`)."""
        model, B, n = job.model, job.size, job.model.dof
        k = _kernels()
        static = self.driver_args(plan, model, job.dtype, packed)
        Tin = model.arm_targets(job.T) if packed is not None and plan.net_in_arm_frame else job.T
        use_near = job.q_near is not None
        q, pos, rot = np.empty((B, n)), np.empty(B), np.empty(B)
        ok, iters = np.empty(B, dtype=bool), np.empty(B, dtype=np.int64)
        args = (
            static[0], job.T, static[1], Tin, static[2], job.q_near if use_near else q, use_near, static[3],
            (q, pos, rot, ok, iters, job.reachable),
        )  # fmt: skip
        key = (plan, job.dtype, use_near)
        if key not in self._compiled:  # compiled: asked once per plan, where it may answer from torch meanwhile
            if self.defer and not _bg.ready(k.solve, args):
                _bg.begin()
                _bg.announce(True)
                from nik.ik.targets import ORTHONORMAL_TOL, _pose_kernels

                return k.solve, args, [(_pose_kernels().poses_ok, (job.T, ORTHONORMAL_TOL))]
            if len(self._compiled) > 256:
                self._compiled.clear()
            self._compiled.add(key)
            _bg.end_if_idle()  # set by the first call's look at a cold cache, where this call compiles here after all
        every = k.solve(*args)
        if not every:
            warnings.warn(model.unreachable_message(job.T, job.reachable), UserWarning, stacklevel=4)
        from nik.ik.stages import Answers

        answers = Answers(q, pos, rot, iters)
        answers._ok = ok
        if plan.q_rest is not None or plan.manipulability > 0.0:  # the preferences, in the null space (nik.ik.goals)
            from nik.ik.goals import rest_compiled

            rest_compiled(plan, job, answers)
        return self.result(job, answers, plan.source)

    # -- guesses -----------------------------------------------------------------------
    def network(self, plan, job: Job):
        model, net, B = job.model, plan.net, job.size
        Tin = model.arm_targets(job.T) if plan.net_in_arm_frame else job.T
        if B <= PACKED_MAX_BATCH:
            packed = model.packed(net)
            if packed is not None:
                hyp, pos, rot, ok, failing = packed.ranked_hypotheses(
                    model.G, model.joints, job.T, job.tol_pos, job.tol_rot, Tin=Tin
                )
                return hyp, pos, rot, (ok, failing)
        with torch.no_grad():
            ref = net.in_mean
            hyp = net(torch.from_numpy(Tin).to(device=ref.device, dtype=ref.dtype))
        hyp = np.ascontiguousarray(hyp.reshape(B, -1, model.dof).cpu().numpy(), dtype=np.float64)
        pos, rot = np.empty(B), np.empty(B)
        _kernels().rank(model.G, model.joints, job.T, hyp, pos, rot)
        return hyp, pos, rot, None

    def closed_form(self, plan, job: Job, idx, q_near):
        guess = _kernels().closed_guess
        model = job.model
        T, reachable = self.rows(job.T, idx), self.rows(job.reachable, idx)
        B, n = T.shape[0], model.dof
        q, pos, rot, ok = np.empty((B, n)), np.empty(B), np.empty(B), np.empty(B, dtype=bool)
        use_near = q_near is not None
        guess(
            model.closed, model.G, model.joints, model.closed_check[job.dtype], T, q_near if use_near else q, use_near,
            LIMIT_ROUNDING, job.tol_pos, job.tol_rot, reachable, (q, pos, rot, ok),
        )  # fmt: skip
        return q, pos, rot

    # -- refiners ----------------------------------------------------------------------
    def refine(self, plan, job: Job, idx, q0, restarts: bool, local: bool = False) -> Refined:
        T, reachable = self.rows(job.T, idx), self.rows(job.reachable, idx)
        run = job.model.lm.solve(
            T, q0, tol_pos=job.tol_pos, tol_rot=job.tol_rot, seed=plan.seed, max_iters=plan.max_iters,
            restarts=restarts, reachable=reachable, local=local,
        )  # fmt: skip
        return Refined(run.q, run.pos_err, run.rot_err, run.iterations)

    def lm(self, plan, job: Job, idx, q0, restarts: bool) -> Refined:
        """Levenberg-Marquardt (the solver's refiner here: ``refine="lm"``)."""
        return self.refine(plan, job, idx, q0, restarts)

    def lm_starts(self, plan, job: Job, idx, starts) -> Refined:
        T = self.rows(job.T, idx)
        run = job.model.lm.solve_starts(
            T, starts, tol_pos=job.tol_pos, tol_rot=job.tol_rot, seed=plan.seed, max_iters=plan.max_iters
        )
        return Refined(run.q, run.pos_err, run.rot_err, run.iterations)

    def uniform_guess(self, plan, job: Job):  # pragma: no cover - refine="none" runs on torch
        raise NotImplementedError("the compiled backend serves refine='lm' only")

    # -- the result ----------------------------------------------------------------------
    def result(self, job: Job, answers, source: str) -> IKResult:
        q, pos, rot = answers.q, answers.pos_err, answers.rot_err
        if job.dtype != torch.float64:  # the answer in the targets' dtype, inside the limits, its errors measured
            q, pos, rot, ok = as_float32(job.model, job.T, q, job.success_pos, job.success_rot)
        else:  # the stages' tolerance is the asked one
            ok = answers.ok(job)
        if job.numpy_out:
            return IKResult(q, pos, rot, ok, answers.iterations, source, reachable=job.reachable)
        return IKResult(
            torch.from_numpy(q),
            torch.from_numpy(pos),
            torch.from_numpy(rot),
            torch.from_numpy(ok),
            torch.from_numpy(answers.iterations),
            source,
            reachable=torch.from_numpy(job.reachable),
        )


def as_float32(model, T: np.ndarray, q: np.ndarray, tol_pos: float, tol_rot: float):
    """``(q, pos, rot, ok)``: the float64 answers ``q: (B, dof)`` to ``T: (B, 4, 4)`` rounded to float32, clamped into
    the float32 limits, their errors measured again by FK (float32) and judged against the asked tolerances."""
    q = np.clip(q.astype(np.float32), model.lo32, model.hi32)
    pos, rot = np.empty(q.shape[0]), np.empty(q.shape[0])
    _kernels().pose_errors(model.G, model.joints, T, q.astype(np.float64), pos, rot)
    ok = (pos <= tol_pos) & (rot <= tol_rot)
    return q, pos.astype(np.float32), rot.astype(np.float32), ok
