"""The torch backend: the stages' work on tensors of the targets' dtype and device (a GPU, or CPU work the
compiled backend does not do: the swarms, ``refine="none"``, a closed-form arm's large batches).

Guesses from :mod:`nik.ik.guesses`, refiners from :mod:`nik.ik.refiners` (the batched LM of :mod:`nik.lm`, the
swarms of :mod:`nik.swarm`), validation from :mod:`nik.ik.targets`.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

from nik.ik.backends.base import Job, Refined
from nik.ik.guesses import analytic_guess, multistart_guess
from nik.ik.refiners import lm_refine, swarm_refine
from nik.ik.result import IKResult
from nik.ik.targets import as_poses, as_q_near
from nik.poses import pose_error
from nik.robots.joints import turns_toward, wrap_mask
from nik.robots.reach import unreachable_message, within_reach
from nik.tolerances import score

__all__ = ["TorchBackend"]


class TorchBackend:
    """The torch backend (see :mod:`nik.ik.backends` for the interface)."""

    name = "torch"

    # -- arrays ------------------------------------------------------------------
    @staticmethod
    def nonzero(mask):
        return mask.nonzero().squeeze(1)

    @staticmethod
    def arange(n: int, like=None):
        """``(n,)`` long indices on the device of ``like``."""
        return torch.arange(n, device=None if like is None else like.device)

    @staticmethod
    def copy(x):
        return x.clone()

    @staticmethod
    def rows(x, idx):
        """``x[idx]`` (``idx``: indices, or None for every row)."""
        return x if idx is None else x[idx]

    @staticmethod
    def put(dst, idx, src) -> None:
        dst[idx] = src.to(dst.dtype)

    @staticmethod
    def norm(x):
        return torch.linalg.vector_norm(x, dim=-1)

    @staticmethod
    def zeros_long(n: int, like=None):
        return torch.zeros(n, dtype=torch.long, device=None if like is None else like.device)

    @staticmethod
    def turns_toward(job: Job, q):
        """``q`` with its wrapping joints moved by whole turns towards ``job.q_near``."""
        lo, hi = job.robot.limits_as(q)
        wrap = wrap_mask(job.robot.limits.double(), prismatic=job.robot.prismatic).to(q.device)
        return turns_toward(q, job.q_near.to(q.dtype), lo, hi, wrap)

    @staticmethod
    def merge(answers, job: Job, idx, res: Refined, strict: bool) -> None:
        """:meth:`nik.ik.stages.Answers.merge` with tensor operations (the failing count is counted again when
        asked: None)."""
        new, old = score(res.pos_err, res.rot_err), answers.score()[idx]
        mask = new < old if strict else new <= old
        keep = idx[mask]
        answers.q[keep] = res.q[mask].to(answers.q.dtype)
        answers.pos_err[keep] = res.pos_err[mask].to(answers.pos_err.dtype)
        answers.rot_err[keep] = res.rot_err[mask].to(answers.rot_err.dtype)
        answers.iterations[idx] += res.iterations.to(answers.iterations.dtype)
        answers._ok = None

    # -- one call --------------------------------------------------------------------------
    def solve(self, robot, plan, T_target, q_near, representation) -> IKResult:
        """The plan on the targets: validated (:meth:`job`), then the stages in a Python loop
        (:func:`nik.ik.stages.run`) with the thread count of :func:`nik.threads.threads_for`."""
        from nik.ik import stages
        from nik.threads import threads_for

        if plan.bounds is not None:  # a tolerant goal: the goal stages (nik.ik.goals)
            from nik.ik import goals

            with threads_for(T_target.shape[0] if hasattr(T_target, "shape") else 1):
                return goals.solve_torch(self, robot, plan, T_target, q_near, representation)
        job = self.job(robot, plan, T_target, q_near, representation, stacklevel=4)
        with threads_for(job.size):
            return stages.run(plan, job)

    # -- the job -------------------------------------------------------------------
    def job(self, robot, plan, T_target, q_near, representation, *, stacklevel: int = 2) -> Job:
        T = as_poses(T_target, representation)
        reachable = within_reach(robot, T)
        msg = unreachable_message(robot, T, reachable)
        if msg is not None:
            warnings.warn(msg, UserWarning, stacklevel=stacklevel)
        near = as_q_near(q_near, T, robot.dof, prismatic=robot.prismatic, limits=robot.limits)
        tol_pos, tol_rot = plan.stage_tolerances(T.dtype == torch.float32)
        numpy_out = isinstance(T_target, np.ndarray)
        return Job(
            self, robot, T, reachable, near, tol_pos, tol_rot, T.dtype, plan.tol_pos, plan.tol_rot, None, numpy_out
        )

    # -- guesses -----------------------------------------------------------------------
    def network(self, plan, job: Job):
        net, T, robot = plan.net, job.T, job.robot
        if plan.net_in_arm_frame:  # the network's arm without the frames: its input in that frame, ranked here
            from nik.ik.stages import _arm_targets
            from nik.nets.multi import hypothesis_pose_error

            Ta = _arm_targets(robot, T)
            hyp = net.hypotheses(Ta) if hasattr(net, "hypotheses") else robot.clamp(net.predict(Ta))[:, None]
            pos, rot = hypothesis_pose_error(robot, T, hyp)
            order = score(pos, rot).argsort(dim=-1)
            hyp = torch.gather(hyp, 1, order[..., None].expand(-1, -1, hyp.shape[-1]))
        elif hasattr(net, "ranked_hypotheses"):
            hyp = net.ranked_hypotheses(T)[0]
        else:  # a plain network: one hypothesis
            hyp = robot.clamp(net.predict(T))[:, None]
        pos, rot = pose_error(T, robot.fk(hyp[:, 0]))
        return hyp, pos, rot, None

    def closed_form(self, plan, job: Job, idx, q_near):
        T = job.T if idx is None else job.T[idx]
        q = analytic_guess(job.robot, T, q_near=q_near)
        pos, rot = pose_error(T, job.robot.fk(q))
        return q, pos, rot

    def uniform_guess(self, plan, job: Job):
        return multistart_guess(job.robot, job.T, seed=plan.seed)

    # -- refiners ----------------------------------------------------------------------
    def refine(self, plan, job: Job, idx, q0, restarts: bool, local: bool = False) -> Refined:
        if plan.refine == "lm":
            return self.lm(plan, job, idx, q0, restarts, local)
        T = self.rows(job.T, idx)
        res = swarm_refine(
            job.robot, T, q0, method=plan.refine, cfg=plan.swarm_cfg, polish=plan.polish, tol_pos=job.tol_pos,
            tol_rot=job.tol_rot, seed=plan.seed, max_iters=plan.max_iters,
        )  # fmt: skip
        dt = T.dtype
        return Refined(res.q.to(dt), res.pos_err.to(dt), res.rot_err.to(dt), res.iterations.long())

    def lm(self, plan, job: Job, idx, q0, restarts: bool, local: bool = False) -> Refined:
        """Levenberg-Marquardt with the plan's settings and cap, whatever the refine method (the multistart
        fallback)."""
        T = self.rows(job.T, idx)
        res = lm_refine(
            job.robot, T, q0, tol_pos=job.tol_pos, tol_rot=job.tol_rot, seed=plan.seed, max_iters=plan.max_iters,
            cfg=plan.lm_cfg, restarts=restarts, reachable=self.rows(job.reachable, idx), local=local,
        )  # fmt: skip
        return Refined(res.q.to(T.dtype), res.pos_err.to(T.dtype), res.rot_err.to(T.dtype), res.iterations.long())

    def lm_starts(self, plan, job: Job, idx, starts) -> Refined:
        from nik.lm import lm_solve

        robot = job.robot
        T = self.rows(job.T, idx)
        g = torch.Generator(device=T.device).manual_seed(int(plan.seed))
        hq, it = lm_solve(
            robot, T, starts, cfg=plan.lm_cfg, tol_pos=job.tol_pos, tol_rot=job.tol_rot, max_iters=plan.max_iters,
            restarts=0, generator=g,
        )  # fmt: skip
        hq = robot.clamp(hq).to(T.dtype)
        pos, rot = pose_error(T, robot.fk(hq))
        return Refined(hq, pos, rot, it.long())

    # -- the result ----------------------------------------------------------------------
    def result(self, job: Job, answers, source: str) -> IKResult:
        ok = (answers.pos_err <= job.success_pos) & (answers.rot_err <= job.success_rot)
        res = IKResult(
            answers.q, answers.pos_err, answers.rot_err, ok, answers.iterations, source, reachable=job.reachable
        )
        return res.numpy() if job.numpy_out else res
