"""Joint speed / acceleration limits of robots (URDF, YAML, per call) and the timing of joint paths
(nik.paths.timing, by toppra): limits kept at 1 ms sampling, toppra's duration, one-line errors."""

from __future__ import annotations

import importlib.util
import math
import sys
import textwrap

import numpy as np
import pytest
import torch

import nik
from nik.paths import timing as T
from nik.robots.config import robot_from_config

needs_toppra = pytest.mark.skipif(
    importlib.util.find_spec("toppra") is None, reason="needs toppra: pip install 'nik-ik[timing]'"
)
RTOL = T.RATE_RTOL  # float rounding of toppra's solver; nothing looser


def _smooth_path(robot, n=60, seed=0):
    """(n, dof) a smooth joint path between two random configurations with a wiggle, inside the limits."""
    g = torch.Generator().manual_seed(seed)
    a, b = robot.sample(2, generator=g, dtype=torch.float64)
    w = torch.linspace(0, 1, n, dtype=torch.float64)[:, None]
    q = a + (b - a) * (w + 0.05 * torch.sin(6 * w))
    return robot.clamp(q).numpy()


def _sample_toppra(tim, dt=1e-3):
    """Positions, velocities, accelerations of toppra's own trajectory object every dt seconds (time stretched)."""
    t = np.append(np.arange(0.0, tim.duration, dt), tim.duration)
    k = tim.stretch
    traj = tim.trajectory
    return t, traj(t / k), traj(t / k, 1) / k, traj(t / k, 2) / k**2


# ---------------------------------------------------------------------------
# timing: limits kept, toppra's answer
# ---------------------------------------------------------------------------
@needs_toppra
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_timed_path_keeps_every_joint_speed_and_acceleration_limit_at_1ms(name):
    robot = nik.load_robot(name)
    q = _smooth_path(robot)
    tim = T.time_path(q, robot=robot)
    for t, qs, qd, qdd in (_sample_toppra(tim), tim.sample(1e-3)):
        assert len(t) > 1000  # seconds of motion, sampled every millisecond
        assert (np.abs(qd) <= tim.vel_limits * (1 + RTOL)).all()
        assert (np.abs(qdd) <= tim.acc_limits * (1 + RTOL)).all()
        assert robot.within_limits(torch.from_numpy(qs), atol=1e-12).all()
    # the limits bind somewhere (a time-optimal answer), and speed is zero at both ends
    assert np.abs(qd).max(axis=0).max() / tim.vel_limits.max() > 0.5
    assert np.abs(tim.qd[[0, -1]]).max() == 0.0
    # the trajectory passes through every waypoint at its time
    np.testing.assert_allclose(tim.trajectory(tim.t / tim.stretch), q, atol=1e-12)
    assert (np.diff(tim.t) > 0).all() and tim.t[0] == 0.0 and tim.t[-1] == tim.duration


@needs_toppra
def test_duration_is_toppras_on_the_same_joint_path():
    import toppra
    import toppra.algorithm
    import toppra.constraint

    robot = nik.load_robot("panda")
    q = _smooth_path(robot, seed=3)
    tim = T.time_path(q, robot=robot)
    vel, acc = robot.vel_limits.numpy(), robot.acc_limits.numpy()
    s = np.concatenate([[0.0], np.cumsum(np.max(np.abs(np.diff(q, axis=0)) / vel, axis=1))])  # the documented s
    path = toppra.SplineInterpolator(s, q)
    cons = [toppra.constraint.JointVelocityConstraint(vel), toppra.constraint.JointAccelerationConstraint(acc)]
    same = toppra.algorithm.TOPPRA(cons, path, gridpoints=tim.gridpoints, solver_wrapper="seidel")
    own = toppra.algorithm.TOPPRA(cons, path, solver_wrapper="seidel")  # toppra's own grid and output spline
    assert tim.stretch == 1.0
    assert tim.duration == pytest.approx(same.compute_trajectory().duration, rel=1e-12)
    assert tim.duration == pytest.approx(own.compute_trajectory().duration, rel=1e-3)


@needs_toppra
def test_waypoint_velocities_and_accelerations_are_the_trajectorys_derivatives():
    robot = nik.load_robot("ur5")
    q = _smooth_path(robot, seed=1)
    tim = T.time_path(q, robot=robot)
    h = 1e-6
    inner = slice(1, -1)
    t = tim.t[inner]
    fd_v = (tim.at(t + h)[0] - tim.at(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(tim.qd[inner], fd_v, atol=1e-5)
    fd_a = (tim.at(t + 2 * h)[1] - tim.at(t + h)[1]) / h  # one-sided: the acceleration after the waypoint
    np.testing.assert_allclose(tim.qdd[inner], fd_a, atol=1e-4)


@needs_toppra
def test_tool_speed_limit_is_kept_and_slows_the_path():
    robot = nik.load_robot("panda")
    q = _smooth_path(robot, seed=2)
    free = T.time_path(q, robot=robot)
    tim = T.time_path(q, robot=robot, tool_speed=0.2)
    t, qs, qd, _ = tim.sample(1e-3)
    _, J = robot.fk_and_jacobian(torch.from_numpy(qs))
    speed = np.linalg.norm(np.einsum("mij,mj->mi", J[:, :3].numpy(), qd), axis=1)
    assert speed.max() <= 0.2 * (1 + RTOL)
    # independent of the Jacobian: FK positions by central differences
    h = 1e-5
    p = lambda tt: robot.fk(torch.from_numpy(tim.at(tt)[0]))[:, :3, 3].numpy()  # noqa: E731
    inner = t[1:-1]
    fd = np.linalg.norm(p(inner + h) - p(inner - h), axis=1) / (2 * h)
    assert fd.max() <= 0.2 * (1 + 1e-6)  # central differences: error O(h^2)
    assert fd.max() > 0.19  # the bound binds
    assert tim.duration > free.duration
    assert (np.abs(qd) <= tim.vel_limits * (1 + RTOL)).all()


@needs_toppra
def test_without_acceleration_limits_a_documented_default_is_kept():
    robot = nik.load_robot("ur5")  # no acceleration limits known
    assert robot.acc_limits is None
    tim = T.time_path(_smooth_path(robot, seed=4), robot=robot)
    assert tim.acc_assumed
    np.testing.assert_array_equal(tim.acc_limits, robot.vel_limits.numpy() * T.DEFAULT_ACC_PER_VEL)
    _, _, qd, qdd = _sample_toppra(tim)
    assert (np.abs(qdd) <= tim.acc_limits * (1 + RTOL)).all()


@needs_toppra
def test_scales_slow_the_path_by_their_factor():
    robot = nik.load_robot("panda")
    q = _smooth_path(robot, seed=5)
    full = T.time_path(q, robot=robot)
    half = T.time_path(q, robot=robot, vel_scale=0.5, acc_scale=0.25)
    # halving every speed and quartering every acceleration is time doubled: the same trajectory at half pace
    assert half.duration == pytest.approx(2 * full.duration, rel=1e-6)
    _, _, qd, qdd = half.sample()
    assert (np.abs(qd) <= 0.5 * robot.vel_limits.numpy() * (1 + RTOL)).all()
    assert (np.abs(qdd) <= 0.25 * robot.acc_limits.numpy() * (1 + RTOL)).all()


@needs_toppra
def test_closed_path_starts_and_ends_at_rest_and_repeated_waypoints_share_a_time():
    robot = nik.load_robot("panda")
    q = _smooth_path(robot, n=30, seed=6)
    loop = np.vstack([q, q[::-1]])  # last row equals the first; rows 29 and 30 are equal
    tim = T.time_path(loop, robot=robot)
    assert np.abs(tim.qd[[0, -1]]).max() == 0.0
    assert tim.t[29] == tim.t[30] and (np.diff(tim.t) >= 0).all()
    np.testing.assert_allclose(tim.at([tim.duration])[0][0], loop[-1], atol=1e-12)
    _, qs, qd, qdd = tim.sample()
    assert (np.abs(qd) <= tim.vel_limits * (1 + RTOL)).all()
    assert (np.abs(qdd) <= tim.acc_limits * (1 + RTOL)).all()


@needs_toppra
def test_a_path_hugging_a_joint_limit_is_timed_inside_the_limits():
    robot = nik.load_robot("panda")
    lo, hi = robot.limits[:, 0].numpy(), robot.limits[:, 1].numpy()
    x = np.linspace(0, 1, 40)
    q = np.tile((lo + hi) / 2, (40, 1))
    q[:, 0] = lo[0] + 0.5 + x
    q[:, 3] = np.minimum(hi[3], hi[3] - 0.6 + 4.8 * x * (1 - x))  # up to the limit, along it, back
    tim = T.time_path(q, robot=robot)
    assert tim.interpolation == "pchip"  # the cubic through these overshoots the limit
    _, qs, qd, qdd = tim.sample()
    assert robot.within_limits(torch.from_numpy(qs)).all()
    assert (np.abs(qd) <= tim.vel_limits * (1 + RTOL)).all()
    assert (np.abs(qdd) <= tim.acc_limits * (1 + RTOL)).all()
    assert tim.stretch < 1.05


@needs_toppra
def test_a_path_that_does_not_move_takes_no_time():
    robot = nik.load_robot("ur5")
    q = np.tile(_smooth_path(robot)[:1], (4, 1))
    tim = T.time_path(q, robot=robot)
    assert tim.duration == 0.0 and (tim.t == 0).all() and (tim.qd == 0).all()
    t, qs, qd, _ = tim.sample()
    assert t.tolist() == [0.0] and np.array_equal(qs, q[:1]) and not qd.any()


# ---------------------------------------------------------------------------
# one-line errors
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("limits", "message"),
    [
        ([1.0, 0.0, 1.0, 1.0, 1.0, 1.0], "shoulder_lift_joint: must be a finite number > 0, got 0.0"),
        ([1.0, 1.0, -2.0, 1.0, 1.0, 1.0], "elbow_joint: must be a finite number > 0, got -2.0"),
        ([math.nan, 1.0, 1.0, 1.0, 1.0, 1.0], "shoulder_pan_joint: must be a finite number > 0, got nan"),
        ([1.0, 1.0, 1.0, 1.0, 1.0, math.inf], "wrist_3_joint: must be a finite number > 0, got inf"),
        ([1.0, 1.0], "expected 6 values (one per joint), got 2"),
        ([1.0, 1.0, "x", 1.0, 1.0, 1.0], "elbow_joint: expected a number, got 'x'"),
    ],
)
def test_bad_limits_are_one_line_errors_naming_the_joint(limits, message):
    robot = nik.load_robot("ur5")
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as err:
        robot.vel_limits = limits
    assert "\n" not in str(err.value) and str(err.value).startswith("ur5: vel_limits: ")
    with pytest.raises(ValueError, match="acc_limits") as err:
        T.time_path(_smooth_path(robot, n=5), robot=robot, acc_limits=limits)
    assert "\n" not in str(err.value)


def test_timing_without_speed_limits_or_with_bad_options_says_what_is_missing():
    robot = nik.load_robot("kuka_kr")  # no vendor speeds known
    q = _smooth_path(robot, n=5)
    with pytest.raises(ValueError, match="timing needs joint speed limits: kuka_kr has none"):
        T.time_path(q, robot=robot)
    with pytest.raises(ValueError, match=r"^vel_scale: must be a number in \(0, 1\], got 1.5$"):
        T.time_path(q, np.ones(6), robot=robot, vel_scale=1.5)
    with pytest.raises(ValueError, match=r"^acc_scale: must be a number in \(0, 1\], got -0.5$"):
        T.time_path(q, np.ones(6), robot=robot, acc_scale=-0.5)
    with pytest.raises(ValueError, match=r"^--acc-scale: must be a number in \(0, 1\], got 0$"):
        T.check_scale(0, "--acc-scale")
    assert T.check_scale(1, "--vel-scale") == 1.0
    with pytest.raises(ValueError, match="tool_speed needs robot="):
        T.time_path(q, np.ones(6), tool_speed=0.1)
    with pytest.raises(ValueError, match="q has 6 columns"):
        T.time_path(q, np.ones(7), robot=nik.load_robot("panda"))
    outside = q.copy()
    outside[2, 1] = 10.0
    with pytest.raises(ValueError, match="waypoint 2 is outside the joint limits"):
        T.time_path(outside, np.ones(6), robot=robot)


def test_missing_toppra_is_a_one_line_error_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "toppra", None)
    with pytest.raises(ValueError, match=r"pip install 'nik-ik\[timing\]'"):
        T.time_path(np.zeros((3, 2)) + [[0, 0], [1, 1], [2, 2]], [1.0, 1.0])


# ---------------------------------------------------------------------------
# limits from URDF and YAML
# ---------------------------------------------------------------------------
def _urdf(velocities) -> str:
    joints = "".join(
        f"""
  <joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 {i % 2} {1 - i % 2}"/>
    <limit lower="-1" upper="1" effort="1" {"" if v is None else f'velocity="{v}"'}/></joint>"""
        for i, v in enumerate(velocities)
    )
    links = "".join(f'<link name="l{i}"/>' for i in range(len(velocities) + 1))
    return f'<robot name="tiny">{links}{joints}\n</robot>'


def test_speed_limits_are_read_from_a_urdf(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    f = tmp_path / "tiny.urdf"
    f.write_text(_urdf([1.5, 2.0, 2.5]))
    robot = nik.load_robot(f)
    assert robot.vel_limits.tolist() == [1.5, 2.0, 2.5] and robot.acc_limits is None
    assert nik.load_robot(f).vel_limits.tolist() == [1.5, 2.0, 2.5]  # read back from the parse cache
    assert nik.load_robot("panda").vel_limits.tolist() == [2.175] * 4 + [2.61] * 3  # the shipped URDF's
    f.write_text(_urdf([1.5, 0, 2.5]))  # a zero (a common placeholder) or a missing velocity: unknown
    assert nik.load_robot(f).vel_limits is None
    f.write_text(_urdf([1.5, None, 2.5]))
    assert nik.load_robot(f).vel_limits is None
    f.write_text(_urdf([1.5, -2, 2.5]))
    with pytest.raises(ValueError, match=r"joint 'j1': <limit velocity='-2'> must be a finite number >= 0") as err:
        nik.load_robot(f)
    assert "\n" not in str(err.value)


KUKA_LIKE = """
name: arm
convention: dh
unit: mm
angles: deg
joints:
  - {alpha: 90, a: 0, d: 300, limits: [-170, 170], vel: 180, acc: 360}
  - {alpha: 0, a: 400, d: 0, limits: [-120, 120], vel: 90, acc: 180}
  - {type: prismatic, alpha: 0, a: 0, d: 0, limits: [0, 500], vel: 250, acc: 1000}
"""


def _yaml(text: str) -> dict:
    import yaml

    return yaml.safe_load(textwrap.dedent(text))


def test_speed_and_acceleration_limits_are_read_from_yaml_in_the_files_units():
    robot = robot_from_config(_yaml(KUKA_LIKE))
    np.testing.assert_allclose(robot.vel_limits.numpy(), [math.pi, math.pi / 2, 0.25], rtol=1e-15)
    np.testing.assert_allclose(robot.acc_limits.numpy(), [2 * math.pi, math.pi, 1.0], rtol=1e-15)
    plain = _yaml(KUKA_LIKE)
    for j in plain["joints"]:
        del j["vel"], j["acc"]
    # the limits play no part in the kinematics: same definition and hash as without them
    assert robot_from_config(plain).definition_hash == robot.definition_hash
    assert robot_from_config(plain).to_definition() == robot.to_definition()
    # the same in one line, top level; and for a file pointing at a URDF (replacing the URDF's)
    plain["vel_limits"] = [180, 90, 250]
    np.testing.assert_allclose(robot_from_config(plain).vel_limits.numpy(), [math.pi, math.pi / 2, 0.25])
    assert nik.load_robot("ur5").vel_limits.tolist() == [math.pi] * 6  # the datasheet's 180 deg/s
    assert nik.load_robot("panda").acc_limits.tolist() == [15, 7.5, 10, 12.5, 15, 20, 20]


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["joints"][1].update(vel=0), "vel: joint2: must be a finite number > 0, got 0.0"),
        (lambda d: d["joints"][2].update(acc=-1), "joint3: must be a finite number > 0, got -1.0"),
        (lambda d: d["joints"][0].update(vel=".nan"), "joint1: expected a number, got '.nan'"),
        (lambda d: d["joints"][1].pop("vel"), r"joints\[1\] \(joint2\): missing 'vel' \(give it for every joint"),
        (lambda d: d.update(vel_limits=[1, 2, 3]), "give 'vel_limits' or 'vel' per joint, not both"),
        (lambda d: d["joints"][0].update(speed=3), r"unknown field\(s\) \['speed'\]"),
    ],
)
def test_bad_yaml_limits_are_one_line_errors_naming_the_joint(edit, message):
    data = _yaml(KUKA_LIKE)
    edit(data)
    with pytest.raises(nik.RobotDefinitionError, match=message) as err:
        robot_from_config(data, source="arm.yaml")
    assert "\n" not in str(err.value) and str(err.value).startswith("arm.yaml")


def test_frames_and_assignment_keep_the_limits():
    robot = nik.load_robot("panda", tool=[0, 0, 0.1, 1, 0, 0, 0])
    assert robot.vel_limits is not None and robot.acc_limits.tolist() == [15, 7.5, 10, 12.5, 15, 20, 20]
    robot.acc_limits = None
    assert robot.acc_limits is None
    robot.acc_limits = torch.full((7,), 3.0)
    assert robot.acc_limits.dtype == torch.float64 and robot.acc_limits.tolist() == [3.0] * 7


# ---------------------------------------------------------------------------
# the t_s column of the path CSV
# ---------------------------------------------------------------------------
def test_time_column_round_trips_through_a_csv(tmp_path):
    t = np.array([0.0, 0.0123456, 0.5, 0.5, 1.25])
    f = tmp_path / "path.csv"
    cells = T.time_cells(t)
    f.write_text("index,t_s,j1_deg\n" + "".join(f"{i},{c},0\n" for i, c in enumerate(cells)))
    np.testing.assert_allclose(T.read_time_column(f), t, atol=5e-7)
    f.write_text("index,t_s\n0,0\n1,0.5\n2,0.4\n")
    with pytest.raises(ValueError, match="row 3: t_s = 0.4 .times must be finite, >= 0 and non-decreasing"):
        T.read_time_column(f)
    f.write_text("index,j1_deg\n0,0\n")
    with pytest.raises(ValueError, match="no 't_s' column"):
        T.read_time_column(f)


# ---------------------------------------------------------------------------
# the picture
# ---------------------------------------------------------------------------
@needs_toppra
def test_timing_plot_writes_a_picture_and_checks_the_joints(tmp_path):
    pytest.importorskip("matplotlib", reason="the picture needs matplotlib")
    from nik.view.timing_plot import plot_timing

    robot = nik.load_robot("panda")
    tim = T.time_path(_smooth_path(robot, n=20), robot=robot)
    out = plot_timing(robot, tim, tmp_path / "pics" / "timing.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in out.parent.iterdir()] == ["timing.png"]  # no temporary file left
    with pytest.raises(ValueError, match="the timing has 7 joints, ur5 has 6"):
        plot_timing(nik.load_robot("ur5"), tim, tmp_path / "x.png")
