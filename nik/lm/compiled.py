"""Levenberg-Marquardt for a few poses through the compiled kernel of :mod:`nik.kernels.lm` (numpy in and out).

The algorithm and its settings are those of the batched torch LM (:class:`~nik.lm.batched.LMCfg`): the same
error, damping, active set at the limits, stall test and iteration limits. What differs is the work per
target: torch's per-operation overhead (microseconds per op, dozens of ops per iteration) is gone, one
iteration of a 7-joint arm costs about a microsecond, so a target is solved in tens of microseconds. Each
target that is within reach may draw the batched LM's whole restart budget
(``restarts + tail_starts * (1 + tail_restarts)`` fresh uniform starts, 274 by default) one after the other;
those after the first ``restarts`` run longer (:data:`TAIL_ITERS_FACTOR`, :data:`TAIL_STALL_FACTOR`): the
batched LM gives its few hard targets many starts side by side, here they get longer runs in turn.

Without a guess, the first start is the best of :data:`FIRST_STARTS` uniform configurations by pose error
(measured, ``benchmarks/latency_kernels.py --sweep``: 4 to 16 candidates give the lowest median and p95 on
panda, ur5 and kuka_kr; 64, the numpy path's count, costs 10 us more per pose in FK alone).

Random starts come from the kernel's seeded streams (target ``b`` of a call: the stream ``b`` of ``seed``),
not from a ``torch.Generator``: the same seed gives the same answer on this path, not the batched path's.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field

import numpy as np

from nik.lm.batched import LMCfg

__all__ = ["FIRST_STARTS", "TAIL_ITERS_FACTOR", "TAIL_STALL_FACTOR", "CompiledLM", "CompiledRun", "restart_budget"]

#: Uniform configurations whose best (by pose error) is the first start of a target without a guess.
FIRST_STARTS = 8
#: The restarts after the first ``LMCfg.restarts`` (the batched LM's first pass) run this many times longer
#: (``iters``) and wait this many times longer for progress (``stall_iters``). Measured on the 20 hardest of
#: 5,000 panda targets, 20 seeds each: mean 280 -> 155 iterations, worst 4,295 -> 1,844, failures 1 -> 0 of 400;
#: the other targets are solved within the first pass and do not see it.
TAIL_ITERS_FACTOR = 4
TAIL_STALL_FACTOR = 2.5


def restart_budget(cfg: LMCfg) -> int:
    """Fresh uniform starts a failing target within reach may draw: the batched LM's total
    (``restarts`` in the first pass, then ``tail_starts`` starts with ``tail_restarts`` restarts each)."""
    return int(cfg.restarts + cfg.tail_starts * (1 + cfg.tail_restarts))


@dataclass
class CompiledRun:
    """What :meth:`CompiledLM.solve` returns for B targets (numpy).

    Attributes:
        q: (B, dof) float64 answers inside the limits (the first start within tolerance, else the start with the
            lowest error).
        iterations: (B,) int64, LM iterations spent over all starts.
        converged: (B,) bool, ``q`` within both tolerances.
        pos_err: (B,) metres; rot_err: (B,) radians (geodesic), of ``q``.
    """

    q: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    pos_err: np.ndarray
    rot_err: np.ndarray


def astuple_run(run: CompiledRun) -> tuple:
    """The fields of ``run`` in order (the kernel's output arguments)."""
    return run.q, run.iterations, run.converged, run.pos_err, run.rot_err


@dataclass
class CompiledLM:
    """The compiled LM of one robot with one :class:`LMCfg` (build with :meth:`of`).

    Attributes:
        G, joints: the model arrays (:meth:`nik.Robot.chain_arrays`).
        opts, iopts: the kernel's options from the config (tolerances and iteration limit set per call).
        budget: restarts a target within reach may draw (:func:`restart_budget`).

    Nothing here is written by :meth:`solve` but the small cache of per-call options (Python dicts, safe under
    threads); the kernel allocates its scratch per call and releases the GIL, so threads may share one model.
    """

    G: np.ndarray
    joints: np.ndarray
    opts: np.ndarray
    iopts: np.ndarray
    budget: int
    _per_call: dict = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, robot, cfg: LMCfg | None = None) -> CompiledLM:
        """The compiled LM of ``robot`` and ``cfg`` (default :class:`LMCfg`), built once per pair and kept."""
        per_robot = _MODELS.setdefault(robot, {})
        key = None if cfg is None else tuple(vars(cfg).values())  # a changed config gets its own model
        model = per_robot.get(key)
        if model is None:
            cfg = cfg or LMCfg()
            from nik.kernels.lm import lm_options

            opts, iopts = lm_options(
                rot_weight=cfg.rot_weight,
                lambda0=cfg.lambda0,
                lambda_up=cfg.lambda_up,
                lambda_down=cfg.lambda_down,
                lambda_min=cfg.lambda_min,
                lambda_max=cfg.lambda_max,
                eps=cfg.eps,
                max_step=cfg.max_step,
                stall_rel=cfg.stall_rel,
                first_iters=cfg.iters,
                iters=cfg.iters,
                stall_iters=cfg.stall_iters,
                tail_after=cfg.restarts,
                tail_iters=TAIL_ITERS_FACTOR * cfg.iters,
                tail_stall_iters=math.ceil(TAIL_STALL_FACTOR * cfg.stall_iters),
            )
            G, joints = robot.chain_arrays()
            model = cls(G, joints, opts, iopts, restart_budget(cfg))
            per_robot[key] = model
        return model

    def solve(
        self,
        T: np.ndarray,
        q0: np.ndarray | None,
        *,
        tol_pos: float,
        tol_rot: float,
        seed: int,
        max_iters: int | None = None,
        restarts: bool = True,
        reachable: np.ndarray | None = None,
        local: bool = False,
    ) -> CompiledRun:
        """LM for ``T: (B, 4, 4)`` float64 from ``q0: (B, dof)`` (None: the best of :data:`FIRST_STARTS` uniform
        configurations), restarting the targets that fail (``restarts=False``: none; none either where
        ``reachable: (B,)`` is False). ``local``: no joint wraps (a step across a limit of a joint of a range of
        ``2 pi`` or more is clamped, not moved a turn: the answer stays near ``q0``)."""
        klm = _klm()
        B, n = T.shape[0], self.joints.shape[0]
        opts, iopts = self.options(tol_pos, tol_rot, max_iters, multistart=q0 is None)
        if q0 is None:
            q0 = np.zeros((B, n))
        elif q0.dtype != np.float64 or not q0.flags.c_contiguous:
            q0 = np.ascontiguousarray(q0, dtype=np.float64)
        budget = self.budget if restarts else 0
        budget = np.full(B, budget, dtype=np.int64) if reachable is None else np.where(reachable, budget, 0)
        if T.dtype != np.float64 or not T.flags.c_contiguous:
            T = np.ascontiguousarray(T, dtype=np.float64)
        run = CompiledRun(
            np.empty((B, n)), np.empty(B, dtype=np.int64), np.empty(B, dtype=bool), np.empty(B), np.empty(B)
        )
        joints = self.joints
        if local:
            from nik.kernels.chain import WRAPS

            joints = joints.copy()
            joints[:, WRAPS] = 0.0
        klm.lm_solve(self.G, joints, T, q0, opts, iopts, budget, _seed(klm, seed), astuple_run(run))
        return run

    def solve_starts(
        self,
        T: np.ndarray,
        starts: np.ndarray,
        *,
        tol_pos: float,
        tol_rot: float,
        seed: int,
        max_iters: int | None = None,
    ) -> CompiledRun:
        """LM for ``T: (B, 4, 4)`` float64 from each target's starts ``starts: (B, K, dof)`` in turn (the first that
        reaches the tolerance ends it; no uniform restarts): :func:`nik.kernels.seeded.lm_starts`."""
        from nik.kernels.seeded import lm_starts

        klm = _klm()
        B, n = T.shape[0], self.joints.shape[0]
        opts, iopts = self.options(tol_pos, tol_rot, max_iters)
        run = CompiledRun(
            np.empty((B, n)), np.empty(B, dtype=np.int64), np.empty(B, dtype=bool), np.empty(B), np.empty(B)
        )
        T = np.ascontiguousarray(T, dtype=np.float64)
        starts = np.ascontiguousarray(starts, dtype=np.float64)
        lm_starts(self.G, self.joints, T, starts, opts, iopts, _seed(klm, seed), *astuple_run(run))
        return run

    def options(
        self, tol_pos: float, tol_rot: float, max_iters: int | None = None, *, multistart: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(opts, iopts)`` of the kernels (:func:`nik.kernels.lm.lm_options`) with the call's tolerances (metres,
        radians), iteration limit of the first start (None: the config's) and, with ``multistart``, the best of
        :data:`FIRST_STARTS` uniform configurations as the first start (else the given start is the first);
        kept per value. Every caller of the LM kernels (this class, the paths' chains) takes them from here."""
        klm = _klm()
        key = (float(tol_pos), float(tol_rot), max_iters, multistart)
        found = self._per_call.get(key)
        if found is None:
            opts, iopts = self.opts.copy(), self.iopts.copy()
            opts[klm.TOL_POS], opts[klm.TOL_ROT] = tol_pos, tol_rot
            if max_iters is not None:
                iopts[klm.FIRST_ITERS] = int(max_iters)
            if multistart:
                iopts[klm.FIRST_STARTS] = FIRST_STARTS
            if len(self._per_call) > 64:
                self._per_call.clear()
            found = self._per_call[key] = (opts, iopts)
        return found


_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_KLM = None
_SEEDS: dict[int, np.ndarray] = {}


def _klm():
    """:mod:`nik.kernels.lm`, imported on first use."""
    global _KLM
    if _KLM is None:
        from nik.kernels import lm

        _KLM = lm
    return _KLM


def _seed(klm, seed) -> np.ndarray:
    """The kernel's random state of ``seed`` (kept for the seeds in use; the kernel only reads it)."""
    state = _SEEDS.get(seed)
    if state is None:
        if len(_SEEDS) > 256:
            _SEEDS.clear()
        state = _SEEDS[seed] = klm.seed_state(seed)
    return state
