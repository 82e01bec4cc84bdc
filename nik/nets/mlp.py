"""The IK network: an MLP from a tool pose to joint angles, with its normalisation buffers.

``IKNet`` maps ``T: (B, 4, 4)`` to ``q: (B, dof)``:

1. the pose becomes a vector by :func:`nik.poses.pose_to_vector` (``representation``:
   ``rpy`` = paper C's ``[x, y, z, Rx, Ry, Rz]``, ``quat``, or ``rot6d``), then is standardised by
   the buffers ``in_mean`` / ``in_std`` (fitted on the training poses);
2. an MLP with ``hidden`` layer sizes and ``activation`` (paper C: one hidden layer of 8, tanh);
3. the output is either ``angles`` (one per joint, in ``[-1, 1]`` for the training range:
   ``q = out_center + out_half * y``, like MATLAB's ``mapminmax``) or ``sincos`` (two per joint,
   ``q = atan2(s, c)`` taken within ``out_center +- pi``; such a joint cannot reach beyond one turn
   around the centre of its range). A prismatic joint is always linear: with ``sincos`` it keeps its
   two outputs, reads the first as ``angles`` does and trains the second towards 0.

The buffers are part of ``state_dict`` and so of every checkpoint, together with the robot
definition and its hash (see :func:`nik.nets.checkpoint.load_checkpoint`).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from nik.poses import POSE_DIMS, pose_to_vector
from nik.robots import Robot

__all__ = ["ACTIVATIONS", "REPRESENTATIONS", "OUTPUTS", "PAPER_C", "DEFAULT", "IKNet"]

#: Activation functions by name; the same callables serve the single net and the batched population.
ACTIVATIONS = {
    "tanh": torch.tanh,
    "relu": torch.relu,
    "silu": nn.functional.silu,
    "gelu": nn.functional.gelu,
    "elu": nn.functional.elu,
    "softplus": nn.functional.softplus,
}
#: Input pose representations (names of :func:`nik.poses.pose_to_vector`).
REPRESENTATIONS = ("rpy", "quat", "rot6d")
#: Output encodings.
OUTPUTS = ("angles", "sincos")

#: Paper C's network: 6-8-6, tanh, xyz + roll-pitch-yaw in, joint angles out.
PAPER_C = {"hidden": [8], "activation": "tanh", "representation": "rpy", "output": "angles"}
#: The realistic default, chosen by measurement (docs/training.md, Network): 3 x 256 SiLU, xyz + 6D rotation in.
DEFAULT = {"hidden": [256, 256, 256], "activation": "silu", "representation": "rot6d", "output": "angles"}


class IKNet(nn.Module):
    """MLP pose -> joint angles for one robot.

    Args:
        robot: the arm (its limits set the default output scaling and the clamp of :meth:`predict`).
        hidden: hidden layer sizes, e.g. ``[8]`` (paper C) or ``[256, 256, 256]``.
        activation: one of :data:`ACTIVATIONS`.
        representation: input pose representation, one of :data:`REPRESENTATIONS`.
        output: ``angles`` or ``sincos``.

    Buffers (saved in the checkpoint): ``in_mean, in_std: (D,)`` input standardisation;
    ``out_center, out_half: (dof,)`` radians, output scaling; ``length_scale: ()`` metres, the
    workspace size used to make the pose loss dimensionless (mean std of the training positions).
    """

    def __init__(
        self,
        robot: Robot,
        *,
        hidden: Sequence[int] = (8,),
        activation: str = "tanh",
        representation: str = "rpy",
        output: str = "angles",
    ):
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; expected one of {sorted(ACTIVATIONS)}")
        if representation not in REPRESENTATIONS:
            raise ValueError(f"unknown input representation {representation!r}; expected one of {REPRESENTATIONS}")
        if output not in OUTPUTS:
            raise ValueError(f"unknown output {output!r}; expected one of {OUTPUTS}")
        hidden = [int(h) for h in hidden]
        if any(h < 1 for h in hidden):
            raise ValueError(f"hidden layer sizes must be >= 1, got {hidden}")
        self.robot = robot
        self.dof = robot.dof
        self.hidden = hidden
        self.activation = activation
        self.representation = representation
        self.output = output
        self.act = ACTIVATIONS[activation]
        # (dof,) bool, not a buffer (checkpoints keep their keys): the robot definition carries it
        self.prismatic = robot.prismatic.clone() if robot.has_prismatic else None
        self.in_dim = POSE_DIMS[representation]
        self.out_dim = self.dof * (2 if output == "sincos" else 1)
        sizes = [self.in_dim, *hidden, self.out_dim]
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:], strict=True))
        lo, hi = robot.limits[:, 0].float(), robot.limits[:, 1].float()
        self.register_buffer("in_mean", torch.zeros(self.in_dim))
        self.register_buffer("in_std", torch.ones(self.in_dim))
        self.register_buffer("out_center", (lo + hi) / 2)
        self.register_buffer("out_half", (hi - lo) / 2)
        self.register_buffer("length_scale", torch.tensor(1.0))

    # -- description --------------------------------------------------------
    def config(self) -> dict:
        """The constructor arguments (plain data) that rebuild this architecture."""
        return {
            "hidden": list(self.hidden),
            "activation": self.activation,
            "representation": self.representation,
            "output": self.output,
        }

    @property
    def n_params(self) -> int:
        """Number of trainable weights and biases (the length of DE's flat vector)."""
        return sum(p.numel() for p in self.parameters())

    def layer_shapes(self) -> list[tuple[int, int]]:
        """``(out, in)`` of each linear layer, in order; the flat vector is W_1, b_1, W_2, b_2, ..."""
        return [(layer.out_features, layer.in_features) for layer in self.layers]

    def __repr__(self) -> str:
        sizes = "-".join(str(s) for s in [self.in_dim, *self.hidden, self.out_dim])
        return (
            f"IKNet({sizes}, {self.activation}, in={self.representation}, out={self.output}, "
            f"robot={self.robot.name!r}, params={self.n_params})"
        )

    # -- normalisation ------------------------------------------------------
    @torch.no_grad()
    def fit_normalisation(self, T: torch.Tensor, q: torch.Tensor | None = None) -> IKNet:
        """Set the buffers from training data.

        Args:
            T: (N, 4, 4) training poses: input mean/std and the length scale.
            q: (N, dof) training joints, optional: the output scaling then maps the data's
               min..max (the training range) to [-1, 1]; otherwise the robot's limits are used.
        """
        v = pose_to_vector(T.double(), self.representation)
        std = v.std(dim=0)
        self.in_mean.copy_(v.mean(dim=0))
        self.in_std.copy_(torch.where(std > 1e-8, std, torch.ones_like(std)))
        self.length_scale.fill_(float(v[:, :3].std(dim=0).mean().clamp_min(1e-3)))
        if q is not None:
            lo, hi = q.double().amin(dim=0), q.double().amax(dim=0)
            half = ((hi - lo) / 2).clamp_min(1e-3)
            self.out_center.copy_((hi + lo) / 2)
            self.out_half.copy_(half)
        return self

    # -- the map ------------------------------------------------------------
    def features(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> standardised input ``(B, D)`` in the buffers' dtype."""
        v = pose_to_vector(T.to(self.in_mean.dtype), self.representation)
        return (v - self.in_mean) / self.in_std

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """Standardised input ``(..., D)`` -> raw network output ``(..., out_dim)``."""
        for layer in self.layers[:-1]:
            x = self.act(layer(x))
        return self.layers[-1](x)

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        """Raw output ``(..., out_dim)`` -> joint angles ``(..., dof)`` (not clamped; differentiable)."""
        if self.output == "angles":
            return self.out_center + self.out_half * y
        s, c = y[..., 0::2], y[..., 1::2]
        phi = torch.atan2(s, c)
        # the angle within out_center +- pi
        d = phi - self.out_center
        q = self.out_center + torch.atan2(torch.sin(d), torch.cos(d))
        if self.prismatic is not None:  # prismatic joints: linear in the first of their two outputs
            q = torch.where(self.prismatic.to(q.device), self.out_center + self.out_half * s, q)
        return q

    def encode(self, q: torch.Tensor) -> torch.Tensor:
        """Joint angles ``(..., dof)`` -> the raw output that decodes to them: the joint-space loss target."""
        q = q.to(self.out_center.dtype)
        if self.output == "angles":
            return (q - self.out_center) / self.out_half
        s, c = torch.sin(q), torch.cos(q)
        if self.prismatic is not None:
            mask = self.prismatic.to(q.device)
            s = torch.where(mask, (q - self.out_center) / self.out_half, s)
            c = torch.where(mask, torch.zeros_like(c), c)
        return torch.stack([s, c], dim=-1).flatten(-2)

    def forward(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> ``q: (B, dof)`` radians, unclamped, differentiable (for training)."""
        return self.decode(self.raw(self.features(T)))

    @torch.no_grad()
    def predict(self, T: torch.Tensor) -> torch.Tensor:
        """``T: (B, 4, 4)`` -> ``q: (B, dof)`` joint angles clamped inside the limits, dtype/device of ``T``."""
        if not isinstance(T, torch.Tensor) or T.ndim != 3 or T.shape[-2:] != (4, 4):
            shape = tuple(T.shape) if isinstance(T, torch.Tensor) else type(T).__name__
            raise ValueError(f"predict: expected poses of shape (B, 4, 4), got {shape}")
        ref = self.in_mean
        q = self.forward(T.to(device=ref.device))
        q = self.robot.clamp(q.to(T.dtype))
        return q.to(T.device)
