"""Training objectives and evaluation metrics.

Two losses, usable by every method (gradient or DE), batched over any leading dimensions
(a population of networks is a leading ``(NP,)``):

- :func:`joint_mse`: paper C eq. (4), ``d = (1/N) sum_i sum_j (y_ij - y*_ij)^2``, on the network's
  raw (normalised) outputs, i.e. joint angles scaled to [-1, 1] over the training range, as a
  MATLAB ``mapminmax`` net sees them (or ``sin/cos`` targets for a ``sincos`` net).
- :func:`pose_loss`: through the differentiable FK, ``mean(|p - p*|^2) / L^2 + w * mean(c^2)`` with
  ``c^2 = ||R - R*||_F^2 / 2 = (2 sin(theta / 2))^2`` the squared chordal rotation distance (a smooth
  stand-in for the squared geodesic angle theta^2, equal to it to second order), ``L`` the network's
  workspace length scale (metres) and ``w`` the rotation weight (dimensionless: 1 rad of rotation
  costs as much as a position error of ``L``). It scores the reached pose, so it never averages two
  IK branches into a joint vector that is neither.

:func:`evaluate` gives the numbers every run reports (mm and degrees).
"""

from __future__ import annotations

import math

import torch

from nik.poses import pose_error

__all__ = ["LOSSES", "joint_mse", "pose_loss", "evaluate"]

LOSSES = ("joint", "pose", "both")


def joint_mse(y: torch.Tensor, y_target: torch.Tensor) -> torch.Tensor:
    """Paper C eq. (4). ``y: (..., N, out)``, ``y_target: (N, out)`` -> ``(...)``.

    Sum over outputs, mean over samples."""
    return (y - y_target).square().sum(-1).mean(-1)


def pose_loss(
    q: torch.Tensor, T_target: torch.Tensor, robot, *, length_scale: float | torch.Tensor, rot_weight: float = 1.0
) -> torch.Tensor:
    """Pose loss through FK.

    Args:
        q: (..., N, dof) joint angles (radians) from the network, unclamped.
        T_target: (N, 4, 4) wanted poses (metres).
        robot: the :class:`nik.Robot` whose FK is used.
        length_scale: metres, the position normaliser ``L``.
        rot_weight: weight ``w`` of the rotation term.

    Returns:
        ``(...)``: the loss per leading index (a scalar for one network).
    """
    T = robot.fk(q)
    T_target = T_target.to(T.dtype)
    pos = (T[..., :3, 3] - T_target[..., :3, 3]).square().sum(-1)
    rot = 0.5 * (T[..., :3, :3] - T_target[..., :3, :3]).square().sum((-1, -2))
    return pos.mean(-1) / (length_scale**2) + rot_weight * rot.mean(-1)


@torch.no_grad()
def evaluate(net, T: torch.Tensor, q: torch.Tensor, *, rot_weight: float = 1.0, chunk: int = 65536) -> dict:
    """Every reported metric of ``net`` on poses ``T: (N, 4, 4)`` with reference joints ``q: (N, dof)``.

    The prediction is :meth:`IKNet.predict` (clamped to the limits). Returns plain floats:
    ``joint_mse`` (eq. 4, normalised outputs), ``joint_rmse_deg`` (all joints), ``joint_max_deg``,
    ``pose_loss``, ``pos_mm_{mean,median,p95}``, ``rot_deg_{mean,median,p95}``, and ``n``.
    """
    preds, ys = [], []
    for i in range(0, T.shape[0], chunk):
        Ti = T[i : i + chunk]
        ys.append(net.raw(net.features(Ti)))
        preds.append(net.predict(Ti))
    y = torch.cat(ys)
    q_hat = torch.cat(preds).to(torch.float64)
    q_ref = q.to(torch.float64)
    T64 = T.to(torch.float64)
    T_hat = net.robot.fk(q_hat)
    pos, rot = pose_error(T64, T_hat)
    dq = q_hat - q_ref
    pos_mm, rot_deg = pos * 1e3, torch.rad2deg(rot)
    pl = pose_loss(q_hat, T64, net.robot, length_scale=float(net.length_scale), rot_weight=rot_weight)
    return {
        "n": int(T.shape[0]),
        "joint_mse": float(joint_mse(y, net.encode(q.to(y.dtype)))),
        "joint_rmse_deg": math.degrees(float(dq.square().mean().sqrt())),
        "joint_max_deg": math.degrees(float(dq.abs().max())),
        "pose_loss": float(pl),
        "pos_mm_mean": float(pos_mm.mean()),
        "pos_mm_median": float(pos_mm.median()),
        "pos_mm_p95": float(torch.quantile(pos_mm, 0.95)),
        "rot_deg_mean": float(rot_deg.mean()),
        "rot_deg_median": float(rot_deg.median()),
        "rot_deg_p95": float(torch.quantile(rot_deg, 0.95)),
    }
