"""FK of every built-in robot against independent references: explicit DH / modified-DH
4x4 products and matrix exponentials written here from methods.md's tables, and
pytorch-kinematics on the same URDF. Prismatic joints: the Stanford arm against a plain numpy
DH product and against pytorch-kinematics, and the kernels on random mixed chains."""

import math

import numpy as np
import pytest
import torch
from torch.testing import assert_close

import nik
from nik.kinematics import FKKernel, chain_fk_eager, chain_jacobian, generate_fk_source, to_homogeneous
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


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7"])
def test_urdf_arm_fk_matches_pytorch_kinematics(name):
    robot = nik.load_robot(name)
    link = robot.flange_link or robot.end_link  # the link a pose means: ur5's tool0, panda's panda_link8
    chain = build_pk_chain(open(robot.source).read(), link).to(dtype=torch.float64)
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
    exact = load_urdf("configs/robots/urdf/panda.urdf", end_link="panda_link8", origins="float64")
    pk_like = nik.load_robot("panda")  # the built-in's poses are of the flange panda_link8
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


@pytest.mark.long
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


@pytest.mark.parametrize("name", ["panda", "stanford"])
def test_fk_of_numpy_joints_is_numpy_equal_to_the_torch_fk(name):
    robot = nik.load_robot(name)
    q = random_q(robot, 6, seed=3)
    reference = robot.fk(q, check=True)
    strided = np.stack([q.numpy(), -q.numpy()], axis=-1)[..., 0]  # q's values, not contiguous
    readonly = q.numpy().copy()
    readonly.flags.writeable = False
    for given, expected in (
        (q[0].numpy(), reference[0]),
        (q.numpy(), reference),
        (q.numpy().reshape(2, 3, robot.dof), reference.reshape(2, 3, 4, 4)),
        (strided[2], reference[2]),
        (readonly, reference),
        (q[1].tolist(), reference[1]),
    ):
        T = robot.fk(given)
        assert isinstance(T, np.ndarray) and T.dtype == np.float64 and T.shape == expected.shape
        np.testing.assert_allclose(T, expected.numpy(), atol=1e-12, rtol=0)
    T32 = robot.fk(q.numpy().astype(np.float32))
    assert T32.dtype == np.float32
    np.testing.assert_allclose(T32, reference.numpy(), atol=2e-6, rtol=0)
    zeros = robot.fk(np.zeros(robot.dof, dtype=int))  # integers are radians (metres) too
    np.testing.assert_allclose(zeros, robot.fk(torch.zeros(robot.dof, dtype=torch.float64)).numpy(), atol=0, rtol=0)


def test_fk_of_numpy_joints_refuses_what_the_torch_fk_refuses():
    robot = nik.load_robot("ur5")
    bad = np.zeros(6)
    bad[3] = np.inf
    for given, match in ((bad, "NaN or inf"), (np.zeros((2, 5)), r"\(\.\.\., 6\)"), (["a"] * 6, "joint values")):
        with pytest.raises(ValueError, match=match):
            robot.fk(given)


def test_fk_of_one_configuration_equals_the_batched_torch_fk_and_keeps_gradients():
    robot = nik.load_robot("panda")
    q = random_q(robot, 600, seed=4)  # over FK_COMPILED_MAX: the batch runs through torch
    batched = robot.fk(q)
    single = torch.stack([robot.fk(qi) for qi in q[:50]])
    assert_close(single, batched[:50], atol=1e-12, rtol=0)
    one = q[7].clone().requires_grad_(True)
    T = robot.fk(one)  # a tensor that requires grad keeps the torch path
    assert T.requires_grad and T.grad_fn is not None
    assert_close(T.detach(), single[7], atol=1e-12, rtol=0)
    T[:3, 3].sum().backward()
    _, J = robot.fk_and_jacobian(q[7])
    assert_close(one.grad, J[:3].sum(dim=0), atol=1e-12, rtol=0)


def test_clamp_within_limits_and_jacobian_take_numpy_and_answer_numpy():
    robot = nik.load_robot("stanford")
    q = random_q(robot, 4, seed=5) * 3.0  # some joints past their limits
    clamped = robot.clamp(q.numpy())
    assert isinstance(clamped, np.ndarray)
    np.testing.assert_array_equal(clamped, robot.clamp(q).numpy())
    inside = robot.within_limits(q.numpy())
    assert isinstance(inside, np.ndarray) and inside.dtype == bool
    np.testing.assert_array_equal(inside, robot.within_limits(q).numpy())
    assert not inside.all() and robot.within_limits(clamped).all()
    T, J = robot.fk_and_jacobian(q[0].numpy())
    T_ref, J_ref = robot.fk_and_jacobian(q[0])
    assert isinstance(T, np.ndarray) and isinstance(J, np.ndarray)
    np.testing.assert_allclose(T, T_ref.numpy(), atol=1e-12, rtol=0)
    np.testing.assert_allclose(J, J_ref.numpy(), atol=1e-12, rtol=0)


# ---------------------------------------------------------------------------
# Prismatic joints
# ---------------------------------------------------------------------------
# The Stanford arm of Corke's Robotics Toolbox (models.DH.Stanford), typed in again in metres and
# radians: (type, theta, d, a, alpha); the joint variable replaces theta (R) or d (P).
STANFORD = [
    ("R", None, 0.412, 0.0, -math.pi / 2),
    ("R", None, 0.154, 0.0, math.pi / 2),
    ("P", -math.pi / 2, None, 0.0203, 0.0),
    ("R", None, 0.0, 0.0, -math.pi / 2),
    ("R", None, 0.0, 0.0, math.pi / 2),
    ("R", None, 0.0, 0.0, 0.0),
]


def dh_numpy(theta, d, a, alpha):
    """Rz(theta) @ Tz(d) @ Tx(a) @ Rx(alpha) as a product of four plain numpy 4x4 matrices."""
    Rz, Tz, Tx, Rx = np.eye(4), np.eye(4), np.eye(4), np.eye(4)
    Rz[:2, :2] = [[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]]
    Tz[2, 3], Tx[0, 3] = d, a
    Rx[1:3, 1:3] = [[math.cos(alpha), -math.sin(alpha)], [math.sin(alpha), math.cos(alpha)]]
    return Rz @ Tz @ Tx @ Rx


def stanford_reference(q):
    T = np.eye(4)
    for qi, (kind, theta, d, a, alpha) in zip(q, STANFORD, strict=True):
        T = T @ (dh_numpy(qi, d, a, alpha) if kind == "R" else dh_numpy(theta, qi, a, alpha))
    return T


def stanford_urdf() -> str:
    """The table above as a URDF: after each row, the next joint's origin is the row's constant part
    Tz(d) Rz(theta) Tx(a) Rx(alpha) = translation (a cos theta, a sin theta, d), then rpy (alpha, 0, theta)."""
    joints, parent, origin = [], "base", (0, 0, 0, 0, 0, 0)
    for i, (kind, theta, d, a, alpha) in enumerate(STANFORD):
        kind_name = "revolute" if kind == "R" else "prismatic"
        lower, upper = (-2.9, 2.9) if kind == "R" else (0.3048, 1.27)
        joints.append(f"""<joint name="j{i + 1}" type="{kind_name}"><parent link="{parent}"/><child link="l{i + 1}"/>
          <origin xyz="{origin[0]!r} {origin[1]!r} {origin[2]!r}" rpy="{origin[3]!r} {origin[4]!r} {origin[5]!r}"/>
          <axis xyz="0 0 1"/><limit lower="{lower}" upper="{upper}" effort="1" velocity="1"/></joint>""")
        parent = f"l{i + 1}"
        th, dd = (0.0, d) if kind == "R" else (theta, 0.0)
        origin = (a * math.cos(th), a * math.sin(th), dd, alpha, 0.0, th)
    links = "".join(f'<link name="l{i + 1}"/>' for i in range(len(STANFORD)))
    xyz, rpy = " ".join(map(repr, origin[:3])), " ".join(map(repr, origin[3:]))
    tool = f"""<link name="tool"/><joint name="jt" type="fixed"><parent link="l6"/><child link="tool"/>
      <origin xyz="{xyz}" rpy="{rpy}"/></joint>"""
    return f'<robot name="stanford_urdf"><link name="base"/>{links}{"".join(joints)}{tool}</robot>'


def test_stanford_fk_matches_plain_numpy_dh_product_at_100_configurations():
    robot = nik.load_robot("stanford")
    assert robot.prismatic.tolist() == [False, False, True, False, False, False]
    q = random_q(robot, 100)
    expected = torch.from_numpy(np.stack([stanford_reference(qi) for qi in q.numpy()]))
    assert_close(robot.fk(q), expected, atol=1e-9, rtol=0)
    # the slide really moves the tool: 0.5 m more travel, 0.5 m further along the boom axis
    q2 = q.clone()
    q2[:, 2] += 0.5
    boom_axis = torch.from_numpy(np.stack([(stanford_reference(qi[:2].tolist() + [0.0, 0, 0, 0]))[:3, 2] for qi in q]))
    assert_close(robot.fk(q2, check=False)[:, :3, 3] - robot.fk(q)[:, :3, 3], 0.5 * boom_axis, atol=1e-12, rtol=0)


def test_prismatic_urdf_fk_matches_pytorch_kinematics(tmp_path):
    (tmp_path / "stanford.urdf").write_text(stanford_urdf())
    robot = load_urdf(tmp_path / "stanford.urdf", end_link="tool")
    assert robot.prismatic.tolist() == [False, False, True, False, False, False]
    assert_close(robot.limits[2], torch.tensor([0.3048, 1.27], dtype=torch.float64))
    chain = build_pk_chain(stanford_urdf(), "tool").to(dtype=torch.float64)
    q = random_q(robot, 100)
    assert_close(robot.fk(q), chain.forward_kinematics(q).get_matrix(), atol=1e-9, rtol=0)
    # the same arm from the YAML table, with exact (float64) URDF origins
    exact = load_urdf(tmp_path / "stanford.urdf", end_link="tool", origins="float64")
    yaml_robot = nik.load_robot("stanford")
    q = random_q(yaml_robot, 100)
    assert_close(exact.fk(q), yaml_robot.fk(q), atol=1e-9, rtol=0)


def test_prismatic_urdf_joint_without_limits_is_a_clear_error(tmp_path):
    text = stanford_urdf().replace('<limit lower="0.3048" upper="1.27" effort="1" velocity="1"/>', "")
    (tmp_path / "nolimit.urdf").write_text(text)
    with pytest.raises(nik.RobotDefinitionError, match="prismatic joint 'j3' needs <limit"):
        load_urdf(tmp_path / "nolimit.urdf", end_link="tool")


def test_stanford_fk_is_differentiable_gradcheck():
    robot = nik.load_robot("stanford")
    q = random_q(robot, 3).requires_grad_()
    assert torch.autograd.gradcheck(robot.fk, (q,))


def test_stanford_jacobian_matches_autograd_and_its_prismatic_column_is_the_axis():
    robot = nik.load_robot("stanford")
    for q in random_q(robot, 5, seed=3):
        T, J = robot.fk_and_jacobian(q)
        lin = torch.autograd.functional.jacobian(lambda x: robot.fk(x)[:3, 3], q)
        assert_close(J[:3], lin, atol=1e-12, rtol=0)
        dR = torch.autograd.functional.jacobian(lambda x: robot.fk(x)[:3, :3], q)
        W = torch.einsum("abk,cb->kac", dR, T[:3, :3])
        assert_close(J[3:], torch.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], dim=0), atol=1e-12, rtol=0)
        boom_axis = torch.from_numpy(stanford_reference(q[:2].tolist() + [0.0, 0, 0, 0])[:3, 2])
        assert_close(J[:3, 2], boom_axis, atol=1e-12, rtol=0)
        assert_close(J[3:, 2], torch.zeros(3, dtype=torch.float64), atol=0, rtol=0)


def _random_chain(n: int, seed: int):
    g = torch.Generator().manual_seed(seed)
    G = torch.zeros(n + 1, 4, 4, dtype=torch.float64)
    Q, _ = torch.linalg.qr(torch.randn(n + 1, 3, 3, generator=g, dtype=torch.float64))
    G[:, :3, :3] = Q * torch.linalg.det(Q).sign()[:, None, None]
    G[:, :3, 3] = torch.randn(n + 1, 3, generator=g, dtype=torch.float64) * 0.3
    G[:, 3, 3] = 1.0
    offsets = torch.randn(n, generator=g, dtype=torch.float64)
    prismatic = torch.rand(n, generator=g) < 0.5
    prismatic[0], prismatic[1] = True, False  # both kinds in every chain
    return G, offsets, prismatic


def _normal_form_by_hand(q, G, offsets, prismatic):
    """G_0 J_1 G_1 ... J_n G_n with J_i = Rz or Tz as explicit 4x4 matrices, one configuration."""
    T = G[0].clone()
    for i in range(len(offsets)):
        v = float(q[i] + offsets[i])
        J = torch.eye(4, dtype=torch.float64)
        if prismatic[i]:
            J[2, 3] = v
        else:
            J[:2, :2] = torch.tensor([[math.cos(v), -math.sin(v)], [math.sin(v), math.cos(v)]], dtype=torch.float64)
        T = T @ J @ G[i + 1]
    return T


@pytest.mark.parametrize("seed", [0, 1])
def test_mixed_chain_kernels_match_the_product_by_hand(seed):
    G, offsets, prismatic = _random_chain(5, seed)
    q = torch.randn(20, 5, generator=torch.Generator().manual_seed(seed + 10), dtype=torch.float64)
    expected = torch.stack([_normal_form_by_hand(qi, G, offsets, prismatic) for qi in q])
    assert_close(to_homogeneous(chain_fk_eager(q, G, offsets, prismatic=prismatic)), expected, atol=1e-12, rtol=0)
    kernel = FKKernel(G.numpy(), offsets.numpy(), prismatic=prismatic)
    assert_close(kernel(q), expected, atol=1e-12, rtol=0)
    T, J = chain_jacobian(q, G, offsets, prismatic=prismatic)
    lin = torch.func.vmap(
        torch.func.jacrev(lambda x: chain_fk_eager(x[None], G, offsets, prismatic=prismatic)[0, :, 3])
    )(q)
    assert_close(J[:, :3], lin, atol=1e-12, rtol=0)
    assert_close(J[:, 3:, prismatic], torch.zeros_like(J[:, 3:, prismatic]), atol=0, rtol=0)


@pytest.mark.parametrize("name", ["puma560", "kuka_kr", "rebot_v_6r", "panda", "ur5"])
def test_generated_fk_of_revolute_arms_does_not_depend_on_the_prismatic_keyword(name):
    robot = nik.load_robot(name)
    assert not bool(robot.prismatic.any())
    G, off = robot.G.numpy(), robot.offsets.numpy()
    assert generate_fk_source(G, off, prismatic=[False] * robot.dof) == generate_fk_source(G, off)
    q = random_q(robot, 10)
    assert_close(
        chain_fk_eager(q, robot.G, robot.offsets, prismatic=robot.prismatic), robot.fk(q)[:, :3], atol=1e-12, rtol=0
    )


def test_mdh_and_poe_prismatic_joints_match_explicit_products(tmp_path):
    # mdh: R - P - R; the prismatic variable adds to d in Rx(alpha) Tx(a) Rz(theta) Tz(d)
    rows = [("R", 0, 0, 0.1, 0), ("P", 30, 0.2, 0.05, -90), ("R", 0, 0.3, 0.0, 90)]  # kind, theta, a, d, alpha
    text = "name: rpr\nconvention: mdh\nunit: m\nangles: deg\njoints:\n" + "".join(
        f"  - {{type: {'prismatic' if k == 'P' else 'revolute'}, alpha: {al}, a: {a}, d: {d}"
        + (f", theta: {th}, limits: [-0.5, 0.5]}}\n" if k == "P" else "}\n")
        for k, th, a, d, al in rows
    )
    robot = nik.load_robot(write_yaml(tmp_path, text))
    q = random_q(robot, 20)
    for qi, T in zip(q, robot.fk(q), strict=True):
        expected = torch.eye(4, dtype=torch.float64)
        for v, (k, th, a, d, al) in zip(qi.tolist(), rows, strict=True):
            theta, dd = (v, d) if k == "R" else (th * DEG, d + v)
            expected = expected @ mdh_matrix(theta, dd, a, al * DEG)
        assert_close(T, expected, atol=1e-12, rtol=0)
    # poe: a slide along (1, 1, 0)/sqrt(2) between two revolute screws; exp of the prismatic twist by matrix_exp
    text = """name: rpr_poe
convention: poe
unit: mm
angles: deg
home: {position: [500, 0, 300]}
joints:
  - {axis: [0, 0, 1], point: [0, 0, 0]}
  - {type: prismatic, axis: [1, 1, 0], offset: 50, limits: [-200, 400]}
  - {axis: [0, 1, 0], point: [500, 0, 300]}
"""
    robot = nik.load_robot(write_yaml(tmp_path, text))
    assert_close(robot.limits[1], torch.tensor([-0.2, 0.4], dtype=torch.float64))
    q = random_q(robot, 20)
    for qi, T in zip(q, robot.fk(q), strict=True):
        X = torch.zeros(4, 4, dtype=torch.float64)
        X[:3, 3] = torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64) / math.sqrt(2)
        M = torch.eye(4, dtype=torch.float64)
        M[:3, 3] = torch.tensor([0.5, 0.0, 0.3], dtype=torch.float64)
        expected = (
            twist_exp((0, 0, 1), (0, 0, 0), float(qi[0]))
            @ torch.linalg.matrix_exp(X * (float(qi[1]) + 0.05))
            @ twist_exp((0, 1, 0), (0.5, 0, 0.3), float(qi[2]))
            @ M
        )
        assert_close(T, expected, atol=1e-12, rtol=0)


def write_yaml(tmp_path, text, name="arm.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["ur5", "puma560", "stanford"])
def test_per_joint_generated_fk_broadcasts_and_matches_robot_fk(name):
    # per_joint=True: one tensor per joint, shapes that broadcast (joint 1 shared by 4 of 8 rows, and so on)
    robot = nik.load_robot(name)
    namespace: dict = {"torch": torch}
    source = generate_fk_source(robot.G.numpy(), robot.offsets.numpy(), prismatic=robot.prismatic, per_joint=True)
    exec(compile(source, "<test>", "exec"), namespace)
    gen = torch.Generator().manual_seed(17)
    shapes = [(1, 1, 2, 5), (1, 2, 2, 5), (1, 2, 2, 5), (2, 2, 2, 5), (2, 1, 2, 5), (2, 2, 2, 5)]
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    qs = [lo[j] + torch.rand(shapes[j], generator=gen, dtype=torch.float64) * (hi[j] - lo[j]) for j in range(6)]
    entries = namespace["fk_kernel"](qs)
    assert len(entries) == 12
    full = torch.stack([q.expand(2, 2, 2, 5) for q in qs], dim=-1)  # (2, 2, 2, 5, 6)
    T = robot.fk(full)
    for i, e in enumerate(entries):
        r, c = divmod(i, 4)
        assert_close(torch.as_tensor(e, dtype=torch.float64).expand(2, 2, 2, 5), T[..., r, c], atol=1e-12, rtol=0)


def _fd_jacobian(robot, q, h=1e-6):
    """``(6, dof)`` by central differences of ``robot.fk``: the position's derivative, and the angular velocity
    ``vee(dR R^T)`` of the rotation's."""
    T0 = robot.fk(q)
    cols = []
    for i in range(robot.dof):
        dq = torch.zeros_like(q)
        dq[i] = h
        Tp, Tm = robot.fk(q + dq), robot.fk(q - dq)
        lin = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T0[:3, :3].T
        cols.append(torch.cat([lin, torch.stack([W[2, 1], W[0, 2], W[1, 0]])]))
    return torch.stack(cols, dim=1)


@pytest.mark.parametrize("name", ["kuka_kr", "rebot_v_6r", "panda", "stanford"])  # DH, POE, URDF, prismatic
def test_robot_jacobian_equals_finite_differences_of_fk(name):
    robot = nik.load_robot(name)
    q = random_q(robot, 5, seed=11)
    J = robot.jacobian(q)
    assert J.shape == (5, 6, robot.dof) and J.dtype == torch.float64
    for b in range(5):
        assert_close(J[b], _fd_jacobian(robot, q[b]), atol=1e-7, rtol=0)
    assert_close(robot.jacobian(q[2]), J[2])  # (dof,) in, (6, dof) out
    assert robot.jacobian(q.reshape(5, 1, robot.dof)).shape == (5, 1, 6, robot.dof)
    assert robot.jacobian(q.float()).dtype == torch.float32
    np_J = robot.jacobian(q[0].numpy())
    assert isinstance(np_J, torch.Tensor) and np_J.dtype == torch.float64


def test_robot_jacobian_is_differentiable_gradcheck():
    robot = nik.load_robot("stanford")  # a prismatic joint among revolute ones
    q = random_q(robot, 2, seed=12).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: robot.jacobian(x), (q,), eps=1e-6, atol=1e-6)
