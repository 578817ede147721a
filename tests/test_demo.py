"""The main job end to end at toy scale: every stage runs, the report opens in Chromium and shows what a
newcomer checks: each driver's action type, the failures' reasons per class with tests.csv, an MP4 and a
.xosc of the first failures, and a garage's difficulty written the same in the gallery and the table."""

from __future__ import annotations

import csv
import json
import re

import cv2
import numpy as np

from garage_mj.driving.drivers import action_type_of
from garage_mj.driving.results import COUNT_COLUMNS
from garage_mj.reporting.demo import DemoConfig, run_demo, run_folder
from tests.browser import page_facts

STILL = "tests.test_demo:StandStill"


class StandStill:
    """A driver that never moves: every test it drives fails (no progress), so the report has failures to show."""

    action_type = "continuous"

    def reset(self, info: dict) -> None:
        pass

    def act(self, obs: dict) -> np.ndarray:
        return np.zeros(2, dtype=np.float32)


def _rows(path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_demo_end_to_end_report_in_chromium(tmp_path):
    # two cruise drivers (the oracle's cruise runs are in test_cruise.py) and the oracle parking in both tasks and
    # both maneuvers (park_assist's park tests are in test_park_oracle.py, a park report's failure pictures in
    # test_report.py), one test each
    cfg = DemoConfig(timesteps=2500, train_seeds=(0, 1), garages=2, tests=1, workers=1, out=str(tmp_path / "demo"),
                     drivers=("vision", STILL), actor_drivers=("vision",), failure_videos=1,
                     park_drivers=("oracle",), park_maneuvers=("forward",), avp_maneuver="reverse",
                     park_garages=1, park_tests=1)
    report = run_demo(cfg)
    out = tmp_path / "demo"
    assert report == out / "report.html"
    facts = page_facts(report)
    text = facts["text"]
    assert facts["imgs"] and all(i["loaded"] for i in facts["imgs"]), facts["imgs"]
    # convergence + heatmap + (preview + MuJoCo render) per garage + regression on the paper's difficulty (no
    # route difficulty: no shipped route model was fitted on these drivers with their continuous actions)
    packs = [link for link in facts["links"] if link.startswith("packs/")]
    garages = len(packs)
    assert garages >= 1
    park_runs = [("oracle", "park", "forward"), ("oracle", "avp", "reverse")]
    park_pictures = [i["src"] for i in facts["imgs"] if "/pictures/" in i["src"]]  # the park failures shown
    # ... then each park or AVP run's park_success.png, and a top-down picture per park failure shown
    assert len(facts["imgs"]) == 2 + 2 * garages + 1 + len(park_runs) + len(park_pictures)
    assert "no route difficulty (no shipped model was fitted on this driver with these actions)" in facts["text"]
    for link in packs:
        assert (out / link / "manifest.json").is_file()
    (table,) = [t for t in facts["tables"] if t["id"] == "cruise-table"]
    # every driver, then the actor drivers again with adverse events (pedestrians, moving cars, clutter)
    assert table["rows"] == garages * (len(cfg.drivers) + len(cfg.actor_drivers)) and table["empty_cells"] == 0
    head = table["head"]
    # one column per failure kind of the outcome table, in its order, then the success rate
    kinds = [c.replace("_", " ") for c in COUNT_COLUMNS.values()]
    assert [h for h in head if h in kinds] == kinds and head[-1] == "success of feasible"
    assert head.index("missed goals") == head.index("deadlocks") + 1
    for row in table["cells"]:
        cell = dict(zip(head, row))
        assert cell["actions"] == action_type_of(cell["driver"].removesuffix(" + actors"))
        assert re.fullmatch(r"\d+\.\d%|n/a", cell["success of feasible"]), cell
    # a garage's difficulty reads the same in the gallery and in the table
    gallery = dict(re.findall(r"garage (\S+) · asset pack\s+difficulty (\d\.\d{3})", text))
    assert len(gallery) == garages
    for row in table["cells"]:  # the gallery names a garage as the table and tests.csv do
        assert gallery[row[0]] == row[head.index("difficulty")], row
    # counts in words: singular where there is one
    assert f"{garages} garage{'s' if garages > 1 else ''}, 1 cruise test per garage and driver" in text
    assert "with actors (1 pedestrian, 1 moving car, 1 clutter object)" in text
    assert "vision + actors" in text and "collisions by what was hit" in text
    assert "a missed goal counts as a deadlock" in text

    failed_runs = 0
    for driver, actors in [(d, False) for d in cfg.drivers] + [(d, True) for d in cfg.actor_drivers]:
        run = f"cruise/{run_folder(driver, actors)}"
        label = driver + (" + actors" if actors else "")
        heading = f"\n{label} · {action_type_of(driver)} actions\n"
        assert heading in text
        assert f"{run}/tests.csv" in facts["links"]
        rows = _rows(out / run / "tests.csv")
        failures = [r for r in rows if r["outcome"] not in ("success", "infeasible")]
        section = text.split(heading, 1)[1]
        section = re.split(r"\n[^\n]+ · (?:continuous|discrete) actions\n", section)[0]  # up to the next run
        for kind in {r["outcome"] for r in failures}:  # every failure class with its count and reasons
            n = sum(r["outcome"] == kind for r in failures)
            assert f"{kind.replace('_', ' ')} ({n})" in section, (label, kind)
        videos = [link for link in facts["links"] if link.startswith(f"{run}/videos/")]
        xoscs = [link for link in facts["links"] if link.startswith(f"{run}/xosc/")]
        assert len(videos) == len(xoscs) == min(cfg.failure_videos, len(failures)), label
        failed_runs += bool(failures)
        for video, xosc in zip(videos, xoscs, strict=True):
            cap = cv2.VideoCapture(str(out / video))
            assert cap.isOpened() and cap.get(cv2.CAP_PROP_FRAME_COUNT) > 0, video
            cap.release()
            assert (out / xosc).read_text().lstrip().startswith("<?xml"), xosc
            (row,) = [r for r in failures if f"{r['garage_hash'][:12]}_{int(r['test']):05d}" in xosc]
            assert row["outcome"] in ("collision", "timeout", "deadlock", "missed_goal")
            assert row["reason"] in text
    assert failed_runs >= 1  # the standing driver fails every test it drives
    _assert_parking_section(facts, out, park_runs)
    index = json.loads((out / "packs" / "index.json").read_text())
    assert len(index["packs"]) == garages
    # a second run resumes every stage (tests, videos) and rewrites the same report
    before = (out / "cruise" / "vision" / "tests.csv").read_text()
    mp4s = {p: p.stat().st_mtime_ns for p in out.glob("cruise/*/videos/*.mp4")}
    run_demo(cfg)
    assert (out / "cruise" / "vision" / "tests.csv").read_text() == before
    assert {p: p.stat().st_mtime_ns for p in out.glob("cruise/*/videos/*.mp4")} == mp4s


def _assert_parking_section(facts: dict, out, runs: list[tuple[str, str, str]]) -> None:
    """The report's park section: success by driver and task as each run's own files have it, each run's park table
    and park_success.png, and a top-down picture of each park failure shown."""
    text = facts["text"]
    assert "\nPark tests\n" in text and "success by driver and task" in text
    (summary,) = [t for t in facts["tables"] if t["id"] == "park-summary"]
    assert summary["rows"] == len(runs) and summary["empty_cells"] == 0
    head = summary["head"]
    srcs = {i["src"] for i in facts["imgs"]}
    for (driver, task, maneuver), row in zip(runs, summary["cells"], strict=True):
        cell = dict(zip(head, row))
        assert (cell["driver"], cell["task"], cell["maneuver"]) == (driver, {"avp": "AVP"}.get(task, task), maneuver)
        run = out / "park" / f"{driver}_{task}_{maneuver}"
        rows = _rows(run / "tests.csv")
        stats = json.loads((run / "summary.json").read_text())
        assert len(rows) == int(cell["tests"]) == 1 and {r["task"] for r in rows} == {task}
        assert {r["maneuver"] for r in rows if r["maneuver"]} <= {maneuver}
        wins = sum(r["outcome"] == "success" for r in rows)
        assert int(cell["successes"]) == wins and int(cell["feasible"]) == stats["feasible"]
        assert cell["success of feasible"] == (f"{stats['success_pct']:.1f}%" if stats["success_pct"] is not None
                                               else "n/a")
        assert f"park/{driver}_{task}_{maneuver}/park_success.png" in srcs
        failures = [r for r in rows if r["outcome"] not in ("success", "infeasible", "unproven")]
        pictures = [s for s in srcs if s.startswith(f"park/{driver}_{task}_{maneuver}/pictures/")]
        assert len(pictures) == len(failures), (driver, task, pictures)
        assert f"park/{driver}_{task}_{maneuver}/tests.csv" in facts["links"]
    oracle = [dict(zip(head, r)) for r in summary["cells"] if r[0] == "oracle"]
    assert sum(int(c["successes"]) for c in oracle) >= 1  # the oracle parks: the section has real numbers
    assert len([t for t in facts["tables"] if t["id"].startswith("park-table-")]) == len(runs)
    assert "success by level: " in text and "oracle park and AVP successes" in text
