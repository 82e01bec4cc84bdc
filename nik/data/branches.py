"""IK branch labels for 6R arms of the PUMA type (shoulder, elbow, wrist flip).

An arm qualifies when, like the PUMA 560 and ``kuka_kr``, it has 6 revolute joints, joints 2
and 3 have parallel axes (a planar shoulder-elbow pair), joint 1's axis is not parallel to
them, and joints 4, 5, 6 form a spherical wrist (their axes meet in one point, the wrist
centre ``c``). Such an arm reaches a generic pose in up to 8 ways: two shoulder choices,
two elbow choices, two wrist flips. The label of a configuration ``q`` is defined from the
geometry of the arm at ``q`` (all in the base frame):

- ``a_i``: unit axis of joint ``i``; ``p_i``: a point on it; ``s = p_2`` (shoulder axis),
  ``e = p_3`` (elbow axis); ``c``: the wrist centre (least-squares meeting point of axes 4..6).
- **shoulder** ``t = (c - p_1) . (a_2 x a_1)``: the wrist centre's reach along the arm's
  forward direction ``a_2 x a_1``, measured from the joint-1 axis. ``t = 0`` is the shoulder
  singularity (for the PUMA 560: the wrist centre on the cylinder of radius d2 about axis 1,
  where the two solutions of theta1 meet). The sign of ``a_2`` is a DH accident, so the side
  that holds the zero configuration ``q = 0`` is called *front* (bit 0 = 0) and the other
  *back* (bit 0 = 1): the arm reaches over its own shoulder.
- **elbow** ``u = ((e - s) x (c - s)) . a_2``: which side of the line shoulder -> wrist centre
  the elbow axis lies on, in the arm plane (components along ``a_2`` drop out, so the d and a
  offsets of the links do not matter). ``u * t > 0`` (``t`` as defined above, before the
  front orientation): *up*, the elbow above that line when ``a_1`` points up (bit 1 = 0);
  ``u * t < 0``: *down* (bit 1 = 1). ``u = 0`` is the elbow singularity (arm stretched or
  folded: shoulder, elbow and wrist centre in line).
- **wrist** ``w = (a_4 x a_6) . a_5``: the sine of the angle from axis 4 to axis 6 about axis 5.
  ``w > 0``: *noflip* (bit 2 = 0); ``w < 0``: *flip* (bit 2 = 1). ``w = 0`` is the wrist
  singularity (axes 4 and 6 aligned). For ``puma560`` and ``kuka_kr`` the flip bit is exactly
  ``sin(q5) < 0`` (tested).

``label = shoulder + 2 * elbow + 4 * wrist`` in 0..7. The two solutions of each choice differ
in exactly that bit (the wrist flip ``(theta4 + pi, -theta5, theta6 + pi)`` negates ``a_5`` and
keeps ``a_4, a_6``; the elbow pair mirrors ``e`` across the line ``s c``; the shoulder pair
changes the sign of ``t``), so the 8 IK solutions of a generic pose get 8 distinct labels, and a
label is constant on each connected region of configurations between singularities.
"""

from __future__ import annotations

import torch

from nik.kinematics import chain_joint_frames

__all__ = [
    "BRANCH_NAMES",
    "BranchClassifier",
    "URBranchClassifier",
    "branch_classifier",
    "branch_labels",
    "branch_name",
    "ik_branch_classifier",
    "joint_frames",
    "ur_branch_classifier",
]

#: Human names of the three bits, value 0 first.
BRANCH_NAMES = (("front", "back"), ("up", "down"), ("noflip", "flip"))
_TOL = 1e-7  # metres / unit vectors: structural checks


def branch_name(label: int) -> str:
    """``5`` -> ``"back/up/flip"``."""
    label = int(label)
    if not 0 <= label <= 7:
        raise ValueError(f"branch label must be in 0..7, got {label}")
    return "/".join(names[(label >> bit) & 1] for bit, names in enumerate(BRANCH_NAMES))


def joint_frames(robot, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Joint axes and points in the base frame.

    Args:
        q: (B, dof) radians.

    Returns:
        ``axes: (B, dof, 3)`` unit axis of each joint and ``points: (B, dof, 3)`` a point on it
        (the origin of the frame the joint turns), metres; dtype of ``q``.
    """
    G, off = robot.G.to(q.device, q.dtype), robot.offsets.to(q.device, q.dtype)
    _, axes, points = chain_joint_frames(q, G, off, prismatic=getattr(robot, "prismatic_or_none", None))
    return axes.transpose(1, 2), points.transpose(1, 2)


def _meeting_point(axes: torch.Tensor, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Least-squares point nearest to the lines ``points[:, k] + t axes[:, k]``: ``(B, 3)`` and residual ``(B,)``."""
    eye = torch.eye(3, dtype=axes.dtype, device=axes.device)
    P = eye - axes.unsqueeze(-1) * axes.unsqueeze(-2)  # (B, k, 3, 3) projectors orthogonal to each axis
    A = P.sum(1)
    b = (P @ points.unsqueeze(-1)).sum(1)
    x = torch.linalg.solve(A, b).squeeze(-1)
    resid = (P @ (x.unsqueeze(1) - points).unsqueeze(-1)).squeeze(-1).norm(dim=-1).amax(-1)
    return x, resid


class BranchClassifier:
    """Computes the branch label (0..7) of joint vectors of one PUMA-type arm; see the module docstring.

    Fast path: every quantity behind the label is invariant under the rotations that do not
    change it, so it depends on few joints only: ``w`` on q5, ``u`` on q3, ``t`` on q2 and q3
    (expressed in the link frames: the wrist centre is a fixed point of link 3, the elbow axis
    a fixed line of link 2). The constants are extracted once from the robot's normal form;
    :meth:`components_reference` computes the same from full joint frames (used by the tests).
    """

    def __init__(self, robot):
        self.robot = robot
        G = robot.G.double()
        R = G[:, :3, :3]
        off = robot.offsets.double()
        self._off = off
        # wrist centre as a fixed point of link 3, in the frame F_4 = G0 Rz1 G1 Rz2 G2 Rz3 G3 (joint 4's frame)
        q0 = torch.zeros(1, robot.dof, dtype=torch.float64)
        axes, points = joint_frames(robot, q0)
        c_world, _ = _meeting_point(axes[:, 3:6], points[:, 3:6])
        F4 = _frame_before(robot, q0, 4)[0]  # (4, 4)
        c4 = F4[:3, :3].T @ (c_world[0] - F4[:3, 3])
        h = G[3, :3, :3] @ c4 + G[3, :3, 3]  # the wrist centre in the frame rotated by joint 3 (before Rz3)
        e2 = G[2, :3, 3]  # elbow-axis point in link-2 frame (frame after Rz2); shoulder point is its origin
        RG2 = R[2]
        # c2(q3) = e2 + RG2 Rz(theta3) h ;  u = (e2 x (RG2 Rz3 h))_z, linear in cos3, sin3
        # Rz3 h = cos3 * (hx, hy, 0) + sin3 * (-hy, hx, 0) + (0, 0, hz)
        self._hc = RG2 @ torch.stack([h[0], h[1], torch.zeros((), dtype=h.dtype)])
        self._hs = RG2 @ torch.stack([-h[1], h[0], torch.zeros((), dtype=h.dtype)])
        self._h1 = RG2 @ torch.stack([torch.zeros((), dtype=h.dtype), torch.zeros((), dtype=h.dtype), h[2]])
        self._e2 = e2
        # t = (c - p1) . (a2 x a1) in the frame after Rz1 (a1 = e_z, p1 = 0): c1 = G1 Rz2 c2
        a2 = R[1] @ torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
        f = torch.linalg.cross(a2, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
        self._t0 = float(f @ G[1, :3, 3])
        self._g = R[1].T @ f
        # w = (a4 x a6) . a5 in the frame before Rz5: a5 = e_z, a4 = R(G4)^T e_z, a6 = Rz5 R(G5) e_z
        a4 = R[4].T[:, 2]
        g5 = R[5][:, 2]
        self._wA = float(a4[0] * g5[0] + a4[1] * g5[1])  # * sin5
        self._wB = float(a4[0] * g5[1] - a4[1] * g5[0])  # * cos5
        # orient "front" so that the zero configuration is front (or, if it is shoulder-singular, the centre of
        # the limits)
        self._front = 1.0
        for qref in (q0, robot.limits.mean(-1).reshape(1, -1)):
            t_ref = float(self._raw(qref)[0][0])
            if abs(t_ref) > 1e-6:
                self._front = 1.0 if t_ref > 0 else -1.0
                break

    def _raw(self, q: torch.Tensor):
        """Unoriented ``t, u, w``, each ``(B,)``, from q2, q3, q5 only."""
        dt = q.dtype
        th = (q[:, [1, 2, 4]].T + self._off[[1, 2, 4]].to(q.device, dt)[:, None]).contiguous()  # (3, B)
        cs, sn = torch.cos(th), torch.sin(th)
        c2, c3, c5 = cs.unbind(0)
        s2, s3, s5 = sn.unbind(0)
        hc, hs, h1, e2 = (x.to(q.device, dt) for x in (self._hc, self._hs, self._h1, self._e2))
        # v = RG2 Rz3 h  (B, 3); c2vec = e2 + v
        vx = c3 * hc[0] + s3 * hs[0] + h1[0]
        vy = c3 * hc[1] + s3 * hs[1] + h1[1]
        vz = c3 * hc[2] + s3 * hs[2] + h1[2]
        u = e2[0] * vy - e2[1] * vx
        cx, cy, cz = vx + e2[0], vy + e2[1], vz + e2[2]
        g = self._g.tolist()
        t = self._t0 + g[0] * (c2 * cx - s2 * cy) + g[1] * (s2 * cx + c2 * cy) + g[2] * cz
        w = self._wA * s5 + self._wB * c5
        return t, u, w

    def components(self, q: torch.Tensor) -> dict[str, torch.Tensor]:
        """The signed quantities behind the label, each ``(B,)``: ``t`` (m), ``u`` (m^2, times sign t), ``w`` (1).

        Their magnitudes measure the distance from the corresponding singularity.
        """
        t, u, w = self._raw(q)
        return {"t": self._front * t, "u": u * torch.sign(t), "w": w}

    def components_reference(self, q: torch.Tensor) -> dict[str, torch.Tensor]:
        """:meth:`components` computed the long way, from the joint axes and points in the base frame."""
        axes, points = joint_frames(self.robot, q)
        a1, a2, a4, a5, a6 = axes[:, 0], axes[:, 1], axes[:, 3], axes[:, 4], axes[:, 5]
        p1, s, e = points[:, 0], points[:, 1], points[:, 2]
        c, _ = _meeting_point(axes[:, 3:6], points[:, 3:6])
        t = ((c - p1) * torch.linalg.cross(a2, a1)).sum(-1)
        u = (torch.linalg.cross(e - s, c - s) * a2).sum(-1)
        w = (torch.linalg.cross(a4, a6) * a5).sum(-1)
        return {"t": self._front * t, "u": u * torch.sign(t), "w": w}

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        """``q: (B, dof)`` -> ``(B,)`` uint8 labels in 0..7 (computed in float64)."""
        t, u, w = self._raw(q.double())
        shoulder = (t * self._front < 0).to(torch.uint8)
        elbow = (u * t < 0).to(torch.uint8)  # sign(u * t) == sign(u * sign t), t unoriented (module docstring)
        return shoulder | (elbow << 1) | ((w < 0).to(torch.uint8) << 2)


def _frame_before(robot, q: torch.Tensor, joint: int) -> torch.Tensor:
    """``(B, 4, 4)`` frame ``G0 Rz(theta1) G1 ... Rz(theta_{joint-1}) G_{joint-1}``; its z axis is joint ``joint``'s."""
    G, off = robot.G.to(q.device, q.dtype), robot.offsets.to(q.device, q.dtype)
    T = G[0].expand(q.shape[0], 4, 4)
    for i in range(joint - 1):
        th = q[:, i] + off[i]
        c, s = torch.cos(th), torch.sin(th)
        Rz = torch.zeros(q.shape[0], 4, 4, dtype=q.dtype, device=q.device)
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1] = c, -s, s, c
        Rz[:, 2, 2] = Rz[:, 3, 3] = 1.0
        T = T @ Rz @ G[i + 1]
    return T


def branch_classifier(robot) -> BranchClassifier | None:
    """The branch classifier of ``robot``, or None if the arm is not of the PUMA type.

    The structure is checked numerically at a few fixed configurations: 6 joints, axes 2 and
    3 parallel, axis 1 not parallel to axis 2, axes 4, 5, 6 meeting in one point, all revolute.
    """
    if robot.dof != 6 or bool(getattr(robot, "prismatic", torch.zeros(1, dtype=torch.bool)).any()):
        return None
    g = torch.Generator().manual_seed(12345)
    q = robot.sample(8, generator=g, dtype=torch.float64)
    axes, points = joint_frames(robot, q)
    a1, a2, a3 = axes[:, 0], axes[:, 1], axes[:, 2]
    if torch.linalg.cross(a2, a3).norm(dim=-1).max() > _TOL:
        return None
    if torch.linalg.cross(a1, a2).norm(dim=-1).min() < 1e-3:
        return None
    wrist = axes[:, 3:6]
    # consecutive wrist axes must not be parallel, and all three must meet in a point
    if torch.linalg.cross(wrist[:, 0], wrist[:, 1]).norm(dim=-1).min() < 1e-3:
        return None
    if torch.linalg.cross(wrist[:, 1], wrist[:, 2]).norm(dim=-1).min() < 1e-3:
        return None
    _, resid = _meeting_point(wrist, points[:, 3:6])
    if resid.max() > _TOL:
        return None
    return BranchClassifier(robot)


def branch_labels(robot, q: torch.Tensor) -> torch.Tensor:
    """``q: (B, dof)`` -> ``(B,)`` uint8 branch labels; ValueError for arms without a classifier."""
    clf = branch_classifier(robot)
    if clf is None:
        raise ValueError(
            f"robot {robot.name!r} has no IK branch classification (it needs 6 joints, parallel "
            "axes 2 and 3 and a spherical wrist, like puma560 and kuka_kr)"
        )
    return clf(q)


class URBranchClassifier:
    """Branch labels (0..7) of 6R arms of the UR type: joints 2, 3, 4 parallel, joint 1 not parallel to
    them, axes 5 and 6 meeting in a point ``P`` (the UR5/UR10 family).

    Such an arm reaches a generic pose in up to 8 ways, two choices each of the shoulder (q1), the wrist
    (q5) and the elbow (q3). Given the shoulder and q5, q6 follows and the planar 3R chain of joints
    2, 3, 4 has to bring axis 4 to a fixed point, up or down. The three signed quantities mirror the
    PUMA ones (module docstring), from the joint frames in the base frame:

    - shoulder ``t = (P - p_1) . (a_2 x a_1)``: ``P``'s reach along the arm's forward direction
      (``P`` lies at a fixed offset along ``a_2``; the two shoulder solutions give ``t`` opposite
      signs); oriented so that the centre of the limits is *front*;
    - elbow ``u = ((p_3 - p_2) x (p_4 - p_2)) . a_2``, times ``sign t``: which side of the line from
      axis 2 to axis 4 the elbow axis 3 lies on;
    - wrist ``w = (a_4 x a_6) . a_5``: the sine of the angle from axis 4 to axis 6 about axis 5.

    ``label = shoulder + 2 * elbow + 4 * wrist``, as for the PUMA type. Computed from full joint frames
    (:func:`joint_frames`), in float64.
    """

    def __init__(self, robot):
        self.robot = robot
        self._front = 1.0
        q0 = torch.zeros(1, robot.dof, dtype=torch.float64)
        for qref in (robot.limits.mean(-1).reshape(1, -1).double(), q0):
            t_ref = float(self._raw(qref)[0][0])
            if abs(t_ref) > 1e-6:
                self._front = 1.0 if t_ref > 0 else -1.0
                break

    def _raw(self, q: torch.Tensor):
        axes, points = joint_frames(self.robot, q.double())
        a1, a2, a4, a5, a6 = axes[:, 0], axes[:, 1], axes[:, 3], axes[:, 4], axes[:, 5]
        P, _ = _meeting_point(axes[:, 4:6], points[:, 4:6])
        t = ((P - points[:, 0]) * torch.linalg.cross(a2, a1)).sum(-1)
        s, e, c = points[:, 1], points[:, 2], points[:, 3]
        u = (torch.linalg.cross(e - s, c - s) * a2).sum(-1)
        w = (torch.linalg.cross(a4, a6) * a5).sum(-1)
        return t, u, w

    def components(self, q: torch.Tensor) -> dict[str, torch.Tensor]:
        """The signed quantities behind the label, each ``(B,)`` (see the class docstring)."""
        t, u, w = self._raw(q)
        return {"t": self._front * t, "u": u * torch.sign(t), "w": w}

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        """``q: (B, dof)`` -> ``(B,)`` uint8 labels in 0..7."""
        t, u, w = self._raw(q)
        shoulder = (t * self._front < 0).to(torch.uint8)
        elbow = (u * t < 0).to(torch.uint8)
        return shoulder | (elbow << 1) | ((w < 0).to(torch.uint8) << 2)


def ur_branch_classifier(robot) -> URBranchClassifier | None:
    """The branch classifier of a UR-type arm (see :class:`URBranchClassifier`), or None if ``robot`` is not one."""
    if robot.dof != 6 or bool(getattr(robot, "prismatic", torch.zeros(1, dtype=torch.bool)).any()):
        return None
    g = torch.Generator().manual_seed(12345)
    q = robot.sample(8, generator=g, dtype=torch.float64)
    axes, points = joint_frames(robot, q)
    a1, a2, a3, a4, a5, a6 = axes.unbind(1)
    if torch.linalg.cross(a2, a3).norm(dim=-1).max() > _TOL or torch.linalg.cross(a2, a4).norm(dim=-1).max() > _TOL:
        return None
    if torch.linalg.cross(a1, a2).norm(dim=-1).min() < 1e-3:
        return None
    if torch.linalg.cross(a4, a5).norm(dim=-1).min() < 1e-3 or torch.linalg.cross(a5, a6).norm(dim=-1).min() < 1e-3:
        return None
    _, resid = _meeting_point(axes[:, 4:6], points[:, 4:6])
    if resid.max() > _TOL:
        return None
    return URBranchClassifier(robot)


def ik_branch_classifier(robot):
    """A branch classifier of ``robot``: the PUMA type (:func:`branch_classifier`) or the UR type
    (:func:`ur_branch_classifier`); None for other arms (redundant arms, arms without such structure)."""
    return branch_classifier(robot) or ur_branch_classifier(robot)
