"""All closed-form IK solutions of a 6R arm with a spherical wrist or three parallel axes.

``solve(robot, T)`` classifies the arm once (:func:`nik.analytic.geometry.family`), builds the constants of
its closed form (:mod:`nik.analytic.kernels`), and then solves any batch of poses with elementwise tensor
work: 8 candidate solutions per pose, each angle moved by 2 pi into the joint limits where possible,
and a validity mask (the candidate exists, lies inside the limits and, with ``check=True``, reaches the
pose by FK within the tolerance). Arms that fit their family only within the tolerance of
:mod:`nik.analytic.geometry` (a URDF's float32-rounded origins) get three damped Newton steps on their
own FK after the closed form.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import torch

from nik.analytic.geometry import POLISH_ABOVE, arm_geometry
from nik.analytic.kernels import KernelConstants, build_constants, run_kernel
from nik.analytic.puma560 import compiled_once, wrap_into_limits
from nik.kinematics import generate_fk_source
from nik.poses import pose_error

__all__ = ["closed_form", "reaches", "solve"]

_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def closed_form(robot) -> KernelConstants:
    """The kernel constants of ``robot`` (cached per robot and definition hash); ValueError if no closed form fits."""
    return _prepared(robot)[0]


def _prepared(robot):
    """``(constants, fk_rows)``: the closed form's constants and the robot's FK as 12 entry rows (cached)."""
    key = robot.definition_hash
    hit = _CACHE.get(robot)
    if hit is not None and hit[0] == key:
        return hit[1:]
    geom = arm_geometry(robot)
    if geom.family is None:
        raise ValueError(
            f"nik.analytic.solve: robot {getattr(robot, 'name', 'robot')!r} has no closed form: {geom.reason}"
        )
    k = build_constants(geom, robot.G.double().numpy(), robot.offsets.double().numpy(), robot.limits.double().numpy())
    k["polish"] = geom.deviation > POLISH_ABOVE * geom.size
    k = _order_by_branch(robot, k)
    namespace: dict = {"torch": torch}
    source = generate_fk_source(robot.G.numpy(), robot.offsets.numpy(), per_joint=True)
    exec(compile(source, "<nik per-joint fk>", "exec"), namespace)
    _CACHE[robot] = (key, k, namespace["fk_kernel"])
    return k, namespace["fk_kernel"]


def _polish(robot, Tf: torch.Tensor, q: torch.Tensor, steps: int = 3) -> torch.Tensor:
    """``steps`` Gauss-Newton steps on the robot's FK for ``q: (N, 8, 6)`` towards ``Tf: (N, 4, 4)``: the one torch LM
    (:func:`nik.lm.loop.lm_loop`) with a small iteration cap, no limits (the caller wraps into them), a fixed damping
    of 1e-12 (float64; 1e-6 below) and every step taken.

    For arms that fit their family only within the tolerance (:data:`nik.analytic.geometry.POLISH_ABOVE`):
    the closed form is exact for the ideal arm, and a step from there converges quadratically.
    """
    from dataclasses import replace

    from nik.lm.batched import LMCfg, chain_of, pose_evaluator
    from nik.lm.loop import Box, lm_loop

    shape = q.shape
    qf = q.reshape(-1, 1, 6)
    Tt = Tf[:, None].expand(-1, shape[1], 4, 4).reshape(-1, 4, 4)
    damping = 1e-12 if q.dtype == torch.float64 else 1e-6
    cfg = replace(LMCfg(), iters=steps, stall_iters=steps + 1, damping="fixed", eps=damping, max_step=math.inf,
                  linear_solver="lu", accept="always", cost_tol=0.0)  # fmt: skip
    chain = chain_of(robot, qf, wrap=False)
    inf = torch.full_like(chain.lo, math.inf)
    box = Box(-inf, inf, torch.zeros_like(chain.wrap))
    return lm_loop(pose_evaluator(Tt, chain, cfg, (0.0, 0.0)), qf, box, cfg).q.reshape(shape)


def _kernel(compiled: bool):
    return compiled_once(run_kernel, "nik.analytic.solve") if compiled else run_kernel


def reaches(T_target: torch.Tensor, T: torch.Tensor, tol_pos: float, tol_rot: float) -> torch.Tensor:
    """``(...,)`` bool: ``T`` within ``tol_pos`` (m) and ``tol_rot`` (rad, geodesic) of ``T_target`` (broadcast).

    Without a square root or an arc function: ``|p - p_t|^2 <= tol_pos^2`` and
    ``|R - R_t|_F^2 = 8 sin^2(angle / 2) <= 8 sin^2(tol_rot / 2)``, the same test as :func:`nik.poses.pose_error`.
    """
    d = T[..., :3, :] - T_target[..., :3, :]
    pos2 = d[..., 3].square().sum(-1)
    rot2 = d[..., :3].square().sum((-2, -1))
    return (pos2 <= tol_pos * tol_pos) & (rot2 <= 8.0 * math.sin(0.5 * tol_rot) ** 2)


def solve(
    robot,
    T: torch.Tensor,
    *,
    check: bool = True,
    tol_pos: float | None = None,
    tol_rot: float | None = None,
    compiled: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    """All (up to 8) closed-form IK solutions of a 6R arm of a known family (:func:`nik.analytic.family`).

    Args:
        robot: a :class:`nik.Robot` whose family is ``"spherical_wrist"`` or ``"three_parallel"``;
            otherwise ``ValueError`` naming the condition that failed.
        T: (..., 4, 4) target tool poses in the base frame, metres; any float dtype/device.
        check: verify every solution by FK (batched) and mark it invalid unless it reaches the pose
            within ``tol_pos`` / ``tol_rot``. With ``check=False`` the mask is existence (no square root
            of a negative number) and joint limits only.
        tol_pos: metres; default 1e-9 (float64) or 2e-5 (lower precision).
        tol_rot: radians; default 1e-9 (float64) or 2e-5 (lower precision).
        compiled: run a ``torch.compile``'d kernel (large batches; the first call compiles).

    Returns:
        ``q: (..., 8, 6)`` joint angles (radians, dtype/device of ``T``; each angle moved by a multiple
        of 2 pi into its limits where possible) and ``valid: (..., 8)`` bool. Invalid entries hold
        finite, meaningless values. Singular poses give finite solutions (where a joint is free, one
        value of it). Slot ``k`` is ``shoulder + 2 elbow + 4 wrist``; for PUMA-type and UR-type arms it
        is the branch label of :func:`nik.data.branches.ik_branch_classifier`.
    """
    if not isinstance(T, torch.Tensor) or T.ndim < 2 or T.shape[-2:] != (4, 4) or not T.is_floating_point():
        shape = tuple(T.shape) if isinstance(T, torch.Tensor) else type(T).__name__
        raise ValueError(f"nik.analytic.solve: T must be a floating-point tensor of shape (..., 4, 4), got {shape}")
    k, fk_rows = _prepared(robot)
    batch = T.shape[:-2]
    Tf = T.reshape(-1, 4, 4)
    lo, hi = robot.limits_as(Tf)
    q, valid, qs = _kernel(compiled)(Tf, k, (lo.tolist(), hi.tolist()))
    if k["polish"] and Tf.shape[0] > 0:
        q = wrap_into_limits(_polish(robot, Tf, q), lo, hi)
        valid = valid & ((q >= lo) & (q <= hi)).all(dim=-1)
        qs = [q[..., j].reshape(-1, 2, 2, 2).permute(1, 2, 3, 0) for j in range(6)]
    if check:
        exact = T.dtype == torch.float64
        tp = tol_pos if tol_pos is not None else (1e-9 if exact else 2e-5)
        tr = tol_rot if tol_rot is not None else (1e-9 if exact else 2e-5)
        if compiled:
            reached = robot.fk(q.reshape(-1, 6), compiled=True, check=False).reshape(-1, 8, 4, 4)
            valid = valid & reaches(Tf[:, None], reached, tp, tr)
        else:  # the same test entry by entry, on the FK of the per-joint angles (shared first joints once)
            e = fk_rows(qs)  # 12 entries, (2, 2, 2, N) or smaller
            pos2 = sum((e[4 * r + 3] - Tf[:, r, 3]).square() for r in range(3))
            rot2 = sum((e[4 * r + c] - Tf[:, r, c]).square() for r in range(3) for c in range(3))
            near = (pos2 <= tp * tp) & (rot2 <= 8.0 * math.sin(0.5 * tr) ** 2)
            valid = valid & near.expand(2, 2, 2, -1).permute(3, 0, 1, 2).reshape(-1, 8)
    return q.reshape(*batch, 8, 6), valid.reshape(*batch, 8)


# ---------------------------------------------------------------------------
# Solution order = branch label
# ---------------------------------------------------------------------------
def _order_by_branch(robot, k: KernelConstants) -> KernelConstants:
    """Choose the root signs so that slot ``shoulder + 2 elbow + 4 wrist`` holds that branch label.

    The solutions are laid out ``(wrist, elbow, shoulder)``; the sign of each square root depends only on
    the choices made before it, so the label bits of the 8 solutions of one generic pose fix every sign.
    The assignment is checked on several poses; if an arm's labels do not follow it (no classifier, or
    inconsistent), the natural order stays and ``k["branch_order"]`` is False.
    """
    from nik.data.branches import ik_branch_classifier

    k = KernelConstants(k)
    k["branch_order"] = False
    clf = ik_branch_classifier(robot)
    if clf is None:
        return k
    gen = torch.Generator().manual_seed(20240518)
    qs = robot.sample(32, generator=gen, dtype=torch.float64)
    T = robot.fk(qs)
    q, reach, _ = run_kernel(T, k, ([-math.inf] * 6, [math.inf] * 6))
    pe, re = pose_error(T[:, None], robot.fk(q))
    ok = reach & (pe < 1e-6) & (re < 1e-6)  # before any polish: within the family tolerance
    labels = clf(q.reshape(-1, 6)).reshape(-1, 8).long()
    new = {name: {} for name in ("s1", "s3", "s5")}
    used = 0
    for b in range(qs.shape[0]):
        if not bool(ok[b].all()) or len(set(labels[b].tolist())) != 8:
            continue
        used += 1
        for idx in range(8):
            kk, jj, ii = idx >> 2, (idx >> 1) & 1, idx & 1
            lab = int(labels[b, idx])
            nk, nj, ni = lab >> 2, (lab >> 1) & 1, lab & 1
            old = {
                "s1": (k["s1"][ii], (ni,)),
                "s3": _at(k["s3"], kk, jj, ii, nk, nj, ni),
                "s5": _at(k["s5"], kk, jj, ii, nk, nj, ni),
            }
            for name, (value, where) in old.items():
                if new[name].setdefault(where, value) != value:
                    return k  # labels do not follow the sign structure: keep the natural order
    if used < 4:
        return k
    for name in ("s1", "s3", "s5"):
        arr = np.array(k[name], dtype=float)
        for where, value in new[name].items():
            arr[where if len(where) > 1 else where[0]] = value
        if len(new[name]) != arr.size:
            return k
        k[name] = arr.tolist()
    k["branch_order"] = True
    return k


def _at(signs, kk, jj, ii, nk, nj, ni):
    """The sign at the natural index of a (wrist?, elbow?, shoulder) sign array and its label index."""
    arr = np.array(signs)
    old = (kk if arr.shape[0] == 2 else 0, jj if arr.shape[1] == 2 else 0, ii)
    new = (nk if arr.shape[0] == 2 else 0, nj if arr.shape[1] == 2 else 0, ni)
    return float(arr[old]), new
