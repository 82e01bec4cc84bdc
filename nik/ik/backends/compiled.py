"""The compiled backend: the stages' work on float64 numpy arrays through the numba kernels of :mod:`nik.kernels`.

For one pose the torch pipeline spends about a millisecond in per-operation overhead, not arithmetic; here each
piece of work is one kernel call over the whole batch. Every per-robot fact (chain arrays, limits, reach bound,
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

import numpy as np
import torch

from nik.ik.backends.base import Job, Refined
from nik.ik.guesses import LIMIT_ROUNDING
from nik.ik.model import APPROXIMATE_CHECK_TOL, CLOSED_FORM_TOL, model_of
from nik.ik.result import IKResult
from nik.ik.targets import pose_array, q_near_array

__all__ = ["APPROXIMATE_CHECK_TOL", "CLOSED_FORM_TOL", "PACKED_MAX_BATCH", "CompiledBackend"]
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

        from nik.kernels import closed, lm, seeded

        _KERNELS = SimpleNamespace(
            rank=seeded.rank,
            merge=seeded.merge,
            closed_guess=closed.guess,
            pose_errors=lm.pose_errors,
        )
    return _KERNELS


class CompiledBackend:
    """The compiled backend (see the module docstring and :mod:`nik.ik.backends` for the interface)."""

    name = "compiled"

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
    def merge(answers, job: Job, idx, res: Refined, strict: bool) -> int:
        """:meth:`nik.ik.stages.Answers.merge` in one kernel call; returns how many targets still fail."""
        return _kernels().merge(
            answers.q, answers.pos_err, answers.rot_err, answers.iterations, answers.ok(job), idx, res.q,
            res.pos_err, res.rot_err, res.iterations, strict, job.tol_pos, job.tol_rot,
        )  # fmt: skip

    # -- the job -------------------------------------------------------------------
    def job(self, robot, plan, T_target, q_near, representation) -> Job:
        T, dtype = pose_array(T_target, representation)
        model = model_of(robot, plan.lm_cfg)
        reachable, every = model.reach(T)
        if not every:
            warnings.warn(model.unreachable_message(T, reachable), UserWarning, stacklevel=4)
        near = q_near_array(q_near, T.shape[0], robot)
        tol_pos, tol_rot = plan.stage_tolerances(dtype == torch.float32)
        return Job(
            self, robot, T, reachable, near, tol_pos, tol_rot, dtype, plan.tol_pos, plan.tol_rot, model,
            numpy_out=isinstance(T_target, np.ndarray),
        )  # fmt: skip

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
            LIMIT_ROUNDING, job.tol_pos, job.tol_rot, reachable, q, pos, rot, ok,
        )  # fmt: skip
        return q, pos, rot

    # -- refiners ----------------------------------------------------------------------
    def refine(self, plan, job: Job, idx, q0, restarts: bool) -> Refined:
        T, reachable = self.rows(job.T, idx), self.rows(job.reachable, idx)
        run = job.model.lm.solve(
            T, q0, tol_pos=job.tol_pos, tol_rot=job.tol_rot, seed=plan.seed, max_iters=plan.max_iters,
            restarts=restarts, reachable=reachable,
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
            pose_errors = _kernels().pose_errors
            model = job.model
            q = np.clip(q.astype(np.float32), model.lo32, model.hi32)
            pos, rot = np.empty(q.shape[0]), np.empty(q.shape[0])
            pose_errors(model.G, model.joints, job.T, q.astype(np.float64), pos, rot)
            ok = (pos <= job.success_pos) & (rot <= job.success_rot)
            pos, rot = pos.astype(np.float32), rot.astype(np.float32)
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
