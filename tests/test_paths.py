"""``IKSolver.solve_path`` and ``nik path``: continuity over a whole path, redundant arms, honest reports, bad input."""

from __future__ import annotations

import csv
import math
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.cli import main
from nik.poses import matrix_to_quaternion
from nik.robots.reach import reach_center, reach_radius
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT


def _rz(a: float) -> torch.Tensor:
    T = torch.eye(4, dtype=torch.float64)
    T[0, 0], T[0, 1], T[1, 0], T[1, 1] = math.cos(a), -math.sin(a), math.sin(a), math.cos(a)
    return T


def _line(robot, q0: torch.Tensor, direction, length: float, n: int) -> torch.Tensor:
    """``(n, 4, 4)``: FK(q0) moved along ``direction`` by up to ``length`` metres, orientation fixed."""
    T0 = robot.fk(q0[None])[0]
    d = torch.as_tensor(direction, dtype=torch.float64)
    s = torch.linspace(0.0, 1.0, n, dtype=torch.float64)
    T = T0.expand(n, 4, 4).clone()
    T[:, :3, 3] = T0[:3, 3] + s[:, None] * length * d / d.norm()
    return T


def _reached(robot, T, q) -> torch.Tensor:
    """The independent check: FK of ``q`` within 0.1 mm / 0.1 deg of ``T`` and every joint inside its limits."""
    pe, re = nik.pose_error(T, robot.fk(q.double()))
    lo, hi = robot.limits.double().T
    inside = ((q >= lo - 1e-9) & (q <= hi + 1e-9)).all(dim=-1)
    return (pe <= DEFAULT_TOL_POS) & (re <= DEFAULT_TOL_ROT) & inside


def _reached_without_a_jump(robot, T, q, max_step: float = math.radians(10.0)) -> torch.Tensor:
    """The independent check of ``res.success`` (issue 49 item 3): :func:`_reached`, except a waypoint whose step from
    a reached waypoint before it (largest joint motion) is above ``max_step``: it is reached only by a jump."""
    fk = _reached(robot, T, q)
    jump = torch.zeros_like(fk)
    jump[1:] = fk[1:] & fk[:-1] & ((q[1:] - q[:-1]).abs().amax(dim=-1) > max_step)
    return fk & ~jump


def _largest_step(q: torch.Tensor) -> float:
    return float((q[1:] - q[:-1]).abs().max())


@pytest.fixture(scope="module")
def ur5():
    return nik.IKSolver("ur5")


@pytest.fixture(scope="module")
def panda():
    return nik.IKSolver("panda")


def _branch_trap(solver):
    """A ur5 path whose default first branch (``solve(T[0])``) runs into the shoulder joint's +180 deg limit: the
    whole pose turns about the base axis, which moves that branch's joint 0 from 115 deg beyond 180 deg."""
    q = torch.tensor([2.0, -1.0, 1.2, -1.5, -1.4, 0.3], dtype=torch.float64)
    T0 = solver.robot.fk(q[None])[0]
    a = float(solver.solve(T0).q[0, 0])
    sweep = (math.pi - abs(a)) + 0.6
    angles = torch.linspace(0.0, math.copysign(sweep, a), int(math.degrees(sweep) / 2) + 1, dtype=torch.float64)
    return torch.stack([_rz(float(t)) @ T0 for t in angles])


def test_branch_trap_is_solved_without_a_jump(ur5):
    T = _branch_trap(ur5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        chain = [ur5.solve(T[0]).q[0]]
        for i in range(1, T.shape[0]):
            chain.append(ur5.solve(T[i], q_near=chain[-1]).q[0])
    assert _largest_step(torch.stack(chain)) > math.radians(90.0)  # the trap is real: the hand-made chain jumps
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no reconfiguration warning either
        res = ur5.solve_path(T)
    assert bool(_reached(ur5.robot, T, res.q).all())
    assert bool(res.success.all())
    assert _largest_step(res.q) < math.radians(3.0)
    assert res.path.largest_step == pytest.approx(_largest_step(res.q))
    assert res.source == "analytic"


def test_q_start_makes_the_trajectory_start_nearest_it(ur5):
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(ur5.robot, q0, [0.0, 1.0, 0.0], 0.1, 30)
    res = ur5.solve_path(T, q_start=q0)
    assert bool(_reached(ur5.robot, T, res.q).all())
    torch.testing.assert_close(res.q[0], q0, atol=1e-6, rtol=0)  # FK(q0) is the first waypoint: q0's own branch
    assert float(res.path.steps[0]) == pytest.approx(float((res.q[0] - q0).abs().max()))
    assert _largest_step(res.q) < math.radians(3.0)
    assert res.source == "q_start"  # the LM chain from q_start follows the whole path: no look-ahead needed


def test_q_start_on_a_trapped_branch_is_not_followed_into_the_limit(ur5):
    """From the trapped branch's own configuration the LM chain would turn joint 0 by a full turn at the limit;
    solve_path falls back to the closed form's branches and reports the one unavoidable large step, nothing more.
    Every pose is reached by FK; the waypoint the jump leads into counts as not reached (issue 49 item 3: a waypoint
    reached only by a step above ``max_step`` is no success), the others are."""
    T = _branch_trap(ur5)
    q_start = ur5.solve(T[0]).q[0]
    with pytest.warns(UserWarning, match="forces a reconfiguration") as caught:
        res = ur5.solve_path(T, q_start=q_start)
    assert res.source == "analytic"
    assert bool(_reached(ur5.robot, T, res.q).all())
    assert int(res.path.reconfigurations.sum()) == 1
    jump = int(res.path.reconfigurations.nonzero()[0])
    assert (~res.success).nonzero().flatten().tolist() == ([jump] if jump > 0 else [])
    assert res.path.reasons[jump] == ("reached only by a step above max_step from the waypoint before" if jump else "")
    assert f"waypoint {jump} of" in str(caught[0].message)


def test_a_joint_with_more_than_a_full_turn_crosses_180_degrees_continuously():
    """kuka_kr's joint 6 (range +-350 deg) turns from 60 to 260 deg: the closed form's answers lie in [-180, 180),
    the trajectory must not jump by a full turn where the joint passes 180 deg."""
    solver = nik.IKSolver("kuka_kr")
    q = torch.tensor([0.3, -0.8, 0.6, 0.4, 0.9, math.radians(60.0)], dtype=torch.float64)
    Q = q.expand(101, 6).clone()
    Q[:, 5] = torch.linspace(math.radians(60.0), math.radians(260.0), 101, dtype=torch.float64)
    T = solver.robot.fk(Q)
    res = solver.solve_path(T, q_start=q)
    assert bool(_reached(solver.robot, T, res.q).all())
    torch.testing.assert_close(res.q, Q, atol=1e-6, rtol=0)  # the arm's own motion, 2 deg per waypoint
    assert _largest_step(res.q) < math.radians(2.5)


def test_redundant_arm_follows_a_line_continuously_from_q_start(panda):
    lo, hi = panda.robot.limits.double().T
    q0 = lo + (hi - lo) * torch.tensor([0.45, 0.6, 0.5, 0.55, 0.4, 0.5, 0.6], dtype=torch.float64)
    T = _line(panda.robot, q0, [-1.0, 0.3, 0.2], 0.15, 60)
    res = panda.solve_path(T, q_start=q0)
    assert bool(_reached(panda.robot, T, res.q).all())
    assert bool(res.success.all())
    full = torch.cat([q0[None], res.q])
    assert _largest_step(full) < math.radians(3.0)
    assert res.path.continuous


def test_redundant_arm_without_q_start_keeps_one_posture(panda):
    q0 = torch.tensor([0.2, 0.3, -0.2, -1.8, 0.1, 2.0, 0.5], dtype=torch.float64)
    T = _line(panda.robot, q0, [0.0, 0.0, 1.0], 0.12, 40)
    res = panda.solve_path(T)
    assert bool(_reached(panda.robot, T, res.q).all())
    assert _largest_step(res.q) < math.radians(3.0)
    assert res.source in ("network", "multistart")


@pytest.mark.long
def test_redundant_arm_does_not_drift_into_a_limit_and_jump(panda, monkeypatch):
    """Back and forth six times along a line whose far end the arm cannot reach in that orientation: without the
    secondary objective (joint-limit centring) the posture drifts into a limit and then jumps; with it, neither."""
    import nik.paths.candidates as candidates
    import nik.paths.solve as paths

    lo, hi = panda.robot.limits.double().T
    q0 = lo + (hi - lo) * torch.tensor([0.5, 0.55, 0.5, 0.5, 0.5, 0.45, 0.5], dtype=torch.float64)
    go = _line(panda.robot, q0, [1.0, 0.5, 0.0], 0.15, 30)
    T = torch.cat([go, go.flip(0)] * 6)

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = panda.solve_path(T, q_start=q0)
        margin = torch.minimum(res.q - lo, hi - res.q) / (hi - lo)  # (N, dof) fraction of each range left
        return res, float(margin.min())

    res, margin = run()
    assert margin > 0.1
    assert res.path.largest_step < math.radians(10.0)
    assert torch.equal(res.success, _reached_without_a_jump(panda.robot, T, res.q))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert int(res.success.sum()) == int(panda.solve(T).success.sum())  # every waypoint any solve reaches
    monkeypatch.setattr(candidates, "PATH_PULL", 0.0)  # the chains' pull, where _chain_path reads it
    monkeypatch.setattr(paths, "_smooth", lambda *a: True)  # the chain alone, without the global search's rescue
    plain, plain_margin = run()  # the check can fail: nearest-to-the-predecessor alone drifts and jumps
    assert plain_margin < 0.05 and plain.path.largest_step > math.radians(90.0)


def test_flags_are_honest_when_the_path_leaves_the_reach(ur5):
    robot = ur5.robot
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    p0 = robot.fk(q0[None])[0, :3, 3]
    outward = p0 - reach_center(robot)
    outward[2] = 0.0
    T = _line(robot, q0, outward, reach_radius(robot), 40)  # ends far beyond the reach
    with pytest.warns(UserWarning) as caught:
        res = ur5.solve_path(T)
    truth = _reached_without_a_jump(robot, T, res.q)
    assert bool(truth[0]) and not bool(truth[-1])
    assert torch.equal(res.success, truth)
    steps = (res.q[1:] - res.q[:-1]).abs().amax(dim=-1)
    problem = ~truth
    problem[1:] |= steps > res.path.max_step
    first = int(problem.nonzero()[0])  # the first waypoint not reached or reached by a reconfiguration
    assert f"waypoint {first} of 40" in str(caught[0].message)
    assert [bool(r) for r in res.path.reasons] == (~truth).tolist()
    assert res.path.reasons[-1] == "out of reach"
    torch.testing.assert_close(res.path.steps[1:], (res.q[1:] - res.q[:-1]).abs().amax(dim=-1), atol=1e-12, rtol=0)


def test_a_step_above_max_step_is_warned_about_as_a_reconfiguration(ur5):
    T = _branch_trap(ur5)
    limit = math.radians(1.0)
    with pytest.warns(UserWarning, match="forces a reconfiguration") as caught:
        res = ur5.solve_path(T, max_step=limit)
    above = ((res.q[1:] - res.q[:-1]).abs().amax(dim=-1) > limit).nonzero()
    assert above.numel() > 0
    assert f"waypoint {int(above[0]) + 1} of" in str(caught[0].message)
    assert res.path.reconfigurations.sum() == above.numel()


def test_solve_path_takes_quaternion_waypoints(ur5):
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(ur5.robot, q0, [1.0, 0.0, 0.0], 0.05, 10)
    v = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    res = ur5.solve_path(v)
    assert bool(_reached(ur5.robot, T, res.q).all())


def _bad_path(kind: str, robot) -> tuple:
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(robot, q0, [0.0, 1.0, 0.0], 0.1, 10)
    q_start = None
    if kind == "nan":
        T[4, 0, 3] = float("nan")
    elif kind == "one pose":
        T = T[:1]
    elif kind == "millimetres":
        T[:, :3, 3] *= 1e3
    elif kind == "not orthonormal":
        T[2, :3, :3] *= 1.3
    elif kind == "q_start outside the limits":
        q_start = q0.clone()
        q_start[5] = 4.0
    elif kind == "q_start of the wrong length":
        q_start = q0[:5]
    return T, q_start


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("nan", "NaN"),
        ("one pose", "at least 2 waypoints"),
        ("not orthonormal", "orthonormal"),
        ("q_start outside the limits", "joint 5 .* outside its limits"),
        ("q_start of the wrong length", r"q_start: expected shape \(6,\)"),
    ],
)
def test_bad_input_is_one_line_value_error(ur5, kind, match):
    T, q_start = _bad_path(kind, ur5.robot)
    with pytest.raises(ValueError, match=match) as err:
        ur5.solve_path(T, q_start=q_start)
    assert "\n" not in str(err.value)


def _write_poses(path, T) -> None:
    quat = matrix_to_quaternion(T[:, :3, :3])
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x", "y", "z", "qw", "qx", "qy", "qz"])
        for p, qq in zip(T[:, :3, 3].tolist(), quat.tolist(), strict=True):
            w.writerow([f"{v:.12g}" for v in p + qq])


def test_cli_round_trip_csv_to_csv(tmp_path, capsys):
    robot = nik.load_robot("ur5")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(robot, q0, [0.0, 1.0, 0.5], 0.1, 25)
    poses, out = tmp_path / "path.csv", tmp_path / "traj.csv"
    _write_poses(poses, T)
    start = [f"{math.degrees(v):.9f}" for v in q0.tolist()]
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--q-start", *start, "--out", str(out)]) == 0
    assert "reached 25 of 25 waypoints" in capsys.readouterr().out
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    names = [f"{n}_deg" for n in robot.joint_names]
    q = torch.tensor([[math.radians(float(r[n])) for n in names] for r in rows], dtype=torch.float64)
    assert q.shape == (25, 6)
    assert bool(_reached(robot, T, q).all())
    assert all(r["success"] == "1" for r in rows)
    assert _largest_step(torch.cat([q0[None], q])) < math.radians(3.0)
    steps = np.array([float(r["step_deg"]) for r in rows[1:]])
    np.testing.assert_allclose(steps, np.degrees((q[1:] - q[:-1]).abs().amax(dim=-1).numpy()), atol=1e-6)


def test_cli_exit_1_when_a_waypoint_fails(tmp_path, capsys):
    robot = nik.load_robot("ur5")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    outward = robot.fk(q0[None])[0, :3, 3] - reach_center(robot)
    outward[2] = 0.0
    poses = tmp_path / "path.csv"
    _write_poses(poses, _line(robot, q0, outward, reach_radius(robot), 20))
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--out", str(tmp_path / "t.csv")]) == 1
    assert "warning: solve_path on ur5: waypoint" in capsys.readouterr().err


def test_a_path_in_millimetres_is_warned_about_and_flagged_as_solve_does_it(ur5):
    """One behaviour for targets beyond the reach, solve and solve_path alike: a warning (one line, the millimetre
    question where they lie 100 x beyond), ``reachable`` False, no success; no exception."""
    T, _ = _bad_path("millimetres", ur5.robot)
    with pytest.warns(UserWarning, match="millimetres") as caught:
        res = ur5.solve_path(T)
    assert "\n" not in str(caught[0].message)
    with pytest.warns(UserWarning, match="were the positions given in millimetres"):
        one = ur5.solve(T)
    assert torch.equal(res.reachable, one.reachable) and not bool(res.reachable.any())
    assert not bool(res.success.any())
    assert res.path.reasons == ["out of reach"] * T.shape[0]


def test_cli_path_given_in_the_wrong_unit_exits_1_with_the_millimetre_question(tmp_path, capsys):
    robot = nik.load_robot("ur5")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(robot, q0, [0.0, 1.0, 0.0], 0.05, 5)
    T[:, :3, 3] *= 1e6  # kilometres given as millimetres: still far beyond the reach in metres
    poses = tmp_path / "path.csv"
    _write_poses(poses, T)
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--unit", "mm"]) == 1
    assert "millimetres" in capsys.readouterr().err


@pytest.mark.parametrize("args", [["--q-start", "1", "2", "3"], ["--q-start", *["0"] * 5, "200"]])
def test_cli_bad_input_exit_2_one_line(tmp_path, capsys, args):
    robot = nik.load_robot("ur5")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(robot, q0, [0.0, 1.0, 0.0], 0.05, 5)
    poses = tmp_path / "path.csv"
    _write_poses(poses, T)
    assert main(["path", "--robot", "ur5", "--poses", str(poses), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("nik path: error:") and "\n" not in err


def test_cli_plot_writes_a_png(tmp_path):
    pytest.importorskip("matplotlib")
    robot = nik.load_robot("ur5")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    poses, png = tmp_path / "path.csv", tmp_path / "traj.png"
    _write_poses(poses, _line(robot, q0, [0.0, 1.0, 0.0], 0.05, 10))
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---- the solver's settings are the path's -----------------------------------------------------------------------
def _panda_line_past_its_reach(robot):
    """A panda line from the middle of its ranges whose far end the arm cannot reach in that orientation (within the
    reach bound: the LM restarts are drawn there)."""
    lo, hi = robot.limits.double().T
    q0 = lo + (hi - lo) * torch.tensor([0.5, 0.55, 0.5, 0.5, 0.5, 0.45, 0.5], dtype=torch.float64)
    return q0, _line(robot, q0, [1.0, 0.5, 0.0], 0.15, 30)


def _ur5_line_out_of_reach(robot):
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    outward = robot.fk(q0[None])[0, :3, 3] - reach_center(robot)
    outward[2] = 0.0
    return _line(robot, q0, outward, reach_radius(robot), 40)


def _quiet_path(solver, T, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solver.solve_path(T, **kw)


def test_the_solvers_lm_settings_drive_the_paths_lm(panda):
    from nik.lm import LMCfg

    q0, T = _panda_line_past_its_reach(panda.robot)
    plain = _quiet_path(panda, T, q_start=q0)
    short = _quiet_path(nik.IKSolver(panda.robot, swarm_cfg=LMCfg(max_step=0.05)), T, q_start=q0)
    assert int(short.iterations.sum()) > int(plain.iterations.sum())  # shorter LM steps: more of them
    assert torch.equal(short.success, _reached_without_a_jump(panda.robot, T, short.q))


def test_fallback_none_draws_no_uniform_restarts_along_the_path(panda):
    from nik.lm import LMCfg

    q0, T = _panda_line_past_its_reach(panda.robot)
    plain = _quiet_path(panda, T, q_start=q0)
    bare = _quiet_path(nik.IKSolver(panda.robot, fallback="none"), T, q_start=q0)
    per_try = LMCfg().iters  # a waypoint: LM from the pulled seed, then from the previous answer, nothing more
    assert int(bare.iterations.max()) <= 2 * per_try < int(plain.iterations.max())
    assert torch.equal(bare.success, _reached_without_a_jump(panda.robot, T, bare.q))


def test_refine_none_keeps_the_closed_forms_branches_as_they_are(ur5):
    T = _ur5_line_out_of_reach(ur5.robot)
    plain = _quiet_path(ur5, T)
    raw = _quiet_path(nik.IKSolver(ur5.robot, refine="none"), T)
    assert int(plain.iterations.sum()) > 0 and int(raw.iterations.sum()) == 0  # no LM at the unreached waypoints
    assert torch.equal(raw.success, _reached_without_a_jump(ur5.robot, T, raw.q))
    assert torch.equal(raw.success, plain.success)
    with pytest.raises(ValueError, match="refine='none'"):
        nik.IKSolver("panda", refine="none").solve_path(T[:5])


def test_fallback_multistart_restarts_the_closed_form_arms_gaps(ur5):
    T = _ur5_line_out_of_reach(ur5.robot)
    plain = _quiet_path(ur5, T)
    more = _quiet_path(nik.IKSolver(ur5.robot, fallback="multistart"), T)
    assert int(more.iterations.sum()) > int(plain.iterations.sum())
    assert torch.equal(more.success, _reached_without_a_jump(ur5.robot, T, more.q))


def test_a_solver_forced_onto_torch_is_refused_in_one_line(ur5):
    T = _ur5_line_out_of_reach(ur5.robot)[:5]
    with pytest.raises(ValueError, match="backend='torch'") as err:
        nik.IKSolver(ur5.robot, backend="torch").solve_path(T)
    assert "\n" not in str(err.value)


def test_a_solver_without_a_network_starts_its_chains_from_uniform_starts_only(panda):
    q0 = torch.tensor([0.2, 0.3, -0.2, -1.8, 0.1, 2.0, 0.5], dtype=torch.float64)
    T = _line(panda.robot, q0, [0.0, 0.0, 1.0], 0.12, 20)
    bare = nik.IKSolver(panda.robot, checkpoint=None).solve_path(T)
    assert bare.source == "multistart"
    assert bool(_reached(panda.robot, T, bare.q).all()) and _largest_step(bare.q) < math.radians(3.0)


# ---- closed loops (issue 29.2) ---------------------------------------------------------------------------------
def _circle(robot, seed: int, n: int = 40, radius: float = 0.05) -> torch.Tensor:
    """``(n, 4, 4)``: a full circle through FK of a random configuration, in a random plane, orientation fixed; its
    last pose equals its first."""
    gen = torch.Generator().manual_seed(seed)
    q0 = robot.sample(1, generator=gen, dtype=torch.float64)[0]
    T0 = robot.fk(q0[None])[0]
    u, v = torch.linalg.qr(torch.randn(3, 2, generator=gen, dtype=torch.float64))[0].T
    a = torch.linspace(0.0, 2 * math.pi, n, dtype=torch.float64)
    T = T0.expand(n, 4, 4).clone()
    T[:, :3, 3] = T0[:3, 3] + radius * ((1 - torch.cos(a))[:, None] * u - torch.sin(a)[:, None] * v)
    return T


@pytest.mark.parametrize("name, seed", [("ur5", 1), ("panda", 1)])
def test_a_closed_circle_ends_on_its_first_row(name, seed, ur5, panda):
    solver = {"ur5": ur5, "panda": panda}[name]
    T = _circle(solver.robot, seed)
    res = solver.solve_path(T)
    q = res.q
    assert res.path.closed
    assert math.degrees(float((q[-1] - q[0]).abs().max())) <= 0.1
    assert bool(_reached(solver.robot, T, q).all())
    assert _largest_step(q) < math.radians(10.0)


def test_a_redundant_arm_drifts_around_a_loop_unless_it_is_closed(panda):
    """The check above can fail: the chain alone (closed=False) ends elsewhere in the null space."""
    T = _circle(panda.robot, 1)
    res = panda.solve_path(T, closed=False)
    assert not res.path.closed and res.path.closure is None
    assert math.degrees(float((res.q[-1] - res.q[0]).abs().max())) > 1.0


def test_an_open_path_is_not_taken_as_closed(ur5):
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    assert not ur5.solve_path(_line(ur5.robot, q0, [0.0, 1.0, 0.0], 0.05, 10)).path.closed


# ---- tolerant paths (issue 29.4) ---------------------------------------------------------------------------------
def _turning_line(robot) -> torch.Tensor:
    """A ur5 line (15 cm) whose orientation turns 60 deg about the tool's z axis on the way, from a start with the
    last wrist joint at 150 deg: with that orientation fixed at every waypoint the wrist must pass its +180 deg limit
    (a reconfiguration); with rotation about z free it need not turn at all."""
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.5, -1.5, math.radians(150.0)], dtype=torch.float64)
    n = 40
    s = torch.linspace(0.0, 1.0, n, dtype=torch.float64)
    T = _line(robot, q0, [0.0, 1.0, 0.0], 0.15, n)
    T[:, :3, :3] = T[:, :3, :3] @ torch.stack([_rz(float(a))[:3, :3] for a in s * math.radians(60.0)])
    return T


def test_a_free_tool_axis_makes_an_infeasible_path_feasible_with_small_steps(ur5):
    T = _turning_line(ur5.robot)
    with pytest.warns(UserWarning, match="reconfiguration"):
        fixed = ur5.solve_path(T)
    assert fixed.path.largest_step > math.radians(10.0)
    res = ur5.solve_path(T, bounds="axis_z")
    half = torch.from_numpy(nik.ik.bounds.parse_bounds("axis_z").expand(1)[0])
    assert bool(nik.poses.within_bounds(T, ur5.robot.fk(res.q), half).all())  # by FK, independently
    assert bool(res.success.all())
    assert _largest_step(res.q) < math.radians(3.0)


def test_a_redundant_arms_chains_keep_the_bounds(panda):
    gen = torch.Generator().manual_seed(1)
    q0 = panda.robot.sample(1, generator=gen, dtype=torch.float64)[0]
    T = _line(panda.robot, q0, [0.0, 1.0, 0.0], 0.1, 30)
    T[:, :3, :3] = T[:, :3, :3] @ torch.stack([_rz(a)[:3, :3] for a in np.linspace(0, math.radians(60), 30)])
    res = panda.solve_path(T, bounds="axis_z")
    half = torch.from_numpy(nik.ik.bounds.parse_bounds("axis_z").expand(1)[0])
    assert bool(nik.poses.within_bounds(T, panda.robot.fk(res.q), half).all())
    assert bool(res.success.all())
    assert _largest_step(res.q) < math.radians(3.0)


# ---- timing (issue 29.3) ----------------------------------------------------------------------------------------
def test_a_timed_path_keeps_its_limits_at_1_ms(ur5):
    pytest.importorskip("toppra")
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    res = ur5.solve_path(_line(ur5.robot, q0, [0.0, 1.0, 0.0], 0.2, 20), timing=True)
    rep = res.path
    assert rep.t.shape == (20,) and rep.qd.shape == rep.qdd.shape == (20, 6)
    assert float(rep.t[0]) == 0.0 and bool((rep.t.diff() > 0).all())
    t, q, qd, qdd = rep.timing.sample(1e-3)
    vel = ur5.robot.vel_limits.numpy()
    assert (np.abs(qd) <= vel * (1 + 1e-6)).all()
    assert (np.abs(qdd) <= rep.timing.acc_limits * (1 + 1e-6)).all()
    np.testing.assert_allclose(rep.timing.at(rep.t.numpy())[0], res.q.numpy(), atol=1e-9)  # through the waypoints


def test_timing_without_speed_limits_is_a_one_line_error():
    robot = nik.load_robot("ur5")
    robot.vel_limits = None
    solver = nik.IKSolver(robot)
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    T = _line(robot, q0, [0.0, 1.0, 0.0], 0.05, 5)
    with pytest.raises(ValueError, match="timing needs joint speed limits") as err:
        solver.solve_path(T, timing=True)
    assert "\n" not in str(err.value)
    res = solver.solve_path(T, timing=True, vel_limits=[1.0] * 6)  # given per call
    assert res.path.timing.duration > 0


def test_a_path_with_missed_waypoints_gets_no_schedule_and_a_warning_that_says_why(ur5):
    """Issue 49 item 4: a ur5 line that leaves the reach (main: timed all the same, without a word)."""
    pytest.importorskip("toppra")
    T = _ur5_line_out_of_reach(ur5.robot)
    with pytest.warns(UserWarning) as caught:
        res = ur5.solve_path(T, timing=True)
    missed = int((~_reached(ur5.robot, T, res.q)).sum())
    assert missed > 0
    assert res.path.t is None and res.path.qd is None and res.path.qdd is None and res.path.timing is None
    said = [str(w.message) for w in caught if "not timed" in str(w.message)]
    assert len(said) == 1 and "\n" not in said[0]
    assert f"{int((~res.success).sum())} waypoint(s) not reached" in said[0].split("not timed")[1]


def test_a_path_with_a_step_above_max_step_gets_no_schedule(ur5):
    """The branch trap from ``q_start`` on its trapped branch has one unavoidable jump: no schedule either; the same
    path with a ``max_step`` above that jump is timed."""
    pytest.importorskip("toppra")
    T = _branch_trap(ur5)
    q_start = ur5.solve(T[0]).q[0]
    with pytest.warns(UserWarning, match="not timed"):
        res = ur5.solve_path(T, q_start=q_start, timing=True)
    assert res.path.t is None and res.path.qd is None
    steps = (res.q[1:] - res.q[:-1]).abs().amax(dim=-1)
    assert float(steps.max()) > res.path.max_step
    loose = ur5.solve_path(T, q_start=q_start, timing=True, max_step=float(steps.max()) + 0.1)
    assert bool(loose.success.all()) and loose.path.t is not None and loose.path.t.shape == (T.shape[0],)


def test_nik_path_timing_on_a_broken_path_warns_and_writes_no_time_column(ur5, tmp_path, capsys):
    """The CLI's choice (``nik path --help``, ``--timing``): the path is written without its ``t_s`` column, the warning
    says why on stderr, exit status 1 (some waypoint not reached), as without ``--timing``."""
    pytest.importorskip("toppra")
    T = _ur5_line_out_of_reach(ur5.robot)
    poses = tmp_path / "line.csv"
    rows = torch.cat([T[:, :3, 3], matrix_to_quaternion(T[:, :3, :3])], dim=-1)
    poses.write_text("x,y,z,qw,qx,qy,qz\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows.tolist()))
    out = tmp_path / "traj.csv"
    assert main(["path", "--robot", "ur5", "--poses", str(poses), "--out", str(out), "--timing"]) == 1
    err = capsys.readouterr().err
    assert "not timed" in err and "Traceback" not in err
    with out.open() as fh:
        header = next(csv.reader(fh))
    assert header[0] == "index" and "t_s" not in header


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"closed": "yes"}, "closed: expected"),
        ({"timing": "fast"}, "timing: expected"),
        ({"timing": {"speed": 1.0}}, "timing: unknown keyword"),
        ({"bounds": "axis_q"}, "bounds"),
    ],
)
def test_bad_closed_timing_or_bounds_is_a_one_line_error(ur5, kw, match):
    q0 = torch.tensor([0.3, -1.2, 1.4, -1.6, -1.5, 0.2], dtype=torch.float64)
    with pytest.raises(ValueError, match=match) as err:
        ur5.solve_path(_line(ur5.robot, q0, [0.0, 1.0, 0.0], 0.05, 5), **kw)
    assert "\n" not in str(err.value)


def test_the_path_solver_is_modules_of_one_job_each():
    """``nik.paths.solve`` keeps ``solve_path`` (and the names its callers read) while parsing, the call's state,
    candidates, the choice, the posture search, repairs and the report live in modules of their own, each opening
    with a docstring; the path kernels and ``solve_path`` take at most 12 parameters (issue 46, item 4)."""
    import importlib
    import inspect

    from nik.paths import kernels, trajopt
    from nik.paths.solve import PathOptions, solve_path

    jobs = ("parse", "run", "candidates", "choice", "search", "repair", "report", "settings", "solve")
    for name in jobs:
        mod = importlib.import_module(f"nik.paths.{name}")
        assert mod.__doc__ and len(mod.__doc__.split()) > 15, name
        assert len(inspect.getsource(mod).splitlines()) < 700, name  # no module of six jobs again
    assert inspect.getmodule(solve_path).__name__ == "nik.paths.solve"
    for fn in (kernels.path_chains, kernels.path_chains_toward, kernels.path_chains_bounded,
               kernels.path_chains_bounded_toward, trajopt.polish_path, solve_path):  # fmt: skip
        params = inspect.signature(getattr(fn, "py_func", fn)).parameters
        assert len(params) <= 12, fn.__name__
    with pytest.raises(TypeError):
        PathOptions()  # the tolerances are the caller's to state


def test_path_chains_with_grouped_arrays_follow_a_path_as_the_drifting_chains_do(ur5):
    """``path_chains(G, joints, T, starts, lm, pull, pull_cap, out)`` is ``path_chains_toward`` drifting to the middle
    of the ranges, and its answers reach the waypoints by FK (an independent check: the torch FK)."""
    from nik.ik.model import model_of
    from nik.kernels.chain import LOWER, UPPER
    from nik.kernels.lm import seed_state
    from nik.paths.kernels import path_chains, path_chains_toward

    robot = ur5.robot
    lm = model_of(robot).lm
    lo, hi = robot.limits.double().T
    q0 = lo + (hi - lo) * torch.tensor([0.4, 0.3, 0.6, 0.5, 0.45, 0.5], dtype=torch.float64)
    T = np.ascontiguousarray(_line(robot, q0, [0.0, 1.0, 0.0], 0.05, 8).numpy())
    starts = q0.numpy()[None].copy()
    opts, iopts = lm.options(1e-6, 1e-5)
    run = (opts, iopts, np.zeros(8, dtype=np.int64), seed_state(0))

    def out():
        return (np.empty((1, 8, 6)), np.empty((1, 8), dtype=np.int64), np.empty((1, 8), dtype=bool),
                np.empty((1, 8)), np.empty((1, 8)))  # fmt: skip

    a, b = out(), out()
    path_chains(lm.G, lm.joints, T, starts, run, 0.02, 0.01, a)
    mid = (0.5 * (lm.joints[:, LOWER] + lm.joints[:, UPPER]))[None].copy()
    path_chains_toward(lm.G, lm.joints, T, starts, (mid, np.full(1, 0.02), np.full(1, 0.01)), run, b)
    assert np.array_equal(a[0], b[0]) and a[2].all()
    pos, rot = nik.pose_error(torch.from_numpy(T), robot.fk(torch.from_numpy(a[0][0])))
    assert float(pos.max()) < 1e-5 and float(rot.max()) < 1e-4
