"""nik.ik.model: one compiled model per robot, its facts checked against the torch references."""

from __future__ import annotations

import gc
import math

import numpy as np
import pytest
import torch

import nik
from nik.ik.model import APPROXIMATE_CHECK_TOL, model_of
from nik.lm import LMCfg
from nik.robots.reach import within_reach


def _poses(robot, n, seed):
    g = torch.Generator().manual_seed(seed)
    return robot.fk(robot.sample(n, generator=g, dtype=torch.float64)).numpy()


def test_model_is_built_once_per_robot_and_lm_config_and_dropped_with_the_robot():
    robot = nik.load_robot("panda")
    m = model_of(robot)
    assert model_of(robot) is m and m.robot is robot
    other = model_of(robot, LMCfg(iters=7))
    assert other is not m and other.lm is not m.lm and other.G is m.G
    ref = m.robot_ref
    del robot, m, other
    gc.collect()
    assert ref() is None


def test_model_limits_reach_and_wraps_match_the_robot():
    robot = nik.load_robot("xarm7")
    m = model_of(robot)
    assert np.array_equal(m.lo, robot.limits[:, 0].numpy()) and np.array_equal(m.hi, robot.limits[:, 1].numpy())
    lo32, hi32 = robot.limits_as(torch.empty(0, dtype=torch.float32))
    assert m.lo32.dtype == np.float32 and np.array_equal(m.lo32, lo32.numpy()) and np.array_equal(m.hi32, hi32.numpy())
    assert np.array_equal(m.wraps, (m.hi - m.lo) > 2 * math.pi + 1e-6)
    T = _poses(robot, 50, 0)
    T[::3, :3, 3] *= 3.0  # some out of reach
    flags, every = m.reach(T)
    assert np.array_equal(flags, within_reach(robot, torch.from_numpy(T)).numpy()) and not every and flags.any()
    assert "beyond the reach of xarm7" in m.unreachable_message(T, flags)
    assert m.unreachable_message(T[flags], flags[flags]) is None


def test_model_closed_solutions_reach_the_target_by_fk_where_valid():
    robot = nik.load_robot("kuka_kr")
    m = model_of(robot)
    assert m.closed is not None and not m.approximate
    T = _poses(robot, 20, 1)
    q, valid = m.closed_solutions(T)
    assert q.shape == (20, 8, 6) and valid.any(axis=1).all()
    from nik.poses import pose_error

    pos, rot = pose_error(torch.from_numpy(T)[:, None], robot.fk(torch.from_numpy(q)))
    assert bool((pos[torch.from_numpy(valid)] < 1e-9).all()) and bool((rot[torch.from_numpy(valid)] < 1e-9).all())
    ref_sols, ref_valid = nik.analytic.solve(robot, torch.from_numpy(T))
    assert np.array_equal(valid.sum(1), ref_valid.numpy().sum(1))
    with pytest.raises(ValueError, match="no closed form"):
        model_of(nik.load_robot("panda")).closed_solutions(T)


def test_an_approximate_closed_form_is_the_ideal_arms_checked_at_the_approximate_tolerance():
    robot = nik.load_robot("kuka_kr")
    G = robot.G.numpy().copy()
    G[4, :3, 3] += 3e-8  # the wrist axes miss each other by 3e-8 m: the family holds only within tolerance
    bent = nik.Robot("bent", G, robot.offsets, robot.limits)
    m = model_of(bent)
    assert m.approximate and m.closed_check[torch.float64] == APPROXIMATE_CHECK_TOL
    q, valid = m.closed_solutions(_poses(bent, 10, 2))
    assert valid.any(axis=1).all()


def test_arm_targets_map_poses_into_the_bare_arms_frame_and_the_arm_hash_ignores_frames():
    bare = nik.load_robot("panda").arm  # the built-in panda without its flange (a tool frame)
    framed = nik.load_robot("panda", base=[0.1, -0.2, 0.8, 0.9238795, 0, 0, 0.3826834], tool=[0, 0, 0.1, 1, 0, 0, 0])
    assert framed.definition_hash != bare.definition_hash and framed.arm_hash == bare.definition_hash
    rebuilt = nik.Robot.from_definition(framed.to_definition())
    assert rebuilt.arm_hash == bare.definition_hash
    m = model_of(framed)
    assert m.has_frames and not model_of(bare).has_frames
    g = torch.Generator().manual_seed(3)
    q = framed.sample(5, generator=g, dtype=torch.float64)
    np.testing.assert_allclose(m.arm_targets(framed.fk(q).numpy()), bare.fk(q).numpy(), atol=1e-12)


def test_packed_networks_are_kept_per_network():
    robot = nik.load_robot("panda")
    net = nik.models.load_pretrained(robot)
    m = model_of(robot)
    p = m.packed(net)
    assert p is not None and m.packed(net) is p
