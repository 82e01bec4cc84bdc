"""Several IK solutions per pose from a network: every hypothesis polished on its own (the IKFlow / PAIK use).

A multi-hypothesis network (:mod:`nik.nets.multi`) gives ``K`` joint vectors per pose, one per head, each on its
own branch or posture. Raw, a head that does not win a pose lands centimetres off it (shipped panda: 18 mm mean
per sample). :func:`network_samples` keeps every head as a sample and runs a few iterations of nik's LM
(:func:`nik.lm.batched.lm_solve`: Marquardt damping, the joint limits held by the active set, no restarts) from
each, separately: the samples stay on their heads' branches, so they stay as diverse as the heads, and the ones
the network put near a solution land on it.

Choices, and what they cost (``python benchmarks/raw_accuracy.py``, panda / xarm7, 2,000 targets, one thread):

- ``iters=5``: per-sample error 1.0 / 1.6 mm mean, 0.4 / 0.5 deg (the raw heads: 18.3 / 25.5 mm); about 15 us a
  sample in torch on the CPU at a batch of 2,000 poses;
- ``rot_weight=0.1`` m/rad: the LM weighs 1 rad of rotation error like 10 cm of position, chosen on other seeds
  than the benchmark's between 0.05 and 0.2 for the lowest of position / 2.9 mm + rotation / 1.5 deg (PAIK's
  figures); the solver's own LM uses 0.5, as its goal is both tolerances, not a balanced error;
- no restarts: a head that cannot reach the pose from where it starts stays the best effort near it, rather than
  becoming another head's solution (a sample, not an answer; :meth:`nik.IKSolver.solve` is for answers).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from nik.lm.batched import lm_solve
from nik.lm.loop import LMCfg
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["SampleCfg", "network_samples", "refine_samples"]


@dataclass(frozen=True)
class SampleCfg:
    """How samples are polished: ``iters`` LM iterations each (0: the raw heads), rotation rows weighted
    ``rot_weight`` (m/rad), stopping where within ``tol_pos`` (m) and ``tol_rot`` (rad)."""

    iters: int = 5
    rot_weight: float = 0.1
    tol_pos: float = DEFAULT_TOL_POS
    tol_rot: float = DEFAULT_TOL_ROT


def refine_samples(robot, T: torch.Tensor, q: torch.Tensor, cfg: SampleCfg = SampleCfg()) -> torch.Tensor:
    """``q: (B, K, dof)`` samples for poses ``T: (B, 4, 4)`` -> ``(B, K, dof)``, each polished by ``cfg.iters`` LM
    iterations on its own (no restarts), inside the limits; dtype/device of ``T``."""
    if q.ndim != 3 or q.shape[0] != T.shape[0] or q.shape[-1] != robot.dof:
        raise ValueError(f"samples: expected q of shape ({T.shape[0]}, K, {robot.dof}), got {tuple(q.shape)}")
    B, K, dof = q.shape
    q = q.to(dtype=T.dtype, device=T.device)
    if cfg.iters <= 0:
        return robot.clamp(q)
    TT = T[:, None].expand(B, K, 4, 4).reshape(B * K, 4, 4)
    lm = replace(LMCfg(), rot_weight=float(cfg.rot_weight))
    out, _ = lm_solve(
        robot, TT, q.reshape(B * K, dof), cfg=lm, tol_pos=cfg.tol_pos, tol_rot=cfg.tol_rot, max_iters=cfg.iters,
        restarts=0,
    )  # fmt: skip
    return out.reshape(B, K, dof)


def network_samples(net, T: torch.Tensor, cfg: SampleCfg = SampleCfg()) -> torch.Tensor:
    """Every hypothesis of ``net`` (a multi-hypothesis network) for poses ``T: (B, 4, 4)``, polished:
    ``(B, K, dof)`` inside the limits (:func:`refine_samples`)."""
    return refine_samples(net.robot, T, net.hypotheses(T), cfg)
