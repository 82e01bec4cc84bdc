"""A one-pass multi-solution network packed for the compiled kernels: its hypotheses for a few poses without torch.

:func:`pack` takes a :class:`~nik.nets.multi.MultiHypIKNet` or :class:`~nik.nets.multi.BranchHeadsIKNet` with
the ``rot6d`` input (the kinds ``nik train`` makes) and returns a :class:`PackedNet`: its weights as one flat
float32 array (:func:`nik.kernels.mlp.mlp_pack`; float32 as in torch, and twice the SIMD lanes of float64) and the
buffers of its input standardisation and output decoding. :meth:`PackedNet.ranked_hypotheses` then gives what
``net.ranked_hypotheses`` gives (``(B, K, dof)`` inside the limits, best first by FK; within float32 rounding of
torch's answer) through :func:`nik.kernels.seeded.ranked_hypotheses`, without torch's per-operation overhead: for
one pose of a 4 x 256 network tens of microseconds instead of about 200 (``benchmarks/learned.py``). Other kinds (a
plain ``IKNet``, the legacy ``branch`` kind) are not packed: :func:`pack` returns None and the caller runs torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PackedNet", "pack"]


@dataclass(frozen=True)
class PackedNet:
    """The arrays of :func:`nik.kernels.seeded.ranked_hypotheses` for one network.

    Attributes:
        flat, layout: the MLP (:func:`nik.kernels.mlp.mlp_pack`, float32); activation: its code.
        in_mean, in_std: (9,) input standardisation; out_center, out_half: (dof,); prismatic: (dof,) bool.
        heads: K, the hypotheses per pose; n_params: the network's parameter count.
    """

    flat: np.ndarray
    layout: np.ndarray
    activation: int
    in_mean: np.ndarray
    in_std: np.ndarray
    out_center: np.ndarray
    out_half: np.ndarray
    prismatic: np.ndarray
    heads: int
    n_params: int

    def ranked_hypotheses(
        self, G: np.ndarray, joints: np.ndarray, T: np.ndarray, tol_pos: float, tol_rot: float, *, Tin=None
    ):
        """Every hypothesis for ``T: (B, 4, 4)`` float64 brought inside the limits of the model ``G, joints``
        (:func:`nik.kernels.chain.chain_model`) and ranked by FK pose error, best first: ``(q (B, K, dof),
        pos (B,), rot (B,), ok (B,), failing)``: the best one's errors (metres, radians), whether it lies within
        the tolerances and how many do not (:func:`nik.kernels.seeded.ranked_hypotheses`). ``Tin: (B, 4, 4)``: the
        poses the network is given when they differ from ``T`` (a network made for the arm without the robot's
        base/tool frames: :meth:`nik.ik.model.Model.arm_targets`); the ranking is always against ``T``."""
        from nik.kernels.seeded import ranked_hypotheses

        return ranked_hypotheses(self.arrays, G, joints, T if Tin is None else Tin, T, tol_pos, tol_rot)

    @property
    def arrays(self) -> tuple:
        """``(flat, layout, activation, in_mean, in_std, out_center, out_half, prismatic, heads)``: the network as
        the kernels take it (:func:`nik.kernels.seeded.ranked_hypotheses`)."""
        return (
            self.flat, self.layout, self.activation, self.in_mean, self.in_std, self.out_center, self.out_half,
            self.prismatic, self.heads,
        )  # fmt: skip


def pack(net) -> PackedNet | None:
    """``net`` packed for the kernels, or None when it is not a one-pass multi-solution network with the
    ``rot6d`` input and an activation the kernels know."""
    from nik.kernels.mlp import ACTIVATIONS, mlp_pack
    from nik.nets.multi import BranchHeadsIKNet, MultiHypIKNet

    if not isinstance(net, (MultiHypIKNet, BranchHeadsIKNet)) or net.representation != "rot6d":
        return None
    if net.activation not in ACTIVATIONS:
        return None
    flat, layout = mlp_pack([(layer.weight.detach().cpu(), layer.bias.detach().cpu()) for layer in net.layers])

    def arr(t, dtype=np.float64):
        return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=dtype)

    return PackedNet(
        flat.astype(np.float32),
        layout,
        ACTIVATIONS[net.activation],
        arr(net.in_mean),
        arr(net.in_std),
        arr(net.out_center),
        arr(net.out_half),
        arr(net.prismatic, np.bool_),
        int(net.n_heads),
        int(net.n_params),
    )
