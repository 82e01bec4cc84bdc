"""The ``nik`` dispatcher: start-up stays light, and bad checkpoints end in one line (exit 2)."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from nik.cli import main

ROOT = Path(__file__).resolve().parents[1]
POSE = ["1.0", "0.2", "1.2", "0", "0.7071068", "0", "0.7071068"]


class _Evil:
    def __reduce__(self):  # a pickle that would run code if unpickled without weights_only
        return (print, ("this must never print",))


@pytest.fixture(scope="module")
def poisoned(tmp_path_factory):
    d = tmp_path_factory.mktemp("ckpt")
    evil = d / "evil.ckpt"
    evil.write_bytes(pickle.dumps({"state_dict": {}, "nik": _Evil()}, protocol=4))
    noise = d / "noise.ckpt"
    noise.write_bytes(bytes(range(256)) * 8)
    return {"evil": evil, "noise": noise}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("data") / "kuka_tiny"
    assert main(["generate", "--robot", "kuka_kr", "--n", "200", "--out", str(out), "--no-progress"]) == 0
    return out


def _one_line_refusal(capsys, rc, path, command):
    out, err = capsys.readouterr()
    assert rc == 2
    assert "this must never print" not in out + err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"nik {command}: error: ")
    assert str(path) in lines[0] and "not a loadable nik checkpoint" in lines[0]
    assert "weights_only` set to `False`" not in err and "Traceback" not in err


@pytest.mark.parametrize("kind", ["evil", "noise"])
def test_solve_with_a_poisoned_checkpoint_prints_one_line_and_exits_2(kind, poisoned, capsys):
    rc = main(["solve", "--robot", "kuka_kr", "--checkpoint", str(poisoned[kind]), "--pose", *POSE])
    _one_line_refusal(capsys, rc, poisoned[kind], "solve")


@pytest.mark.parametrize("kind", ["evil", "noise"])
def test_evaluate_with_a_poisoned_checkpoint_prints_one_line_and_exits_2(kind, poisoned, dataset, tmp_path, capsys):
    args = ["evaluate", "--robot", "kuka_kr", "--checkpoint", str(poisoned[kind]), "--data", str(dataset)]
    rc = main([*args, "--n", "5", "--refinements", "lm", "--no-pk", "--out", str(tmp_path / "eval")])
    _one_line_refusal(capsys, rc, poisoned[kind], "evaluate")
    assert not (tmp_path / "eval").exists()


_HELP_EVERYWHERE = """
import sys
from nik.cli import build_parser, main
commands = list(build_parser()._subparsers._group_actions[0].choices)
for command in commands:
    try:
        main([command, "--help"])
    except SystemExit as done:
        assert done.code == 0, (command, done.code)
print(len(commands), "torch" in sys.modules)
"""


def test_nik_help_imports_no_torch():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    top = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "nik.cli", "--help"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert top.returncode == 0 and "usage: nik" in top.stdout, top.stderr[-2000:]
    imported = {line.rsplit("|", 1)[-1].strip() for line in top.stderr.splitlines() if line.startswith("import time")}
    assert "nik.cli" in imported and "torch" not in imported
    each = subprocess.run(
        [sys.executable, "-c", _HELP_EVERYWHERE], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120
    )
    assert each.returncode == 0, each.stderr[-2000:]
    count, loaded = each.stdout.split()[-2:]
    assert int(count) >= 9 and loaded == "False"  # every subcommand's --help too


_STARTUP = """
import contextlib, io, sys
import nik
import nik.cli
from nik.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main(["--help"])
    except SystemExit:
        pass
    rc = main(["solve", "--robot", "puma560", "--pose", "0.4", "0.15", "0.3", "0", "1", "0", "0"])
assert rc == 0, rc
print(sorted(m for m in ("lightning", "pytorch_lightning", "matplotlib") if m in sys.modules))
"""


def test_import_nik_help_and_solve_do_not_load_lightning_or_matplotlib():
    done = subprocess.run([sys.executable, "-c", _STARTUP], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


@pytest.mark.parametrize(
    "argv",
    [
        ["networks", "list"],
        ["solve", "--robot", "kuka_kr", "--pose", "1", "0.2", "1.2", "0", "0.7071068", "0", "0.7071068"],
    ],
)
def test_output_into_a_closed_pipe_ends_quietly_without_a_traceback(argv):
    # nik networks | head: the reader is gone before nik writes (a pipe whose read end is closed)
    script = (
        "import os, sys\n"
        "r, w = os.pipe(); os.close(r); os.dup2(w, 1)\n"
        "from nik.cli import main\n"
        f"sys.exit(main({argv!r}))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 141 and proc.stderr == "", proc.stderr
