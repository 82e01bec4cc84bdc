"""The README's and docs' examples run as written: every ```shell block of README.md and then of each
docs/*.md page (in :data:`DOC_ORDER`), in document order, with the large sizes shrunk by :data:`SHRINK`;
then every ```python block in the same order; in a copy of the repository with no data and no runs.

The first two ```bash blocks of the README are CI's set-up and test commands and are not run here.
Links between the pages must resolve (files and heading anchors), and no page cites an issue number.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
FENCE = re.compile(r"^```(\S*)\n(.*?)^```[ \t]*$", re.M | re.S)

#: The order in which the docs pages' blocks run, after the README's: a page may use what an earlier
#: one made (training.md makes data/kuka_kr_100k and runs/adam/last.ckpt, which learned.md and
#: solving.md use). Every page of docs/ is listed (checked).
DOC_ORDER = [
    "robots.md",
    "datasets.md",
    "training.md",
    "learned.md",
    "solving.md",
    "bounds.md",
    "collisions.md",
    "paths.md",
    "costs.md",
    "timing.md",
    "view.md",
    "swarm.md",
    "evaluation.md",
    "scaling.md",
    "speed.md",
    "papers.md",
]

#: (what the pages say, what the test runs): sizes, epochs, budgets and run counts shrunk so that all
#: pages run in about a minute and a half. Each entry must match somewhere (checked), so the table cannot
#: silently go stale when a page changes.
SHRINK = [
    ("--n 1000000 ", "--n 3000 "),
    ("--n 200000 ", "--n 2000 "),
    ("--n 100000 ", "--n 2000 "),
    ("--n 50000 ", "--n 2000 "),
    ("--n 500 --refinements lm", "--n 20 --refinements lm"),
    ("--n 1000 --out runs/eval/puma560", "--n 20 --refinements lm,ipso --no-pk --out runs/eval/puma560"),
    ("--trainer.max_epochs 5\n", "--trainer.max_epochs 1 --model.hidden [32]\n"),
    ("--trainer.max_epochs 6 ", "--trainer.max_epochs 1 --model.hidden [32] "),
    ("--trainer.max_epochs 20\n", "--trainer.max_epochs 1 --model.hidden [32]\n"),
    (
        "--config configs/train/de_bp.yaml --data.path data/kuka_kr_100k\n",
        "--config configs/train/de_bp.yaml --data.path data/kuka_kr_100k --model.pop_size 16 "
        "--model.generations 3 --trainer.max_epochs 5 --trainer.check_val_every_n_epoch 1\n",
    ),
    ("de_generation.py --threads 2\n", "de_generation.py --threads 2 --repeats 1 --samples 100\n"),
    ("--samples 10000 1000\n", "--samples 100 --repeats 1\n"),
    (
        "--budget 45 --seeds 0 1 2",
        "--budget 0.5 --seeds 0 --nets paper --methods adam --runs-dir runs/compare_readme",
    ),
    ("--steps 100 --de-generations 60 --seeds 0 1 2", "--steps 2 --de-generations 1 --seeds 0"),
    ("paper_d.py --out runs/paper_d", "paper_d.py --runs 1 --out runs/paper_d"),
    (
        "nik train stanford --minutes 1 ",
        "nik train stanford --minutes 1 --max-steps 3 --hidden 32 --val-n 100 --eval-batch 20 --eval-one 2 ",
    ),
    ("paper_a.py --n 100", "paper_a.py --n 2 --iters 20"),
    ("refine.py --n 1000 --swarm-n 100 --boundary", "refine.py --n 4 --swarm-n 1 --skip-uniform"),
    (
        "python -m pytest tests/test_swarm.py",
        "python -m pytest -q -p no:cacheprovider --collect-only tests/test_swarm.py",
    ),
]


def pages() -> list[Path]:
    """README.md, then the docs pages in :data:`DOC_ORDER`."""
    return [README] + [DOCS / name for name in DOC_ORDER]


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """``(language, body)`` of every fenced block of ``text``, in order."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(text)]


def all_blocks() -> list[tuple[str, str, str]]:
    """``(page name, language, body)`` of every fenced block of every page, in running order."""
    return [(p.name, lang, body) for p in pages() for lang, body in fenced_blocks(p.read_text())]


def shrink(script: str) -> str:
    for old, new in SHRINK:
        assert old in script, f"no page contains {old!r} any more: update SHRINK in tests/test_readme.py"
        script = script.replace(old, new)
    return script


def test_doc_order_lists_every_page_of_docs():
    assert sorted(DOC_ORDER) == sorted(p.name for p in DOCS.glob("*.md"))


def test_every_fence_names_its_language_and_ci_blocks_come_first():
    blocks = fenced_blocks(README.read_text())
    langs = [lang for lang, _ in blocks]
    assert "" not in langs, "a README block has no language; use shell, python, text or yaml"
    assert set(langs) <= {"bash", "shell", "python", "text", "yaml"}
    assert langs[:2] == ["bash", "bash"] and langs.count("bash") == 2
    assert "pip install" in blocks[0][1] and "pytest" in blocks[1][1]
    for page in DOC_ORDER:
        langs = {lang for lang, _ in fenced_blocks((DOCS / page).read_text())}
        assert langs <= {"shell", "python", "text", "yaml"}, f"docs/{page}: block languages {langs}"


def _slug(heading: str) -> str:
    """GitHub's anchor for a Markdown heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text())
    return {_slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+)$", text, re.M)}


def test_links_between_pages_resolve():
    link = re.compile(r"\]\(([^)\s]+)\)")
    broken = []
    for page in pages():
        text = FENCE.sub("", page.read_text())
        for target in link.findall(text):
            if re.match(r"[a-z]+:", target):
                continue  # http(s), mailto
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                broken.append(f"{page.name}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                broken.append(f"{page.name}: {target} (no such heading)")
    assert not broken, "\n".join(broken)


def test_no_page_cites_an_issue_number():
    for page in pages():
        found = re.findall(r"\bissues? \d+", page.read_text(), re.I)
        assert not found, f"{page.name} cites {found}: say what was measured, not which issue asked"


def _copy_repo(dst: Path) -> Path:
    ignore = shutil.ignore_patterns(
        ".git", ".venv", "runs", "__pycache__", ".pytest_cache", "*.egg-info", ".ruff_cache"
    )
    shutil.copytree(ROOT, dst, ignore=ignore)
    data = dst / "data"
    for p in data.iterdir() if data.is_dir() else []:  # a fresh clone has only data/README*
        if not p.name.lower().startswith("readme"):
            shutil.rmtree(p) if p.is_dir() else p.unlink()
    return dst


def _env(work: Path) -> dict:
    """PATH with this interpreter's folder first (``python`` and the ``nik`` entry point of the venv; a
    ``nik`` shim when the entry point is not installed) and the copy's code importable."""
    bindir = Path(sys.executable).parent
    shim = work / ".readme-bin"
    shim.mkdir()
    py = shim / "python"  # a script, not a symlink: a venv's interpreter must be started by its own path
    py.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    py.chmod(0o755)
    if not (bindir / "nik").exists():
        nik = shim / "nik"
        nik.write_text(
            f'#!/bin/sh\nexec "{sys.executable}" -c "import sys; from nik.cli import main; sys.exit(main())" "$@"\n'
        )
        nik.chmod(0o755)
    path = os.pathsep.join([str(shim), str(bindir), os.environ.get("PATH", "")])
    return {**os.environ, "PATH": path, "PYTHONPATH": str(work), "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}


_PYTHON_DRIVER = """
import sys, traceback
blocks = sys.argv[1:]
for path in blocks:
    src = open(path).read()
    try:
        exec(compile(src, path, "exec"), {"__name__": "__readme__"})
    except Exception:
        traceback.print_exc()
        print(f"python block {path} failed", file=sys.stderr)
        sys.exit(1)
"""


@pytest.mark.long
def test_shell_then_python_blocks_of_readme_and_docs_run_in_a_fresh_copy(tmp_path):
    blocks = all_blocks()
    shell = [(page, body) for page, lang, body in blocks if lang == "shell"]
    assert shell, "no page has a ```shell block"
    work = _copy_repo(tmp_path / "nik")
    env = _env(work)
    parts = ["set -euo pipefail"]
    for i, (page, body) in enumerate(shell):
        parts += [f"echo '### {page}: shell block {i}' >&2", body]
    script = shrink("\n".join(parts) + "\n")
    (work / "readme.sh").write_text(script)
    done = subprocess.run(["bash", "readme.sh"], cwd=work, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"shell blocks failed:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"
    assert (work / "runs" / "solutions.csv").is_file()
    assert not (work / "poses.csv").exists() and not (work / "solutions.csv").exists()  # examples write under runs/
    assert (work / "runs" / "stanford" / "last.ckpt").is_file()
    assert (work / "runs" / "stanford" / "stanford.safetensors").is_file()
    assert (work / "runs" / "adam" / "last.ckpt").is_file()
    assert (work / "runs" / "solver_eval_puma560" / "last.ckpt").is_file()
    assert (work / "runs" / "eval" / "puma560" / "errors.png").is_file()

    # YAML examples with a name are saved as <name>.yaml, as the text around them says
    for _page, lang, body in blocks:
        name = re.search(r"^name:\s*(\S+)", body, re.M)
        if lang == "yaml" and name:
            (work / f"{name.group(1)}.yaml").write_text(body)
    paths = []
    for i, (page, _lang, body) in enumerate(b for b in blocks if b[1] == "python"):
        path = work / f"block_{i}_{Path(page).stem}.py"
        path.write_text(textwrap.dedent(body))
        paths.append(str(path))
    done = subprocess.run(
        [sys.executable, "-c", _PYTHON_DRIVER, *paths], cwd=work, env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, f"python blocks failed:\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}"


@pytest.mark.parametrize("old", [old for old, _ in SHRINK])
def test_shrink_table_entries_still_match_a_page(old):
    shell = "\n".join(body for _page, lang, body in all_blocks() if lang == "shell")
    assert old in shell


def test_the_five_minute_tour_trains_for_at_most_two_minutes():
    # the tour's title is a promise: its commands' declared budgets (`--minutes`) leave time for the rest
    text = README.read_text()
    tour = re.search(r"^## A five-minute tour\n(.*?)^## ", text, re.M | re.S)
    assert tour, "README lost its five-minute tour"
    shell = "\n".join(body for lang, body in fenced_blocks(tour.group(1)) if lang == "shell")
    assert "nik train" in shell
    budgets = [float(m) for m in re.findall(r"--minutes\s+([\d.]+)", shell)]
    assert budgets and all(b > 0 for b in budgets) and sum(budgets) <= 2, budgets
