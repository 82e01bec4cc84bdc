"""nik.evaluate: the URDF export, the table header and the cumulative error plot."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.testing import assert_close

import nik
from nik.evaluate import EvalReport, line_style, markdown_table, plot_errors, robot_to_urdf, write_report
from nik.robots.urdf import build_pk_chain


def test_robot_to_urdf_writes_prismatic_joints_that_pytorch_kinematics_follows():
    robot = nik.load_robot("stanford")
    text, end = robot_to_urdf(robot)
    assert text.count('type="prismatic"') == 1
    chain = build_pk_chain(text, end).to(dtype=torch.float64)
    q = robot.sample(50, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    # pytorch-kinematics parses rpy through float32: about 1e-9 m here
    assert_close(chain.forward_kinematics(q).get_matrix(), robot.fk(q), atol=1e-7, rtol=0)


@pytest.mark.parametrize(("threads", "text"), [(1, "CPU (1 thread),"), (2, "CPU (2 threads),")])
def test_table_header_says_thread_or_threads(threads, text):
    header = markdown_table(EvalReport(robot="puma560", data="data/x", n=3, threads=threads)).splitlines()[0]
    assert text in header


def test_ten_lines_have_pairwise_different_styles():
    colours = [f"C{k}" for k in range(10)]
    styles = [line_style(i, 10, colours) for i in range(10)]
    for key in ("color", "marker", "markevery"):
        assert len({str(s[key]) for s in styles}) == 10, key
    assert len({s["linestyle"] for s in styles}) == 4


def test_write_report_writes_table_json_and_a_png_plot(tmp_path):
    rng = np.random.default_rng(0)
    report = EvalReport(robot="puma560", data="data/x", n=50, threads=1)
    report.errors = {
        "a": (10 ** rng.uniform(-4, 1, 50), 10 ** rng.uniform(-4, 1, 50)),
        "b (same as a)": (10 ** rng.uniform(-4, 1, 50), 10 ** rng.uniform(-4, 1, 50)),
        "exact": (np.zeros(50), np.zeros(50)),  # below the 1e-12 floor: drawn at the floor, not lost
    }
    paths = write_report(report, tmp_path / "eval")
    png = paths["plot"].read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert paths["markdown"].read_text().startswith("Robot `puma560`")
    assert sorted(p.name for p in (tmp_path / "eval").iterdir()) == ["errors.png", "evaluation.json", "evaluation.md"]
    assert plot_errors(report, tmp_path / "again.png").stat().st_size > 10_000


# ---- URDF arms: the peer row is built, or skipped with a note; rows are never lost ---------------------------------
# A 6R arm with rpy origins that float32 parsing leaves slightly non-orthonormal (as every URDF loaded through
# pytorch-kinematics is): robot_to_urdf used to find "no roll-pitch-yaw form" for such arms.
ODD_ARM = """<?xml version="1.0" encoding="utf-8"?>
<robot name="odd6">
  <link name="base"/>{links}{joints}
</robot>
"""


def _odd_arm_urdf() -> str:
    rpys = ["0 0 0", "1.3 0.2 -0.4", "-0.7 0.1 0.9", "0.3 -1.1 0.5", "1.9 0.4 -2.2", "-0.6 0.8 0.35"]
    xyzs = ["0 0 0.3", "0.05 0 0.1", "0.4 0 0", "0.1 0.05 0.3", "0 0.02 0.1", "0 0 0.08"]
    links = "".join(f'\n  <link name="l{i + 1}"/>' for i in range(6))
    joints = "".join(
        f'\n  <joint name="j{i + 1}" type="revolute"><parent link="{"base" if i == 0 else f"l{i}"}"/>'
        f'<child link="l{i + 1}"/><origin xyz="{xyzs[i]}" rpy="{rpys[i]}"/><axis xyz="0 0 1"/>'
        f'<limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>'
        for i in range(6)
    )
    return ODD_ARM.format(links=links, joints=joints)


@pytest.fixture(scope="module")
def odd_arm(tmp_path_factory):
    path = tmp_path_factory.mktemp("odd") / "odd6.urdf"
    path.write_text(_odd_arm_urdf())
    return nik.load_robot(path)


@pytest.fixture(scope="module")
def odd_data(odd_arm, tmp_path_factory):
    from nik.data import generate_dataset

    return generate_dataset(odd_arm, 60, tmp_path_factory.mktemp("odd_data") / "d", seed=0, progress=False)


def test_robot_to_urdf_handles_a_urdf_arm_with_float32_origins(odd_arm):
    R = odd_arm.G[:, :3, :3]
    assert float((R.transpose(-1, -2) @ R - torch.eye(3, dtype=R.dtype)).abs().max()) > 1e-12  # the hard case
    text, end = robot_to_urdf(odd_arm)
    chain = build_pk_chain(text, end).to(dtype=torch.float64)
    q = odd_arm.sample(50, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    assert_close(chain.forward_kinematics(q).get_matrix(), odd_arm.fk(q), atol=1e-6, rtol=0)


def _short_eval(robot, data, **kw):
    from nik.evaluate import evaluate

    return evaluate(robot, data=data, n=4, checkpoint=None, swarm="lm", seed=0, **kw)


def test_evaluate_on_a_urdf_arm_has_the_peer_row(odd_arm, odd_data):
    report = _short_eval(odd_arm, odd_data)
    assert "pytorch-kinematics" in [r.method for r in report.rows]


def test_a_peer_row_that_cannot_be_built_is_skipped_with_a_one_line_note(odd_arm, odd_data, monkeypatch):
    import nik.evaluate as ev

    # a roll-pitch-yaw conversion that loses the roll: no transform round-trips, robot_to_urdf gives up
    lossy = ev.matrix_to_rpy
    monkeypatch.setattr(ev, "matrix_to_rpy", lambda R: lossy(R) * torch.tensor([0.0, 1.0, 1.0], dtype=R.dtype))
    with pytest.raises(RuntimeError, match="no roll-pitch-yaw form"):
        robot_to_urdf(odd_arm)
    seen = []
    report = _short_eval(
        odd_arm, odd_data, hooks=ev.EvalHooks(on_row=lambda rep: seen.append([r.method for r in rep.rows]))
    )
    methods = [r.method for r in report.rows]
    assert "pytorch-kinematics" not in methods and len(methods) >= 1
    assert seen[-1] == methods  # told after every row
    skipped = [n for n in report.notes if n.startswith("pytorch-kinematics row skipped")]
    assert len(skipped) == 1 and "\n" not in skipped[0] and "roll-pitch-yaw" in skipped[0]


def test_rows_computed_before_a_failure_are_written(monkeypatch, tmp_path):
    import nik.evaluate as ev
    from nik.cli import main

    data = tmp_path / "puma"
    assert main(["generate", "--robot", "puma560", "--n", "60", "--out", str(data), "--no-progress"]) == 0
    calls = {"n": 0}
    real_row = ev._row

    def failing_second_row(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("boom in the second row")
        return real_row(*args, **kw)

    monkeypatch.setattr(ev, "_row", failing_second_row)
    out = tmp_path / "eval"
    argv = ["evaluate", "--robot", "puma560", "--data", str(data), "--n", "4", "--out", str(out)]
    with pytest.raises(RuntimeError, match="boom"):
        main([*argv, "--swarm", "lm", "--no-pk"])
    table = (out / "evaluation.md").read_text()
    assert calls["n"] == 2 and table.count("\n| ") == 2  # the header and the one row made before the failure


# ---- rows for what users run: the default pipeline, LM multistart, the shipped network (--checkpoint auto) -----------
@pytest.fixture(scope="module")
def kuka_data(tmp_path_factory):  # kuka_kr: an arm with a closed form and a shipped network
    from nik.data import generate_dataset

    return generate_dataset("kuka_kr", 80, tmp_path_factory.mktemp("kuka") / "d", seed=2, progress=False)


def _methods(out):
    import json

    doc = json.loads((out / "evaluation.json").read_text())
    return [r["method"] for r in doc["rows"]], doc


def test_cli_checkpoint_auto_evaluates_the_shipped_network_and_the_default_pipeline(kuka_data, tmp_path, capsys):
    from nik.cli import main

    out = tmp_path / "auto"
    argv = ["evaluate", "--robot", "kuka_kr", "--data", str(kuka_data), "--n", "4", "--no-pk", "--swarm", "lm"]
    assert main([*argv, "--checkpoint", "auto", "--refinements", "lm", "--out", str(out)]) == 0, capsys.readouterr()
    methods, doc = _methods(out)
    for row in ("default pipeline", "LM multistart, no network", "network", "network + lm", "analytic (closed form)"):
        assert row in methods
    assert "shipped" in (out / "evaluation.md").read_text()
    rows = {r["method"]: r for r in doc["rows"]}
    assert rows["default pipeline"]["success_01mm_01deg"] == 1.0  # closed form + LM on a spherical-wrist arm
    # without a network: the same table less the network rows, and it says why
    out = tmp_path / "none"
    assert main([*argv, "--checkpoint", "none", "--out", str(out)]) == 0
    methods, doc = _methods(out)
    assert "default pipeline" in methods and "LM multistart, no network" in methods
    assert not any(m.startswith("network") for m in methods)
    assert any("checkpoint none" in n for n in doc["notes"])
    capsys.readouterr()


def test_default_pipeline_row_is_what_iksolver_robot_returns(odd_arm, odd_data):
    from nik.data import load_dataset
    from nik.evaluate import evaluate

    report = evaluate(odd_arm, data=odd_data, n=5, checkpoint="auto", include_pk=False, swarm="lm", seed=3)
    T = load_dataset(odd_data).split("test").pose[:5].to(torch.float64)
    res = nik.IKSolver(odd_arm).solve(T, seed=3)  # its own default tolerances, as evaluate uses
    pos_mm, _ = report.errors["default pipeline"]
    assert_close(torch.as_tensor(pos_mm), res.pos_err * 1e3, atol=1e-9, rtol=0)
    assert any("no network shipped" in n for n in report.notes)  # auto on an arm nik ships nothing for


def test_no_two_rows_of_errors_png_share_colour_and_marker(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(1)
    report = EvalReport(robot="puma560", data="data/x", n=20, threads=1)
    # 14 rows: more than the full table of an arm with a closed form and a network (12), more than 10 colours
    report.errors = {f"row {k}": (10 ** rng.uniform(-4, 1, 20), 10 ** rng.uniform(-4, 1, 20)) for k in range(14)}
    figures = []
    real_close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), real_close(fig)))
    plot_errors(report, tmp_path / "errors.png")
    (fig,) = figures
    for ax in fig.axes:
        drawn = [ln for ln in ax.get_lines() if ln.get_label() in report.errors]
        assert len(drawn) == 14
        looks = {(ln.get_color(), ln.get_marker()) for ln in drawn}
        assert len(looks) == 14, sorted(looks)


# ---- each row says the guess that served, "no network" rows use none, every row is timed after a warm-up ----------
@pytest.fixture(scope="module")
def panda_data(tmp_path_factory):  # panda: no closed form, a shipped network
    from nik.data import generate_dataset

    return generate_dataset("panda", 40, tmp_path_factory.mktemp("panda") / "d", seed=4, progress=False)


def test_rows_say_the_guess_that_served_and_rows_with_different_guesses_differ(panda_data):
    from nik.data import load_dataset
    from nik.evaluate import evaluate
    from nik.nets.multi import MultiHypIKNet
    from nik.nets.pair import save_pair
    from nik.nets.registry import install, user_dir

    robot = nik.load_robot("panda")
    torch.manual_seed(0)  # an installed network for panda (it replaces the shipped one): "no network" rows ignore it
    tiny = MultiHypIKNet(robot, hidden=[8], heads=2).eval()
    installed = install(save_pair(tiny, user_dir().parent / "export" / "tiny.safetensors"))
    n = 4  # the whole test split
    report = evaluate(
        robot, data=panda_data, n=n, checkpoint="auto", refinements=("ipso",), swarm="ipso", include_pk=False, seed=1
    )
    # the same swarm from another guess: other answers (they were one row twice when the swarm picked the network up)
    assert not np.array_equal(report.errors["network + ipso"][0], report.errors["uniform-init ipso"][0])
    assert f"installed network for panda's definition hash, {installed}" in report.network
    rows = {r.method: r for r in report.rows}
    guess = {m: r.note.split(";")[0] for m, r in rows.items()}
    T = load_dataset(panda_data).split("test").pose[:n].to(torch.float64)
    assert guess["default pipeline"] == f"guess {nik.IKSolver(robot).solve(T, seed=1).source}"
    assert guess["network"] == guess["network + ipso"] == "guess network"
    for method in ("LM multistart, no network", "uniform-init ipso"):
        assert guess[method] == "guess multistart", method
    # the raw network row is the installed network's guess, given by path here
    raw = nik.IKSolver(robot, checkpoint=installed, refine="none").solve(T, seed=1)
    assert_close(torch.as_tensor(report.errors["network"][0]), raw.pos_err * 1e3, atol=1e-9, rtol=0)


def test_every_row_is_timed_after_a_warm_up_call_of_the_same_solver(odd_arm, odd_data, monkeypatch):
    import nik.evaluate as ev
    from nik.solver import IKSolver

    calls = []
    real_solve = IKSolver.solve

    def recording_solve(self, T, *args, **kw):
        calls.append((id(self), int(T.shape[0])))
        return real_solve(self, T, *args, **kw)

    monkeypatch.setattr(IKSolver, "solve", recording_solve)
    monkeypatch.setattr(ev, "WARMUP_TARGETS", 2)  # fewer than the test poses: the warm-up call is told apart
    n = 6
    report = ev.evaluate(odd_arm, data=odd_data, n=n, checkpoint=None, swarm="pso", include_pk=False, seed=0)
    assert len(report.rows) == 3  # default, LM multistart, uniform-init pso
    # each row: a warm-up call on the first 2 poses, then the timed call on all n, by the same solver
    assert [b for _, b in calls] == [2, n] * 3
    assert all(calls[2 * k][0] == calls[2 * k + 1][0] for k in range(3))


# ---- no row carries the kernels' background compile; a network the solver set aside is said so (issue 50) ----------
def test_rows_are_timed_after_the_kernels_background_compile_has_ended(odd_arm, odd_data, monkeypatch):
    import time

    import nik.evaluate as ev
    from nik.kernels import background
    from nik.solver import IKSolver

    class ColdKernel:  # stands for a nik kernel whose first compile runs in a background thread (a cold cache)
        def typeof_pyval(self, value):
            return type(value).__name__

        def compile(self, signature):
            time.sleep(1.0)

    started = []
    real_solve = IKSolver.solve

    def first_call_starts_the_compile(self, T, *args, **kw):
        if not started:  # the first call of a cold process: answered by torch, the compile goes on behind it
            started.append(background.compile_later(ColdKernel(), (0,)))
        return real_solve(self, T, *args, **kw)

    busy_when_timed = []
    real_timed = ev._timed

    def timed(fn, device=None):
        busy_when_timed.append(background.BUSY)
        return real_timed(fn, device)

    monkeypatch.setattr(IKSolver, "solve", first_call_starts_the_compile)
    monkeypatch.setattr(ev, "_timed", timed)
    report = ev.evaluate(odd_arm, data=odd_data, n=6, checkpoint=None, swarm="lm", include_pk=False, seed=0)
    assert started and busy_when_timed and not any(busy_when_timed), busy_when_timed
    (note,) = [n for n in report.notes if n.startswith("every row is timed after a warm-up call")]
    waited = float(note.split("this run waited ")[1].split(" s")[0])
    assert 0.5 <= waited < 60, note
    assert "no row carries one-time costs" in markdown_table(report)


def test_a_network_the_solver_set_aside_is_said_in_its_row_with_what_guessed_instead(tmp_path):
    from nik.data import generate_dataset
    from nik.evaluate import evaluate
    from nik.nets import IKNet, save_checkpoint

    robot = nik.load_robot("kuka_kr")  # a closed form: it guesses where the network is set aside
    data = generate_dataset(robot, 60, tmp_path / "kuka", seed=2, progress=False)
    torch.manual_seed(0)
    ckpt = save_checkpoint(IKNet(robot, hidden=[8]).eval(), tmp_path / "untrained.ckpt")  # guesses at random
    with pytest.warns(UserWarning, match="no better than uniform starts"):
        report = evaluate(
            robot, data=data, checkpoint=ckpt, n=6, refinements=("lm",), swarm="lm", include_pk=False, seed=0
        )
    rows = {r.method: r for r in report.rows}
    restarts = rows["network + lm + LM restarts"].note
    assert restarts.startswith("guess analytic; network set aside by the solver: no better a start than uniform")
    assert "the closed form guessed instead" in restarts and "no closed form" not in restarts
    # the rows that ask for the network's own guess keep it, and say nothing of setting it aside
    for method in ("network", "network + lm"):
        assert rows[method].note.startswith("guess network") and "set aside" not in rows[method].note
    assert "set aside" in markdown_table(report)


def test_evaluate_reads_another_split_and_tells_its_hooks(odd_arm, tmp_path):
    """``evaluate(data=(directory, split), hooks=EvalHooks(progress, on_row))``: the poses of that split (the val
    split here, twice the test split's size), a progress message before each row and the report after each row; at
    most 12 parameters (issue 46, item 4)."""
    import inspect

    from nik.data import Sampling, generate_dataset, load_dataset
    from nik.evaluate import EvalHooks, evaluate

    data = generate_dataset(
        odd_arm, 40, tmp_path / "d", seed=1, progress=False, fsync=False, sampling=Sampling(val_fraction=0.2)
    )
    said, rows = [], []
    hooks = EvalHooks(progress=said.append, on_row=lambda rep: rows.append(len(rep.rows)))
    report = evaluate(odd_arm, data=(data, "val"), n=100, checkpoint=None, swarm="lm", include_pk=False, hooks=hooks)
    assert report.n == len(load_dataset(data).split("val")) == 8 != len(load_dataset(data).split("test"))
    assert rows == list(range(1, len(report.rows) + 1)) and len(said) == len(report.rows)
    with pytest.raises(ValueError, match="data: expected a dataset directory"):
        evaluate(odd_arm, data=(data, "val", 3))
    assert len(inspect.signature(evaluate).parameters) <= 12
