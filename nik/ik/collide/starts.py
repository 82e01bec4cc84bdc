"""The starts of the collision re-solve beyond the answer itself: the closed form's valid branches (closed-form
arms) or the network's hypotheses, ranked (:func:`_starts`)."""

from __future__ import annotations

import numpy as np
import torch

from nik.ik.collide.choice import _numpy


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
