"""A provable reach bound: which target positions no configuration of an arm can reach.

In the normal form ``T(q) = G_0 J_1 G_1 J_2 ... J_n G_n`` (:mod:`nik.kinematics`) the first joint
turns (or slides) about the z axis through the origin ``c`` of ``G_0``. The tool position is

    p(q) = c + R_0 J_1 (t_1 + R_1 J_2 (t_2 + ... ))

with ``t_i`` the translation of ``G_i``; rotations keep lengths, so ``|p - c| <= sum_i |t_i|``
(plus, for a prismatic joint, the largest ``|q_i + o_i|`` it allows). That sum, :func:`reach_radius`,
is an upper bound: a target farther than it from ``c`` is out of reach for every ``q``. The bound is
loose in general (it ignores joint limits and link directions) but never wrong; targets inside it
may still be unreachable, and those are left to the solver's per-target budget.
"""

from __future__ import annotations

import torch

__all__ = ["MM_HINT_FACTOR", "reach_center", "reach_radius", "reach_ratio", "unreachable_message", "within_reach"]

#: Relative slack on the bound against rounding (a target on the boundary must not be flagged).
REACH_SLACK = 1e-9


def reach_center(robot) -> torch.Tensor:
    """``(3,)`` float64: a point on the first joint's axis (the origin of ``G_0``), metres."""
    return robot.G[0, :3, 3].clone()


def reach_radius(robot) -> float:
    """Upper bound (metres) on ``|p(q) - reach_center|`` over every configuration ``q``."""
    G = robot.G
    r = float(torch.linalg.vector_norm(G[1:, :3, 3], dim=-1).sum())
    prismatic = getattr(robot, "prismatic", None)
    if prismatic is not None and bool(torch.as_tensor(prismatic).any()):
        pm = torch.as_tensor(prismatic, dtype=torch.bool)
        travel = (robot.limits[pm] + robot.offsets[pm, None]).abs().amax(dim=-1)
        r += float(travel.sum())
    return r


def reach_ratio(robot, T: torch.Tensor) -> torch.Tensor:
    """``(B,)``: distance of each target position (``T: (B, 4, 4)``) from the first axis point,
    divided by :func:`reach_radius` (> 1: provably out of reach)."""
    c = reach_center(robot).to(dtype=T.dtype, device=T.device)
    d = torch.linalg.vector_norm(T[..., :3, 3] - c, dim=-1)
    return d / max(reach_radius(robot), 1e-300)


def within_reach(robot, T: torch.Tensor) -> torch.Tensor:
    """``(B,)`` bool: False where no configuration can reach the position of ``T: (B, 4, 4)``."""
    return reach_ratio(robot, T) <= 1.0 + REACH_SLACK


#: From this factor beyond the reach on, the message asks whether the position was given in millimetres.
MM_HINT_FACTOR = 100.0


def unreachable_message(robot, T: torch.Tensor, reachable: torch.Tensor, *, unit_hint: str = "") -> str | None:
    """One line about the targets of ``T: (B, 4, 4)`` that ``reachable: (B,)`` flags as out of reach
    (None when every target is within reach). When the farthest lies ``MM_HINT_FACTOR`` times or more
    beyond the reach, the line asks whether the positions were given in millimetres (``unit_hint``
    names the remedy, e.g. ``"pass --unit mm"``)."""
    bad = ~reachable
    n_bad = int(bad.sum())
    if n_bad == 0:
        return None
    ratio = reach_ratio(robot, T)
    worst = float(ratio[bad].max())
    r_mm = reach_radius(robot) * 1e3
    msg = (
        f"{n_bad} of {len(reachable)} target(s) lie beyond the reach of {robot.name} (no configuration reaches "
        f"farther than {r_mm:.0f} mm from its first joint axis; farthest target at {worst:.3g} x that distance)"
    )
    if worst >= MM_HINT_FACTOR:
        hint = f" ({unit_hint})" if unit_hint else ""
        msg += f"; were the positions given in millimetres? nik expects metres{hint}"
    return msg
