"""CI (.ci/run) runs README's set-up and test commands as a user would, before it installs anything more, then
re-runs only the test files that skipped for want of an extra or a program (.ci/skipped_files.py); and README's
set-up is enough for every command README shows (toppra, for ``nik path --timing``, is a core dependency)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _skipped_files():
    spec = importlib.util.spec_from_file_location("skipped_files", ROOT / ".ci" / "skipped_files.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.skipped_files


def test_readmes_commands_run_on_their_own_before_ci_installs_any_extra_or_program():
    lines = [
        line.strip()
        for line in (ROOT / ".ci" / "run").read_text().splitlines()
        if line.strip() and not line.strip().startswith(("#", "echo"))
    ]
    setup = lines.index('bash -c "${commands[0]}"')
    tests = next(i for i, line in enumerate(lines) if line.startswith('bash -c "${commands[1]}"'))
    installs = [i for i, line in enumerate(lines) if re.search(r"pip install|apt-get (update|install)", line)]
    assert installs and setup < tests < min(installs), (setup, tests, installs)
    rerun = [i for i, line in enumerate(lines) if line.startswith(".venv/bin/python -m pytest")]
    assert rerun and max(installs) < rerun[-1] and '"${rerun[@]}"' in lines[rerun[-1]]


def test_toppra_is_a_core_dependency_so_readmes_set_up_times_paths():
    text = (ROOT / "pyproject.toml").read_text()
    core = text[text.index("dependencies = [") : text.index("[project.optional-dependencies]")]
    assert re.search(r'^\s*"toppra>=', core, re.M), core


def test_ci_re_runs_exactly_the_files_that_skipped_for_want_of_an_install(tmp_path):
    skip = "import pytest\n\n@pytest.mark.skipif(True, reason={!r})\ndef test_a():\n    pass\n"
    tests = {
        "test_extra.py": skip.format("viser not installed (pip install -e '.[view]')"),
        "test_module.py": "import pytest\n\npytest.importorskip('no_such_module_of_nik_37')\n",
        "test_coal.py": "import pytest\n\ndef test_c():\n    pytest.skip({!r})\n".format(
            "the mesh check needs coal (extra collision-check)"
        ),
        "test_gpu.py": skip.format("needs a CUDA GPU"),
        "test_runs.py": "def test_e():\n    assert True\n",
    }
    for name, text in tests.items():
        (tmp_path / name).write_text(text)
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-ra", "-p", "no:cacheprovider", "."],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    found = _skipped_files()(out.stdout)
    assert sorted(Path(f).name for f in found) == ["test_coal.py", "test_extra.py", "test_module.py"], out.stdout
