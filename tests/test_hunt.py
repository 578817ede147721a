"""garage-mj hunt: ranked failures, valid mutated garages, reproducible failures, resume."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from garage_mj.cli import main
from garage_mj.cli.hunt import failure_summary
from garage_mj.core.backends import Compute
from garage_mj.driving.drivers import ActionTypeWarning
from garage_mj.driving.hunt import FAILURE_COLUMNS, HuntConfig, HuntError, HuntResult, Scored, rerun
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.generation.library import Library
from garage_mj.generation.search import replay
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.hunt import hunt

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick
QUIET = Compute(progress=False)  # one process, no progress bar
CFG = HuntConfig(budget=16, tests=2, population=4, elites=2, worst=1)


@pytest.fixture(scope="module")
def hunted(tmp_path_factory):
    out = tmp_path_factory.mktemp("hunt") / "h"
    # discrete actions make waypoint fail often (it is made for continuous ones): one warning for the whole hunt
    with pytest.warns(ActionTypeWarning, match="driver 'waypoint' is made for continuous actions") as caught:
        res = hunt(CruiseSettings("waypoint", seed=3, action_type="discrete", env=FAST), out, map="tiny_7x11",
                   config=CFG, videos=False, compute=QUIET)
    assert len([w for w in caught if issubclass(w.category, ActionTypeWarning)]) == 1
    return out, res


def test_the_action_type_is_recorded(hunted):
    out, res = hunted
    state = json.loads((out / "hunt.json").read_text())
    assert (state["settings"]["action_type"], state["action_type_from"]) == ("discrete", "--action-type")
    run = json.loads((out / "cruise" / "run.json").read_text())
    assert (run["action_type"], run["action_type_from"]) == ("discrete", "--action-type")
    assert res.action_label == "discrete actions from --action-type; the driver's own: continuous"
    assert not list(out.rglob(".garage-mj.lock"))  # the locks of the hunt, its cruise and packs go when it ends


def test_outputs_ranked_and_budget_kept(hunted):
    out, res = hunted
    assert res.tests <= CFG.budget and res.generations >= 1
    with open(out / "failures.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(FAILURE_COLUMNS) and "missed_goals" in FAILURE_COLUMNS
    for r in rows:  # every failure in one class
        assert int(r["failures"]) == sum(int(r[c]) for c in ("collisions", "deadlocks", "missed_goals", "timeouts"))
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
    state, run = json.loads((out / "hunt.json").read_text()), json.loads((out / "cruise" / "run.json").read_text())
    assert state["settings"]["test_timeout"] == run["test_timeout"] == 120.0
    del state["settings"]["test_timeout"], run["test_timeout"]  # as a hunt from before the setting wrote them
    (out / "hunt.json").write_text(json.dumps(state))
    (out / "cruise" / "run.json").write_text(json.dumps(run))
    with pytest.warns(ActionTypeWarning):
        res2 = hunt(CruiseSettings("waypoint", seed=3, action_type="discrete", env=FAST), out, map="tiny_7x11",
                    config=CFG, videos=False, compute=QUIET)
    assert (out / "cruise" / "tests.csv").read_text() == before  # nothing re-run
    assert [s.source.hash for s in res2.ranked] == [s.source.hash for s in res.ranked]
    with pytest.warns(ActionTypeWarning), pytest.raises(HuntError, match=r"other settings \(seed\)"):
        hunt(CruiseSettings("waypoint", seed=4, action_type="discrete", env=FAST), out, map="tiny_7x11",
             config=CFG, compute=QUIET)
    with pytest.warns(ActionTypeWarning), pytest.raises(HuntError, match=r"other settings \(test_timeout\)"):
        hunt(CruiseSettings("waypoint", seed=3, action_type="discrete", env=FAST, test_timeout=5), out,
             map="tiny_7x11", config=CFG, compute=QUIET)
    with pytest.raises(HuntError, match=r"other settings \(action_type\)"):  # waypoint's own: continuous
        hunt(CruiseSettings("waypoint", seed=3, env=FAST), out, map="tiny_7x11", config=CFG, compute=QUIET)


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert main(["hunt", "--map", "tiny_7x11", "--budget", "3", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "budget" in err[0]
    assert main(["hunt", "--library", str(tmp_path / "nope.sqlite"), "--out", str(tmp_path / "y")]) == 2
    assert "no such file" in capsys.readouterr().err


def scored(seed: int, outcomes: list[str]) -> Scored:
    src = CruiseSource.from_garage(paint_garage("tiny_7x11", seed=seed), f"g{seed}")
    return Scored(src, rows=[{"outcome": o} for o in outcomes])


def test_the_closing_lines_list_only_garages_with_a_failure():
    ranked = [scored(1, ["collision", "success"]), scored(2, ["missed_goal", "success", "success"]),
              scored(3, ["success", "success"]), scored(4, ["infeasible"])]
    res = HuntResult(Path("h"), 7, 2, ranked, {}, action_label="continuous actions, the driver's own")
    assert failure_summary(res).splitlines() == [
        "7 tests on 4 garages in 2 generations (continuous actions, the driver's own); 2 garages with a failure:",
        "  g1: 1 of 2 feasible tests failed (50%)",
        "  g2: 1 of 3 feasible tests failed (33%)"]
    many = HuntResult(Path("h"), 7, 2, [scored(s, ["timeout"]) for s in range(1, 8)], {}, action_label="x")
    lines = failure_summary(many).splitlines()
    assert lines[0].endswith("; 7 garages with a failure, the 5 worst:") and len(lines) == 6
    none = HuntResult(Path("h"), 2, 1, [scored(3, ["success", "success"])], {}, action_label="x")
    assert failure_summary(none) == "2 tests on 1 garage in 1 generation (x); 0 garages with a failure"


def test_cli_hunt_runs_the_drivers_own_action_type(tmp_path, capsys):
    out = tmp_path / "h"
    assert main(["hunt", "--map", "tiny_7x11", "--driver", "waypoint", "--budget", "2", "--tests", "1",
                 "--population", "2", "--elites", "1", "--worst", "1", "--no-videos", "--quiet",
                 "--out", str(out)]) == 0
    printed, err = capsys.readouterr()
    assert "warning" not in err
    assert "garages in 0 generations (continuous actions, the driver's own); " in printed.splitlines()[0]
    state = json.loads((out / "hunt.json").read_text())
    assert (state["settings"]["action_type"], state["action_type_from"]) == ("continuous", "driver")


def test_the_report_has_the_demo_reports_style_and_names_videos_by_garage(hunted):
    from garage_mj.reporting.cruise import video_name
    from garage_mj.reporting.hunt import record_videos, write_hunt_report
    from garage_mj.reporting.report import CSS
    from tests.browser import page_facts

    out, res = hunted
    mp4s = record_videos(res)
    first = next(r for r in res.worst[0].failures if r["outcome"] not in ("driver_crash", "driver_timeout"))
    assert [p.name for p in mp4s] == [video_name(first)]  # <garage>_<test>_<outcome>.mp4, as cruise names them
    assert mp4s[0].name.startswith(video_name(first).split("_0")[0]) and mp4s[0].is_file()
    report = write_hunt_report(out, res.table, res.worst, res.files["packs"], res.files["xosc"], mp4s, "waypoint")
    assert CSS in report.read_text()
    facts = page_facts(report)
    assert facts["imgs"] and all(i["loaded"] for i in facts["imgs"]), facts["imgs"]
    assert f"videos/{mp4s[0].name}" in facts["links"]
    (table,) = facts["tables"]
    assert table["id"] == "hunt-table" and table["rows"] == min(50, len(res.table))
