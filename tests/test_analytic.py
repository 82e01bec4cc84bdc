"""Closed-form PUMA-type IK (nik.analytic): reach, distinctness, wrist variants, singularities, geometry checks."""

from __future__ import annotations

import math

import pytest
import torch
import yaml

import nik
from nik.analytic import is_puma_like, puma560_ik, puma560_params

PUMA_LIKE = ["puma560", "kuka_kr", "rebot_v_6r"]


def _wrapped(a: torch.Tensor) -> torch.Tensor:
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def _generic_q(robot) -> torch.Tensor:
    """A configuration away from every singularity: 30 % into each joint range, elbow bent, wrist tilted."""
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    q = lo + torch.tensor([0.55, 0.45, 0.35, 0.6, 0.3, 0.4], dtype=torch.float64) * (hi - lo)
    return q


@pytest.fixture(scope="module")
def puma():
    return nik.load_robot("puma560")


def test_generic_pose_valid_solutions_reach_it(puma):
    q = _generic_q(puma)
    T = puma.fk(q)
    sols, valid = puma560_ik(puma, T)
    assert sols.shape == (8, 6) and valid.shape == (8,)
    assert bool(valid.any())
    pos, rot = nik.pose_error(T, puma.fk(sols[valid]))
    torch.testing.assert_close(pos, torch.zeros_like(pos), atol=1e-9, rtol=0)
    torch.testing.assert_close(rot, torch.zeros_like(rot), atol=1e-9, rtol=0)
    # the configuration the pose came from is one of the valid solutions
    assert bool((_wrapped(sols[valid] - q).abs().amax(-1) < 1e-9).any())


def test_generic_pose_has_eight_distinct_solutions(puma):
    T = puma.fk(_generic_q(puma))
    sols, _ = puma560_ik(puma, T, check=False)
    # all 8 (limits ignored) reach the pose ...
    pos, rot = nik.pose_error(T, puma.fk(sols))
    assert float(pos.max()) < 1e-9 and float(rot.max()) < 1e-9
    # ... and are pairwise distinct
    dist = _wrapped(sols[:, None] - sols[None]).abs().amax(-1)
    off_diag = dist[~torch.eye(8, dtype=torch.bool)]
    assert float(off_diag.min()) > 1e-3


@pytest.mark.parametrize("name", PUMA_LIKE)
def test_random_poses_all_valid_solutions_reach_and_respect_limits(name):
    robot = nik.load_robot(name)
    q = robot.sample(500, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    T = robot.fk(q)
    sols, valid = puma560_ik(robot, T)
    pos, rot = nik.pose_error(T[:, None], robot.fk(sols))
    assert float(pos[valid].max()) < 1e-9 and float(rot[valid].max()) < 1e-9
    assert bool(robot.within_limits(sols[valid]).all())
    # the sampled configuration is always found among the valid solutions
    found = ((_wrapped(sols - q[:, None]).abs().amax(-1) < 1e-7) & valid).any(-1)
    assert bool(found.all())


@pytest.mark.parametrize("name", PUMA_LIKE)
def test_quaternion_and_matrix_wrists_agree(name):
    robot = nik.load_robot(name)
    T = robot.fk(robot.sample(300, generator=torch.Generator().manual_seed(4), dtype=torch.float64))
    q_quat, v_quat = puma560_ik(robot, T, wrist="quaternion")
    q_mat, v_mat = puma560_ik(robot, T, wrist="matrix")
    assert torch.equal(v_quat, v_mat)
    torch.testing.assert_close(_wrapped(q_quat - q_mat)[v_quat], torch.zeros_like(q_quat[v_quat]), atol=1e-9, rtol=0)


def test_batched_shapes_match_one_by_one(puma):
    T = puma.fk(puma.sample(6, generator=torch.Generator().manual_seed(5), dtype=torch.float64)).reshape(2, 3, 4, 4)
    sols, valid = puma560_ik(puma, T)
    assert sols.shape == (2, 3, 8, 6) and valid.shape == (2, 3, 8)
    for i in range(2):
        for j in range(3):
            s1, v1 = puma560_ik(puma, T[i, j])
            assert torch.equal(v1, valid[i, j])
            torch.testing.assert_close(s1, sols[i, j], atol=1e-12, rtol=0)


def _stretched_q(robot, q: torch.Tensor) -> torch.Tensor:
    """``q`` with joint 3 set so that the arm (shoulder to wrist centre) is fully stretched."""
    g = puma560_params(robot)
    c2 = 1.0 if math.cos(g.alpha[1]) > 0 else -1.0
    u, w = g.a[2], c2 * (-math.sin(g.alpha[2]) * g.d[3])
    theta3 = c2 * (-math.atan2(w, u))  # phi3 = -psi: the upper arm and forearm aligned
    q = q.clone()
    q[2] = _wrapped(torch.tensor(theta3 - g.offsets[2], dtype=torch.float64))
    return q


@pytest.mark.parametrize("kind", ["wrist", "stretched", "both"])
def test_singular_poses_give_finite_values_and_honest_mask(puma, kind):
    q = _generic_q(puma)
    if kind in ("wrist", "both"):
        q[4] = 0.0  # theta5 = 0: axes 4 and 6 aligned
    if kind in ("stretched", "both"):
        q = _stretched_q(puma, q)
    T = puma.fk(q)
    sols, valid = puma560_ik(puma, T)
    assert bool(torch.isfinite(sols).all())
    assert bool(valid.any())
    pos, rot = nik.pose_error(T, puma.fk(sols[valid]))
    assert float(pos.max()) <= 1e-6 and float(rot.max()) <= 1e-6


def test_unreachable_pose_is_all_invalid_and_finite(puma):
    T = puma.fk(_generic_q(puma))
    T[:3, 3] = torch.tensor([3.0, 0.0, 0.0], dtype=torch.float64)  # 3 m away: beyond reach
    sols, valid = puma560_ik(puma, T)
    assert bool(torch.isfinite(sols).all())
    assert not bool(valid.any())


def test_float32_input(puma):
    T = puma.fk(puma.sample(200, generator=torch.Generator().manual_seed(6), dtype=torch.float32))
    sols, valid = puma560_ik(puma, T)
    assert sols.dtype == torch.float32
    pos, rot = nik.pose_error(T[:, None], puma.fk(sols))
    assert bool(valid.any(-1).float().mean() > 0.95)
    assert float(pos[valid].max()) <= 2e-5 and float(rot[valid].max()) <= 2e-5


def _write(tmp_path, data: dict):
    path = tmp_path / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data))
    return nik.load_robot(path)


def test_paper_a_variant_and_modified_dh_table(tmp_path):
    # paper A's worked example: a2 = 431.8, a3 = 0 (standard DH)
    rows = [(-90, 0, 0), (0, 431.8, 149.09), (90, 0, 0), (-90, 0, 433.07), (90, 0, 0), (0, 0, 56.25)]
    paper_a = _write(
        tmp_path,
        {
            "name": "puma_paper_a",
            "convention": "dh",
            "unit": "mm",
            "angles": "deg",
            "joints": [{"alpha": al, "a": a, "d": d} for al, a, d in rows],
        },
    )
    # paper B / Craig: modified DH, the tool offset d6 as a tool frame
    craig = [(0, 0, 0), (-90, 0, 0), (0, 431.8, 149.09), (-90, -20.32, 433.07), (90, 0, 0), (-90, 0, 0)]
    mdh = _write(
        tmp_path,
        {
            "name": "puma_craig",
            "convention": "mdh",
            "unit": "mm",
            "angles": "deg",
            "tool": {"position": [0, 0, 56.25]},
            "joints": [{"alpha": al, "a": a, "d": d} for al, a, d in craig],
        },
    )
    for robot in (paper_a, mdh):
        q = robot.sample(300, generator=torch.Generator().manual_seed(7), dtype=torch.float64)
        T = robot.fk(q)
        sols, valid = puma560_ik(robot, T)
        pos, rot = nik.pose_error(T[:, None], robot.fk(sols))
        assert float(pos[valid].max()) < 1e-9 and float(rot[valid].max()) < 1e-9
        assert bool(((_wrapped(sols - q[:, None]).abs().amax(-1) < 1e-7) & valid).any(-1).all())
    # the same arm: the canonical geometry agrees with the built-in table up to the a3 term
    assert math.isclose(puma560_params(mdh).d6, 0.05625, abs_tol=1e-12)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_non_puma_robot_is_refused(name):
    robot = nik.load_robot(name)
    assert not is_puma_like(robot)
    with pytest.raises(ValueError, match="PUMA"):
        puma560_ik(robot, torch.eye(4, dtype=torch.float64))


def test_bad_arguments(puma):
    with pytest.raises(ValueError, match="wrist"):
        puma560_ik(puma, torch.eye(4, dtype=torch.float64), wrist="euler")
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        puma560_ik(puma, torch.zeros(3, 3))


def test_an_arm_with_a_prismatic_joint_is_not_puma_like():
    assert not is_puma_like(nik.load_robot("stanford"))
    puma = nik.load_robot("puma560")
    # the same chain with joint 6 declared prismatic: no longer a PUMA
    slid = nik.Robot("puma_slide", puma.G, puma.offsets, puma.limits, prismatic=[False] * 5 + [True])
    assert is_puma_like(puma) and not is_puma_like(slid)
    with pytest.raises(ValueError, match=r"prismatic joint\(s\) \[6\]"):
        puma560_params(slid)


# ---- URDF arms: origins parsed through float32 leave rotations orthonormal to about 1e-7 only ------------------------
def _via_urdf(name, tmp_path):
    from nik.evaluate import robot_to_urdf

    text, end = robot_to_urdf(nik.load_robot(name))
    path = tmp_path / f"{name}.urdf"
    path.write_text(text)
    return nik.load_robot(path, end_link=end)


def test_puma_like_urdf_arm_with_float32_origins_is_recognised_and_solved(tmp_path):
    robot = _via_urdf("rebot_v_6r", tmp_path)
    R = robot.G[:, :3, :3]
    assert float((R.transpose(-1, -2) @ R - torch.eye(3, dtype=R.dtype)).abs().max()) > 1e-8  # the hard case
    assert is_puma_like(robot)
    q = robot.sample(30, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    T = robot.fk(q)
    sols, valid = puma560_ik(robot, T)
    assert valid.any(-1).all()
    reached = robot.fk(sols[valid])
    target = T[:, None].expand(-1, 8, -1, -1)[valid]
    pos, rot = nik.poses.pose_error(target, reached)
    assert float(pos.max()) < 1e-6 and float(rot.max()) < 1e-6  # FK of the robot itself, not of a rounded copy


def test_general_6r_urdf_arm_with_float32_origins_is_not_puma_like(tmp_path):
    text = (
        '<robot name="g6"><link name="l0"/>'
        + "".join(
            f'<link name="l{i + 1}"/><joint name="j{i + 1}" type="revolute">'
            f'<parent link="l{i}"/><child link="l{i + 1}"/>'
            f'<origin xyz="0.1 {0.02 * i} 0.2" rpy="{0.3 + i} {0.2 * i - 0.5} {1.1 - 0.4 * i}"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
            for i in range(6)
        )
        + "</robot>"
    )
    path = tmp_path / "g6.urdf"
    path.write_text(text)
    robot = nik.load_robot(path)
    assert robot.dof == 6
    assert not is_puma_like(robot)  # used to raise RuntimeError("canonical_dh: factor 1 has no DH form")
    with pytest.raises(ValueError, match="not PUMA-like"):
        puma560_params(robot)
