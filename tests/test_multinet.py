"""nik.multinet: multi-solution networks (branch-conditioned, multi-head), their encoding and hypotheses."""

from __future__ import annotations

import math

import pytest
import torch

import nik
from nik.data.branches import URBranchClassifier, branch_classifier, ik_branch_classifier, ur_branch_classifier
from nik.nets.multi import BranchHeadsIKNet, BranchIKNet, MultiHypIKNet, build_net, hypothesis_pose_error


def _poses(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return q, robot.fk(q)


@pytest.mark.parametrize("name", ["kuka_kr", "ur5", "panda"])
def test_sincos_encoding_round_trips_every_joint_within_the_limits(name):
    robot = nik.load_robot(name)
    net = MultiHypIKNet(robot, hidden=[4], heads=2)
    q, _ = _poses(robot, 200, 0)
    back = net.decode(net.encode(q.float()))
    # kuka_kr's joints 4 and 6 span more than a turn: the decoded angle is the same angle modulo 2 pi
    diff = torch.remainder(back.double() - q + math.pi, 2 * math.pi) - math.pi
    assert float(diff.abs().max()) < 1e-5
    assert net.head_dim == 2 * robot.dof


def test_a_prismatic_joint_is_a_scaled_value_not_sincos():
    robot = nik.load_robot("ur5")
    robot.prismatic = torch.tensor([False, False, True, False, False, False])  # as h1's Robot.prismatic
    net = MultiHypIKNet(robot, hidden=[4], heads=1)
    assert net.head_dim == 11
    q, _ = _poses(nik.load_robot("ur5"), 50, 1)
    y = net.encode(q.float())
    lo, hi = robot.limits[2]
    torch.testing.assert_close(y[:, 4].double(), (q[:, 2] - (lo + hi) / 2) / ((hi - lo) / 2), rtol=0, atol=1e-6)
    torch.testing.assert_close(net.decode(y)[:, 2].double(), q[:, 2], rtol=0, atol=1e-5)


@pytest.mark.parametrize(
    "cls,name",
    [
        (BranchHeadsIKNet, "kuka_kr"),
        (BranchHeadsIKNet, "ur5"),
        (BranchIKNet, "kuka_kr"),
        (BranchIKNet, "ur5"),
        (MultiHypIKNet, "panda"),
    ],
)
def test_hypotheses_are_inside_the_limits_and_predict_is_the_best_by_fk(cls, name):
    robot = nik.load_robot(name)
    torch.manual_seed(0)
    net = cls(robot, hidden=[16, 16]).fit_normalisation(_poses(robot, 300, 2)[1]).eval()
    _, T = _poses(robot, 40, 3)
    hyp = net.hypotheses(T)
    assert hyp.shape == (40, 8, robot.dof) and hyp.dtype == T.dtype
    assert bool(robot.within_limits(hyp.reshape(-1, robot.dof)).all())
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = (pos + 0.1 * rot).argmin(-1)
    torch.testing.assert_close(net.predict(T), hyp[torch.arange(40), best])
    # rebuilt from its plain-data config with the same weights: same output
    twin = build_net(robot, net.config())
    twin.load_state_dict(net.state_dict())
    assert torch.equal(twin.eval().hypotheses(T), hyp)


@pytest.mark.parametrize("cls", [BranchHeadsIKNet, BranchIKNet])
def test_branch_net_hypothesis_k_is_its_output_for_label_k(cls):
    robot = nik.load_robot("kuka_kr")
    torch.manual_seed(1)
    net = cls(robot, hidden=[8]).eval()
    _, T = _poses(robot, 5, 4)
    hyp = net.hypotheses(T)
    for k in (0, 5, 7):
        torch.testing.assert_close(net.predict_branch(T, k), hyp[:, k])
    with pytest.raises(ValueError, match="0..7"):
        net.predict_branch(T, 8)


@pytest.mark.parametrize("cls,passes", [(BranchHeadsIKNet, 1), (MultiHypIKNet, 1), (BranchIKNet, 8)])
def test_one_forward_pass_gives_every_hypothesis_except_in_the_legacy_branch_net(cls, passes):
    """Rows through the trunk's last hidden layer per target: 1 (one pass), 8 for the legacy label-input net."""
    robot = nik.load_robot("ur5")
    net = cls(robot, hidden=[16, 16]).eval()
    rows = []
    net.layers[1].register_forward_hook(lambda mod, inp, out: rows.append(inp[0].reshape(-1, 16).shape[0]))
    _, T = _poses(robot, 10, 5)
    assert net.hypotheses(T).shape == (10, 8, robot.dof)
    assert sum(rows) == passes * 10


def test_bad_configurations_are_refused():
    with pytest.raises(ValueError, match="no IK branch labels"):
        BranchIKNet(nik.load_robot("panda"))
    with pytest.raises(ValueError, match="no IK branch labels"):
        BranchHeadsIKNet(nik.load_robot("panda"))
    with pytest.raises(ValueError, match="heads"):
        MultiHypIKNet(nik.load_robot("panda"), heads=0)
    with pytest.raises(ValueError, match="kind"):
        build_net(nik.load_robot("panda"), {"kind": "flow"})
    with pytest.raises(ValueError, match=r"\(B, 4, 4\)"):
        MultiHypIKNet(nik.load_robot("panda"), hidden=[4]).hypotheses(torch.eye(4))


def test_ur_type_arms_get_branch_labels_and_puma_type_keep_theirs():
    assert isinstance(ur_branch_classifier(nik.load_robot("ur5")), URBranchClassifier)
    assert branch_classifier(nik.load_robot("ur5")) is None  # not of the PUMA type
    assert ur_branch_classifier(nik.load_robot("kuka_kr")) is None  # axis 4 is not parallel to 2 and 3
    assert ur_branch_classifier(nik.load_robot("panda")) is None
    assert ik_branch_classifier(nik.load_robot("kuka_kr")) is not None


def test_ur5_solutions_of_one_pose_with_the_same_label_are_the_same_solution():
    """Given the pose and the label, the solution is unique (modulo 2 pi): what a branch net relies on."""
    robot = nik.load_robot("ur5")
    clf = ur_branch_classifier(robot)
    q, T = _poses(robot, 3, 5)
    solver = nik.IKSolver(robot, checkpoint=None, refine="lm")
    labels_seen = 0
    for i in range(3):
        sols = solver.solve_all(T[i : i + 1], n_starts=128, tol_pos=1e-8, tol_rot=1e-8)
        lab = clf(sols)
        diff = torch.remainder(sols[:, None] - sols[None] + math.pi, 2 * math.pi) - math.pi
        same_label = lab[:, None] == lab[None]
        assert bool((diff.abs().amax(-1)[same_label] < 1e-4).all())
        labels_seen = max(labels_seen, int(lab.unique().numel()))
        # the reference configuration's own label is among them
        assert int(clf(q[i : i + 1])[0]) in lab.tolist()
    assert labels_seen >= 6
