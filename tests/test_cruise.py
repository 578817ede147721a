"""Batch cruise: paper regression, CSV append/resume, worker-count independence, CLI and video."""

from __future__ import annotations

import csv
import json

import cv2
import pytest

from garage_mj.cli import main
from garage_mj.driving.regression import PAPER_R, PAPER_TABLE, paper_regression, pearson, regression
from garage_mj.driving.results import read_tests
from garage_mj.driving.sources import CruiseError, CruiseSource, cruise_seed
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.cruise import run_cruise

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick


@pytest.fixture(scope="module")
def garages():
    return [paint_garage("tiny_7x11", seed=s) for s in (1, 2)]


def rows_of(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_paper_table_gives_the_papers_r():
    fit = paper_regression()
    assert fit.r == pytest.approx(PAPER_R, abs=0.005) and fit.n == len(PAPER_TABLE) == 16
    assert fit.slope < 0
    assert pearson([0, 1, 2], [5, 5, 5]) != pearson([0, 1, 2], [5, 5, 5])  # constant: NaN
    line = regression([0.0, 1.0], [100.0, 0.0])
    assert (line.r, line.slope, line.intercept) == pytest.approx((-1.0, -100.0, 100.0))


def test_test_seeds_depend_only_on_seed_garage_and_index():
    assert cruise_seed(0, "ab", 3) == cruise_seed(0, "ab", 3)
    assert len({cruise_seed(0, "ab", i) for i in range(50)} | {cruise_seed(1, "ab", 0)}) == 51


def test_append_resume_no_duplicates_no_loss(garages, tmp_path):
    out = tmp_path / "run"
    first = run_cruise(garages, 2, "waypoint", seed=5, out_dir=out, env=FAST, max_tests=3, progress=False)
    assert first.tests_run == 3 and len(rows_of(out / "tests.csv")) == 3  # "interrupted" after 3
    before = rows_of(out / "tests.csv")
    second = run_cruise(garages, 2, "waypoint", seed=5, out_dir=out, env=FAST, progress=False)
    after = rows_of(out / "tests.csv")
    assert second.tests_run == 1 and after[:3] == before
    assert sorted((r["garage_hash"], r["test"]) for r in after) == sorted(
        {(r["garage_hash"], r["test"]) for r in after})
    assert len(after) == 4
    assert run_cruise(garages, 2, "waypoint", seed=5, out_dir=out, env=FAST, progress=False).tests_run == 0
    summary = rows_of(out / "summary.csv")
    assert [int(r["tests"]) for r in summary] == [2, 2]
    assert set(summary[0]) >= {"garage", "difficulty", "E[X]", "E[Y]", "collisions", "timeouts", "deadlocks",
                               "success_pct"}
    stats = json.loads((out / "summary.json").read_text())
    assert {"r", "slope", "intercept", "n"} <= set(stats) and stats["n"] == 2
    assert (out / "regression.png").stat().st_size > 1000
    assert all(r["outcome"] in ("success", "collision", "timeout", "deadlock") for r in after)


def test_a_torn_last_line_is_dropped_and_rerun(garages, tmp_path):
    out = tmp_path / "torn"
    run_cruise(garages[:1], 2, "waypoint", out_dir=out, env=FAST, progress=False)
    good = rows_of(out / "tests.csv")
    text = (out / "tests.csv").read_text()
    (out / "tests.csv").write_text(text[: len(text) - 20])  # crash in the middle of the last row
    assert len(read_tests(out / "tests.csv")) == 1
    again = run_cruise(garages[:1], 2, "waypoint", out_dir=out, env=FAST, progress=False)
    assert again.tests_run == 1
    assert [r["outcome"] for r in rows_of(out / "tests.csv")] == [r["outcome"] for r in good]


def test_other_settings_are_refused(garages, tmp_path):
    run_cruise(garages[:1], 1, "waypoint", out_dir=tmp_path, env=FAST, progress=False)
    with pytest.raises(CruiseError, match="other settings .*driver"):
        run_cruise(garages[:1], 1, "vision", out_dir=tmp_path, env=FAST, progress=False)


def test_results_do_not_depend_on_the_worker_count(garages, tmp_path):
    one = run_cruise(garages, 2, "vision", workers=1, out_dir=tmp_path / "w1", env=FAST, progress=False)
    two = run_cruise(garages, 2, "vision", workers=2, out_dir=tmp_path / "w2", env=FAST, progress=False)

    def key(rows):
        return sorted(tuple(v for k, v in r.items() if k != "wall_s") for r in rows)

    assert key(one.rows) == key(two.rows)


@pytest.fixture(scope="module")
def library(garages, tmp_path_factory):
    from garage_mj.generation.library import Library

    path = tmp_path_factory.mktemp("lib") / "lib.sqlite"
    with Library(path) as lib:
        for i, g in enumerate(garages):
            lib.add(g, map="tiny_7x11", run="test", seed=i, episode=0, timestep=0)
    return path


def test_cli_cruise_runs_and_bad_driver_is_one_line(library, tmp_path, capsys):
    assert main(["cruise", "--library", str(library), "--map", "tiny_7x11", "--tests", "1", "--driver",
                 "waypoint", "--out", str(tmp_path / "c"), "--quiet", "--action-type", "continuous"]) == 0
    assert "Pearson r" in capsys.readouterr().out
    assert len(rows_of(tmp_path / "c" / "tests.csv")) == 2
    assert main(["cruise", "--library", str(library), "--tests", "1", "--driver", "nope:Nothing",
                 "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("garage-mj cruise: error: driver 'nope:Nothing'") and "\n" not in err
    assert main(["cruise", "--packs", str(tmp_path / "missing"), "--out", str(tmp_path / "e")]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_cli_video_is_a_readable_mp4(library, tmp_path):
    video = tmp_path / "one.mp4"
    assert main(["cruise", "--library", str(library), "--limit", "1", "--driver", "waypoint",
                 "--video", str(video)]) == 0
    cap = cv2.VideoCapture(str(video))
    frames = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames += 1
        assert frame.shape == (240, 320, 3)
    cap.release()
    assert frames > 5


def test_sources_carry_the_metrics(garages):
    s = CruiseSource.from_garage(garages[0])
    assert 0 <= s.difficulty <= 1 and s.mean_road_length > 0 and s.name.startswith("tiny_7x11-")
