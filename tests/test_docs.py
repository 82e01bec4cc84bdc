"""What README.md and docs/ state about nik matches nik: the robots tables, the names they use, the papers' citations,
and the extra that the tests' skip messages tell users to install."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import nik
from nik.analytic import family
from nik.nets.registry import SHIPPED_DIR, find_network

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _table_rows(text: str, header_start: str) -> dict[str, list[str]]:
    """``{name: cells}`` of the Markdown table whose header row starts with ``header_start``; the first cell is
    a name in backticks."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header_start))
    rows = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0].strip("`")] = cells
    return rows


def test_the_readme_robots_table_lists_every_built_in_arm_with_its_closed_form_and_shipped_network():
    rows = _table_rows((ROOT / "README.md").read_text(), "| name | DOF | defined by | closed form | shipped network")
    assert sorted(rows) == sorted(nik.builtin_robots())
    for name, (_, dof, _, closed, shipped, _) in rows.items():
        robot = nik.load_robot(name)
        assert int(dof) == robot.dof, name
        assert closed.startswith("yes") == (family(robot) is not None), name
        assert shipped.startswith("yes") == (find_network(robot, [SHIPPED_DIR]) is not None), name


def test_the_robots_page_table_lists_every_built_in_arm():
    rows = _table_rows((ROOT / "docs" / "robots.md").read_text(), "| name | dof | definition | source |")
    assert sorted(rows) == sorted(nik.builtin_robots())
    for name, cells in rows.items():
        assert int(cells[1]) == nik.load_robot(name).dof, name


def test_every_nik_name_the_docs_use_is_an_attribute_after_a_plain_import_nik():
    names = sorted({m for p in PAGES for m in re.findall(r"\bnik\.([A-Za-z_]\w*)", p.read_text())})
    assert "tolerances" in names
    code = f"import nik\nmissing = [n for n in {names!r} if not hasattr(nik, n)]\nprint(missing)"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]"
    assert nik.tolerances.DEFAULT_TOL_POS == 1e-4


def test_every_dotted_nik_name_the_docs_use_resolves_after_a_plain_import_nik():
    # docs write nik.collision.meshcheck.mesh_check, nik.ik.backends.one_pose, ...: each works as written after
    # `import nik` (a module of a package is imported on first read), while `import nik` itself stays light
    names = sorted({m for p in PAGES for m in re.findall(r"\bnik(?:\.[A-Za-z_]\w*){2,}", p.read_text())})
    assert "nik.collision.meshcheck.mesh_check" in names and len(names) >= 50, names
    code = (
        "import sys\nimport nik\n"
        "heavy = sorted(m for m in ('lightning', 'matplotlib', 'coal', 'torch', 'numba') if m in sys.modules)\n"
        f"missing = []\nfor name in {names!r}:\n"
        "    obj = nik\n"
        "    try:\n"
        "        for part in name.split('.')[1:]:\n"
        "            obj = getattr(obj, part)\n"
        "    except AttributeError as err:\n"
        "        missing.append(f'{name}: {err}')\n"
        "print(heavy)\nprint(missing)"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    heavy, missing = done.stdout.strip().splitlines()[-2:]
    assert heavy == "[]", f"import nik loaded {heavy}"
    assert missing == "[]", missing


#: The four source papers (the reference list of the project's methods specification): what identifies each.
PAPERS = {
    "A": ("Rui Ting", "simulated annealing particle swarm optimization", "Computer Engineering and Applications",
          "2010, 46(3): 27-29"),
    "B": ("Ge Xiaochuan", "Application of Double Quaternion in the Inverse Kinematics of 6R Serial Robots",
          "Computer Systems & Applications", "doi:10.15888/j.cnki.csa.005433"),
    "C": ("Bai Wenfeng", "improved differential evolution-neural network", "Journal of Changchun University of "
          "Technology", "doi:10.15923/j.cnki.cn22-1382/t.2017.2.11"),
    "D": ("Li Xichen", "improved PSO algorithm", "Journal of Hunan University of Technology",
          "doi:10.3969/j.issn.1673-9833.2021.05.003"),
}  # fmt: skip


def test_the_papers_page_cites_each_source_paper_in_full_and_no_page_calls_them_unidentified():
    text = " ".join((ROOT / "docs" / "papers.md").read_text().split())
    for key, parts in PAPERS.items():
        entry = text[text.index(f"**Paper {key}**:") :][:600]
        for part in parts:
            assert part in entry, (key, part)
    for page in PAGES:
        flat = " ".join(page.read_text().split()).lower()
        for stale in ("not identified", "did not identify", "no citation", "reference is still to be added"):
            assert stale not in flat, (page.name, stale)


def test_every_example_robot_data_skip_names_the_one_extra_of_pyproject_that_installs_it():
    pyproject = (ROOT / "pyproject.toml").read_text()
    section = pyproject[pyproject.index("[project.optional-dependencies]") :]
    extras = dict(re.findall(r"^([\w-]+) = \[(.*)\]$", section, re.M))
    named, lines = set(), 0
    for test in sorted((ROOT / "tests").glob("test_*.py")):
        for line in test.read_text().splitlines():
            if re.search(r"example-robot-data (is )?not installed", line):
                lines += 1
                found = re.findall(r"\.\[([\w-]+)\]", line) + re.findall(r"the ([\w-]+) extra", line)
                assert found, (test.name, line.strip())
                named.update(found)
    assert lines >= 2
    assert len(named) == 1, named
    (extra,) = named
    assert '"example-robot-data' in extras[extra], (extra, extras)


def test_ci_installs_every_extra_and_program_the_tests_skip_without():
    # CI runs README's set-up and tests (.ci/run); every optional extra a skip message names (pip install -e
    # ".[X]") and every program a test looks up (shutil.which) must be installed there, or its tests never run
    ci = (ROOT / ".ci" / "run").read_text()
    installed = set()
    for extras in re.findall(r"pip install[^\n]*-e \"?'?\.\[([\w,-]+)\]", ci):
        installed.update(extras.split(","))
    apt = " ".join(re.findall(r"apt-get install[^\n]*", ci))
    wanted_extras, programs = set(), set()
    for test in sorted((ROOT / "tests").glob("test_*.py")):
        text = test.read_text()
        wanted_extras.update(
            e for found in re.findall(r"pip install -e ['\"]\.\[([\w,-]+)\]", text) for e in found.split(",")
        )
        programs.update(re.findall(r"shutil\.which\(\"([\w.-]+)\"\)", text))
    assert {"view", "urdf-tests"} <= wanted_extras and "chromium-headless-shell" in programs
    assert wanted_extras - {"dev"} <= installed, wanted_extras - installed
    assert all(p in apt for p in programs), (programs, apt)


def test_every_evaluation_table_of_the_docs_has_the_default_pipeline_row_and_the_guess_that_served_each_row():
    # tables of nik evaluate made before the default-pipeline row and the per-row guess label misread as current
    text = (ROOT / "docs" / "evaluation.md").read_text()
    tables = re.findall(r"^\| method \|.*\n\|[-|]+\|\n((?:\|.*\n?)+)", text, re.M)
    assert len(tables) >= 2
    for rows in tables:
        rows = [r for r in rows.strip().splitlines()]
        assert rows[0].startswith("| default pipeline |"), rows[0]
        notes = [r.rstrip(" |").rsplit("|", 1)[1].strip() for r in rows if not r.startswith("| pytorch-kinematics |")]
        assert all(n.startswith("guess ") for n in notes), notes


def test_view_page_documents_the_headless_browser_flags_of_its_test():
    """Issue 37 item 8: a picture of the page without a display, with the Chromium flags tests/test_view.py uses."""
    launch = (ROOT / "tests" / "test_view.py").read_text()
    flags = re.findall(r'"(--(?:no-sandbox|use-gl=\w+|use-angle=\w+|enable-unsafe-swiftshader))"', launch)
    assert len(flags) == 4, flags
    page = (ROOT / "docs" / "view.md").read_text()
    command = next(line for line in page.splitlines() if line.startswith("chromium-headless-shell "))
    assert all(f in command for f in flags) and "--screenshot=" in page


def test_collisions_page_says_that_fitting_spheres_to_meshes_needs_the_collision_check_extra():
    text = (ROOT / "docs" / "collisions.md").read_text()
    sentence = next((s for s in re.split(r"(?<=\.)\s", text) if "fitting spheres to meshes" in s.lower()), "")
    assert "`collision-check` extra" in sentence and "trimesh" in sentence
    extras = (ROOT / "pyproject.toml").read_text()
    assert re.search(r'^collision-check = \[.*"trimesh', extras, re.M)  # the extra does install trimesh


def test_readme_one_pose_figures_are_those_of_the_stored_run_it_cites():
    """Issue 37 item 8: README's pose-by-pose speed against ik_LM and TRAC-IK, and its tight loop, are the ranges
    over the arms of the stored result it names."""
    text = (ROOT / "README.md").read_text()
    m = re.search(
        r"one\s+pose took (\d+)-(\d+) us, ([\d.]+)-([\d.]+)x the speed of Robotics Toolbox's C\+\+ `ik_LM` and "
        r"([\d.]+)-([\d.]+)x that of TRAC-IK; in a tight\s+loop (\d+)-(\d+) us \(the latest stored run, "
        r"\[(benchmarks/results/[\w.]+)\]",
        text,
    )
    assert m, "README's one-pose sentence"
    rows = [
        [c.strip() for c in line.strip("|").split("|")]
        for line in (ROOT / m.group(9)).read_text().splitlines()
        if line.startswith("| ") and not line.startswith("| robot")
    ]
    per_arm = {}
    for robot, solver, median, *rest in rows:
        key = "nik" if "interleaved" in solver else "tight" if "tight" in solver else "trac" if "TRAC" in solver else ""
        per_arm.setdefault(robot, {})[key] = (float(median), float(rest[-1].rstrip("x")))
    us = [a["nik"][0] for a in per_arm.values()]
    vs_lm = [a["nik"][1] for a in per_arm.values()]
    vs_trac = [a["trac"][0] / a["nik"][0] for a in per_arm.values()]
    tight = [a["tight"][0] for a in per_arm.values()]
    assert len(per_arm) >= 4
    assert (float(m.group(1)), float(m.group(2))) == (min(us), max(us))
    assert (float(m.group(3)), float(m.group(4))) == (min(vs_lm), max(vs_lm))
    assert (float(m.group(5)), float(m.group(6))) == (round(min(vs_trac), 1), round(max(vs_trac), 1))
    assert (float(m.group(7)), float(m.group(8))) == (min(tight), max(tight))


def _distribution_name() -> str:
    text = (ROOT / "pyproject.toml").read_text()
    return re.search(r'^\[project\]\n(?:.*\n)*?name = "([^"]+)"', text, re.M).group(1)


def test_the_distribution_is_not_the_package_index_s_nik_and_every_install_hint_names_it():
    # the package index's `nik` is an unrelated project: a hint `pip install 'nik[...]'` would fetch it
    dist = _distribution_name()
    assert dist != "nik" and dist.startswith("nik"), dist
    files = [*sorted((ROOT / "nik").rglob("*.py")), *sorted((ROOT / "benchmarks").glob("*.py")), *PAGES]
    hints, wrong = 0, []
    for path in files:
        text = path.read_text()
        for m in re.finditer(r"pip install\s+['\"]?(nik[\w-]*)(?=[\[\s'\"`)]|$)", text, re.M):
            if text.startswith("` does not install this one", m.end()):
                continue  # README's warning about the index's `nik`
            hints += 1
            if m.group(1) != dist:
                wrong.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert hints >= 5 and not wrong, (hints, wrong)
