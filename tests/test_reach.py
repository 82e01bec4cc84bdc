"""nik.reach: the provable reach bound flags far targets and never a reachable one."""

from __future__ import annotations

import pytest
import torch

import nik
from nik.robots.reach import reach_center, reach_radius, reach_ratio, unreachable_message, within_reach


@pytest.mark.parametrize("name", ["puma560", "kuka_kr", "ur5", "panda", "rebot_v_6r"])
def test_no_sampled_configuration_lies_beyond_the_bound(name):
    robot = nik.load_robot(name)
    q = robot.sample(4000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    T = robot.fk(q)
    assert bool(within_reach(robot, T).all())
    assert float(reach_ratio(robot, T).max()) <= 1.0


@pytest.mark.parametrize("name", ["ur5", "panda", "kuka_kr"])
def test_target_at_twice_the_reach_is_unreachable_and_one_at_full_extension_is_not(name):
    robot = nik.load_robot(name)
    q = robot.sample(4000, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    T = robot.fk(q)
    c = reach_center(robot)
    d = torch.linalg.vector_norm(T[:, :3, 3] - c, dim=-1)
    boundary = T[d.argmax()].clone()  # the most extended of the sampled configurations
    far = boundary.clone()
    u = (boundary[:3, 3] - c) / torch.linalg.vector_norm(boundary[:3, 3] - c)
    far[:3, 3] = c + 2.0 * reach_radius(robot) * u
    flags = within_reach(robot, torch.stack([boundary, far]))
    assert flags.tolist() == [True, False]


def test_a_straight_arm_reaches_exactly_its_bound():
    # two links of 0.3 m and 0.2 m along x, joints about z: fully stretched at q = 0, reach 0.5 m
    G = torch.eye(4).repeat(3, 1, 1).double()
    G[1, 0, 3], G[2, 0, 3] = 0.3, 0.2
    robot = nik.Robot("planar2", G, [0.0, 0.0], [[-3.0, 3.0], [-3.0, 3.0]])
    assert reach_radius(robot) == pytest.approx(0.5)
    T = robot.fk(torch.zeros(1, 2, dtype=torch.float64))
    assert bool(within_reach(robot, T).all())
    T2 = T.clone()
    T2[0, 0, 3] = 0.5 * 1.001
    assert not bool(within_reach(robot, T2).any())


def test_message_counts_the_far_targets_and_asks_about_millimetres_only_when_far_enough():
    robot = nik.load_robot("ur5")
    T = robot.fk(robot.sample(3, generator=torch.Generator().manual_seed(2), dtype=torch.float64))
    assert unreachable_message(robot, T, within_reach(robot, T)) is None
    T[0, :3, 3] *= 3.0 / float(reach_ratio(robot, T[:1]))  # 3 x the reach
    msg = unreachable_message(robot, T, within_reach(robot, T))
    assert msg.startswith("1 of 3 target(s)") and "millimetres" not in msg
    T[1, :3, 3] *= 1000.0
    assert "millimetres" in unreachable_message(robot, T, within_reach(robot, T), unit_hint="pass --unit mm")


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_compiled_flags_and_the_message_agree_with_the_torch_bound(name):
    """One bound, one message: the compiled flags (the robot's model, what solve and solve_path use) equal
    within_reach on targets on both sides of the bound, and the model words its warning with unreachable_message."""
    from nik.ik.model import model_of

    robot = nik.load_robot(name)
    T = robot.fk(robot.sample(64, generator=torch.Generator().manual_seed(4), dtype=torch.float64))
    scale = torch.linspace(0.5, 400.0, 64, dtype=torch.float64)
    c = reach_center(robot)
    T[:, :3, 3] = c + (T[:, :3, 3] - c) * scale[:, None]
    flags = within_reach(robot, T)
    assert 0 < int(flags.sum()) < 64
    compiled, every = model_of(robot).reach(T.numpy().copy())
    assert compiled.tolist() == flags.tolist() and not every
    assert model_of(robot).unreachable_message(T.numpy(), compiled) == unreachable_message(robot, T, flags)
