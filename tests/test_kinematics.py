"""FK of every built-in robot against independent references: explicit DH / modified-DH
4x4 products and matrix exponentials written here from methods.md's tables, and
pytorch-kinematics on the same URDF."""

import math

import pytest
import torch
from torch.testing import assert_close

import nik
from nik.robots.urdf import build_pk_chain, load_urdf

DEG = math.pi / 180

# methods.md 1.1, 1.2, 1.3 typed in again (not read from configs/), mm and degrees
PUMA_DH = [  # alpha, a, d
    (-90, 0, 0),
    (0, 431.8, 149.09),
    (90, -20.32, 0),
    (-90, 0, 433.07),
    (90, 0, 0),
    (0, 0, 56.25),
]
KUKA_DH = [  # offset, d, a, alpha
    (0, 675, 260, 90),
    (90, 0, 645, 0),
    (0, 0, 35, 90),
    (0, 670, 0, 90),
    (180, 0, 0, 90),
    (0, 115, 0, 0),
]
D1, D2, D3, D4, D5, D6 = 100, 320, 290, 121, 310, 112.5
REBOT_SCREWS = [  # omega, r
    ((0, 0, 1), (0, 0, 0)),
    ((0, 1, 0), (D1, 0, D2)),
    ((0, 1, 0), (D1, 0, D2 + D3)),
    ((1, 0, 0), (D1, 0, D2 + D3 + D4)),
    ((0, -1, 0), (D1 + D5, 0, D2 + D3 + D4)),
    ((0, 0, 1), (D1 + D5, 0, D2 + D3 + D4 + D6)),
]


def dh_matrix(theta, d, a, alpha):
    """Standard DH link transform Rz(theta) Tz(d) Tx(a) Rx(alpha), written out entry by entry."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return torch.tensor(
        [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1]],
        dtype=torch.float64,
    )


def mdh_matrix(theta, d, a, alpha):
    """Modified (Craig) DH link transform Rx(alpha) Tx(a) Rz(theta) Tz(d), written out entry by entry."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return torch.tensor(
        [[ct, -st, 0, a], [st * ca, ct * ca, -sa, -sa * d], [st * sa, ct * sa, ca, ca * d], [0, 0, 0, 1]],
        dtype=torch.float64,
    )


def twist_exp(omega, r, theta):
    """exp([xi] theta) for a revolute screw by torch.linalg.matrix_exp of the 4x4 twist."""
    w = torch.tensor(omega, dtype=torch.float64)
    v = -torch.linalg.cross(w, torch.tensor(r, dtype=torch.float64))
    X = torch.zeros(4, 4, dtype=torch.float64)
    X[:3, :3] = torch.tensor([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    X[:3, 3] = v
    return torch.linalg.matrix_exp(X * theta)


def reference_fk(name, q):
    """One configuration q (list of radians) -> 4x4, metres, by the explicit products above."""
    T = torch.eye(4, dtype=torch.float64)
    if name == "puma560":
        for qi, (al, a, d) in zip(q, PUMA_DH, strict=True):
            T = T @ dh_matrix(qi, d * 1e-3, a * 1e-3, al * DEG)
    elif name == "kuka_kr":
        for qi, (off, d, a, al) in zip(q, KUKA_DH, strict=True):
            T = T @ dh_matrix(qi + off * DEG, d * 1e-3, a * 1e-3, al * DEG)
    elif name == "rebot_v_6r":
        for qi, (w, r) in zip(q, REBOT_SCREWS, strict=True):
            T = T @ twist_exp(w, [x * 1e-3 for x in r], qi)
        M = torch.eye(4, dtype=torch.float64)
        M[:3, 3] = torch.tensor([D1 + D5, 0, D2 + D3 + D4], dtype=torch.float64) * 1e-3
        T = T @ M
    return T


def random_q(robot, n, seed=0, dtype=torch.float64):
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=dtype)


@pytest.mark.parametrize("name", ["puma560", "kuka_kr", "rebot_v_6r"])
def test_builtin_fk_matches_explicit_products_at_100_configurations(name):
    robot = nik.load_robot(name)
    q = random_q(robot, 100)
    expected = torch.stack([reference_fk(name, qi.tolist()) for qi in q])
    assert_close(robot.fk(q), expected, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_urdf_arm_fk_matches_pytorch_kinematics(name):
    robot = nik.load_robot(name)
    chain = build_pk_chain(open(robot.source).read(), robot.end_link).to(dtype=torch.float64)
    assert chain.get_joint_parameter_names() == robot.joint_names
    q = random_q(robot, 100)
    assert_close(robot.fk(q), chain.forward_kinematics(q).get_matrix(), atol=1e-9, rtol=0)


def test_urdf_with_other_end_link_matches_pytorch_kinematics():
    robot = nik.load_robot("configs/robots/urdf/panda.urdf", end_link="panda_hand_tcp")
    assert robot.end_link == "panda_hand_tcp" and robot.dof == 7
    chain = build_pk_chain(open(robot.source).read(), "panda_hand_tcp").to(dtype=torch.float64)
    q = random_q(robot, 20)
    assert_close(robot.fk(q), chain.forward_kinematics(q).get_matrix(), atol=1e-9, rtol=0)


def test_urdf_float64_origins_differ_from_pytorch_kinematics_only_by_its_float32_rpy_parse():
    exact = load_urdf("configs/robots/urdf/panda.urdf", origins="float64")
    pk_like = nik.load_robot("panda")
    q = random_q(exact, 50)
    assert_close(exact.fk(q), pk_like.fk(q), atol=2e-7, rtol=0)
    R = exact.fk(q)[:, :3, :3]
    eye = torch.eye(3, dtype=torch.float64).expand_as(R)
    assert_close(R.transpose(-1, -2) @ R, eye, atol=1e-14, rtol=0)


def test_puma_zero_pose_is_the_table_by_hand():
    # all theta = 0: R = I, p = (a2 + a3, d2, d4 + d6)
    T = nik.load_robot("puma560").fk(torch.zeros(6, dtype=torch.float64))
    expected = torch.eye(4, dtype=torch.float64)
    expected[:3, 3] = torch.tensor([431.8 - 20.32, 149.09, 433.07 + 56.25], dtype=torch.float64) * 1e-3
    assert_close(T, expected, atol=1e-12, rtol=0)


def test_kuka_zero_pose_is_the_table_by_hand():
    # theta = offsets (0, 90, 0, 0, 180, 0): arm up, forearm and tool forward along +x
    T = nik.load_robot("kuka_kr").fk(torch.zeros(6, dtype=torch.float64))
    expected = torch.tensor(
        [[0, 0, 1, (260 + 670 + 115) * 1e-3], [0, 1, 0, 0], [-1, 0, 0, (675 + 645 + 35) * 1e-3], [0, 0, 0, 1]],
        dtype=torch.float64,
    )
    assert_close(T, expected, atol=1e-12, rtol=0)


def test_poe_home_pose_is_home():
    T = nik.load_robot("rebot_v_6r").fk(torch.zeros(6, dtype=torch.float64))
    expected = torch.eye(4, dtype=torch.float64)
    expected[:3, 3] = torch.tensor([0.410, 0.0, 0.731], dtype=torch.float64)
    assert_close(T, expected, atol=1e-12, rtol=0)


def test_mdh_convention_matches_explicit_craig_products(tmp_path):
    rows = [(0, 0, 0), (-90, 0, 243.5), (0, 431.8, -93.4), (-90, -20.32, 433.07), (90, 0, 0), (-90, 0, 0)]
    text = "name: puma_mdh\nconvention: mdh\nunit: mm\nangles: deg\njoints:\n" + "".join(
        f"  - {{alpha: {al}, a: {a}, d: {d}}}\n" for al, a, d in rows
    )
    (tmp_path / "puma_mdh.yaml").write_text(text)
    robot = nik.load_robot(tmp_path / "puma_mdh.yaml")
    q = random_q(robot, 30)
    for qi, T in zip(q, robot.fk(q), strict=True):
        expected = torch.eye(4, dtype=torch.float64)
        for theta, (al, a, d) in zip(qi.tolist(), rows, strict=True):
            expected = expected @ mdh_matrix(theta, d * 1e-3, a * 1e-3, al * DEG)
        assert_close(T, expected, atol=1e-9, rtol=0)


def test_dh_chain_written_as_urdf_gives_the_same_fk(tmp_path):
    # the KUKA table as a URDF: each DH link is an origin (rpy, xyz) for the next joint
    robot = nik.load_robot("kuka_kr")
    joints, parent = [], "base"
    origin = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # x y z r p y before joint 1
    for i, (_, d, a, al) in enumerate(KUKA_DH):
        joints.append(f"""<joint name="j{i + 1}" type="revolute"><parent link="{parent}"/><child link="l{i + 1}"/>
          <origin xyz="{origin[0]} {origin[1]} {origin[2]}" rpy="{origin[3]} {origin[4]} {origin[5]}"/>
          <axis xyz="0 0 1"/><limit lower="-6" upper="6" effort="1" velocity="1"/></joint>""")
        parent = f"l{i + 1}"
        origin = (a * 1e-3, 0.0, d * 1e-3, al * DEG, 0.0, 0.0)  # Tz(d) Tx(a) Rx(alpha), rotation last
    # Tz(d) Tx(a) Rx(alpha) = translation (a, 0, d) then Rx(alpha): a URDF origin applies xyz then rpy
    links = "".join(f'<link name="l{i + 1}"/>' for i in range(6))
    tool = f"""<link name="tool"/><joint name="jt" type="fixed"><parent link="l6"/><child link="tool"/>
      <origin xyz="{origin[0]} {origin[1]} {origin[2]}" rpy="{origin[3]} {origin[4]} {origin[5]}"/></joint>"""
    urdf = f'<robot name="kuka_urdf"><link name="base"/>{links}{"".join(joints)}{tool}</robot>'
    (tmp_path / "kuka.urdf").write_text(urdf)
    urdf_robot = load_urdf(tmp_path / "kuka.urdf", end_link="tool", origins="float64")
    q = random_q(robot, 50)
    offsets = torch.tensor([off for off, *_ in KUKA_DH], dtype=torch.float64) * DEG
    assert_close(urdf_robot.fk(q + offsets), robot.fk(q), atol=1e-9, rtol=0)


def test_fk_is_differentiable_gradcheck():
    robot = nik.load_robot("kuka_kr")
    q = random_q(robot, 3).requires_grad_()
    assert torch.autograd.gradcheck(robot.fk, (q,))


def test_batched_equals_one_by_one():
    robot = nik.load_robot("panda")
    q = random_q(robot, 16)
    batched = robot.fk(q)
    single = torch.stack([robot.fk(qi) for qi in q])
    assert_close(batched, single, atol=0, rtol=0)


@pytest.mark.parametrize("shape", [(), (5,), (2, 3), (2, 1, 4)])
def test_any_leading_batch_shape(shape):
    robot = nik.load_robot("puma560")
    q = random_q(robot, math.prod(shape) if shape else 1).reshape(*shape, robot.dof)
    T = robot.fk(q)
    assert T.shape == (*shape, 4, 4)
    assert_close(T.reshape(-1, 4, 4), robot.fk(q.reshape(-1, robot.dof)))


def test_float32_follows_float64_and_keeps_dtype():
    robot = nik.load_robot("kuka_kr")
    q64 = random_q(robot, 200)
    T32 = robot.fk(q64.float())
    assert T32.dtype == torch.float32
    assert_close(T32.double(), robot.fk(q64), atol=2e-6, rtol=0)


def test_compiled_fk_equals_eager():
    robot = nik.load_robot("ur5")
    q = random_q(robot, 64)
    assert_close(robot.fk(q, compiled=True), robot.fk(q), atol=1e-12, rtol=0)


@pytest.mark.parametrize("name", ["kuka_kr", "panda", "rebot_v_6r"])
def test_jacobian_matches_autograd(name):
    robot = nik.load_robot(name)
    q = random_q(robot, 1)[0]
    T, J = robot.fk_and_jacobian(q)
    assert_close(T, robot.fk(q))
    lin = torch.autograd.functional.jacobian(lambda x: robot.fk(x)[:3, 3], q)
    assert_close(J[:3], lin, atol=1e-12, rtol=0)
    # angular part: dR/dq_i = [w_i]x R, so w_i = vee(dR/dq_i R^T)
    dR = torch.autograd.functional.jacobian(lambda x: robot.fk(x)[:3, :3], q)  # (3, 3, dof)
    W = torch.einsum("abk,cb->kac", dR, T[:3, :3])
    omega = torch.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], dim=0)
    assert_close(J[3:], omega, atol=1e-12, rtol=0)


def test_fk_rejects_nan_and_wrong_last_dimension():
    robot = nik.load_robot("kuka_kr")
    with pytest.raises(ValueError, match="NaN or inf"):
        robot.fk(torch.full((2, 6), float("nan")))
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        robot.fk(torch.zeros(2, 7))
