"""nik.evaluate helpers that need no trained network."""

import torch
from torch.testing import assert_close

import nik
from nik.evaluate import robot_to_urdf
from nik.robots.urdf import build_pk_chain


def test_robot_to_urdf_writes_prismatic_joints_that_pytorch_kinematics_follows():
    robot = nik.load_robot("stanford")
    text, end = robot_to_urdf(robot)
    assert text.count('type="prismatic"') == 1
    chain = build_pk_chain(text, end).to(dtype=torch.float64)
    q = robot.sample(50, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    # pytorch-kinematics parses rpy through float32: about 1e-9 m here
    assert_close(chain.forward_kinematics(q).get_matrix(), robot.fk(q), atol=1e-7, rtol=0)
