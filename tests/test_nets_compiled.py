"""nik.nets.compiled: a packed network's compiled hypotheses are the torch network's, ranked the same way."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import nik
from nik.models import load_pretrained
from nik.nets.compiled import pack


@pytest.mark.parametrize("name", ["panda", "kuka_kr"])  # multihead; branch heads
def test_packed_ranked_hypotheses_equal_the_torch_networks_within_float32_rounding(name):
    robot = nik.load_robot(name).arm  # the arm the network was made for (the built-in panda: without its flange)
    net = load_pretrained(robot)
    packed = pack(net)
    assert packed is not None and packed.heads == net.n_hypotheses
    T = robot.fk(robot.sample(32, generator=torch.Generator().manual_seed(5), dtype=torch.float64))
    G, joints = robot.chain_arrays()
    tol_pos, tol_rot = 0.02, 0.05
    q, pos, rot, ok, failing = packed.ranked_hypotheses(G, joints, np.ascontiguousarray(T.numpy()), tol_pos, tol_rot)
    ref, _ = net.ranked_hypotheses(T)  # torch: forward, clamp, rank by FK
    # the same hypotheses as a set per pose (two within float32 rounding may swap places) ...
    d = (torch.from_numpy(q)[:, :, None] - ref[:, None]).abs().amax(-1)  # (B, K, K)
    assert float(d.amin(-1).amax()) < 1e-4
    # ... and the same best one, whose errors are measured by FK
    torch.testing.assert_close(torch.from_numpy(q[:, 0]), ref[:, 0], atol=1e-4, rtol=0)
    p, r = nik.pose_error(T, robot.fk(torch.from_numpy(q[:, 0].copy())))
    torch.testing.assert_close(torch.from_numpy(pos), p, atol=1e-12, rtol=0)
    torch.testing.assert_close(torch.from_numpy(rot), r, atol=1e-9, rtol=0)
    assert ok.tolist() == ((p <= tol_pos) & (r <= tol_rot)).tolist() and failing == int((~torch.from_numpy(ok)).sum())


def test_kinds_the_kernels_do_not_cover_are_not_packed():
    from nik.models import IKNet

    assert pack(IKNet(nik.load_robot("ur5"), hidden=[8])) is None
