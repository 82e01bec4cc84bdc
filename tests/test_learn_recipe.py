"""nik train (nik.learn.recipe, nik.learn.stream): from a robot file to an exported, checked network."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch
import yaml

import nik
from nik.cli import main
from nik.errors import CheckpointError
from nik.learn.stream import FKStreamDataModule

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*treespec"),
    pytest.mark.filterwarnings("ignore:.*does not have many workers"),
    pytest.mark.filterwarnings("ignore:.*IterableDataset"),
]

#: A small 4-joint arm (no IK branch labels: the multi-head kind) in the YAML format of interface.md.
ARM = {
    "name": "test_arm",
    "convention": "dh",
    "unit": "mm",
    "angles": "deg",
    "joints": [
        {"alpha": -90, "a": 0, "d": 300, "limits": [-170, 170]},
        {"alpha": 0, "a": 250, "d": 0, "limits": [-120, 120]},
        {"alpha": 90, "a": 50, "d": 0, "limits": [-120, 120]},
        {"alpha": 0, "a": 0, "d": 200, "limits": [-170, 170]},
    ],
}
#: Tiny and fast: a few seconds of training inside a one-minute budget.
TINY = ["--minutes", "1", "--max-steps", "30", "--hidden", "16", "16", "--batch-size", "128"]
TINY += ["--steps-per-epoch", "10", "--val-n", "200", "--threads", "1"]


def _arm(tmp_path: Path, name: str = "test_arm") -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({**ARM, "name": name}))
    return path


def test_acceptance_nik_train_exports_a_network_that_loads_by_path_under_another_name_and_refuses_a_flipped_byte(
    tmp_path, capsys, monkeypatch
):
    arm = _arm(tmp_path)
    out = tmp_path / "export" / "my_arm.safetensors"
    args = ["train", str(arm), *TINY, "--eval-batch", "20", "--eval-one", "2", "--runs", str(tmp_path / "runs")]
    assert main([*args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out}" in printed and "multihead" in printed
    # with the network: its guess, or uniform starts where nik.ik.judge sets a network of 30 steps aside
    expected_rows = ("raw network, best of 8", "with the network (guess: ", "no network (guess: multistart)")
    for expected in (*expected_rows, "batch of 20", "one pose (2 poses)"):
        assert expected in printed
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["training"]["command"] == "nik " + " ".join([*args, "--out", str(out)])
    assert meta["training"]["data"]["source"] == "fk_stream" and meta["training"]["steps"] == 30
    from nik.learn.recipe import data_sha256

    assert meta["training"]["data_sha256"] == data_sha256(meta["training"]["data"], meta["robot_hash"])
    assert "run_dir" not in meta["training"]  # a path of this machine: the command says where the run went
    assert meta["net"]["kind"] == "multihead" and meta["robot"] == "test_arm"
    run = tmp_path / "runs" / "test_arm"
    assert (run / "last.ckpt").is_file() and (run / "history.csv").is_file() and (run / "report.txt").is_file()
    assert (run / "curve.png").read_bytes()[:4] == b"\x89PNG"

    # the same arm under another name, loaded by path: it gets the network, and the network solves
    other = nik.load_robot(_arm(tmp_path, "renamed_arm"))
    assert other.definition_hash == nik.load_robot(arm).definition_hash
    solver = nik.IKSolver(other, checkpoint=str(out))
    assert solver.has_network and solver.net.robot.name == "renamed_arm"  # (30 steps: nik.ik.judge may set it aside)
    T = other.fk(other.sample(8, generator=torch.Generator().manual_seed(3), dtype=torch.float64))
    plan = replace(solver.plan(), source="network", net=solver.net)  # the network itself: a plan made by hand
    res = solver.solve(T, plan=plan)
    assert bool(res.success.all()) and res.source == "network"

    # a flipped byte is refused, by the library and by the CLI (exit 2, one line)
    data = bytearray(out.read_bytes())
    data[len(data) // 2] ^= 0x01
    out.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="SHA-256"):
        nik.IKSolver(other, checkpoint=str(out))
    pose = ["--pose", "0.3", "0.3", "0.3", "1", "0", "0", "0"]
    rc = main(["solve", "--robot", str(tmp_path / "renamed_arm.yaml"), "--checkpoint", str(out), *pose])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "SHA-256" in err


def test_install_makes_auto_pick_the_network_for_the_arm_under_any_name(tmp_path, capsys):
    arm = _arm(tmp_path)
    assert nik.IKSolver(arm).initial_source == "multistart"
    args = ["train", str(arm), *TINY, "--no-eval", "--install", "--runs", str(tmp_path / "runs")]
    assert main(args) == 0
    out, err = capsys.readouterr()
    assert f"installed as {nik.nets.registry.user_dir() / 'test_arm.safetensors'}" in out
    both = out + err
    assert both.count("installed as") == 1 and both.count(f'nik.IKSolver("{arm.resolve()}")') == 1  # said once
    # what it says to run is true: the YAML by its absolute path (IKSolver('test_arm') is no built-in)
    assert out.rstrip().endswith(f'nik.IKSolver("{arm.resolve()}")') and "now uses it" not in out
    other = nik.load_robot(_arm(tmp_path, "same_arm_elsewhere"))
    solver = nik.IKSolver(other)
    assert solver.has_network and solver.net.robot.name == "same_arm_elsewhere"  # (nik.ik.judge may set it aside)
    assert (nik.nets.registry.user_dir() / "test_arm.safetensors").is_file()


def test_a_run_resumes_where_it_stopped_and_records_both_commands(tmp_path, capsys):
    arm = _arm(tmp_path)
    base = ["train", str(arm), *TINY[:2], "--hidden", "16", "--batch-size", "64", "--steps-per-epoch", "10"]
    base += ["--val-n", "100", "--no-eval", "--runs", str(tmp_path / "runs")]
    assert main([*base, "--max-steps", "20"]) == 0
    with pytest.raises(FileExistsError, match="--resume continues it"):
        from nik.learn.recipe import TrainCfg, train_network

        train_network(TrainCfg(robot=arm, runs=str(tmp_path / "runs"), hidden=(16,), evaluate=False))
    assert main([*base, "--max-steps", "40", "--resume"]) == 0
    meta = json.loads((tmp_path / "runs" / "test_arm" / "test_arm.json").read_text())
    assert meta["training"]["steps"] == 40
    assert meta["training"]["counters"]["sample_evals"] == 40 * 64  # 20 + 20 steps, nothing repeated
    assert meta["training"]["resumed_from_commands"][0].endswith("--max-steps 20")
    history = (tmp_path / "runs" / "test_arm" / "history.csv").read_text().splitlines()
    assert len(history) == 1 + 4  # a validation every 10 steps, both parts


def test_bad_options_are_one_line_errors(tmp_path, capsys):
    arm = _arm(tmp_path)
    runs = ["--runs", str(tmp_path / "runs")]
    assert main(["train", str(arm), "--resume", *runs]) == 2
    assert "no run to resume" in capsys.readouterr().err
    assert main(["train", str(arm), "--kind", "branch_heads", *runs]) == 2
    assert "no IK branch labels" in capsys.readouterr().err
    assert main(["train", str(arm), "--out", str(tmp_path / "x.pt"), *runs]) == 2
    assert ".safetensors" in capsys.readouterr().err
    from nik.data import generate_dataset

    data = generate_dataset("puma560", 300, tmp_path / "data", seed=0, progress=False)
    assert main(["train", str(arm), "--data", str(data), *runs]) == 2
    assert "was made for robot 'puma560'" in capsys.readouterr().err


def test_a_branch_labelled_arm_gets_a_one_pass_branch_heads_network_and_trains_on_a_dataset(tmp_path, capsys):
    from nik.data import generate_dataset

    data = generate_dataset("puma560", 2000, tmp_path / "data", seed=0, progress=False)
    out = tmp_path / "p.safetensors"
    args = ["train", "puma560", *TINY, "--data", str(data), "--no-eval", "--runs", str(tmp_path / "runs")]
    assert main([*args, "--out", str(out)]) == 0
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["net"]["kind"] == "branch_heads"
    assert meta["training"]["data"]["source"] == "dataset" and meta["training"]["data"]["path"] == str(data)
    assert "branches are labelled" in meta["training"]["kind_choice"]


def test_stream_gives_fresh_seeded_batches_whose_poses_are_the_fk_of_their_joints():
    robot = nik.load_robot("panda")
    dm = FKStreamDataModule(robot, batch_size=32, steps_per_epoch=3, val_n=50, norm_n=100, seed=5)
    dm.setup("fit")
    batches = list(dm.train_dataloader())
    assert len(batches) == 3 and all(T.shape == (32, 4, 4) and q.shape == (32, 7) for T, q in batches)
    assert not torch.equal(batches[0][1], batches[1][1])  # fresh samples at every step
    for T, q in batches:
        assert bool(robot.within_limits(q.double()).all())
        torch.testing.assert_close(T.double(), robot.fk(q.double()), atol=2e-6, rtol=0)
    again = FKStreamDataModule(robot, batch_size=32, steps_per_epoch=3, val_n=50, norm_n=100, seed=5)
    again.setup("fit")
    assert torch.equal(next(iter(again.train_dataloader()))[1], batches[0][1])  # seeded
    assert torch.equal(again.val_data[1], dm.val_data[1]) and dm.describe()["source"] == "fk_stream"


def test_nik_train_help_does_not_load_lightning():
    code = (
        "import sys, contextlib, io\nfrom nik.cli import main\nwith contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n        main(['train', '--help'])\n    except SystemExit:\n        pass\n"
        "print('lightning' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.stdout.strip().splitlines()[-1] == "False", done.stderr[-2000:]


def test_train_without_install_says_how_to_install_and_prints_notes_as_one_line(tmp_path, capsys):
    urdf = ROOT / "configs" / "robots" / "urdf" / "panda.urdf"  # its default tool link leaves the fingers out
    args = ["train", str(urdf), *TINY[:2], "--max-steps", "2", "--hidden", "8", "--no-eval"]
    assert main([*args, "--val-n", "50", "--threads", "1", "--runs", str(tmp_path / "runs")]) == 0
    out, err = capsys.readouterr()
    pair = tmp_path / "runs" / "panda" / "panda.safetensors"
    assert f"not installed: `nik networks install {pair}`" in out
    assert f'nik.IKSolver(nik.load_robot("{urdf}", end_link="panda_hand_tcp"), checkpoint="{pair}")' in out
    note = [line for line in err.splitlines() if "default tool link" in line]
    assert len(note) == 1 and note[0].startswith("nik: note: panda.urdf: default tool link 'panda_hand_tcp'")
    assert "Warning" not in err and "load_urdf(" not in err  # no category, no source line


def test_nik_train_records_per_call_type_what_pays_and_its_report_says_it(tmp_path, capsys, monkeypatch):
    """Issue 48 item 1: the exported JSON carries the decision and its figures (no probe when loaded); the report
    gives, for single poses and for batches, the time with and without the network and what the solver uses."""
    from nik.ik import judge

    arm = _arm(tmp_path)
    out = tmp_path / "mine.safetensors"
    args = ["train", str(arm), *TINY, "--eval-batch", "20", "--eval-one", "2", "--runs", str(tmp_path / "runs")]
    assert main([*args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    rec = json.loads(out.with_suffix(".json").read_text())["network_use"]
    robot = nik.load_robot(arm)
    assert rec["robot_hash"] == robot.definition_hash and 0.0 <= rec["wins"] <= 1.0
    decided = rec["against"]["multistart"]
    lines = {}
    for call, key in (("single poses:", "pose"), ("batches:", "batch")):
        (line,) = [ln for ln in printed.splitlines() if ln.strip().startswith(call)]
        lines[key] = line
        w, wo = decided[f"{key}_us"]
        assert w > 0 and wo > 0 and f"{w:.1f} us a pose with the network, {wo:.1f} us without" in line
        assert ("the network" if decided[key] else "no network") == line.split(":", 1)[1].split("(")[0].strip()
        assert decided[key] == (rec["wins"] >= judge.MIN_WINS and w <= wo)
    assert "what IKSolver(robot, checkpoint=PATH) uses, per call type" in printed
    assert (tmp_path / "runs" / "test_arm" / "report.txt").read_text().count(lines["pose"].strip()) == 1
    for probe in ("measure", "verdict"):  # the file decides: nothing is measured again
        monkeypatch.setattr(judge, probe, lambda *a, **k: (_ for _ in ()).throw(AssertionError("a probe ran")))
    solver = nik.IKSolver(robot, checkpoint=str(out))
    use = solver.network_use
    assert use["how"] == "record" and (use["pose"], use["batch"]) == (decided["pose"], decided["batch"])
    T = robot.fk(robot.sample(6, generator=torch.Generator().manual_seed(5), dtype=torch.float64))
    with pytest.warns(UserWarning) if rec["wins"] < judge.MIN_WINS else _no_warning():
        one = solver.solve(T[:1])
    assert one.source == ("network" if decided["pose"] else "multistart") and bool(one.success.all())
    assert solver.solve(T).source == ("network" if decided["batch"] else "multistart")


def _no_warning():
    import contextlib
    import warnings

    @contextlib.contextmanager
    def ctx():
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            yield

    return ctx()


def test_where_the_network_slows_single_poses_a_small_one_is_trained_beside_it_and_installed_with_it(
    tmp_path, capsys, monkeypatch
):
    """Issue 48 item 1: ``nik train`` by default produces what pays for both call types: where the main network's
    record says single poses are faster without it, a single-pose network is trained for the rest of the budget,
    linked from the main JSON, reported per call type, installed with it, and used by ``IKSolver(robot)``."""
    from nik.nets import registry
    from nik.nets.pair import load_pair

    monkeypatch.setenv("NIK_HOME", str(tmp_path / "home"))
    arm = _arm(tmp_path)
    out = tmp_path / "mine.safetensors"
    args = ["train", str(arm), *TINY, "--eval-batch", "20", "--eval-one", "2", "--runs", str(tmp_path / "runs")]
    assert main([*args, "--out", str(out), "--install"]) == 0
    printed = capsys.readouterr().out
    meta = json.loads(out.with_suffix(".json").read_text())
    one = tmp_path / "mine_one.safetensors"
    if meta["network_use"]["against"]["multistart"]["pose"]:  # the main network pays for single poses: none needed
        assert "single_pose_network" not in meta and not one.exists()
        return
    assert meta["single_pose_network"] == one.name
    one_meta = json.loads(one.with_suffix(".json").read_text())
    assert one_meta["role"] == "single_pose" and one_meta["net"]["hidden"] == [64, 64]
    assert (tmp_path / "runs" / "test_arm_one" / "last.ckpt").is_file()
    rec = one_meta["network_use"]["against"]["multistart"]
    for call, key in (("single poses:", "pose"), ("batches:", "batch")):
        w, wo = rec[f"{key}_us"]
        (line,) = [ln for ln in printed.splitlines() if ln.strip().startswith(f"[mine_one.safetensors] {call}")]
        assert f"{w:.1f} us a pose with the network, {wo:.1f} us without" in line
    installed = registry.user_dir() / "test_arm_one.safetensors"
    assert installed.is_file() and load_pair(installed).n_params == load_pair(one).n_params
    solver = nik.IKSolver(nik.load_robot(arm))
    assert solver.net is not None and solver.single_pose_net is not None
    assert solver.single_pose_net.n_params == load_pair(one).n_params
    use = solver.network_use
    assert use["how"] == "record" and (use["pose"], use["batch"]) == (rec["pose"], rec["batch"])
    # the main file by path: the main network alone, as its own record says
    by_path = nik.IKSolver(nik.load_robot(arm), checkpoint=str(out))
    assert by_path.single_pose_net is None
    assert by_path.network_use["pose"] == meta["network_use"]["against"]["multistart"]["pose"]


def test_a_zero_single_pose_share_trains_the_main_network_alone_on_the_whole_budget(tmp_path, capsys):
    arm = _arm(tmp_path)
    out = tmp_path / "alone.safetensors"
    args = ["train", str(arm), *TINY, "--no-eval", "--runs", str(tmp_path / "runs"), "--single-pose-share", "0"]
    assert main([*args, "--out", str(out)]) == 0
    meta = json.loads(out.with_suffix(".json").read_text())
    assert "single_pose_network" not in meta and not (tmp_path / "alone_one.safetensors").exists()
    assert meta["training"]["minutes_budget"] == 1.0
    assert main([*args[:-1], "1.5", "--out", str(tmp_path / "bad.safetensors")]) == 2
    assert "--single-pose-share must be in [0, 1), got 1.5" in capsys.readouterr().err
