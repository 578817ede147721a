"""garage-mj hunt (issue 13): ranked failures, valid mutated garages, reproducible failures, resume."""

from __future__ import annotations

import csv

import pytest

from garage_mj.cli import main
from garage_mj.driving.hunt import HuntConfig, HuntError, rerun
from garage_mj.generation.library import Library
from garage_mj.generation.search import replay
from garage_mj.reporting.hunt import hunt

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick
CFG = HuntConfig(budget=16, tests=2, population=4, elites=2, worst=1)


@pytest.fixture(scope="module")
def hunted(tmp_path_factory):
    out = tmp_path_factory.mktemp("hunt") / "h"
    res = hunt("waypoint", out, map="tiny_7x11", config=CFG, seed=3, action_type="discrete", env=FAST,
               progress=False, videos=False)
    return out, res


def test_outputs_ranked_and_budget_kept(hunted):
    out, res = hunted
    assert res.tests <= CFG.budget and res.generations >= 1
    with open(out / "failures.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(res.ranked) > CFG.population  # children were made and tested
    pct = [float(r["failure_pct"]) for r in rows if r["failure_pct"]]
    assert pct == sorted(pct, reverse=True) and pct[0] > 0
    assert (out / "report.html").is_file() and "Hunt: where waypoint fails" in (out / "report.html").read_text()
    worst = res.files["packs"]
    assert len(worst) == 1 and (worst[0] / "manifest.json").is_file()
    assert res.files["xosc"] and all(p.is_file() for p in res.files["xosc"])


def test_mutated_garages_are_ones_the_painter_makes(hunted):
    out, res = hunted
    children = [s for s in res.ranked if s.parent]
    assert children
    with Library(out / "hunt.sqlite", create=False) as lib:
        assert lib.count() == len(res.ranked)
    for s in children[:3]:
        painted, info = replay(s.source.garage)
        assert info["usable"] and painted.canonical_hash() == s.source.hash


def test_a_listed_failure_reproduces_and_a_rerun_resumes(hunted):
    out, res = hunted
    worst = next(s for s in res.ranked if s.failures)
    row = worst.failures[0]
    again = rerun(out, worst.source.hash[:12], int(row["test"]))
    assert (again["outcome"], again["time"], again["hit"]) == (row["outcome"], float(row["time"]), row["hit"])
    before = (out / "cruise" / "tests.csv").read_text()
    res2 = hunt("waypoint", out, map="tiny_7x11", config=CFG, seed=3, action_type="discrete", env=FAST,
                progress=False, videos=False)
    assert (out / "cruise" / "tests.csv").read_text() == before  # nothing re-run
    assert [s.source.hash for s in res2.ranked] == [s.source.hash for s in res.ranked]
    with pytest.raises(HuntError, match="other settings"):
        hunt("waypoint", out, map="tiny_7x11", config=CFG, seed=4, action_type="discrete", env=FAST, progress=False)


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert main(["hunt", "--map", "tiny_7x11", "--budget", "3", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "budget" in err[0]
    assert main(["hunt", "--library", str(tmp_path / "nope.sqlite"), "--out", str(tmp_path / "y")]) == 2
    assert "no such file" in capsys.readouterr().err
