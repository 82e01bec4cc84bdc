"""nik.learn.compare (``nik compare``): a verdict per metric, budgets kept, a reproducible step budget, outputs
under runs/compare by default, bad budgets refused before any work. Training runs on a 3,000-sample kuka_kr
dataset and a few steps or seconds."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

pytestmark = [
    pytest.mark.filterwarnings("ignore:LightningCLI's args parameter"),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*treespec"),
]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from nik.data import generate_dataset

    out = tmp_path_factory.mktemp("data") / "kuka_3k"
    generate_dataset("kuka_kr", 3000, out, seed=0, progress=False)
    return out


def _compare(cwd: Path, monkeypatch, *args: str) -> int:
    from nik.cli import main

    monkeypatch.chdir(cwd)
    return main(["compare", *args])


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


# -- 1. the verdict -------------------------------------------------------------------------------------------
def _result(method: str, seed: int, value: float) -> dict:
    from nik.learn.compare import METRICS

    return {"net": "paper", "method": method, "seed": seed, "all_phases": True, **{k: value for k, _, _ in METRICS}}


def test_verdict_names_the_winner_per_metric_with_its_margin_against_the_spread_over_seeds():
    from nik.learn.compare import METRICS, verdict

    clear = [_result("adam", s, v) for s, v in enumerate((10.0, 10.5, 11.0))]
    clear += [_result("bp", s, v) for s, v in enumerate((20.0, 21.0, 22.0))]
    clear += [_result("lbfgs", s, v) for s, v in enumerate((30.0, 31.0, 32.0))]
    lines = verdict(clear)
    assert len(lines) == len(METRICS)
    for line, (_, label, unit) in zip(lines, METRICS, strict=True):
        assert f"paper net, {label}: best adam 10.5 {unit}, then bp 21.0 {unit}" in line
        assert f"margin 10.5 {unit} against sd 0.500 and 1.00 over 3 seeds: established" in line

    overlap = [_result("adam", s, v) for s, v in enumerate((10.0, 12.0, 14.0))]
    overlap += [_result("bp", s, v) for s, v in enumerate((13.0, 13.5, 14.5))]
    assert all("best adam" in x and "not established (the seeds overlap)" in x for x in verdict(overlap))

    two = [_result(m, s, v + s) for m, v in (("adam", 1.0), ("bp", 5.0)) for s in (0, 1)]
    assert all("not established" in x and "2 seeds are too few" in x for x in verdict(two))

    one = [_result("adam", 0, 1.0), _result("bp", 0, 2.0)]
    assert all("one seed: the ranking is not established" in x for x in verdict(one))

    unfinished = [{**r, "all_phases": r["method"] != "adam"} for r in clear]
    assert all("adam did not run all its phases" in x for x in verdict(unfinished))


# -- 2. budgets kept ------------------------------------------------------------------------------------------
def test_a_wall_clock_budget_is_kept_inside_long_steps_and_an_unfinished_de_bp_says_so(dataset, tmp_path, monkeypatch):
    # on the default net (135,686 weights) one full-batch L-BFGS step and DE's first generation each take longer
    # than the budget: the clock is checked inside them
    budget = 3.0
    rc = _compare(
        tmp_path,
        monkeypatch,
        *("--data", str(dataset), "--nets", "default", "--methods", "lbfgs", "de_bp"),
        *("--budget", str(budget), "--seeds", "0", "--de-samples", "500", "--out", "out/c"),
    )
    assert rc == 0
    rows = {r["method"]: r for r in _rows(tmp_path / "out/c.csv")}
    for method, r in rows.items():
        assert float(r["train_s"]) <= budget * 1.1, (method, r["train_s"])
        assert r["stopped_by"] == "clock"
    assert rows["de_bp"]["all_phases"] == "False" and rows["de_bp"]["samples_a_step"] == "500"
    md = (tmp_path / "out/c.md").read_text()
    de_bp = next(line for line in md.splitlines() if line.startswith("| default | de_bp |"))
    assert "BP never ran" in de_bp and "DE 500 of 2400" in de_bp
    assert "random 500-sample subset" in md and "3 s of wall clock per run" in md


# -- 3. reproducible ------------------------------------------------------------------------------------------
def test_a_step_budget_gives_the_same_table_twice(dataset, tmp_path, monkeypatch):
    from nik.learn.compare import TIME_KEYS

    args = ("--data", str(dataset), "--nets", "paper", "--methods", "adam", "lbfgs", "de_bp", "--seeds", "0")
    args += ("--steps", "6", "--de-generations", "3")
    for name in ("a", "b"):
        assert _compare(tmp_path, monkeypatch, *args, "--out", f"{name}/c") == 0
    a, b = _rows(tmp_path / "a/c.csv"), _rows(tmp_path / "b/c.csv")
    assert len(a) == 3
    for ra, rb in zip(a, b, strict=True):
        untimed = [k for k in ra if k not in TIME_KEYS]
        assert [ra[k] for k in untimed] == [rb[k] for k in untimed]
        assert ra["stopped_by"] == "steps" and ra["steps"] == "6"

    def cells(path: Path) -> list[list[str]]:  # the table without its time column
        lines = [x for x in path.read_text().splitlines() if x.startswith("| paper")]
        return [[c for i, c in enumerate(x.split("|")) if i != 7] for x in lines]

    assert cells(tmp_path / "a/c.md") == cells(tmp_path / "b/c.md")
    md = (tmp_path / "a/c.md").read_text()
    assert "Budget: 6 steps per run (a step budget" in md and "| DE 3 of 3 gen + BP 2 steps |" in md
    assert "test joint RMSE: best" in md and "one seed: the ranking is not established" in md


# -- 4. outputs -----------------------------------------------------------------------------------------------
def test_without_out_it_writes_under_runs_compare_not_into_the_checkout(dataset, tmp_path, monkeypatch):
    args = ("--data", str(dataset), "--nets", "paper", "--methods", "adam", "--seeds", "0", "--steps", "2")
    assert _compare(tmp_path, monkeypatch, *args) == 0
    home = tmp_path / "runs" / "compare" / dataset.name
    assert sorted(p.name for p in home.glob("compare*")) == ["compare.csv", "compare.md", "compare_history.csv"]
    assert (home / "paper" / "adam" / "seed0" / "last.ckpt").is_file()
    assert not (tmp_path / "benchmarks").exists()


def test_compare_help_states_every_default():
    from nik.learn.cli import build_parser

    actions = [a for a in build_parser()._actions if a.option_strings and a.dest != "help"]
    assert {a.dest for a in actions} >= {"budget", "steps", "seeds", "out", "runs_dir", "de_samples"}
    for a in actions:
        assert "default" in (a.help or ""), a.option_strings


# -- 5. bad budgets -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "bad",
    [
        ("--budget", "0"),
        ("--budget", "-5"),
        ("--budget", "nan"),
        ("--steps", "0"),
        ("--steps", "-3"),
        ("--seeds", "-1"),
        ("--seeds", "0", "0"),
        ("--de-samples", "-1"),
        ("--de-generations", "0"),
    ],
)
def test_a_bad_budget_is_refused_in_one_line_before_any_work(bad, dataset, tmp_path, monkeypatch, capsys):
    rc = _compare(tmp_path, monkeypatch, "--data", str(dataset), "--methods", "adam", *bad)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and err.startswith("nik compare: error: --"), err
    assert bad[0] in err
    assert list(tmp_path.iterdir()) == []  # nothing written
