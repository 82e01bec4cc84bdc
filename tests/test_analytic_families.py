"""nik.analytic.family / nik.analytic.solve: the family from the joint axes whatever the definition, FK round
trips on random and singular poses, completeness against a brute-force multistart LM, slot = branch label."""

from __future__ import annotations

import importlib.metadata
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

import nik
from nik.analytic import family, puma560_ik, solve
from nik.analytic.geometry import arm_geometry
from nik.data.branches import ik_branch_classifier
from nik.kinematics import chain_joint_frames
from nik.robots.urdf import load_urdf

SPHERICAL = ["puma560", "kuka_kr", "rebot_v_6r"]
THREE_PARALLEL = ["ur5"]
FAMILY_OF = {**{n: "spherical_wrist" for n in SPHERICAL}, **{n: "three_parallel" for n in THREE_PARALLEL}}


def _wrapped(a: torch.Tensor) -> torch.Tensor:
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def _random_frame(gen: torch.Generator, scale: float = 0.5) -> np.ndarray:
    """A seeded rigid transform: rotation from a random unit quaternion, translation up to ``scale`` m."""
    w, x, y, z = (torch.randn(4, generator=gen, dtype=torch.float64) / 1.0).tolist()
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = (torch.rand(3, generator=gen, dtype=torch.float64) * 2 - 1).numpy() * scale
    return T


def _redefined(robot, *, seed: int, frames: bool = True, offsets: bool = False, name: str | None = None):
    """The same arm with a random base and tool frame and/or random joint offsets (a different definition)."""
    gen = torch.Generator().manual_seed(seed)
    G = robot.G.numpy().copy()
    off = robot.offsets.numpy().copy()
    if frames:
        G[0] = _random_frame(gen) @ G[0]
        G[-1] = G[-1] @ _random_frame(gen, 0.2)
    if offsets:
        off = off + (torch.rand(robot.dof, generator=gen, dtype=torch.float64) * 2 - 1).numpy() * math.pi
    return nik.Robot(name or robot.name + "_redefined", G, off, robot.limits, robot.joint_names)


def _rotated_factor(robot, i: int, angle: float):
    """``robot`` with ``G_i`` turned by ``angle`` about its x axis (tilts joint ``i + 1``'s axis)."""
    G = robot.G.numpy().copy()
    c, s = math.cos(angle), math.sin(angle)
    Rx = np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])
    G[i] = G[i] @ Rx
    return nik.Robot(robot.name + "_tilted", G, robot.offsets, robot.limits, robot.joint_names)


def _write(tmp_path, data: dict):
    path = tmp_path / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data))
    return nik.load_robot(path)


def _ur5_dh(tmp_path):
    """UR5 from Universal Robots' published standard DH table (metres, degrees), not from its URDF."""
    rows = [(90, 0, 0.089159), (0, -0.425, 0), (0, -0.39225, 0), (90, 0, 0.10915), (-90, 0, 0.09465), (0, 0, 0.0823)]
    return _write(
        tmp_path,
        {
            "name": "ur5_dh",
            "convention": "dh",
            "unit": "m",
            "angles": "deg",
            "joints": [{"alpha": al, "a": a, "d": d, "limits": [-360, 360]} for al, a, d in rows],
        },
    )


def _puma_mdh(tmp_path):
    """PUMA 560 in Craig's modified DH (paper B), the tool offset d6 as a tool frame."""
    rows = [(0, 0, 0), (-90, 0, 0), (0, 431.8, 149.09), (-90, -20.32, 433.07), (90, 0, 0), (-90, 0, 0)]
    return _write(
        tmp_path,
        {
            "name": "puma_craig",
            "convention": "mdh",
            "unit": "mm",
            "angles": "deg",
            "tool": {"position": [0, 0, 56.25]},
            "joints": [{"alpha": al, "a": a, "d": d} for al, a, d in rows],
        },
    )


def _assert_round_trip(robot, n: int = 300, seed: int = 3):
    """Random configurations -> poses -> solve: every valid solution reaches its pose within 1e-9 m / 1e-9 rad,
    lies inside the limits, and the configuration the pose came from is among the valid solutions, in the slot
    of its branch label where the arm has a branch classifier."""
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    T = robot.fk(q)
    sols, valid = solve(robot, T)
    assert sols.shape == (n, 8, 6) and valid.shape == (n, 8)
    assert bool(torch.isfinite(sols).all())
    pos, rot = nik.pose_error(T[:, None], robot.fk(sols))
    assert float(pos[valid].max()) <= 1e-9 and float(rot[valid].max()) <= 1e-9
    assert bool(robot.within_limits(sols[valid]).all())
    match = (_wrapped(sols - q[:, None]).abs().amax(-1) < 1e-7) & valid
    found = match.any(-1)
    assert bool(found.all()), f"{int((~found).sum())} of {n} sampled configurations not among the solutions"
    clf = ik_branch_classifier(robot)
    if clf is not None:  # the training label of q is the slot the closed form puts it in
        assert torch.equal(clf(q).long(), match.float().argmax(-1))


# ---------------------------------------------------------------------------
# Classification
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", SPHERICAL + THREE_PARALLEL + ["panda", "stanford"])
def test_builtin_arms_are_classified(name):
    assert family(nik.load_robot(name)) == FAMILY_OF.get(name)


def test_rebot_wrist_centre_is_where_its_poe_axes_4_5_6_meet():
    # methods.md 1.3: axis 4 along x through (d1, 0, d2+d3+d4), axis 5 along -y through (d1+d5, 0, d2+d3+d4),
    # axis 6 along z through (d1+d5, 0, d2+d3+d4+d6): all three pass through (d1+d5, 0, d2+d3+d4) = (410, 0, 731) mm
    geom = arm_geometry(nik.load_robot("rebot_v_6r"))
    assert geom.family == "spherical_wrist"
    np.testing.assert_allclose(geom.point, [0.410, 0.0, 0.731], atol=1e-12)


def test_other_definitions_of_the_same_arms_keep_their_family(tmp_path):
    ur5 = nik.load_robot("ur5")
    kuka = nik.load_robot("kuka_kr")
    rebot = nik.load_robot("rebot_v_6r")
    cases = {
        "three_parallel": [
            _ur5_dh(tmp_path),
            load_urdf("configs/robots/urdf/ur5.urdf", origins="float64"),
            _redefined(ur5, seed=1),
            _redefined(ur5, seed=2, frames=False, offsets=True),
        ],
        "spherical_wrist": [
            _puma_mdh(tmp_path),
            _redefined(kuka, seed=3),
            _redefined(rebot, seed=4, offsets=True),
        ],
    }
    for expected, robots in cases.items():
        for robot in robots:
            assert family(robot) == expected, robot.name


@pytest.mark.parametrize(
    "make, reason",
    [
        (lambda: nik.load_robot("panda"), "7 joints"),
        (lambda: nik.load_robot("stanford"), "prismatic"),
        (lambda: _rotated_factor(nik.load_robot("ur5"), 2, 1e-3), "axes 2, 3, 4 are not parallel"),
        (lambda: _rotated_factor(nik.load_robot("kuka_kr"), 2, 1e-3), "axes 2 and 3 are not parallel"),
    ],
)
def test_arms_outside_both_families_are_refused_with_the_reason(make, reason):
    robot = make()
    assert family(robot) is None
    assert reason in arm_geometry(robot).reason
    with pytest.raises(ValueError, match="has no closed form"):
        solve(robot, torch.eye(4, dtype=torch.float64))


def test_axes_5_and_6_apart_is_not_three_parallel():
    ur5 = nik.load_robot("ur5")
    G = ur5.G.numpy().copy()
    G[5, 0, 3] += 1e-3  # 1 mm between axes 5 and 6
    moved = nik.Robot("ur5_moved", G, ur5.offsets, ur5.limits)
    assert family(moved) is None
    assert "axes 5 and 6 do not meet" in arm_geometry(moved).reason


@pytest.mark.parametrize("name, factor", [("kuka_kr", 2), ("ur5", 3)])
def test_within_tolerance_an_arm_keeps_its_family_and_exact_solutions(name, factor):
    # axes 2 and 3 (kuka) or 3 and 4 (ur5) 1e-8 rad from parallel: inside the stated 1e-6, and the Newton
    # polish after the closed form still reaches every pose within 1e-9
    robot = _rotated_factor(nik.load_robot(name), factor, 1e-8)
    assert family(robot) == FAMILY_OF[name]
    assert arm_geometry(robot).deviation > 1e-9
    _assert_round_trip(robot, n=200)


# ---------------------------------------------------------------------------
# example-robot-data: every 6R URDF against its known answer
# ---------------------------------------------------------------------------
# Known answers, from each arm's published kinematics (not from nik):
# - Universal Robots UR3/UR5/UR10: shoulder lift, elbow and wrist 1 are parallel pitch axes; wrist 2 and wrist 3
#   meet (DH a5 = 0): three parallel.
# - Kinova Jaco 2 j2s6s200 ("s6s": spherical wrist, 6 DOF), alone and on ANYmal: shoulder and elbow parallel,
#   the three wrist axes meet: spherical wrist.
# - SO-100 / SO-101: five arm joints (pitch axes 2, 3, 4 parallel, then wrist roll) and, when asked for by its
#   end_link (the default leaves the gripper out), the gripper jaw as joint 6, whose axis does not meet the roll
#   axis: neither.
# - TALOS left arm (arm_left_2 .. 7 in this file): shoulder roll and upper-arm yaw are perpendicular, so neither
#   a PUMA shoulder (axes 2 and 3 parallel) nor three parallel axes, though its wrist axes meet: neither.
# - Alexander (a leg to the foot): hip pitch, knee and ankle pitch parallel (axes 3, 4, 5), not a wrist: neither.
# - Unitree Z1 (to link06, before the gripper: the default leaves jointGripper out): joints 2, 3, 4 parallel pitch
#   axes, 5 and 6 meet: three parallel.
ERD_KNOWN = {
    ("ur_description/urdf/ur3_gripper.urdf", None): "three_parallel",
    ("ur_description/urdf/ur3_joint_limited_robot.urdf", None): "three_parallel",
    ("ur_description/urdf/ur3_robot.urdf", None): "three_parallel",
    ("ur_description/urdf/ur5_gripper.urdf", None): "three_parallel",
    ("ur_description/urdf/ur5_joint_limited_robot.urdf", None): "three_parallel",
    ("ur_description/urdf/ur5_robot.urdf", None): "three_parallel",
    ("ur_description/urdf/ur10_joint_limited_robot.urdf", None): "three_parallel",
    ("ur_description/urdf/ur10_robot.urdf", None): "three_parallel",
    ("kinova_description/robots/kinova.urdf", None): "spherical_wrist",
    ("anymal_b_simple_description/robots/anymal-kinova.urdf", None): "spherical_wrist",
    ("so_arm_description/urdf/so100.urdf", "jaw"): None,
    ("so_arm_description/urdf/so101.urdf", "moving_jaw_so101_v1_link"): None,
    ("talos_data/robots/talos_left_arm.urdf", None): None,
    ("alexander_description/urdf/alexander_v1.lowerBodyOnly.urdf", None): None,
    ("z1_description/urdf/z1.urdf", None): "three_parallel",
    ("b1_description/urdf/b1-z1.urdf", None): "three_parallel",
}


def _erd_root() -> Path | None:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        if str(f).endswith("ur_description/urdf/ur5_robot.urdf"):
            return Path(dist.locate_file(f)).parents[2]
    return None


@pytest.fixture(scope="module")
def erd_root():
    root = _erd_root()
    if root is None:
        pytest.skip('example-robot-data is not installed (pip install -e ".[urdf-tests]")')
    return root


def test_every_6r_urdf_of_example_robot_data_has_a_known_answer(erd_root):
    unknown, seen = [], set()
    for path in sorted(erd_root.rglob("*.urdf")):
        try:
            robot = nik.load_robot(path)
        except ValueError:
            continue  # not readable by pytorch-kinematics (a few humanoids and ur3.urdf): no chain to classify
        if robot.dof != 6 or robot.has_prismatic:
            continue
        rel = path.relative_to(erd_root).as_posix()
        seen.add(rel)
        if (rel, None) not in ERD_KNOWN:
            unknown.append(rel)
    assert not unknown, f"6R URDFs without a known answer in ERD_KNOWN: {unknown}"
    assert len(seen) >= 10


@pytest.mark.parametrize("key", list(ERD_KNOWN), ids=lambda k: Path(k[0]).stem if isinstance(k, tuple) else None)
def test_example_robot_data_arm_is_classified_and_solved(erd_root, key):
    rel, end_link = key
    path = erd_root / rel
    if not path.is_file():
        pytest.skip(f"{rel} is not in this version of example-robot-data")
    robot = nik.load_robot(path, end_link=end_link)
    assert robot.dof == 6
    assert family(robot) == ERD_KNOWN[key]
    if ERD_KNOWN[key] is not None:
        _assert_round_trip(robot, n=150)


# ---------------------------------------------------------------------------
# FK round trips
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", SPHERICAL + THREE_PARALLEL)
def test_random_poses_round_trip(name):
    _assert_round_trip(nik.load_robot(name), n=500)


def test_round_trip_under_other_definitions(tmp_path):
    for robot in (
        _ur5_dh(tmp_path),
        _puma_mdh(tmp_path),
        _redefined(nik.load_robot("ur5"), seed=11, offsets=True),
        _redefined(nik.load_robot("kuka_kr"), seed=12, offsets=True),
        _redefined(nik.load_robot("rebot_v_6r"), seed=13),
    ):
        _assert_round_trip(robot, n=200)


@pytest.mark.parametrize("name", SPHERICAL)
def test_same_solutions_as_puma560_ik(name):
    robot = nik.load_robot(name)
    T = robot.fk(robot.sample(300, generator=torch.Generator().manual_seed(9), dtype=torch.float64))
    a, va = solve(robot, T)
    b, vb = puma560_ik(robot, T)
    assert torch.equal(va.sum(-1), vb.sum(-1))
    # every valid solution of one is a valid solution of the other (the slot order differs)
    d = _wrapped(a[:, :, None] - b[:, None]).abs().amax(-1)  # (N, 8, 8)
    d = torch.where(va[:, :, None] & vb[:, None], d, torch.full_like(d, math.inf))
    assert bool((d.amin(-1) < 1e-9)[va].all()) and bool((d.amin(-2) < 1e-9)[vb].all())


def test_batched_shapes_match_one_by_one():
    robot = nik.load_robot("ur5")
    T = robot.fk(robot.sample(6, generator=torch.Generator().manual_seed(5), dtype=torch.float64)).reshape(2, 3, 4, 4)
    sols, valid = solve(robot, T)
    assert sols.shape == (2, 3, 8, 6) and valid.shape == (2, 3, 8)
    for i in range(2):
        for j in range(3):
            s1, v1 = solve(robot, T[i, j])
            assert s1.shape == (8, 6) and torch.equal(v1, valid[i, j])
            torch.testing.assert_close(s1, sols[i, j], atol=1e-12, rtol=0)


@pytest.mark.parametrize("name", ["ur5", "kuka_kr"])
def test_float32_input(name):
    robot = nik.load_robot(name)
    q = robot.sample(300, generator=torch.Generator().manual_seed(6), dtype=torch.float32)
    T = robot.fk(q)
    sols, valid = solve(robot, T)
    assert sols.dtype == torch.float32 and sols.device == T.device
    pos, rot = nik.pose_error(T[:, None], robot.fk(sols))
    assert float(valid.any(-1).float().mean()) > 0.95
    assert float(pos[valid].max()) <= 2e-5 and float(rot[valid].max()) <= 2e-5


def test_unreachable_pose_is_all_invalid_and_finite():
    for name in ("ur5", "puma560"):
        robot = nik.load_robot(name)
        T = robot.fk(torch.zeros(6, dtype=torch.float64))
        T[:3, 3] = torch.tensor([3.0, 0.0, 0.0], dtype=torch.float64)  # 3 m away: out of reach
        for check in (True, False):
            sols, valid = solve(robot, T, check=check)
            assert bool(torch.isfinite(sols).all()) and not bool(valid.any())


def test_bad_input_is_a_value_error():
    ur5 = nik.load_robot("ur5")
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        solve(ur5, torch.zeros(3, 3))
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        solve(ur5, torch.eye(4, dtype=torch.long))


# ---------------------------------------------------------------------------
# Singular poses
# ---------------------------------------------------------------------------
def _signed(robot, q: torch.Tensor, kind: str) -> torch.Tensor:
    """Signed distance from a singularity ``(B,)``, from the joint lines at ``q`` (independent of nik.analytic).

    ``c``: where axes 5 and 6 meet (the wrist centre of a spherical wrist, P of a three-parallel arm).
    wrist: ``(a4 x a6) . a5`` (axis 6 along axis 4); shoulder: ``(c - p1) . (a2 x a1)`` (c on the shoulder's
    fold); elbow: ``((p3 - p2) x (c - p2)) . a2`` (spherical: shoulder, elbow and c in line) or
    ``((p3 - p2) x (p4 - p2)) . a2`` (three parallel: the planar pair stretched or folded).
    """
    _, ax, pt = chain_joint_frames(q, robot.G, robot.offsets)
    a = [ax[..., i] for i in range(6)]
    p = [pt[..., i] for i in range(6)]
    w = p[5] - p[4]
    b = (a[4] * a[5]).sum(-1, keepdim=True)
    d, e = (a[4] * w).sum(-1, keepdim=True), (a[5] * w).sum(-1, keepdim=True)
    t4 = (d - b * e) / (1 - b * b)
    c = p[4] + t4 * a[4]
    if kind == "wrist":
        return (torch.linalg.cross(a[3], a[5]) * a[4]).sum(-1)
    if kind == "shoulder":
        return ((c - p[0]) * torch.linalg.cross(a[1], a[0])).sum(-1)
    tip = c if family(robot) == "spherical_wrist" else p[3]
    return (torch.linalg.cross(p[2] - p[1], tip - p[1]) * a[1]).sum(-1)


def _singular_q(robot, kinds: tuple[str, ...], seed: int) -> torch.Tensor | None:
    """A configuration inside the limits where every signed quantity of ``kinds`` is zero, by bisection."""
    joint = {"wrist": 4, "shoulder": 1, "elbow": 2}
    q = robot.sample(1, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)[0]
    for kind in kinds:
        j = joint[kind]
        lo, hi = float(robot.limits[j, 0]), float(robot.limits[j, 1])

        def f(x, j=j, kind=kind):
            qq = q.clone()
            qq[j] = x
            return float(_signed(robot, qq[None], kind)[0])

        grid = np.linspace(lo, hi, 97)
        vals = [f(x) for x in grid]
        k = next((i for i in range(96) if vals[i] * vals[i + 1] <= 0), None)
        if k is None:
            return None
        a, b, fa = grid[k], grid[k + 1], vals[k]
        for _ in range(200):
            m = 0.5 * (a + b)
            fm = f(m)
            if fm == 0.0 or b - a < 1e-16:
                a = b = m
                break
            a, b, fa = (m, b, fm) if (fm > 0) == (fa > 0) else (a, m, fa)
        q[j] = 0.5 * (a + b)
    return q


@pytest.mark.parametrize("name", SPHERICAL + THREE_PARALLEL)
@pytest.mark.parametrize("kinds", [("wrist",), ("shoulder",), ("elbow",), ("shoulder", "wrist"), ("elbow", "wrist")])
def test_singular_poses_give_finite_solutions_that_reach_the_pose(name, kinds):
    robot = nik.load_robot(name)
    q = None
    for seed in range(20):
        q = _singular_q(robot, kinds, seed)
        if q is not None:
            break
    assert q is not None, f"no {kinds} singular configuration found for {name}"
    for kind in kinds:
        assert abs(float(_signed(robot, q[None], kind)[0])) < 1e-12  # truly singular, not a sign jump
    T = robot.fk(q)
    sols, valid = solve(robot, T)
    assert bool(torch.isfinite(sols).all())
    assert bool(valid.any())
    pos, rot = nik.pose_error(T, robot.fk(sols[valid]))
    assert float(pos.max()) <= 1e-9 and float(rot.max()) <= 1e-9
    # every candidate the kernel calls reachable reaches the pose, singular or not (limits aside)
    sols_nc, reach = solve(robot, T, check=False)
    pos, rot = nik.pose_error(T, robot.fk(sols_nc[reach]))
    assert float(pos.max()) <= 1e-9 and float(rot.max()) <= 1e-9


# ---------------------------------------------------------------------------
# Completeness: a brute-force multistart LM finds no solution the closed form misses
# ---------------------------------------------------------------------------
def _lm_solve():
    try:
        from nik.lm import lm_solve
    except ImportError:  # before the house of issue 15
        from nik.swarm import lm_solve
    return lm_solve


def _multistart_solutions(robot, T: torch.Tensor, starts: int, seed: int) -> torch.Tensor:
    """Distinct (modulo 2 pi) converged LM solutions inside the limits from ``starts`` uniform starts: (K, 6)."""
    lm_solve = _lm_solve()
    gen = torch.Generator().manual_seed(seed)
    q0 = robot.sample(starts, generator=gen, dtype=torch.float64)
    q, _ = lm_solve(
        robot, T.expand(starts, 4, 4), q0, tol_pos=1e-12, tol_rot=1e-12, max_iters=80, restarts=0, generator=gen
    )
    pos, rot = nik.pose_error(T, robot.fk(q))
    q = q[(pos < 1e-9) & (rot < 1e-9) & robot.within_limits(q)]
    distinct: list[torch.Tensor] = []
    for row in q:
        if all(float(_wrapped(row - d).abs().max()) > 1e-6 for d in distinct):
            distinct.append(row)
    return torch.stack(distinct) if distinct else q[:0]


@pytest.mark.long
@pytest.mark.parametrize("name", ["puma560", "kuka_kr", "ur5", "ur5_redefined"])
def test_closed_form_finds_every_solution_a_multistart_lm_finds(name):
    robot = _redefined(nik.load_robot("ur5"), seed=21) if name == "ur5_redefined" else nik.load_robot(name)
    gen = torch.Generator().manual_seed(31)
    total = 0
    for q_true in robot.sample(2, generator=gen, dtype=torch.float64):
        T = robot.fk(q_true)
        lm = _multistart_solutions(robot, T, starts=256, seed=int(total) + 7)
        sols, valid = solve(robot, T)
        assert len(lm) >= 2
        d = _wrapped(lm[:, None] - sols[valid][None]).abs().amax(-1)  # (K_lm, K_cf)
        missed = lm[d.amin(-1) > 1e-6]
        assert len(missed) == 0, f"{name}: multistart LM solutions the closed form missed: {missed.tolist()}"
        total += len(lm)
    assert total >= 4


# ---------------------------------------------------------------------------
# Slot = branch label (nik.data.branches), for training labels and for the solver
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", SPHERICAL + THREE_PARALLEL)
def test_slot_of_each_solution_is_its_branch_label(name):
    robot = nik.load_robot(name)
    clf = ik_branch_classifier(robot)
    assert clf is not None
    q = robot.sample(400, generator=torch.Generator().manual_seed(12), dtype=torch.float64)
    T = robot.fk(q)
    sols, valid = solve(robot, T)
    # the label the training data gives q is the slot whose solution is q
    slot = ((_wrapped(sols - q[:, None]).abs().amax(-1) < 1e-7) & valid).float().argmax(-1)
    assert torch.equal(clf(q).long(), slot)
    # and every valid solution sits in the slot of its own label (away from the singular sets, where labels flip)
    comps = clf.components(sols[valid])
    generic = torch.stack([comps[c].abs() for c in ("t", "u", "w")]).amin(0) > 1e-6
    labels = clf(sols[valid]).long()
    slots = torch.arange(8).expand_as(valid)[valid]
    assert torch.equal(labels[generic], slots[generic])
    assert float(generic.float().mean()) > 0.99
