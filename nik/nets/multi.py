"""Networks that represent several IK solutions of one pose instead of averaging them.

A pose of a 6R arm has up to 8 joint solutions, a pose of a 7-DOF arm a continuum; a plain
regression (:class:`nik.nets.IKNet`) averages them into a joint vector that is none of them.
Two networks here give *hypotheses* ``(B, K, dof)`` instead:

- :class:`BranchHeadsIKNet` (arms with IK branch labels, :func:`nik.data.branches.ik_branch_classifier`:
  PUMA type such as ``puma560``, ``kuka_kr``, ``rebot_v_6r``; UR type such as ``ur5``): one trunk on the
  pose and 8 output heads, head ``k`` = branch ``k`` (shoulder + 2 elbow + 4 wrist, 0..7), trained on
  the head of each sample's label; given pose and label the solution is unique, so each head's
  regression is well posed. One forward pass gives all 8 hypotheses.
- :class:`MultiHypIKNet` (any arm, redundant ones included, e.g. ``panda``): one trunk and K
  output heads, trained with a relaxed winner-takes-all loss (the best head gets the gradient,
  the others a small share) in joint space and then through FK; its hypotheses are the K heads.
- :class:`BranchIKNet` (kind ``branch``, kept to load older files): the label enters as a one-hot
  input, so its 8 hypotheses take 8 forward passes of the whole MLP (8 x the cost of one pass of a
  :class:`BranchHeadsIKNet` of the same size; measured in ``benchmarks/learned.py``). New networks are
  :class:`BranchHeadsIKNet`.

Both share the output encoding: revolute joints are predicted as ``(sin, cos)`` pairs (wrap-free:
a joint with a range of 2 pi or more has no seam; the angle is taken within ``out_center +- pi``
and then clamped to the limits), prismatic joints (``robot.prismatic``, when the robot has it) as
a value scaled to ``[-1, 1]`` over the limits. ``predict(T)`` gives the hypothesis with the
smallest FK pose error, ``hypotheses(T)`` all of them, clamped inside the limits.

The input is :func:`nik.poses.pose_to_vector` (``rot6d``: xyz + two rotation columns),
standardised by the buffers ``in_mean`` / ``in_std``. All buffers are in ``state_dict``.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from nik.nets.mlp import ACTIVATIONS
from nik.poses import POSE_DIMS, pose_error, pose_to_vector
from nik.robots import Robot
from nik.tolerances import score as pos_rot_score

__all__ = ["KINDS", "PLAIN", "BranchHeadsIKNet", "BranchIKNet", "MultiHypIKNet", "build_net", "hypothesis_pose_error"]


def hypothesis_pose_error(robot: Robot, T: torch.Tensor, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Pose error of hypotheses ``q: (B, K, dof)`` for targets ``T: (B, 4, 4)``: ``pos, rot: (B, K)`` (m, rad)."""
    return pose_error(T[:, None].to(q.dtype), robot.fk(q))


def _prismatic_mask(robot: Robot) -> torch.Tensor:
    p = getattr(robot, "prismatic", None)
    if p is None:
        return torch.zeros(robot.dof, dtype=torch.bool)
    return torch.as_tensor(p, dtype=torch.bool).reshape(robot.dof)


class _HypothesisNet(nn.Module):
    """Shared part: input standardisation, the MLP trunk, the per-joint output encoding, hypotheses."""

    kind = ""

    def __init__(
        self,
        robot: Robot,
        *,
        hidden: Sequence[int],
        activation: str,
        n_extra_in: int,
        n_heads: int,
        representation: str = "rot6d",
    ):
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; expected one of {sorted(ACTIVATIONS)}")
        if representation not in POSE_DIMS:
            raise ValueError(f"unknown input representation {representation!r}; expected one of {sorted(POSE_DIMS)}")
        hidden = [int(h) for h in hidden]
        if not hidden or any(h < 1 for h in hidden):
            raise ValueError(f"hidden layer sizes must be >= 1 (at least one layer), got {hidden}")
        self.robot = robot
        self.dof = robot.dof
        self.hidden = hidden
        self.activation = activation
        self.representation = representation
        self.act = ACTIVATIONS[activation]
        self.n_heads = int(n_heads)
        pris = _prismatic_mask(robot)
        self.register_buffer("prismatic", pris, persistent=False)
        # output columns of one head: (sin, cos) per revolute joint, one value per prismatic joint
        self.head_dim = int(2 * (~pris).sum() + pris.sum())
        self.pose_dim = POSE_DIMS[representation]
        self.in_dim = self.pose_dim + n_extra_in
        sizes = [self.in_dim, *hidden, self.n_heads * self.head_dim]
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:], strict=True))
        lo, hi = robot.limits[:, 0].float(), robot.limits[:, 1].float()
        self.register_buffer("in_mean", torch.zeros(self.pose_dim))
        self.register_buffer("in_std", torch.ones(self.pose_dim))
        self.register_buffer("out_center", (lo + hi) / 2)
        self.register_buffer("out_half", (hi - lo) / 2)
        self.register_buffer("length_scale", torch.tensor(1.0))

    # -- description ---------------------------------------------------------------
    def config(self) -> dict:
        """Plain data that rebuilds this architecture with :func:`build_net` (``kind`` included)."""
        return {
            "kind": self.kind,
            "hidden": list(self.hidden),
            "activation": self.activation,
            "representation": self.representation,
        }

    @property
    def n_params(self) -> int:
        return sum(p.numel() for p in self.parameters())

    @property
    def n_hypotheses(self) -> int:
        return self.n_heads

    def __repr__(self) -> str:
        sizes = "-".join(str(s) for s in [self.in_dim, *self.hidden, self.n_heads * self.head_dim])
        return f"{type(self).__name__}({sizes}, {self.activation}, robot={self.robot.name!r}, params={self.n_params})"

    @torch.no_grad()
    def fit_normalisation(self, T: torch.Tensor):
        """Input mean/std and the length scale (mean std of the positions, metres) from training poses ``(N, 4, 4)``."""
        v = pose_to_vector(T.double(), self.representation)
        std = v.std(dim=0)
        self.in_mean.copy_(v.mean(dim=0))
        self.in_std.copy_(torch.where(std > 1e-8, std, torch.ones_like(std)))
        self.length_scale.fill_(float(v[:, :3].std(dim=0).mean().clamp_min(1e-3)))
        return self

    def features(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> standardised pose vector ``(B, pose_dim)``, buffers' dtype."""
        v = pose_to_vector(T.to(self.in_mean.dtype), self.representation)
        return (v - self.in_mean) / self.in_std

    def mlp(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers[:-1]:
            x = self.act(layer(x))
        return self.layers[-1](x)

    # -- output encoding -----------------------------------------------------------
    def encode(self, q: torch.Tensor) -> torch.Tensor:
        """Joints ``(..., dof)`` -> one head's target ``(..., head_dim)`` (the joint-space loss target)."""
        q = q.to(self.out_center.dtype)
        cols = []
        for j in range(self.dof):
            if bool(self.prismatic[j]):
                cols.append(((q[..., j] - self.out_center[j]) / self.out_half[j])[..., None])
            else:
                cols.append(torch.stack([torch.sin(q[..., j]), torch.cos(q[..., j])], dim=-1))
        return torch.cat(cols, dim=-1)

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        """One head's raw output ``(..., head_dim)`` -> joints ``(..., dof)``, unclamped, differentiable."""
        out, k = [], 0
        for j in range(self.dof):
            c = self.out_center[j]
            if bool(self.prismatic[j]):
                out.append(c + self.out_half[j] * y[..., k])
                k += 1
            else:
                d = torch.atan2(y[..., k], y[..., k + 1]) - c
                out.append(c + torch.atan2(torch.sin(d), torch.cos(d)))
                k += 2
        return torch.stack(out, dim=-1)

    # -- hypotheses ----------------------------------------------------------------
    def raw_hypotheses(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> raw outputs ``(B, K, head_dim)`` of every hypothesis."""
        raise NotImplementedError

    def forward(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> hypotheses ``(B, K, dof)`` radians, unclamped, differentiable (for training)."""
        return self.decode(self.raw_hypotheses(T))

    def _check(self, T) -> None:
        if not isinstance(T, torch.Tensor) or T.ndim != 3 or T.shape[-2:] != (4, 4):
            shape = tuple(T.shape) if isinstance(T, torch.Tensor) else type(T).__name__
            raise ValueError(f"expected poses of shape (B, 4, 4), got {shape}")

    @torch.no_grad()
    def hypotheses(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> every hypothesis ``(B, K, dof)`` clamped inside the limits, dtype/device of ``T``."""
        self._check(T)
        q = self.forward(T.to(device=self.in_mean.device))
        return self.robot.clamp(q.to(T.dtype)).to(T.device)

    @torch.no_grad()
    def ranked_hypotheses(self, T: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Hypotheses sorted by FK pose error (:func:`nik.tolerances.score`), best first:
        ``q: (B, K, dof)`` and that error ``(B, K)``."""
        q = self.hypotheses(T)
        pos, rot = hypothesis_pose_error(self.robot, T, q)
        score = pos_rot_score(pos, rot)
        order = score.argsort(dim=-1)
        q = torch.gather(q, 1, order[..., None].expand(-1, -1, q.shape[-1]))
        return q, torch.gather(score, 1, order)

    @torch.no_grad()
    def predict(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> the hypothesis with the smallest FK pose error ``(B, dof)``, inside the limits."""
        return self.ranked_hypotheses(T)[0][:, 0]


def _require_branch_labels(robot: Robot, cls: str) -> None:
    from nik.data.branches import ik_branch_classifier

    if ik_branch_classifier(robot) is None:
        raise ValueError(
            f"{cls}: robot {robot.name!r} has no IK branch labels (PUMA type: parallel axes 2, 3 and a "
            "spherical wrist; UR type: parallel axes 2, 3, 4); use MultiHypIKNet"
        )


class _Labelled:
    """Branch labels of joints and the hypothesis of a given branch (shared by the branch networks)."""

    def labels(self, q: torch.Tensor) -> torch.Tensor:
        """Branch labels ``(B,)`` long of joints ``q: (B, dof)`` (the training condition)."""
        from nik.data.branches import ik_branch_classifier

        if not hasattr(self, "_clf"):
            self._clf = ik_branch_classifier(self.robot)
        return self._clf(q).long()

    @torch.no_grad()
    def predict_branch(self, T: torch.Tensor, branch) -> torch.Tensor:
        """``T: (B, 4, 4)``, ``branch`` int or ``(B,)`` -> the joints of that branch ``(B, dof)``, inside the limits."""
        self._check(T)
        b = torch.as_tensor(branch, device=self.in_mean.device).long().expand(T.shape[0])
        if bool(((b < 0) | (b > 7)).any()):
            raise ValueError("branch labels must be in 0..7")
        q = self.decode(self.raw_branch(T.to(self.in_mean.device), b))
        return self.robot.clamp(q.to(T.dtype)).to(T.device)


class BranchHeadsIKNet(_Labelled, _HypothesisNet):
    """Pose -> 8 hypotheses from one trunk and 8 heads, head ``k`` = IK branch ``k`` (module docstring).

    One forward pass gives every hypothesis. Training (:class:`nik.learn.multi.MultiSolutionIK`,
    ``kind: branch_heads``) supervises only the head of each sample's branch label.

    Args:
        robot: an arm with a branch classifier (PUMA or UR type).
        hidden: hidden layer sizes of the trunk, e.g. ``[256, 256, 256, 256]``.
        activation: one of :data:`nik.nets.mlp.ACTIVATIONS`.
        representation: input pose representation (default ``rot6d``).
    """

    kind = "branch_heads"

    def __init__(
        self,
        robot: Robot,
        *,
        hidden: Sequence[int] = (256, 256, 256, 256),
        activation: str = "silu",
        representation: str = "rot6d",
    ):
        _require_branch_labels(robot, "BranchHeadsIKNet")
        super().__init__(
            robot, hidden=hidden, activation=activation, n_extra_in=0, n_heads=8, representation=representation
        )

    def raw_hypotheses(self, T: torch.Tensor) -> torch.Tensor:
        y = self.mlp(self.features(T))
        return y.reshape(*y.shape[:-1], 8, self.head_dim)

    def raw_branch(self, T: torch.Tensor, branch: torch.Tensor) -> torch.Tensor:
        """Raw output ``(B, head_dim)`` of head ``branch: (B,)`` (0..7) for poses ``T: (B, 4, 4)``."""
        y = self.raw_hypotheses(T)
        idx = branch.long().to(y.device)[:, None, None].expand(-1, 1, self.head_dim)
        return y.gather(1, idx)[:, 0]


class BranchIKNet(_Labelled, _HypothesisNet):
    """Legacy (kind ``branch``): pose + one-hot IK branch label -> joints; 8 hypotheses, one per branch,
    by 8 forward passes (module docstring). Kept so that files made with it still load; new networks are
    :class:`BranchHeadsIKNet` (one pass).

    Args:
        robot: an arm with a branch classifier (PUMA or UR type).
        hidden: hidden layer sizes, e.g. ``[512, 512, 512]``.
        activation: one of :data:`nik.nets.mlp.ACTIVATIONS`.
        representation: input pose representation (default ``rot6d``).
    """

    kind = "branch"

    def __init__(
        self,
        robot: Robot,
        *,
        hidden: Sequence[int] = (512, 512, 512),
        activation: str = "silu",
        representation: str = "rot6d",
    ):
        _require_branch_labels(robot, "BranchIKNet")
        super().__init__(
            robot, hidden=hidden, activation=activation, n_extra_in=8, n_heads=1, representation=representation
        )
        self.n_heads = 8  # hypotheses: one per branch (the output layer has one head)

    def raw_branch(self, T: torch.Tensor, branch: torch.Tensor) -> torch.Tensor:
        """Raw output ``(B, head_dim)`` for poses ``T: (B, 4, 4)`` and labels ``branch: (B,)`` in 0..7."""
        x = self.features(T)
        onehot = nn.functional.one_hot(branch.long().to(x.device), 8).to(x.dtype)
        return self.mlp(torch.cat([x, onehot], dim=-1))

    def raw_hypotheses(self, T: torch.Tensor) -> torch.Tensor:
        B = T.shape[0]
        x = self.features(T)
        onehot = torch.eye(8, dtype=x.dtype, device=x.device)
        inp = torch.cat([x[:, None].expand(B, 8, x.shape[-1]), onehot.expand(B, 8, 8)], dim=-1)
        return self.mlp(inp)


class MultiHypIKNet(_HypothesisNet):
    """Pose -> K hypotheses from K output heads on one MLP trunk (module docstring).

    Args:
        robot: any arm.
        hidden: hidden layer sizes of the trunk.
        activation: one of :data:`nik.nets.mlp.ACTIVATIONS`.
        heads: number of hypotheses K.
        representation: input pose representation (default ``rot6d``).
    """

    kind = "multihead"

    def __init__(
        self,
        robot: Robot,
        *,
        hidden: Sequence[int] = (512, 512, 512),
        activation: str = "silu",
        heads: int = 8,
        representation: str = "rot6d",
    ):
        if int(heads) < 1:
            raise ValueError(f"heads must be >= 1, got {heads}")
        super().__init__(
            robot, hidden=hidden, activation=activation, n_extra_in=0, n_heads=heads, representation=representation
        )

    def config(self) -> dict:
        return {**super().config(), "heads": self.n_heads}

    def raw_hypotheses(self, T: torch.Tensor) -> torch.Tensor:
        y = self.mlp(self.features(T))
        return y.reshape(*y.shape[:-1], self.n_heads, self.head_dim)


#: Network kinds by the ``kind`` of their :meth:`config`.
KINDS = {"branch_heads": BranchHeadsIKNet, "multihead": MultiHypIKNet, "branch": BranchIKNet}


#: The ``kind`` an exported plain network (:class:`nik.nets.IKNet`, one guess a pose: ``train.py``'s bp, adam, lbfgs,
#: de, de_bp) records in its pair's JSON; its checkpoints record no kind.
PLAIN = "plain"


def build_net(robot: Robot, config: dict):
    """Rebuild a network from its :meth:`config` (plain data): ``{"kind": "branch_heads" | "multihead" | "branch",
    ...}``, or ``{"kind": "plain", ...}`` (:data:`PLAIN`): a :class:`nik.nets.IKNet` from ``train.py``."""
    cfg = dict(config)
    kind = cfg.pop("kind", None)
    if kind == PLAIN:
        from nik.nets.mlp import IKNet

        return IKNet(robot, **cfg)
    if kind not in KINDS:
        raise ValueError(f"unknown network kind {kind!r}; expected one of {sorted([*KINDS, PLAIN])}")
    return KINDS[kind](robot, **cfg)
