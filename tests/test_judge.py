"""nik.ik.judge: a given network that guesses no better than uniform starts gives way (issue 37 item 4)."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.ik import judge
from nik.nets.checkpoint import save_checkpoint
from nik.nets.multi import build_net


def _useless(robot, kind: str, seed: int = 0):
    """A network of the shipped architecture that is useless: ``untrained`` (fresh weights, the shipped input
    normalisation), ``scrambled`` (the shipped one, its output units permuted) or ``randomised`` (the shipped one,
    every weight drawn again at its tensor's scale)."""
    shipped = nik.models.load_pretrained(robot)
    g = torch.Generator().manual_seed(seed)
    if kind == "untrained":
        torch.manual_seed(seed)
        net = build_net(robot, shipped.config())
        net.in_mean.copy_(shipped.in_mean)
        net.in_std.copy_(shipped.in_std)
        return net.eval()
    net = copy.deepcopy(shipped)
    with torch.no_grad():
        if kind == "scrambled":
            last = [m for m in net.modules() if isinstance(m, torch.nn.Linear)][-1]
            perm = torch.randperm(last.out_features, generator=g)
            last.weight.copy_(last.weight[perm])
            last.bias.copy_(last.bias[perm])
        else:
            for p in net.parameters():
                p.copy_(torch.randn(p.shape, generator=g) * p.std().clamp_min(1e-3))
    return net.eval()


def _targets(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return robot.fk(q).numpy()


@pytest.mark.parametrize("name", ["panda", "ur5"])
@pytest.mark.parametrize("kind", ["untrained", "scrambled", "randomised"])
def test_a_useless_network_given_by_path_gives_way_and_answers_as_without_one(tmp_path, name, kind):
    robot = nik.load_robot(name)
    path = save_checkpoint(_useless(robot, kind), tmp_path / f"{kind}.ckpt")
    solver = nik.IKSolver(robot, checkpoint=str(path), analytic=False)
    dropped = judge.counts()["dropped"]
    with pytest.warns(UserWarning, match="no better than uniform starts"):
        plan = solver.plan()
    assert plan.source == "multistart" and plan.net is None
    assert judge.counts()["dropped"] == dropped + 1
    v = judge.verdict(solver.net, robot)
    assert not v.earns and v.wins < judge.MIN_WINS
    T = _targets(robot, 60, seed=5)
    res = solver.solve(T)
    ref = nik.IKSolver(robot, checkpoint=None, analytic=False).solve(T)
    assert res.source == "multistart" and bool(res.success.all()) and bool(ref.success.all())
    np.testing.assert_array_equal(res.q, ref.q)  # the same plan as without a network: the same answers


def test_a_randomised_network_set_on_the_solver_gives_way_on_both_backends():
    robot = nik.load_robot("panda")
    T = _targets(robot, 40, seed=7)
    for backend in ("compiled", "torch"):
        solver = nik.IKSolver(robot, analytic=False, backend=backend)
        solver.net = _useless(robot, "randomised", seed=3)
        with pytest.warns(UserWarning, match="solving without it"):
            res = solver.solve(torch.from_numpy(T))
        assert res.source == "multistart" and bool(res.success.all())


def test_on_a_closed_form_arm_a_useless_network_gives_way_to_the_closed_form(tmp_path):
    robot = nik.load_robot("ur5")
    path = save_checkpoint(_useless(robot, "untrained"), tmp_path / "u.ckpt")
    solver = nik.IKSolver(robot, checkpoint=str(path))
    with pytest.warns(UserWarning, match="no better than uniform starts"):
        res = solver.solve(_targets(robot, 30, seed=2))
    assert res.source == "analytic" and bool(res.success.all())


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7"])
def test_the_shipped_networks_earn_their_place_given_by_object(name):
    robot = nik.load_robot(name)
    net = nik.models.load_pretrained(robot)
    v = judge.verdict(net, robot)
    assert v.earns and v.wins >= 0.9 and v.net_median < v.uniform_median
    solver = nik.IKSolver(robot, analytic=False)
    solver.net = net  # given: judged, and kept
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert solver.plan().source == "network" and solver.plan().net is net


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7", "kuka_kr"])
def test_the_shipped_single_pose_networks_earn_their_place_and_serve_single_poses_on_the_cpu(name):
    from nik.nets.pair import load_pair
    from nik.nets.pretrained import PRETRAINED_DIR

    robot = nik.load_robot(name)
    small = load_pair(PRETRAINED_DIR / f"{name}_one.safetensors", robot=robot.arm)
    v = judge.verdict(small, robot.arm)  # trained for the bare arm: judged in its frame
    assert v.earns and v.wins >= 0.9 and v.net_median < v.uniform_median
    solver = nik.IKSolver(robot, analytic=False)  # ur5, kuka_kr: the network asked for, the closed form aside
    plan = solver.plan(backend="compiled")
    assert plan.source == "network" and plan.net is solver.single_pose_net
    assert plan.net_in_arm_frame == (robot.arm is not robot)
    assert solver.plan(backend="torch").net is solver.net  # the main network elsewhere
    T = _targets(robot, 8, seed=3)
    res = solver.solve(T[:1])
    assert res.source == "network" and bool(res.success.all())


def test_the_raw_guess_and_no_fallback_keep_a_useless_network(tmp_path):
    robot = nik.load_robot("panda")
    path = str(save_checkpoint(_useless(robot, "scrambled"), tmp_path / "s.ckpt"))
    raw = nik.IKSolver(robot, checkpoint=path, refine="none", analytic=False)
    assert raw.plan(backend="torch").source == "network"  # what the network guesses, as asked
    alone = nik.IKSolver(robot, checkpoint=path, fallback="none", analytic=False)
    assert alone.plan().source == "network"  # what the network delivers alone (the evaluation's rows)


def test_a_network_is_judged_once_and_again_after_its_weights_change():
    robot = nik.load_robot("panda")
    net = _useless(robot, "untrained", seed=11)
    judged = judge.counts()["judged"]
    first = judge.verdict(net, robot)
    assert judge.verdict(net, robot) is first and judge.counts()["judged"] == judged + 1
    other = nik.IKSolver(robot, analytic=False)
    other.net = net
    with pytest.warns(UserWarning):
        assert other.plan().net is None
    assert judge.counts()["judged"] == judged + 1  # the verdict is kept per network
    shipped = nik.models.load_pretrained(robot)
    with torch.no_grad():  # trained in place (here: the shipped weights loaded into it)
        for p, s in zip(net.parameters(), shipped.parameters(), strict=True):
            p.copy_(s)
    again = judge.verdict(net, robot)
    assert judge.counts()["judged"] == judged + 2 and again.earns and not first.earns
