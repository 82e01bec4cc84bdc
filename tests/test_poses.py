"""Pose representations, pose errors and validation."""

import math

import numpy as np
import pytest
import torch
from torch.testing import assert_close

import nik
from nik import poses


def random_rotations(n, seed=0, dtype=torch.float64):
    q = torch.randn(n, 4, generator=torch.Generator().manual_seed(seed), dtype=dtype)
    return poses.quaternion_to_matrix(q)


def random_poses(n, seed=0, dtype=torch.float64):
    p = torch.randn(n, 3, generator=torch.Generator().manual_seed(seed + 1), dtype=dtype)
    return poses.make_pose(random_rotations(n, seed, dtype), p)


def axis_angle(axis, angle, dtype=torch.float64):
    """Rodrigues' formula, independent of nik.poses."""
    k = torch.tensor(axis, dtype=dtype) / torch.linalg.vector_norm(torch.tensor(axis, dtype=dtype))
    K = torch.tensor([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]], dtype=dtype)
    return torch.eye(3, dtype=dtype) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


@pytest.mark.parametrize("representation", ["quat", "quat_xyzw", "rpy", "rot6d", "matrix"])
def test_pose_vector_round_trip(representation):
    T = random_poses(500)
    v = poses.pose_to_vector(T, representation)
    assert v.shape == (500, poses.POSE_DIMS[representation])
    assert_close(poses.vector_to_pose(v, representation), T, atol=1e-12, rtol=0)


def test_quaternion_round_trip_near_pi_rotations_uses_a_stable_pivot():
    # 180-degree rotations make trace = -1, where the naive w-pivot formula divides by ~0
    Rs = torch.stack([axis_angle(a, math.pi - 1e-9) for a in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1])])
    q = poses.matrix_to_quaternion(Rs)
    assert_close(torch.linalg.vector_norm(q, dim=-1), torch.ones(4, dtype=torch.float64))
    assert_close(poses.quaternion_to_matrix(q), Rs, atol=1e-12, rtol=0)


def test_quaternion_convention_is_w_x_y_z():
    q = poses.matrix_to_quaternion(axis_angle([0, 0, 1], math.pi / 2))
    s = math.sqrt(0.5)
    assert_close(q, torch.tensor([s, 0, 0, s], dtype=torch.float64))


def test_rpy_matches_paper_c_equation_3():
    R = random_rotations(100, seed=4)
    n, o, a = R[..., :, 0], R[..., :, 1], R[..., :, 2]
    expected = torch.stack(
        [
            torch.atan2(o[:, 2], a[:, 2]),
            torch.atan2(-n[:, 2], torch.sqrt(n[:, 0] ** 2 + n[:, 1] ** 2)),
            torch.atan2(n[:, 1], n[:, 0]),
        ],
        dim=-1,
    )
    assert_close(poses.matrix_to_rpy(R), expected)
    # R = Rz(yaw) Ry(pitch) Rx(roll)
    r, p, y = 0.3, -0.4, 1.2
    assert_close(
        poses.rpy_to_matrix(torch.tensor([r, p, y], dtype=torch.float64)),
        axis_angle([0, 0, 1], y) @ axis_angle([0, 1, 0], p) @ axis_angle([1, 0, 0], r),
    )


def test_pose_error_is_zero_at_identity_and_has_finite_gradient():
    T = random_poses(8)
    T2 = T.clone().requires_grad_()
    pos, rot = nik.pose_error(T, T2)
    assert_close(pos, torch.zeros(8, dtype=torch.float64), atol=1e-15, rtol=0)
    assert_close(rot, torch.zeros(8, dtype=torch.float64), atol=1e-7, rtol=0)
    (pos.sum() + rot.sum()).backward()
    assert torch.isfinite(T2.grad).all()


@pytest.mark.parametrize("angle", [1e-9, 1e-6, 1e-3, 1.0, math.pi - 1e-6, math.pi])
def test_pose_error_recovers_the_rotation_angle(angle):
    T = random_poses(1, seed=2)[0]
    R = T[:3, :3] @ axis_angle([0.2, -0.5, 0.7], angle)
    T2 = poses.make_pose(R, T[:3, 3] + torch.tensor([0.003, 0.0, -0.004], dtype=torch.float64))
    pos, rot = nik.pose_error(T, T2)
    assert not torch.isnan(rot)
    assert_close(pos, torch.tensor(0.005, dtype=torch.float64))
    assert_close(rot, torch.tensor(angle, dtype=torch.float64), rtol=1e-6, atol=1e-12 if angle < 1 else 1e-7)


def test_rot6d_gram_schmidt_repairs_a_noisy_6d_vector():
    R = random_rotations(10, seed=7)
    v = poses.matrix_to_rot6d(R) * 3.0  # scaled columns still map back to R
    assert_close(poses.rot6d_to_matrix(v), R)


# ---- validation -----------------------------------------------------------
def test_validate_pose_accepts_float32_rotations():
    poses.validate_pose(random_poses(100).float())


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda T: T.__setitem__((3, 0, 3), float("nan")), "pose 3 contains NaN or inf"),
        (lambda T: T.__setitem__((2, 0, 0), T[2, 0, 0] * 1.3), r"rotation of pose 2 is not orthonormal"),
        (lambda T: T.__setitem__((1, slice(0, 3), 0), -T[1, :3, 0]), r"pose 1 has det"),
        (lambda T: T.__setitem__((0, 3, 0), 1.0), r"pose 0 has bottom row"),
    ],
)
def test_validate_pose_names_the_problem_and_the_row(mutate, message):
    T = random_poses(5)
    mutate(T)
    with pytest.raises(ValueError, match=message):
        poses.validate_pose(T)


def test_validate_pose_rejects_wrong_shape():
    with pytest.raises(ValueError, match=r"T_target: expected shape \(\.\.\., 4, 4\), got \(3, 3\)"):
        poses.validate_pose(torch.eye(3))


def test_validate_quaternion_normalises_near_unit_and_rejects_zero():
    q = torch.tensor([[1.0005, 0, 0, 0]], dtype=torch.float64)
    assert_close(poses.validate_quaternion(q), torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float64))
    with pytest.raises(ValueError, match="row 0 has norm 0"):
        poses.validate_quaternion(torch.zeros(1, 4))


def test_quat_xyzw_is_the_quaternion_w_last_as_ros_gives_it():
    # a quarter turn about z: w = cos 45 deg, z = sin 45 deg; ROS order puts w last
    T = poses.make_pose(axis_angle([0, 0, 1], math.pi / 2), torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64))
    c = math.cos(math.pi / 4)
    assert_close(poses.pose_to_vector(T, "quat_xyzw"), torch.tensor([0.1, 0.2, 0.3, 0, 0, c, c], dtype=torch.float64))
    assert_close(poses.vector_to_pose(torch.tensor([0.1, 0.2, 0.3, 0, 0, c, c], dtype=torch.float64), "quat_xyzw"), T)
    xyzw = np.array([[1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.9]])
    assert poses.xyzw_to_wxyz(xyzw).tolist() == [[1.0, 2.0, 3.0, 0.9, 0.1, 0.2, 0.3]]
