"""``nik generate`` and ``nik data info``: outputs, one-line errors, exit codes."""

import subprocess
import sys
from pathlib import Path

import pytest
import torch

from nik.cli import main
from nik.data import load_dataset

REPO = Path(__file__).resolve().parents[1]


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_generate_then_info(tmp_path, capsys):
    out = tmp_path / "kuka"
    code, stdout, err = run(
        capsys, "generate", "--robot", "kuka_kr", "--n", "2000", "--out", str(out), "--seed", "3", "--no-progress"
    )
    assert code == 0, err
    assert "wrote 2000 samples" in stdout
    ds = load_dataset(out, robot="kuka_kr")
    assert len(ds) == 2000 and ds.meta["seed"] == 3

    code, stdout, err = run(capsys, "data", "info", str(out))
    assert code == 0, err
    assert "kuka_kr" in stdout and "min (deg)" in stdout and "extent (mm)" in stdout
    assert "train 1,600, val 200, test 200" in stdout
    lines = [ln for ln in stdout.splitlines() if ln.startswith("joint5")]
    lo, hi = float(lines[0].split()[1]), float(lines[0].split()[2])
    assert -130 <= lo < -125 and 125 < hi <= 130  # degrees, within kuka_kr's joint 5 limits


def test_generate_options(tmp_path, capsys):
    out = tmp_path / "puma"
    code, _, err = run(
        capsys,
        "generate",
        "--robot",
        "puma560",
        "--n",
        "1e3",
        "--out",
        str(out),
        "--sampler",
        "sobol",
        "--dtype",
        "float32",
        "--val-fraction",
        "0.2",
        "--test-fraction",
        "0",
        "--branch",
        "5",
        "--chunk-size",
        "700",
        "--no-progress",
    )
    assert code == 0, err
    ds = load_dataset(out)
    assert ds.q.dtype == torch.float32 and len(ds) == 1000 and ds.meta["sampler"] == "sobol"
    assert ds.meta["split_sizes"] == {"train": 800, "val": 200, "test": 0}
    assert bool((ds.branch == 5).all())


def test_same_command_twice_gives_identical_arrays(tmp_path, capsys):
    for name in ("a", "b"):
        code, _, err = run(
            capsys,
            "generate",
            "--robot",
            "kuka_kr",
            "--n",
            "3000",
            "--out",
            str(tmp_path / name),
            "--seed",
            "11",
            "--no-progress",
        )
        assert code == 0, err
    a, b = load_dataset(tmp_path / "a"), load_dataset(tmp_path / "b")
    assert torch.equal(a.q, b.q) and torch.equal(a.pose, b.pose)
    assert a.meta["files"]["q.npy"]["sha256"] == b.meta["files"]["q.npy"]["sha256"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--n", "0"], "positive"),
        (["--n", "-3"], "positive"),
        (["--robot", "nosuch"], "unknown robot 'nosuch'"),
        (["--ranges", "limits_typo.yaml"], "ranges file not found"),
        (
            ["--ranges", str(REPO / "configs/robots/kuka_kr_training_ranges.yaml"), "--robot", "puma560"],
            "outside the joint limits",
        ),
        (["--val-fraction", "1.5"], "val_fraction"),
        (["--robot", "ur5", "--branch", "2"], "no IK branch classification"),
    ],
)
def test_bad_arguments_one_line_error(tmp_path, capsys, args, message):
    base = {"--robot": "kuka_kr", "--n": "10", "--out": str(tmp_path / "d")}
    argv = ["generate", "--no-progress"]
    for k, v in base.items():
        if k not in args:
            argv += [k, v]
    code, stdout, err = run(capsys, *argv, *args)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "d").exists()


def test_existing_output_refused_then_overwritten(tmp_path, capsys):
    out = str(tmp_path / "d")
    assert run(capsys, "generate", "--robot", "kuka_kr", "--n", "10", "--out", out, "--no-progress")[0] == 0
    code, _, err = run(capsys, "generate", "--robot", "kuka_kr", "--n", "20", "--out", out, "--no-progress")
    assert code == 2 and "already exists" in err and "--overwrite" in err
    assert len(load_dataset(out)) == 10
    code, _, err = run(
        capsys, "generate", "--robot", "kuka_kr", "--n", "20", "--out", out, "--overwrite", "--no-progress"
    )
    assert code == 0, err
    assert len(load_dataset(out)) == 20


def test_unwritable_folder(tmp_path, capsys):
    (tmp_path / "f").write_text("x")
    code, _, err = run(
        capsys, "generate", "--robot", "kuka_kr", "--n", "10", "--out", str(tmp_path / "f" / "d"), "--no-progress"
    )
    assert code == 2 and "a file is in the way" in err


def test_info_on_corrupt_dataset(tmp_path, capsys):
    out = tmp_path / "d"
    assert run(capsys, "generate", "--robot", "kuka_kr", "--n", "100", "--out", str(out), "--no-progress")[0] == 0
    with open(out / "pose.npy", "r+b") as f:
        f.seek(300)
        f.write(b"\xff\xff")
    code, _, err = run(capsys, "data", "info", str(out))
    assert code == 2 and "pose.npy" in err and "checksum" in err


def test_subprocess_exit_code_and_no_traceback(tmp_path):
    cmd = [
        sys.executable,
        "-c",
        "import sys; from nik.cli import main; sys.exit(main())",
        "generate",
        "--robot",
        "kuka_kr",
        "--n",
        "0",
        "--out",
        str(tmp_path / "d"),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == ["nik generate: error: --n must be a positive integer, got 0"]


def test_info_shows_a_prismatic_joint_in_mm(tmp_path, capsys):
    out = tmp_path / "stanford"
    code, _, err = run(capsys, "generate", "--robot", "stanford", "--n", "1000", "--out", str(out), "--no-progress")
    assert code == 0, err
    code, stdout, err = run(capsys, "data", "info", str(out))
    assert code == 0, err
    (boom,) = [ln.split() for ln in stdout.splitlines() if ln.startswith("boom")]
    assert boom[-1] == "mm" and 304.8 <= float(boom[1]) < float(boom[2]) <= 1270.0
    assert float(boom[3]) == 304.8 and float(boom[4]) == 1270.0
    (waist,) = [ln.split() for ln in stdout.splitlines() if ln.startswith("waist")]
    assert waist[-1] == "deg" and float(waist[3]) == -170.0


def test_generate_end_link_picks_the_tool_link_and_says_so(tmp_path, capsys):
    out = tmp_path / "ur5_tool0"
    code, stdout, err = run(
        capsys, "generate", "--robot", "ur5", "--end-link", "tool0", "--n", "200", "--out", str(out), "--no-progress"
    )
    assert code == 0, err
    assert "of ur5 (tool link tool0)" in stdout
    ds = load_dataset(out)
    assert ds.meta["robot"]["definition"]["end_link"] == "tool0"
    import nik

    robot = nik.load_robot("ur5", end_link="tool0")
    torch.testing.assert_close(ds.pose[:5], robot.fk(ds.q[:5].to(torch.float64)), atol=1e-12, rtol=0)
    assert load_dataset(out, robot=robot) is not None  # the dataset belongs to the tool0 arm ...
    with pytest.raises(ValueError, match="made with tool link 'tool0', this robot's is 'wrist_3_link'"):
        load_dataset(out, robot="ur5")  # ... not to the default (wrist_3_link) one
    code, stdout, err = run(capsys, "data", "info", str(out))
    assert code == 0, err
    assert "tool link tool0" in stdout


def test_end_link_on_an_arm_without_links_is_a_one_line_error(tmp_path, capsys):
    code, _, err = run(
        capsys, "generate", "--robot", "puma560", "--end-link", "tool0", "--n", "10", "--out", str(tmp_path / "x")
    )
    assert code == 2
    assert err.strip().count("\n") == 0 and "--end-link" in err and "URDF" in err


@pytest.mark.parametrize("robot", ["panda", "ur5", "kuka_kr"])
def test_generate_and_info_name_the_arms_end_alike(robot, tmp_path, capsys):
    out = tmp_path / robot
    code, stdout, err = run(capsys, "generate", "--robot", robot, "--n", "100", "--out", str(out), "--no-progress")
    assert code == 0, err
    said = stdout.split(f"samples of {robot}", 1)[1].split(" to ", 1)[0]  # " (flange panda_link8 on panda_link7)"
    code, info, err = run(capsys, "data", "info", str(out))
    assert code == 0, err
    (line,) = [ln for ln in info.splitlines() if ln.startswith("robot ")]
    if said:
        assert line.endswith(f"joints, {said.strip()[1:-1]})"), (said, line)
    else:  # an arm without links: nothing named by either
        assert line.endswith("joints)") and "tool link" not in line
    if robot == "panda":
        assert "flange panda_link8 on panda_link7" in line


def test_a_long_generation_prints_progress_lines_when_stderr_is_not_a_terminal(tmp_path, capsys, monkeypatch):
    import nik.data.generate as gen

    monkeypatch.setattr(gen, "PROGRESS_EVERY_S", 0.0)  # a line at every block of 65,536 (a long run: every 10 s)
    out = tmp_path / "kuka"
    n = 3 * gen.BLOCK_SIZE
    code, stdout, err = run(capsys, "generate", "--robot", "kuka_kr", "--n", str(n), "--out", str(out))
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("nik generate kuka_kr: ")]
    assert len(lines) == 2, err  # a line per block but the last
    assert all(f" / {n:,} samples (" in ln and " s left" in ln for ln in lines), lines
    done = [int(ln.split(": ")[1].split(" / ")[0].replace(",", "")) for ln in lines]
    assert done == [gen.BLOCK_SIZE, 2 * gen.BLOCK_SIZE]
    assert "\r" not in err and "it/s" not in err and "sample/s" not in err  # no redrawn tqdm bar
    monkeypatch.setattr(gen, "PROGRESS_EVERY_S", 10.0)  # a short run prints none
    code, stdout, err = run(capsys, "generate", "--robot", "kuka_kr", "--n", "1000", "--out", str(tmp_path / "short"))
    assert code == 0 and "nik generate kuka_kr:" not in err
