"""Damped least squares / Levenberg-Marquardt IK from joint guesses, batched.

Error of a configuration (6-vector, base frame)::

    e = [p* - p ;  rot_weight * log(R* R^T)]          (metres; rot_weight metres per radian)

with ``log`` the rotation vector (axis times angle, so ``|log| = `` the geodesic angle) and the
geometric Jacobian of :meth:`nik.Robot.fk_and_jacobian` (rotation rows scaled alike). Step::

    dq = (J^T J + lambda (diag(J^T J) + eps))^-1 J^T e        (Marquardt scaling)

limited to ``max_step`` radians per joint, then brought inside the limits (wrapping joints
wrap, the others are clamped). A step is kept only if it lowers ``|e|^2``: then lambda
shrinks by ``lambda_down``, otherwise the step is rejected and lambda grows by ``lambda_up``
(adaptive damping). Each iteration costs one FK + Jacobian per row.

Guesses are ``(B, K, dof)``: K starts per target. A target stops (costs nothing more) as soon as
one of its starts reaches tolerance; its answer is the converged start with the lowest error,
or, if none converged, the start with the lowest error.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from nik.kinematics import chain_jacobian
from nik.poses import matrix_to_quaternion
from nik.robots.model import Robot
from nik.swarm.bounds import apply_bounds, wrap_mask

__all__ = ["LMCfg", "lm_solve", "so3_log"]


@dataclass
class LMCfg:
    """Levenberg-Marquardt settings (``method="lm"`` and ``polish=True``)."""

    iters: int = 60  # iteration limit (each: one FK + Jacobian per start); converged targets stop early
    starts: int = 32  # uniform random starts per target when no guess is given (measured on 1,000 random
    #                   targets: 8 -> 92-99.9 %, 32 -> 99.3-100 % within 0.1 mm / 0.1 deg on the built-in arms)
    rot_weight: float = 0.5  # m/rad, weight of the rotation error rows
    lambda0: float = 1e-3  # initial damping (relative to diag(J^T J))
    lambda_up: float = 5.0  # damping factor after a rejected step
    lambda_down: float = 0.3  # damping factor after an accepted step
    lambda_min: float = 1e-9
    lambda_max: float = 1e6
    eps: float = 1e-9  # added to diag(J^T J), m^2
    max_step: float = 0.5  # rad, largest change of any joint in one step


def so3_log(R: torch.Tensor) -> torch.Tensor:
    """Rotation vector ``(..., 3)`` of ``R: (..., 3, 3)`` (angle in [0, pi] times the unit axis).

    Through the unit quaternion (Shepperd's method, ``w >= 0``): ``2 atan2(|v|, w) v / |v|``,
    with the limit ``2 v / w`` near the identity; robust at every angle, including pi.
    """
    quat = matrix_to_quaternion(R)
    w, v = quat[..., :1], quat[..., 1:]
    nv = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    small = nv < 1e-7
    scale = torch.where(small, 2.0 / w.clamp_min(1e-12), 2.0 * torch.atan2(nv, w) / nv.clamp_min(1e-30))
    return v * scale


def _error(T_target: torch.Tensor, T: torch.Tensor, rot_weight: float):
    """``(e (..., 6) weighted, pos (...,), rot (...,))`` for ``(..., 3, 4)`` poses."""
    dp = T_target[..., :3, 3] - T[..., :3, 3]
    w = so3_log(T_target[..., :3, :3] @ T[..., :3, :3].transpose(-1, -2))
    pos = torch.linalg.vector_norm(dp, dim=-1)
    rot = torch.linalg.vector_norm(w, dim=-1)
    return torch.cat([dp, rot_weight * w], dim=-1), pos, rot


def lm_solve(
    robot: Robot,
    T_target: torch.Tensor,
    q0: torch.Tensor,
    *,
    cfg: LMCfg | None = None,
    tol_pos: float = 1e-4,
    tol_rot: float = 1e-3,
    max_iters: int | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Levenberg-Marquardt from guesses.

    Args:
        T_target: (B, 4, 4) (or (B, 3, 4)) wanted poses, metres.
        q0: (B, dof) or (B, K, dof) starts, radians (brought inside the limits first).
        tol_pos, tol_rot: stop a target when a start is within both (metres, radians).

    Returns:
        ``q: (B, dof)`` inside the limits, and ``iterations: (B,)`` long.
    """
    cfg = cfg or LMCfg()
    iters_max = cfg.iters if max_iters is None else int(max_iters)
    dtype, device = T_target.dtype, T_target.device
    q = (q0 if q0.ndim == 3 else q0.unsqueeze(1)).to(dtype=dtype, device=device)
    B, K, n = q.shape
    lo, hi = robot.limits_as(T_target)
    wrap = wrap_mask(robot.limits, prismatic=robot.prismatic).to(device)
    G = robot.G.to(device=device, dtype=dtype)
    off = robot.offsets.to(device=device, dtype=dtype)
    prismatic = robot.prismatic_or_none
    Tt = T_target[..., :3, :].unsqueeze(1)  # (B, 1, 3, 4)
    rw = cfg.rot_weight
    row_w = torch.tensor([1.0, 1.0, 1.0, rw, rw, rw], dtype=dtype, device=device)

    def evaluate(qq, tt):
        T, J = chain_jacobian(qq.reshape(-1, n), G, off, prismatic=prismatic)
        T, J = T.reshape(*qq.shape[:-1], 3, 4), J.reshape(*qq.shape[:-1], 6, n) * row_w[:, None]
        e, pos, rot = _error(tt, T, rw)
        return e, J, pos, rot

    q, _ = apply_bounds(q, None, lo, hi, wrap, "clamp")
    e, J, pos, rot = evaluate(q, Tt)
    E = (e * e).sum(-1)
    lam = torch.full((B, K), cfg.lambda0, dtype=dtype, device=device)
    out_q = q[:, 0].clone()
    out_it = torch.zeros(B, dtype=torch.long, device=device)
    active = torch.arange(B, device=device)
    eye = torch.eye(n, dtype=dtype, device=device)

    def pick(qq, EE, conv):
        score = torch.where(conv, EE, EE + float("inf"))
        score = torch.where(conv.any(1, keepdim=True), score, EE)
        i = score.argmin(dim=1)
        return torch.gather(qq, 1, i[:, None, None].expand(-1, 1, n)).squeeze(1)

    for it in range(iters_max + 1):
        conv = (pos <= tol_pos) & (rot <= tol_rot)
        done = conv.any(dim=1)
        if bool(done.any()):
            out_q[active[done]] = pick(q[done], E[done], conv[done])
            keep = ~done
            active, q, e, J, E, lam, Tt = active[keep], q[keep], e[keep], J[keep], E[keep], lam[keep], Tt[keep]
            pos, rot = pos[keep], rot[keep]
            if active.numel() == 0:
                break
        if it == iters_max:
            break
        JT = J.transpose(-1, -2)
        A = JT @ J
        g = (JT @ e.unsqueeze(-1)).squeeze(-1)
        diag = torch.diagonal(A, dim1=-2, dim2=-1) + cfg.eps
        dq = torch.linalg.solve(A + lam[..., None, None] * torch.diag_embed(diag) + cfg.eps * eye, g)
        big = dq.abs().amax(dim=-1, keepdim=True)
        dq = dq * torch.clamp(cfg.max_step / big.clamp_min(1e-30), max=1.0)
        qc, _ = apply_bounds(q + dq, None, lo, hi, wrap, "clamp")
        ec, Jc, posc, rotc = evaluate(qc, Tt)
        Ec = (ec * ec).sum(-1)
        acc = Ec < E
        a3 = acc[..., None]
        q = torch.where(a3, qc, q)
        e = torch.where(a3, ec, e)
        J = torch.where(a3[..., None], Jc, J)
        E = torch.where(acc, Ec, E)
        pos = torch.where(acc, posc, pos)
        rot = torch.where(acc, rotc, rot)
        lam = torch.where(acc, lam * cfg.lambda_down, lam * cfg.lambda_up).clamp(cfg.lambda_min, cfg.lambda_max)
        out_it[active] += 1
    if active.numel():
        conv = (pos <= tol_pos) & (rot <= tol_rot)
        out_q[active] = pick(q, E, conv)
    return out_q, out_it
