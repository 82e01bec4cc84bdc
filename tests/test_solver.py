"""nik.IKSolver: round trips for every built-in robot, input forms, q_near, solve_all, bad inputs, checkpoints."""

from __future__ import annotations

import importlib.util
import math
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.analytic import puma560_ik
from nik.poses import matrix_to_quaternion, matrix_to_rpy

HAS_MODELS = importlib.util.find_spec("nik.models") is not None


def _targets(robot, n: int, seed: int):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return q, robot.fk(q)


def _check_round_trip(robot, res, T, tol_pos, tol_rot):
    assert res.q.shape == (T.shape[0], robot.dof)
    assert bool(res.success.all())
    assert bool(robot.within_limits(res.q).all())
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    torch.testing.assert_close(pos, res.pos_err)
    torch.testing.assert_close(rot, res.rot_err)
    assert float(pos.max()) <= tol_pos and float(rot.max()) <= tol_rot


@pytest.mark.parametrize("name", ["puma560", "kuka_kr", "rebot_v_6r"])
def test_round_trip_analytic_robots(name):
    robot = nik.load_robot(name)
    _, T = _targets(robot, 50, 1)
    solver = nik.IKSolver(robot)
    assert solver.initial_source == "analytic"
    res = solver.solve(T)
    _check_round_trip(robot, res, T, 1e-9, 1e-9)
    assert int(res.iterations.sum()) == 0  # the closed form is already exact


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_round_trip_other_robots_from_a_near_guess(name):
    robot = nik.load_robot(name)
    q, T = _targets(robot, 20, 2)
    noise = 0.05 * torch.randn(q.shape, generator=torch.Generator().manual_seed(3), dtype=q.dtype)
    solver = nik.IKSolver(robot, checkpoint=None, refine="lm", analytic=False)  # ur5 has a closed form too
    assert solver.initial_source == "multistart"
    res = solver.solve(T, q_near=robot.clamp(q + noise))
    _check_round_trip(robot, res, T, 1e-4, 1e-3)


def test_round_trip_ur5_multistart_swarm():
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 8, 4)
    res = nik.IKSolver(robot, refine="ipso").solve(T, tol_pos=1e-3, tol_rot=1e-2, seed=0)
    # honest flags: whatever succeeded is within tolerance, whatever failed is not
    assert bool(res.success.float().mean() >= 0.5)
    ok = res.success
    assert bool((res.pos_err[ok] <= 1e-3).all()) and bool((res.rot_err[ok] <= 1e-2).all())
    assert bool(((res.pos_err[~ok] > 1e-3) | (res.rot_err[~ok] > 1e-2)).all())
    assert bool(robot.within_limits(res.q).all())


def test_every_input_form_gives_the_same_answer():
    robot = nik.load_robot("puma560")
    _, T = _targets(robot, 5, 5)
    solver = nik.IKSolver(robot)
    ref = solver.solve(T).q
    quat = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    rpy = torch.cat([T[:, :3, 3], matrix_to_rpy(T[:, :3, :3])], dim=-1)
    forms = [
        (quat, None),
        (quat, "quat"),
        (rpy, None),
        (rpy, "rpy"),
        (T.numpy(), None),
        (T.tolist(), None),
        (quat.numpy(), "quat"),
    ]
    for value, rep in forms:
        res = solver.solve(value, representation=rep)
        torch.testing.assert_close(torch.as_tensor(res.q), ref, atol=1e-9, rtol=0)
        assert bool(res.success.all())
    # a single pose in each form counts as B = 1
    for single in (T[0], quat[0], rpy[0]):
        res = solver.solve(single)
        assert res.q.shape == (1, 6)
        torch.testing.assert_close(res.q[0], ref[0], atol=1e-9, rtol=0)


def test_near_unit_quaternion_is_normalised():
    robot = nik.load_robot("puma560")
    _, T = _targets(robot, 3, 6)
    quat = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3]) * 1.003], dim=-1)
    res = nik.IKSolver(robot).solve(quat)
    assert bool(res.success.all())


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda v: v.__setitem__((1, 3), 0.0) or v[1, 3:].zero_(), "row 1: quaternion"),
        (lambda v: v[2, 3:].mul_(1.5), "row 2: quaternion"),
        (lambda v: v.__setitem__((1, 0), float("nan")), "row 1: x, y, z contains NaN"),
        (lambda v: v.__setitem__((0, 4), float("inf")), "row 0: quaternion .* NaN or inf"),
    ],
)
def test_bad_quaternion_rows_are_rejected(mutate, match):
    robot = nik.load_robot("puma560")
    _, T = _targets(robot, 3, 7)
    v = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    mutate(v)
    with pytest.raises(ValueError, match=match):
        nik.IKSolver(robot).solve(v)


def test_bad_matrices_are_rejected():
    robot = nik.load_robot("puma560")
    solver = nik.IKSolver(robot)
    _, T = _targets(robot, 3, 8)
    bad = T.clone()
    bad[2, :3, :3] *= 1.2
    with pytest.raises(ValueError, match="pose 2 is not orthonormal"):
        solver.solve(bad)
    bad = T.clone()
    bad[1, 0, 3] = float("nan")
    with pytest.raises(ValueError, match="pose 1 contains NaN"):
        solver.solve(bad)
    with pytest.raises(ValueError, match="cannot tell the pose form"):
        solver.solve(torch.zeros(3, 5))
    with pytest.raises(ValueError, match=r"expected shape \(B, 7\)"):
        solver.solve(torch.zeros(3, 6), representation="quat")
    with pytest.raises(ValueError, match="representation"):
        solver.solve(T, representation="euler")
    with pytest.raises(ValueError, match="q_near"):
        solver.solve(T, q_near=torch.zeros(5))
    with pytest.raises(ValueError, match="refine must be one of"):
        nik.IKSolver(robot, refine="newton")


def test_q_near_picks_the_nearest_closed_form_solution():
    robot = nik.load_robot("puma560")
    _, T = _targets(robot, 1, 9)
    sols, valid = puma560_ik(robot, T[0])
    assert int(valid.sum()) >= 2
    solver = nik.IKSolver(robot)
    g = torch.Generator().manual_seed(10)
    for s in sols[valid]:
        near = s + 0.05 * torch.randn(6, generator=g, dtype=s.dtype)
        res = solver.solve(T, q_near=near)
        torch.testing.assert_close(res.q[0], s, atol=1e-9, rtol=0)


def test_q_near_picks_the_nearest_solution_without_closed_form():
    robot = nik.load_robot("ur5")
    q, T = _targets(robot, 4, 11)
    res = nik.IKSolver(robot, refine="lm").solve(T, q_near=robot.clamp(q + 0.02), tol_pos=1e-10, tol_rot=1e-10)
    assert bool(res.success.all())
    torch.testing.assert_close(res.q, q, atol=1e-6, rtol=0)


def test_refine_none_reports_the_raw_guess_with_its_true_errors():
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 6, 12)
    res = nik.IKSolver(robot, refine="none").solve(T)
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    torch.testing.assert_close(res.pos_err, pos)
    torch.testing.assert_close(res.rot_err, rot)
    assert torch.equal(res.success, (pos <= 1e-4) & (rot <= 1e-3))
    assert int(res.iterations.sum()) == 0


def test_seed_makes_results_repeatable():
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 3, 13)
    solver = nik.IKSolver(robot, refine="pso")
    a = solver.solve(T, seed=5, plan={"max_iters": 20}, tol_pos=1e-3, tol_rot=1e-2)
    b = solver.solve(T, seed=5, plan={"max_iters": 20}, tol_pos=1e-3, tol_rot=1e-2)
    assert torch.equal(a.q, b.q)


def test_solve_all_puma_returns_the_valid_closed_form_solutions():
    robot = nik.load_robot("puma560")
    q, T = _targets(robot, 1, 14)
    sols = nik.IKSolver(robot).solve_all(T[0])
    _, valid = puma560_ik(robot, T[0])
    assert sols.shape == (int(valid.sum()), 6)
    pos, rot = nik.pose_error(T[0], robot.fk(sols))
    assert float(pos.max()) < 1e-9 and float(rot.max()) < 1e-9
    wrapped = torch.remainder(sols - q + math.pi, 2 * math.pi) - math.pi
    assert bool((wrapped.abs().amax(-1) < 1e-7).any())


def test_solve_all_multistart_finds_several_distinct_solutions():
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 1, 15)
    sols = nik.IKSolver(robot, refine="lm").solve_all(T, n_starts=128)
    assert sols.shape[0] >= 2
    pos, rot = nik.pose_error(T[0], robot.fk(sols))
    assert float(pos.max()) <= 1e-4 and float(rot.max()) <= 1e-3
    diff = torch.remainder(sols[:, None] - sols[None] + math.pi, 2 * math.pi) - math.pi
    dist = diff.abs().amax(-1) + torch.eye(sols.shape[0], dtype=sols.dtype) * 10
    assert float(dist.min()) >= 1e-3
    with pytest.raises(ValueError, match="one pose"):
        nik.IKSolver(robot).solve_all(torch.eye(4).expand(2, 4, 4))


@pytest.mark.skipif(not HAS_MODELS, reason="nik.models (the training issue) is not in this build")
def test_checkpoint_network_path_and_robot_mismatch(tmp_path):
    from nik.errors import CheckpointError
    from nik.models import IKNet, save_checkpoint

    robot = nik.load_robot("ur5")
    q, T = _targets(robot, 64, 16)
    torch.manual_seed(0)
    net = IKNet(robot, hidden=[16]).fit_normalisation(T, q)
    path = save_checkpoint(net, tmp_path / "ur5.ckpt")
    raw = nik.IKSolver(robot, checkpoint=path, refine="none")
    assert raw.initial_source == "network"
    res = raw.solve(T[:8])
    torch.testing.assert_close(res.q, robot.clamp(net.predict(T[:8])))
    refined = nik.IKSolver(robot, checkpoint=path, refine="lm").solve(T[:8], q_near=robot.clamp(q[:8] + 0.02))
    assert bool(refined.success.all())
    with pytest.raises(CheckpointError, match="ur5.*puma560|puma560.*ur5"):
        nik.IKSolver("puma560", checkpoint=path)


def test_numpy_q_near_and_float32_targets():
    robot = nik.load_robot("kuka_kr")
    q, T = _targets(robot, 4, 17)
    res = nik.IKSolver(robot).solve(T.float(), q_near=np.asarray(q[0]))
    assert res.q.dtype == torch.float32
    assert bool(res.success.all())


@pytest.mark.skipif(not HAS_MODELS, reason="nik.models (the training issue) is not in this build")
def test_fallback_to_the_closed_form_rescues_a_poor_network(tmp_path):
    from nik.models import IKNet, save_checkpoint

    robot = nik.load_robot("puma560")
    q, T = _targets(robot, 32, 18)
    torch.manual_seed(0)
    path = save_checkpoint(IKNet(robot, hidden=[4]).fit_normalisation(T, q), tmp_path / "poor.ckpt")  # untrained
    without = nik.IKSolver(robot, checkpoint=path, refine="lm", fallback=False).solve(T, plan={"max_iters": 3})
    assert not bool(without.success.all())
    rescued = nik.IKSolver(robot, checkpoint=path, refine="lm").solve(T, plan={"max_iters": 3})
    _check_round_trip(robot, rescued, T, 1e-4, 1e-3)


@pytest.mark.skipif(not HAS_MODELS, reason="nik.models (the training issue) is not in this build")
def test_multistart_fallback_rescues_a_poor_network_on_an_arm_without_closed_form(tmp_path):
    from nik.models import IKNet, save_checkpoint

    robot = nik.load_robot("ur5")
    q, T = _targets(robot, 32, 19)
    torch.manual_seed(0)
    path = save_checkpoint(IKNet(robot, hidden=[4]).fit_normalisation(T, q), tmp_path / "poor.ckpt")  # untrained
    without = nik.IKSolver(robot, checkpoint=path, refine="lm", fallback=False).solve(T, plan={"max_iters": 3})
    assert not bool(without.success.all())
    rescued = nik.IKSolver(robot, checkpoint=path, refine="lm", fallback="multistart")
    rescued = rescued.solve(T, tol_pos=1e-4, tol_rot=1e-3, plan={"max_iters": 3})
    _check_round_trip(robot, rescued, T, 1e-4, 1e-3)


def test_default_solver_reaches_random_targets_on_a_7_dof_urdf_arm():
    robot = nik.load_robot("panda")
    q, T = _targets(robot, 16, 20)
    res = nik.IKSolver(robot).solve(T, seed=0)  # uniform-init ipso + LM polish, then LM multi-start fallback
    _check_round_trip(robot, res, T, 1e-4, 1e-3)


def test_unknown_fallback_is_refused():
    with pytest.raises(ValueError, match="fallback must be"):
        nik.IKSolver("ur5", fallback="maybe")
    with pytest.raises(ValueError, match="needs an arm with a closed form"):
        nik.IKSolver("panda", fallback="analytic")


def test_default_solver_round_trips_1000_stanford_arm_configurations():
    # issue 11: a Stanford arm (standard DH, one prismatic joint) defined in YAML without code;
    # at least 99.9 % of 1,000 random configurations within 0.1 mm / 0.1 deg, limits always held
    robot = nik.load_robot("stanford")
    q, T = _targets(robot, 1000, 1)
    res = nik.IKSolver(robot).solve(T, seed=0)
    assert bool(robot.within_limits(res.q).all())
    pos, rot = nik.pose_error(T, robot.fk(res.q))
    torch.testing.assert_close(pos, res.pos_err)
    within = (pos <= 1e-4) & (rot <= math.radians(0.1))
    assert float(within.double().mean()) >= 0.999, int((~within).sum())
    assert bool((res.success <= within).all())  # success (0.1 mm / 0.057 deg) implies the looser check


def test_solve_all_keeps_distinct_slide_lengths_apart():
    from nik.ik import dedupe

    q = torch.tensor(
        [[0.1, 0.2, 0.3], [0.1, 0.2, 0.3 + 2 * math.pi], [0.1 + 2 * math.pi, 0.2, 0.3]], dtype=torch.float64
    )
    assert dedupe(q).shape[0] == 1  # revolute: 2 pi apart is the same configuration
    kept = dedupe(q, prismatic=torch.tensor([False, False, True]))
    assert kept.shape[0] == 2  # a slide 2 pi metres longer is another configuration


# ---------------------------------------------------------------------------
# issue 11 item 5: q_near exactly on a limit of a joint with more than a full turn of range
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "joints"), [("puma560", [5]), ("kuka_kr", [3, 5])])
def test_q_near_on_a_multi_turn_joint_limit_returns_the_solution_at_q_near(name, joints):
    robot = nik.load_robot(name)
    q = robot.sample(50, generator=torch.Generator().manual_seed(11), dtype=torch.float64)
    side = torch.arange(50) % 2 == 0  # half on the lower limit, half on the upper one
    for j in joints:
        q[:, j] = torch.where(side, robot.limits[j, 0], robot.limits[j, 1])
    T = robot.fk(q)
    res = nik.IKSolver(robot).solve(T, q_near=q)
    assert bool(res.success.all())
    # the configuration q_near itself solves every pose, so the nearest answer is q_near (to rounding)
    assert float((res.q - q).abs().max()) < 1e-6


# ---------------------------------------------------------------------------
# issue 11 item 6: tolerances
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(("field", "value"), [("tol_pos", -1e-4), ("tol_pos", float("nan")), ("tol_rot", -0.1)])
def test_negative_or_nan_tolerance_is_refused(field, value):
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 2, 3)
    with pytest.raises(ValueError, match=field):
        nik.IKSolver(robot).solve(T, **{field: value})
    with pytest.raises(ValueError, match="tol_rot"):
        nik.IKSolver(robot).solve(T, tol_rot=float("nan"))


# ---------------------------------------------------------------------------
# issue 10: reachability, restarts, limits, determinism of the default (LM) pipeline
# ---------------------------------------------------------------------------
def test_default_refinement_is_lm():
    assert nik.IKSolver(nik.load_robot("ur5")).refine == "lm"


def test_targets_out_of_reach_are_flagged_warned_and_not_successful():
    robot = nik.load_robot("panda")
    q, T = _targets(robot, 6, 4)
    far = T.clone()
    far[:2, :3, 3] = T[:2, :3, 3] * 50.0  # far beyond the panda's reach of < 1 m
    with pytest.warns(UserWarning, match="beyond the reach of panda"):
        res = nik.IKSolver(robot).solve(far, seed=0)
    assert res.reachable.tolist() == [False, False, True, True, True, True]
    assert not bool(res.success[:2].any())
    assert bool(res.success[2:].all())
    assert bool(robot.within_limits(res.q).all())


def test_a_target_given_in_millimetres_gets_the_millimetre_hint():
    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 1, 5)
    T_mm = T.clone()
    T_mm[:, :3, 3] = T[:, :3, 3] * 1000.0 + 300.0
    with pytest.warns(UserWarning, match="millimetres"):
        nik.IKSolver(robot).solve(T_mm)


def test_same_seed_gives_identical_results_and_answers_stay_inside_the_limits():
    robot = nik.load_robot("panda")
    _, T = _targets(robot, 40, 6)
    a = nik.IKSolver(robot).solve(T, seed=3)
    b = nik.IKSolver(robot).solve(T, seed=3)
    assert torch.equal(a.q, b.q) and torch.equal(a.iterations, b.iterations)
    assert bool(robot.within_limits(a.q).all())
    assert float(a.success.float().mean()) >= 0.95


# ---- one rotation tolerance everywhere (0.1 mm / 0.1 deg, as every table measures) ---------------------------------
def test_every_entry_point_defaults_to_the_one_tolerance():
    import inspect

    from nik.evaluate import evaluate
    from nik.ik import DEFAULT_TOL_POS, DEFAULT_TOL_ROT
    from nik.lm import lm_solve
    from nik.swarm import refine

    assert DEFAULT_TOL_POS == 1e-4 and DEFAULT_TOL_ROT == pytest.approx(math.radians(0.1), rel=1e-15)
    for fn in (nik.IKSolver.solve, nik.IKSolver.solve_all, lm_solve, refine, evaluate):
        params = inspect.signature(fn).parameters
        assert params["tol_pos"].default == DEFAULT_TOL_POS, fn.__qualname__
        assert params["tol_rot"].default == DEFAULT_TOL_ROT, fn.__qualname__


def test_cli_tolerances_default_to_the_same_and_print_rounded(tmp_path, capsys):
    import csv

    from nik.cli import build_parser, main

    args = build_parser().parse_args(["solve", "--robot", "puma560", "--pose", *["0"] * 7])
    assert (args.tol_mm, args.tol_deg) == (0.1, 0.1)
    robot = nik.load_robot("puma560")
    T = robot.fk(robot.sample(2, generator=torch.Generator().manual_seed(8), dtype=torch.float64))
    poses = tmp_path / "p.csv"
    with poses.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x", "y", "z", "qw", "qx", "qy", "qz"])
        for row in torch.cat([T[:, :3, 3], nik.poses.matrix_to_quaternion(T[:, :3, :3])], -1).tolist():
            w.writerow([repr(v) for v in row])
    assert main(["solve", "--robot", "puma560", "--poses", str(poses), "--out", str(tmp_path / "s.csv")]) == 0
    assert "within 0.1 mm / 0.1 deg" in capsys.readouterr().out


# ---- angles given in degrees where radians are expected ------------------------------------------------------------
def test_rpy_angles_beyond_two_pi_are_warned_about():
    solver = nik.IKSolver("puma560", refine="none")
    with pytest.warns(UserWarning, match=r"row 0: roll, pitch, yaw .*beyond 2 pi.*degrees"):
        solver.solve([0.4, 0.1, 0.3, 180, 0, 90])  # the example: degrees read as radians
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # radians, even near the ends of their ranges: no warning
        solver.solve([[0.4, 0.1, 0.3, 3.1, -1.5, 6.2], [0.4, 0.1, 0.3, -6.28, 0.0, 0.0]])


def test_joint_angles_beyond_two_pi_are_warned_about():
    robot = nik.load_robot("puma560")
    T = robot.fk(robot.sample(1, generator=torch.Generator().manual_seed(0), dtype=torch.float64))
    solver = nik.IKSolver(robot)
    with pytest.warns(UserWarning, match=r"q_near: row 0, joint 2 = -90 .*beyond 2 pi.*degrees"):
        solver.solve(T, q_near=[0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solver.solve(T, q_near=[0.0, -1.5, 1.5, 0.0, 0.0, 0.0])


def test_a_joint_that_turns_further_than_two_pi_or_slides_is_not_taken_for_degrees(tmp_path):
    path = tmp_path / "long.yaml"  # joint 1 turns +-540 deg, joint 3 slides up to 9 m
    path.write_text(
        "convention: dh\nangles: deg\njoints:\n"
        "  - {alpha: 90, a: 0, d: 0.3, limits: [-540, 540]}\n"
        "  - {alpha: 0, a: 0.4, d: 0}\n"
        "  - {alpha: 0, a: 0, d: 0, type: prismatic, limits: [0, 9]}\n"
    )
    robot = nik.load_robot(path)
    T = robot.fk(torch.tensor([[7.0, 0.3, 8.0]], dtype=torch.float64))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        nik.IKSolver(robot).solve(T, q_near=[7.0, 0.3, 8.0])  # inside the ranges: radians and metres
    with pytest.warns(UserWarning, match=r"joint 1 = 500 .*beyond 2 pi"):
        nik.IKSolver(robot).solve(T, q_near=[500.0, 0.3, 8.0])  # 500 (deg?) outside the +-9.42 rad range


# ---- solve_all: one solution per IK branch -------------------------------------------------------------------------
def _wrapped_max_diff(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``(K, M)``: the largest joint difference (radians, modulo 2 pi) between rows of a and rows of b."""
    d = a[:, None] - b[None]
    return (torch.remainder(d + math.pi, 2 * math.pi) - math.pi).abs().amax(-1)


@pytest.mark.parametrize("name,seed", [("rebot_v_6r", 1000), ("rebot_v_6r", 1001), ("rebot_v_6r", 1003), ("ur5", 1001)])
def test_solve_all_returns_one_solution_per_branch_without_the_closed_form(name, seed):
    robot = nik.load_robot(name)
    T = robot.fk(robot.sample(1, generator=torch.Generator().manual_seed(seed), dtype=torch.float64))
    sols = nik.IKSolver(robot, analytic=False).solve_all(T)  # LM from the network's hypotheses + 256 starts
    assert 1 <= sols.shape[0] <= 8  # a 6R arm has at most 8
    d = _wrapped_max_diff(sols, sols) + torch.eye(sols.shape[0], dtype=sols.dtype) * 10
    assert float(d.min()) > math.radians(1.0), "two solutions within 1 deg in every joint"
    pos, rot = nik.poses.pose_error(T.expand(sols.shape[0], 4, 4), robot.fk(sols))
    assert float(pos.max()) < 1e-9 and float(rot.max()) < 1e-9  # polished far below the tolerance
    if name == "rebot_v_6r":  # PUMA-like: the closed form is the independent reference
        closed, valid = puma560_ik(robot, T[0])
        closed = closed[valid]
        match = _wrapped_max_diff(sols, closed)
        assert float(match.min(1).values.max()) < 1e-8  # each solution is one of the closed form's
        assert sols.shape[0] == closed.shape[0]  # ... and every closed-form solution was found


def test_a_pose_given_x_y_z_w_gives_the_answer_of_the_same_pose_given_w_first():
    # ROS order (qx, qy, qz, qw) with representation="quat_xyzw": the same targets, the same answers, in solve,
    # solve_all and on both backends' input checks (a tensor, numpy, a single pose); read as "quat" it is another pose
    robot = nik.load_robot("puma560")
    _, T = _targets(robot, 4, 11)
    solver = nik.IKSolver(robot)
    wxyz = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    xyzw = wxyz[:, [0, 1, 2, 4, 5, 6, 3]]
    ref = solver.solve(wxyz, representation="quat", seed=0)
    for value in (xyzw, xyzw.numpy(), xyzw.tolist()):
        res = solver.solve(value, representation="quat_xyzw", seed=0)
        torch.testing.assert_close(torch.as_tensor(res.q), ref.q, atol=1e-9, rtol=0)
        assert bool(res.success.all())
        pos, rot = nik.pose_error(robot.fk(torch.as_tensor(res.q)), T)
        assert bool((pos <= 1e-4).all()) and bool((rot <= 1e-3).all())
    single = solver.solve(xyzw[0], representation="quat_xyzw", seed=0)
    torch.testing.assert_close(single.q[0], ref.q[0], atol=1e-9, rtol=0)
    torch.testing.assert_close(solver.solve_all(xyzw[0], representation="quat_xyzw"), solver.solve_all(T[0]))
    misread = solver.solve(xyzw, representation="quat", seed=0)
    assert float(nik.pose_error(robot.fk(misread.q), T)[1].max()) > 0.1  # w last read as w first: another rotation
    bad = xyzw.clone()
    bad[1, 3:] *= 2
    with pytest.raises(ValueError, match=r"row 1: quaternion \(x, y, z, w\) has norm 2;"):
        solver.solve(bad, representation="quat_xyzw")


def test_a_path_given_x_y_z_w_gives_the_trajectory_of_the_same_path_given_w_first():
    robot = nik.load_robot("ur5")
    q = robot.sample(1, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    steps = torch.linspace(0, 0.05, 6, dtype=torch.float64)[:, None]
    T = robot.fk(q).repeat(6, 1, 1)
    T[:, :3, 3] += steps * torch.tensor([1.0, 0.5, 0.0], dtype=torch.float64)  # a 5.6 cm line, fixed orientation
    wxyz = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    solver = nik.IKSolver(robot)
    ref = solver.solve_path(wxyz, q[0], representation="quat")
    res = solver.solve_path(wxyz[:, [0, 1, 2, 4, 5, 6, 3]], q[0], representation="quat_xyzw")
    assert bool(ref.success.all()) and bool(res.success.all())
    torch.testing.assert_close(res.q, ref.q, atol=1e-9, rtol=0)


def test_solve_plan_dict_changes_the_iteration_cap_and_refuses_unknown_fields():
    """``solve(plan={"max_iters": N})``: the refinement's iteration limit as one field of the plan group (the
    solver's own plan of the call, that field changed): no refinement at 0 iterations, the same answer as the plan
    changed by hand, and a field the plan lacks refused in one line. ``solve`` takes at most 12 parameters."""
    import inspect

    robot = nik.load_robot("ur5")
    _, T = _targets(robot, 4, 21)
    solver = nik.IKSolver(robot, checkpoint=None, analytic=False)
    none = solver.solve(T, plan={"max_iters": 0, "restarts": False, "hypotheses": False, "fallback": "none"})
    assert int(none.iterations.sum()) == 0 and not bool(none.success.any())
    capped = solver.solve(T, seed=2, plan={"max_iters": 3})
    by_hand = solver.solve(T, plan=solver.plan(seed=2, max_iters=3, poses=4))
    assert torch.equal(capped.q, by_hand.q) and int(capped.iterations.max()) >= 1
    with pytest.raises(ValueError, match="plan: 'iterations' is not a field"):
        solver.solve(T, plan={"iterations": 3})
    assert len(inspect.signature(nik.IKSolver.solve).parameters) - 1 <= 12  # self aside
