"""nik.ik.samples: every head of a network polished on its own, judged by FK round trip."""

import pytest
import torch

import nik
from nik.ik.samples import SampleCfg, network_samples, refine_samples
from nik.nets import load_pretrained
from nik.nets.multi import hypothesis_pose_error


@pytest.fixture(scope="module")
def panda_net():
    return load_pretrained("panda").eval()


def _targets(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return robot.fk(q)


def test_polished_samples_are_within_paik_per_sample_error_and_keep_the_heads_apart(panda_net):
    robot = panda_net.robot
    T = _targets(robot, 300, 11)
    raw = panda_net.hypotheses(T)
    q = network_samples(panda_net, T)
    assert q.shape == raw.shape
    assert robot.within_limits(q).all()
    pos, rot = hypothesis_pose_error(robot, T, q)
    raw_pos, _ = hypothesis_pose_error(robot, T, raw)
    assert float(pos.mean()) < 2.9e-3 < float(raw_pos.mean())  # PAIK's per-sample mean, the raw heads' above it
    assert float(torch.rad2deg(rot).mean()) < 1.5
    # each sample stays near its own head: the polish does not pull the heads onto one solution
    d = (q[:, :, None] - q[:, None]).abs().amax(-1)
    off_diag = ~torch.eye(q.shape[1], dtype=torch.bool)
    assert float((d[:, off_diag] > 0.1).double().mean()) > 0.95


def test_zero_iterations_give_the_raw_heads_inside_the_limits(panda_net):
    T = _targets(panda_net.robot, 20, 3)
    q = network_samples(panda_net, T, SampleCfg(iters=0))
    assert torch.equal(q, panda_net.robot.clamp(panda_net.hypotheses(T)))


def test_more_iterations_never_raise_a_samples_weighted_error():
    robot = nik.load_robot("xarm7")
    T = _targets(robot, 50, 5)
    q0 = robot.sample(50 * 4, generator=torch.Generator().manual_seed(1), dtype=torch.float64).reshape(50, 4, -1)
    cfg = SampleCfg()

    def cost(k):  # the LM's own objective: position^2 + (rot_weight * rotation)^2
        pos, rot = hypothesis_pose_error(robot, T, refine_samples(robot, T, q0, SampleCfg(iters=k)))
        return pos**2 + (cfg.rot_weight * rot) ** 2

    e = [cost(k) for k in (0, 2, 6)]
    assert (e[1] <= e[0] * (1 + 1e-9)).all() and (e[2] <= e[1] * (1 + 1e-9)).all()
    assert float(e[2].mean()) < 0.5 * float(e[0].mean())


def test_samples_of_the_wrong_shape_are_refused_in_one_line():
    robot = nik.load_robot("panda")
    T = _targets(robot, 4, 0)
    with pytest.raises(ValueError, match=r"expected q of shape \(4, K, 7\)"):
        refine_samples(robot, T, torch.zeros(4, 7, dtype=torch.float64))
