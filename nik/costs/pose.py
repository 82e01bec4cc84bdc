"""The pose terms: the exact pose, and the pose bounded per axis of the target's tool frame (TRAC-IK's bounds).

Both measure :func:`nik.poses.tool_error` of the tool against the target ``T: (B, 4, 4)``, TRAC-IK's error in the
target's tool frame (position ``R_t^T (p - p_t)`` metres, rotation vector of ``R_t^T R`` radians, or with one tool
axis free the swing of that axis), the rotation rows times ``rot_weight`` (metres per radian, LM's 0.5):

- :func:`pose` (:class:`PoseTerm`): ``r = d``; check: position error <= ``tol_pos`` and geodesic angle <=
  ``tol_rot`` (:func:`nik.poses.pose_error`, the classic tolerances);
- :func:`bounded_pose` (:class:`BoundedPoseTerm`): the dead zone of the compiled LM, ``r_i = sign(d_i) max(|d_i| -
  DEAD_ZONE bound_i, 0)`` (0 on free axes; :func:`dead_zone`); check: every ``|d_i| <= bound_i``
  (:func:`nik.poses.within_bounds`). Its Jacobian is the kernel's choice: the Jacobian of ``d`` on every bounded
  row, inside its zone too (:mod:`nik.kernels.lm`, module docstring: the linear model then holds a row where it is
  instead of letting a step push it back out), zero on free rows; outside the zones it is the residual's own.

The compiled kernel of both is :func:`nik.kernels.lm.bounded_residuals` (the exact pose: zero bounds, no free
axis); :meth:`PoseTerm.compiled` and :meth:`BoundedPoseTerm.compiled` call it on numpy and the tests compare.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from nik.costs.term import Term
from nik.poses import ROT_FREE, pose_error, rotation_angle, rotation_modes, tool_error, within_bounds
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = ["DEAD_ZONE", "BoundedPoseTerm", "PoseTerm", "bounded_pose", "dead_zone", "pose"]

#: The dead zone of the bounded residual, a fraction of each bound (the compiled kernel's
#: ``nik.kernels.lm.DEAD_ZONE``; a test checks that they agree).
DEAD_ZONE = 0.5
#: Weight of the rotation rows, metres per radian (:class:`nik.lm.LMCfg`'s ``rot_weight``).
ROT_WEIGHT = 0.5


def dead_zone(d: torch.Tensor, bounds: torch.Tensor) -> torch.Tensor:
    """``sign(d) max(|d| - DEAD_ZONE * bound, 0)`` per entry of ``d: (..., 6)``; 0 on free axes (``inf`` bounds)."""
    finite = torch.isfinite(bounds)
    z = DEAD_ZONE * torch.where(finite, bounds, torch.zeros_like(bounds))
    return torch.where(finite & (d.abs() > z), d - torch.copysign(z, d), torch.zeros_like(d))


def _skew(v: torch.Tensor) -> torch.Tensor:
    """``[v]x: (..., 3, 3)`` of ``v: (..., 3)``."""
    z = torch.zeros_like(v[..., 0])
    x, y, w = v.unbind(-1)
    return torch.stack([z, -w, y, w, z, -x, -y, x, z], dim=-1).reshape(*v.shape, 3)


def _rotation_rows(d_rot: torch.Tensor, R_rel: torch.Tensor, modes: torch.Tensor) -> torch.Tensor:
    """``M: (..., 3, 3)`` with ``d(rotation rows) = M a``, ``a = R_t^T omega`` (the angular velocity in the target
    frame): ``J_l^-1`` of the rotation vector (mode -1), the swing's ``-(ds/dv) [v]x`` (mode k, row k zero), 0."""
    th2 = (d_rot * d_rot).sum(-1)
    th = th2.sqrt()
    small = th < 1e-4
    h = 0.5 * torch.where(small, torch.ones_like(th), th)
    cc = torch.where(small, torch.full_like(th, 1.0 / 12.0), (1.0 - h * torch.cos(h) / torch.sin(h)) / (4 * h * h))
    S = _skew(d_rot)
    eye = torch.eye(3, dtype=d_rot.dtype, device=d_rot.device)
    M = eye - 0.5 * S + cc[..., None, None] * (S @ S)
    M = torch.where((modes == ROT_FREE)[..., None, None], torch.zeros_like(M), M)
    for k in range(3):
        sel = modes == k
        if not bool(sel.any()):
            continue
        v = R_rel[..., :, k]
        ek = torch.zeros_like(v)
        ek[..., k] = 1.0
        vk = v[..., k]
        s2 = (v * v).sum(-1) - vk * vk
        n2 = s2 + vk * vk
        tiny = s2 < 1e-8
        sg = torch.where(tiny, torch.ones_like(s2), s2).sqrt()
        phi = torch.atan2(sg, vk)
        f = torch.where(tiny, torch.ones_like(s2), phi / sg)
        gs = torch.where(tiny, torch.full_like(s2, -2.0 / 3.0), (vk * sg / n2 - phi) / (s2 * sg))
        grad_f = gs[..., None] * (v - vk[..., None] * ek) + (-1.0 / n2)[..., None] * ek
        u = torch.linalg.cross(ek, v, dim=-1)
        dsdv = u[..., :, None] * grad_f[..., None, :] + f[..., None, None] * _skew(ek)
        Mk = -(dsdv @ _skew(v))
        M = torch.where(sel[..., None, None], Mk, M)
    return M


def bounded_residual(Tt: torch.Tensor, T: torch.Tensor, J: torch.Tensor, bounds: torch.Tensor, rw: float):
    """The bounded error of LM and its Jacobian, for poses ``T: (..., 3, 4)`` with geometric Jacobians
    ``J: (..., 6, n)`` (base frame, rows linear then angular velocity) against ``Tt: (..., 3|4, 4)`` and
    ``bounds: (..., 6)`` (``inf`` = free).

    Returns ``(e, Jr, E, pos, rot, inside)``: ``e = -r (..., 6)`` with ``r`` the dead-zone residual of
    :func:`nik.poses.tool_error` (rotation rows times ``rw``), ``Jr (..., 6, n)`` the Jacobian of that error
    (``d(tool_error)/dq``, rotation rows times ``rw``, rows of free axes zero), ``E = |e|^2``, the position
    error (m) and geodesic angle (rad) of ``T``, and ``inside``: every axis within its bound.
    """
    modes = rotation_modes(bounds)
    d = tool_error(Tt, T, modes)
    finite = torch.isfinite(bounds)
    b = torch.where(finite, bounds, torch.zeros_like(bounds))
    r = dead_zone(d, bounds)
    w = torch.tensor([1.0, 1.0, 1.0, rw, rw, rw], dtype=T.dtype, device=T.device)
    r = r * w
    inside = ((d.abs() <= b) | ~finite).all(-1)
    Rt_T = Tt[..., :3, :3].transpose(-1, -2)
    R_rel = Rt_T @ T[..., :3, :3]
    Jp = Rt_T @ J[..., :3, :]
    M = _rotation_rows(d[..., 3:], R_rel, modes)
    Jw = M @ (Rt_T @ J[..., 3:, :])
    Jr = torch.cat([Jp, Jw], dim=-2) * (w * finite.to(T.dtype))[..., :, None]
    pos = torch.linalg.vector_norm(T[..., :3, 3] - Tt[..., :3, 3], dim=-1)
    rot = rotation_angle(R_rel)
    return -r, Jr, (r * r).sum(-1), pos, rot, inside


def _analytic(robot, Tt: torch.Tensor, q: torch.Tensor, bounds, rot_weight: float):
    """``(r (B, 6), J (B, 6, dof))`` of the pose terms from one FK + geometric Jacobian (``bounds`` None: zeros)."""
    T, J = robot.fk_and_jacobian(q.detach())
    Tt = Tt.to(dtype=q.dtype, device=q.device).expand(q.shape[0], 4, 4)
    b = Tt.new_zeros(q.shape[0], 6) if bounds is None else bounds.to(Tt).expand(q.shape[0], 6)
    e, Jr, *_ = bounded_residual(Tt, T[..., :3, :], J, b, rot_weight)
    return -e, Jr


def _targets(T, batch: int | None = None) -> torch.Tensor:
    T = torch.as_tensor(T, dtype=torch.float64) if not isinstance(T, torch.Tensor) else T
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"pose term: expected target poses (B, 4, 4), got shape {tuple(T.shape)}")
    return T.reshape(-1, 4, 4)


def _rows(rot_weight: float, like: torch.Tensor) -> torch.Tensor:
    return torch.tensor([1.0, 1.0, 1.0, rot_weight, rot_weight, rot_weight], dtype=like.dtype, device=like.device)


def _compiled(robot, T: torch.Tensor, q, bounds: np.ndarray, modes: np.ndarray, rot_weight: float):
    from nik.kernels.lm import bounded_residuals

    G, joints = robot.chain_arrays()
    Q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, robot.dof))
    Tt = np.ascontiguousarray(T.detach().cpu().numpy(), dtype=np.float64)
    Tt = np.broadcast_to(Tt, (len(Q), 4, 4)).copy()
    e, J = np.empty((len(Q), 6)), np.empty((len(Q), 6, robot.dof))
    bounded_residuals(G, joints, Tt, Q, np.ascontiguousarray(bounds), np.ascontiguousarray(modes), rot_weight, e, J)
    return -e, J


@dataclass(eq=False)
class PoseTerm(Term):
    """The exact pose (module docstring). ``T: (B, 4, 4)`` (or ``(1, 4, 4)`` for every row), metres / radians."""

    robot: object
    T: torch.Tensor
    tol_pos: float = DEFAULT_TOL_POS
    tol_rot: float = DEFAULT_TOL_ROT
    rot_weight: float = ROT_WEIGHT
    weight: float = 1.0
    name: str = "pose"

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, 6)``: :func:`nik.poses.tool_error` (rotation rows times ``rot_weight``)."""
        T = self.T.to(dtype=q.dtype, device=q.device)
        return tool_error(T, self.robot.fk(q)) * _rows(self.rot_weight, q)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(r, J)`` by :func:`bounded_residual` with zero bounds: the geometric Jacobian of one FK pass mapped to
        the tool-frame error (the kernel's, exact; no autograd)."""
        return _analytic(self.robot, self.T, q, None, self.rot_weight)

    def check(self, q: torch.Tensor) -> torch.Tensor:
        pos, rot = pose_error(self.T.to(dtype=q.dtype, device=q.device), self.robot.fk(q))
        return (pos <= self.tol_pos) & (rot <= self.tol_rot)

    def why(self) -> str:
        return f"{self.name}: outside tolerance ({self.tol_pos * 1e3:.3g} mm, {np.degrees(self.tol_rot):.3g} deg)"

    def compiled(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(r (B, 6), J (B, 6, dof))`` of the compiled kernel (:func:`nik.kernels.lm.bounded_residuals`, zero
        bounds and no free axis: the same residual) for numpy ``q: (B, dof)``."""
        B = int(np.asarray(q).reshape(-1, self.robot.dof).shape[0])
        return _compiled(self.robot, self.T, q, np.zeros((B, 6)), np.full(B, -1, dtype=np.int64), self.rot_weight)


@dataclass(eq=False)
class BoundedPoseTerm(Term):
    """The pose bounded per tool axis (module docstring). ``bounds: (B, 6)`` half-widths (x, y, z m, rx, ry, rz rad,
    ``inf`` = free; :func:`nik.ik.bounds.parse_bounds` makes them from shorthands), ``T: (B, 4, 4)``."""

    robot: object
    T: torch.Tensor
    bounds: torch.Tensor
    rot_weight: float = ROT_WEIGHT
    weight: float = 1.0
    name: str = "bounds"
    _modes: torch.Tensor = field(init=False, repr=False)

    def __post_init__(self):
        self._modes = rotation_modes(self.bounds)

    def _error(self, q: torch.Tensor) -> torch.Tensor:
        T = self.T.to(dtype=q.dtype, device=q.device)
        return tool_error(T, self.robot.fk(q), self._modes.to(q.device)) * _rows(self.rot_weight, q)

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, 6)``: the dead zone of the weighted :func:`nik.poses.tool_error` (0 on free axes)."""
        b = self.bounds.to(dtype=q.dtype, device=q.device) * _rows(self.rot_weight, q)
        return dead_zone(self._error(q), b)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(r, J)`` by :func:`bounded_residual` (module docstring: bounded rows keep the Jacobian of ``d``, free
        rows zero)."""
        return _analytic(self.robot, self.T, q, self.bounds, self.rot_weight)

    def check(self, q: torch.Tensor) -> torch.Tensor:
        T = self.T.to(dtype=q.dtype, device=q.device)
        return within_bounds(T, self.robot.fk(q), self.bounds.to(dtype=q.dtype, device=q.device))

    def why(self) -> str:
        return f"{self.name}: outside the bounds"

    def compiled(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(r (B, 6), J (B, 6, dof))`` of :func:`nik.kernels.lm.bounded_residuals` for numpy ``q: (B, dof)``."""
        B = int(np.asarray(q).reshape(-1, self.robot.dof).shape[0])
        half = np.broadcast_to(self.bounds.detach().cpu().numpy().astype(np.float64), (B, 6)).copy()
        modes = np.broadcast_to(self._modes.cpu().numpy().astype(np.int64), (B,)).copy()
        return _compiled(self.robot, self.T, q, half, modes, self.rot_weight)


def pose(robot, T, *, tol_pos: float = DEFAULT_TOL_POS, tol_rot: float = DEFAULT_TOL_ROT,
         rot_weight: float = ROT_WEIGHT, weight: float = 1.0, name: str = "pose") -> PoseTerm:  # fmt: skip
    """The exact pose of the tool at ``T: (B, 4, 4)`` (metres); success within ``tol_pos`` m, ``tol_rot`` rad."""
    return PoseTerm(robot, _targets(T), float(tol_pos), float(tol_rot), float(rot_weight), float(weight), name)


def bounded_pose(robot, T, bounds, *, rot_weight: float = ROT_WEIGHT, weight: float = 1.0,
                 name: str = "bounds") -> BoundedPoseTerm:  # fmt: skip
    """The pose at ``T: (B, 4, 4)`` within ``bounds: (6,) | (B, 6)`` per tool axis (m, rad; ``inf`` = free)."""
    T = _targets(T)
    b = torch.as_tensor(np.asarray(bounds, dtype=np.float64) if not isinstance(bounds, torch.Tensor) else bounds)
    b = b.to(torch.float64).reshape(-1, 6)
    if bool(torch.isnan(b).any()) or bool((b < 0).any()):
        raise ValueError(f"bounded_pose: bounds must be half-widths >= 0 (inf = free), got {b.tolist()}")
    return BoundedPoseTerm(robot, T, b.expand(T.shape[0], 6) if b.shape[0] == 1 else b, float(rot_weight),
                           float(weight), name)  # fmt: skip
