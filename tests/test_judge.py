"""nik.ik.judge: a given network that guesses no better than uniform starts gives way (issue 37 item 4); a network
serves single poses and batches each only where it pays (issue 48 item 1, issue 50 item 11)."""

from __future__ import annotations

import copy
import json
import time
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.ik import judge
from nik.nets.checkpoint import save_checkpoint
from nik.nets.multi import build_net


def _useless(robot, kind: str, seed: int = 0):
    """A network of the shipped architecture that is useless: ``untrained`` (fresh weights, the shipped input
    normalisation), ``scrambled`` (the shipped one, its output units permuted) or ``randomised`` (the shipped one,
    every weight drawn again at its tensor's scale)."""
    shipped = nik.models.load_pretrained(robot)
    g = torch.Generator().manual_seed(seed)
    if kind == "untrained":
        torch.manual_seed(seed)
        net = build_net(robot, shipped.config())
        net.in_mean.copy_(shipped.in_mean)
        net.in_std.copy_(shipped.in_std)
        return net.eval()
    net = copy.deepcopy(shipped)
    with torch.no_grad():
        if kind == "scrambled":
            last = [m for m in net.modules() if isinstance(m, torch.nn.Linear)][-1]
            perm = torch.randperm(last.out_features, generator=g)
            last.weight.copy_(last.weight[perm])
            last.bias.copy_(last.bias[perm])
        else:
            for p in net.parameters():
                p.copy_(torch.randn(p.shape, generator=g) * p.std().clamp_min(1e-3))
    return net.eval()


def _targets(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return robot.fk(q).numpy()


@pytest.mark.parametrize("name", ["panda", "ur5"])
@pytest.mark.parametrize("kind", ["untrained", "scrambled", "randomised"])
def test_a_useless_network_given_by_path_gives_way_and_answers_as_without_one(tmp_path, name, kind):
    robot = nik.load_robot(name)
    path = save_checkpoint(_useless(robot, kind), tmp_path / f"{kind}.ckpt")
    solver = nik.IKSolver(robot, checkpoint=str(path), analytic=False)
    dropped = judge.counts()["dropped"]
    with pytest.warns(UserWarning, match="no better than uniform starts"):
        plan = solver.plan()
    assert plan.source == "multistart" and plan.net is None
    assert judge.counts()["dropped"] == dropped + 1
    v = judge.verdict(solver.net, robot)
    assert not v.earns and v.wins < judge.MIN_WINS
    T = _targets(robot, 60, seed=5)
    res = solver.solve(T)
    ref = nik.IKSolver(robot, checkpoint=None, analytic=False).solve(T)
    assert res.source == "multistart" and bool(res.success.all()) and bool(ref.success.all())
    np.testing.assert_array_equal(res.q, ref.q)  # the same plan as without a network: the same answers


def test_a_randomised_network_set_on_the_solver_gives_way_on_both_backends():
    robot = nik.load_robot("panda")
    T = _targets(robot, 40, seed=7)
    for backend in ("compiled", "torch"):
        solver = nik.IKSolver(robot, analytic=False, backend=backend)
        solver.net = _useless(robot, "randomised", seed=3)
        with pytest.warns(UserWarning, match="solving without it"):
            res = solver.solve(torch.from_numpy(T))
        assert res.source == "multistart" and bool(res.success.all())


def test_on_a_closed_form_arm_a_useless_network_gives_way_to_the_closed_form(tmp_path):
    robot = nik.load_robot("ur5")
    path = save_checkpoint(_useless(robot, "untrained"), tmp_path / "u.ckpt")
    solver = nik.IKSolver(robot, checkpoint=str(path))
    with pytest.warns(UserWarning, match="no better than uniform starts"):
        res = solver.solve(_targets(robot, 30, seed=2))
    assert res.source == "analytic" and bool(res.success.all())


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7"])
def test_the_shipped_networks_earn_their_place_given_by_object(name):
    robot = nik.load_robot(name)
    net = nik.models.load_pretrained(robot)
    v = judge.verdict(net, robot)
    assert v.earns and v.wins >= 0.9 and v.net_median < v.uniform_median
    solver = nik.IKSolver(robot, analytic=False)
    solver.net = net  # given: judged, and kept
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert solver.plan().source == "network" and solver.plan().net is net


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7", "kuka_kr"])
def test_the_shipped_single_pose_networks_earn_their_place_and_serve_single_poses_on_the_cpu(name):
    from nik.nets.pair import load_pair
    from nik.nets.pretrained import PRETRAINED_DIR

    robot = nik.load_robot(name)
    small = load_pair(PRETRAINED_DIR / f"{name}_one.safetensors", robot=robot.arm)
    v = judge.verdict(small, robot.arm)  # trained for the bare arm: judged in its frame
    assert v.earns and v.wins >= 0.9 and v.net_median < v.uniform_median
    solver = nik.IKSolver(robot, analytic=False)  # ur5, kuka_kr: the network asked for, the closed form aside
    plan = solver.plan(backend="compiled")
    assert plan.source == "network" and plan.net is solver.single_pose_net
    assert plan.net_in_arm_frame == (robot.arm is not robot)
    assert solver.plan(backend="torch").net is solver.net  # the main network elsewhere
    T = _targets(robot, 8, seed=3)
    res = solver.solve(T[:1])
    assert res.source == "network" and bool(res.success.all())


def test_the_raw_guess_and_no_fallback_keep_a_useless_network(tmp_path):
    robot = nik.load_robot("panda")
    path = str(save_checkpoint(_useless(robot, "scrambled"), tmp_path / "s.ckpt"))
    raw = nik.IKSolver(robot, checkpoint=path, refine="none", analytic=False)
    assert raw.plan(backend="torch").source == "network"  # what the network guesses, as asked
    alone = nik.IKSolver(robot, checkpoint=path, fallback="none", analytic=False)
    assert alone.plan().source == "network"  # what the network delivers alone (the evaluation's rows)


def test_a_network_is_judged_once_and_again_after_its_weights_change():
    robot = nik.load_robot("panda")
    net = _useless(robot, "untrained", seed=11)
    judged = judge.counts()["judged"]
    first = judge.verdict(net, robot)
    assert judge.verdict(net, robot) is first and judge.counts()["judged"] == judged + 1
    other = nik.IKSolver(robot, analytic=False)
    other.net = net
    with pytest.warns(UserWarning):
        assert other.plan().net is None
    assert judge.counts()["judged"] == judged + 1  # the verdict is kept per network
    shipped = nik.models.load_pretrained(robot)
    with torch.no_grad():  # trained in place (here: the shipped weights loaded into it)
        for p, s in zip(net.parameters(), shipped.parameters(), strict=True):
            p.copy_(s)
    again = judge.verdict(net, robot)
    assert judge.counts()["judged"] == judged + 2 and again.earns and not first.earns


class _CostlyForward(torch.nn.Module):
    """A network whose forward pass costs ``cost`` seconds of CPU a call (busy, not asleep: the judge times CPU),
    whatever the batch, with the guesses of ``net`` behind it; not packed for the kernels, so every call runs it."""

    def __init__(self, net, cost: float):
        super().__init__()
        self.inner, self.cost, self.robot, self.in_mean = net, cost, net.robot, net.in_mean

    def _spend(self) -> None:
        end = time.process_time() + self.cost
        while time.process_time() < end:
            pass

    def forward(self, T):
        self._spend()
        return self.inner(T)

    def hypotheses(self, T):
        self._spend()
        return self.inner.hypotheses(T)


@pytest.fixture
def one_thread():
    """One torch thread (the issue's protocol): two threads on a loaded two-core machine wait on each other."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_a_network_that_helps_batches_but_slows_single_poses_serves_batches_only(one_thread):
    robot = nik.load_robot("panda")
    net = _CostlyForward(nik.models.load_pretrained(robot), cost=1e-3)  # 1 ms a forward pass, whatever the batch
    solver = nik.IKSolver(robot, analytic=False)
    solver.net = net
    timed = judge.counts()["timed"]
    use = solver.network_use
    assert use["how"] == "measured" and use["pose"] is False and use["batch"] is True and use["wins"] >= 0.9
    assert use["pose_us"][0] > 1000 > use["pose_us"][1]  # the forward pass's millisecond is one pose's cost
    assert use["batch_us"][0] < use["batch_us"][1]  # spread over the batch, its guesses save more than it costs
    T = _targets(robot, 64, seed=9)
    one, many = solver.solve(T[0]), solver.solve(T)
    assert one.source == "multistart" and bool(one.success.all())
    assert many.source == "network" and bool(many.success.all())
    assert solver.plan(poses=1).net is None and solver.plan().net is net
    other = nik.IKSolver(robot, analytic=False)
    other.net = net
    assert other.network_use["pose"] is False and other.solve(T[0]).source == "multistart"
    assert judge.counts()["timed"] == timed + 1  # measured once per network in the process
    solver.network_use = {"pose": True, "batch": False}  # decided by hand
    assert solver.solve(T[0]).source == "network" and solver.solve(T).source == "multistart"
    assert solver.network_use["how"] == "asked"
    solver.network_use = None
    assert solver.solve(T[0]).source == "multistart" and solver.solve(T).source == "network"
    with pytest.raises(ValueError, match="network_use"):
        solver.network_use = {"pose": 1}


def test_network_use_says_why_without_a_network_and_for_the_raw_guess():
    robot = nik.load_robot("panda")
    assert nik.IKSolver(robot, checkpoint=None).network_use["how"] == "no network"
    raw = nik.IKSolver(robot, refine="none")
    assert raw.network_use["pose"] and raw.network_use["batch"] and raw.network_use["how"].startswith("asked")


def _no_probe(*args, **kwargs):
    raise AssertionError("a probe ran")


def test_a_file_that_records_the_decision_is_used_without_a_probe_until_its_weights_change(
    tmp_path, monkeypatch, one_thread
):
    from nik.learn.report import record_use
    from nik.nets.pair import save_pair

    robot = nik.load_robot("ur5")
    path = save_pair(nik.models.load_pretrained(robot), tmp_path / "mine.safetensors")
    rec = record_use(path)
    meta = json.loads(path.with_suffix(".json").read_text())
    assert meta["network_use"] == rec and rec["robot_hash"] == robot.arm_hash and rec["wins"] >= 0.9
    decided = rec["against"]["multistart"]
    assert isinstance(decided["pose"], bool) and isinstance(decided["batch"], bool)
    assert all(x > 0 for x in decided["pose_us"] + decided["batch_us"])
    assert decided["pose"] == (decided["pose_us"][0] <= decided["pose_us"][1])
    for probe in ("measure", "verdict"):
        monkeypatch.setattr(judge, probe, _no_probe)
    solver = nik.IKSolver(robot, checkpoint=str(path), analytic=False)
    use = solver.network_use
    assert use["how"] == "record" and (use["pose"], use["batch"]) == (decided["pose"], decided["batch"])
    T = _targets(robot, 40, seed=4)
    one, many = solver.solve(T[0]), solver.solve(T)
    assert one.source == ("network" if decided["pose"] else "multistart") and bool(one.success.all())
    assert many.source == ("network" if decided["batch"] else "multistart") and bool(many.success.all())
    net = solver.net
    assert judge.use(net, robot, nik.IKSolver, arm_frame=True).how == "record"  # made for the bare arm
    with torch.no_grad():  # trained further in place: the record no longer speaks for it
        next(net.parameters()).mul_(1.0)
    with pytest.raises(AssertionError, match="a probe ran"):
        judge.use(net, robot, nik.IKSolver, arm_frame=True)


def test_a_record_made_while_the_kernels_still_compile_is_timed_not_provisional(tmp_path, monkeypatch, one_thread):
    """``nik train`` on a machine whose kernels are not compiled yet: the record it writes must hold real times (a
    provisional "serves both" would make one pose slower for good)."""
    from nik.learn.report import record_use
    from nik.nets.pair import save_pair

    monkeypatch.setattr(judge, "_deferring", lambda: True)  # what a cold kernel cache says
    robot = nik.load_robot("ur5")
    path = save_pair(nik.models.load_pretrained(robot), tmp_path / "cold.safetensors")
    decided = record_use(path)["against"]["multistart"]
    assert all(x is not None and x > 0 for x in decided["pose_us"] + decided["batch_us"])
    assert decided["pose"] == (decided["pose_us"][0] <= decided["pose_us"][1])


def test_a_checkpoint_without_a_record_is_timed_once_on_first_use_and_kept_for_the_process(tmp_path, one_thread):
    """Issue 50 item 11: a network of train.py's kind (a Lightning-format checkpoint: no JSON, no record) is timed
    on its first call and serves each call type only where it paid, for every solver of the process."""
    robot = nik.load_robot("ur5")
    path = save_checkpoint(nik.models.load_pretrained(robot), tmp_path / "plain.ckpt")
    timed = judge.counts()["timed"]
    first = nik.IKSolver(robot, checkpoint=str(path), analytic=False)
    use = first.network_use
    assert use["how"] == "measured" and judge.counts()["timed"] == timed + 1
    for key in ("pose", "batch"):
        w, wo = use[f"{key}_us"]
        assert use[key] == (w <= wo) and w > 0 and wo > 0
    T = _targets(robot, 30, seed=6)
    assert first.solve(T[0]).source == ("network" if use["pose"] else "multistart")
    assert first.solve(T).source == ("network" if use["batch"] else "multistart")
    again = nik.IKSolver(robot, checkpoint=str(path), analytic=False)
    assert again.net is first.net and again.network_use == use and judge.counts()["timed"] == timed + 1
