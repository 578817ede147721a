"""Batch cruise: paper regression, CSV append/resume, worker-count independence, CLI and video."""

from __future__ import annotations

import csv
import json

import cv2
import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.driving.difficulty.regression import (
    PAPER_R,
    PAPER_TABLE,
    paper_regression,
    pearson,
    regression,
)
from garage_mj.driving.drivers import ActionTypeWarning
from garage_mj.driving.results import SUMMARY_COLUMNS, TEST_COLUMNS, read_tests, write_csv, write_outputs
from garage_mj.driving.sources import CruiseError, CruiseSettings, CruiseSource, cruise_seed
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.cruise import pick_tests, run_cruise, video_name

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick
QUIET = Compute(progress=False)  # one process, no progress bar


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


def test_attainable_r_is_what_a_perfect_difficulty_reaches_through_test_noise():
    import numpy as np

    from garage_mj.driving.difficulty.regression import attainable_r, bootstrap_attainable_r

    rng = np.random.default_rng(0)
    for spread, tests in ((0.0, 50), (0.05, 50), (0.2, 50), (0.05, 800)):
        truth = np.clip(0.7 + rng.normal(0.0, spread, 3000), 0.0, 1.0)  # each garage's true success rate
        measured = 100.0 * rng.binomial(tests, truth) / tests
        got = attainable_r(measured, [tests] * len(truth))
        if spread:  # a difficulty = -truth would reach this |r|
            assert got == pytest.approx(pearson(truth, measured), abs=0.05)
        else:  # noise alone: near 0 (the square root lifts a small positive estimate)
            assert got < 0.2
    lo, hi = bootstrap_attainable_r(measured, [tests] * len(measured))
    assert lo <= attainable_r(measured, [tests] * len(measured)) <= hi
    assert attainable_r([90.0, 90.0], [50, 50]) != attainable_r([90.0, 90.0], [50, 50])  # no spread: NaN


def test_test_seeds_depend_only_on_seed_garage_and_index():
    assert cruise_seed(0, "ab", 3) == cruise_seed(0, "ab", 3)
    assert len({cruise_seed(0, "ab", i) for i in range(50)} | {cruise_seed(1, "ab", 0)}) == 51


def test_append_resume_no_duplicates_no_loss(garages, tmp_path):
    out = tmp_path / "run"
    first = run_cruise(garages, 2, CruiseSettings("waypoint", seed=5, env=FAST), out, max_tests=3,
                       compute=QUIET)
    assert first.tests_run == 3 and len(rows_of(out / "tests.csv")) == 3  # "interrupted" after 3
    before = rows_of(out / "tests.csv")
    second = run_cruise(garages, 2, CruiseSettings("waypoint", seed=5, env=FAST), out, compute=QUIET)
    after = rows_of(out / "tests.csv")
    assert second.tests_run == 1 and after[:3] == before
    assert sorted((r["garage_hash"], r["test"]) for r in after) == sorted(
        {(r["garage_hash"], r["test"]) for r in after})
    assert len(after) == 4
    assert run_cruise(garages, 2, CruiseSettings("waypoint", seed=5, env=FAST), out,
                      compute=QUIET).tests_run == 0
    summary = rows_of(out / "summary.csv")
    assert [int(r["tests"]) for r in summary] == [2, 2]
    assert set(summary[0]) >= {"garage", "difficulty", "E[X]", "E[Y]", "collisions", "timeouts", "deadlocks",
                               "success_pct"}
    stats = json.loads((out / "summary.json").read_text())
    assert {"r", "slope", "intercept", "n"} <= set(stats) and stats["n"] == 2
    assert (out / "regression.png").stat().st_size > 1000
    assert all(r["outcome"] in ("success", "collision", "timeout", "deadlock", "missed_goal") for r in after)
    # no action type given: the driver's own (waypoint: continuous), recorded with where it came from
    run = json.loads((out / "run.json").read_text())
    assert (run["action_type"], run["action_type_from"]) == ("continuous", "driver")
    assert (stats["action_type"], stats["action_type_from"]) == ("continuous", "driver")
    assert second.action_label == "continuous actions, the driver's own"


def test_another_action_type_is_warned_recorded_and_resumes(garages, tmp_path):
    out = tmp_path / "discrete"
    with pytest.warns(ActionTypeWarning, match="driver 'waypoint' is made for continuous actions but runs with "
                                               "discrete ones"):
        first = run_cruise(garages[:1], 1, CruiseSettings("waypoint", action_type="discrete", env=FAST), out,
                           compute=QUIET)
    run = json.loads((out / "run.json").read_text())
    stats = json.loads((out / "summary.json").read_text())
    assert (run["action_type"], run["action_type_from"]) == ("discrete", "--action-type")
    assert (stats["action_type"], stats["action_type_from"]) == ("discrete", "--action-type")
    assert first.action_label == "discrete actions from --action-type; the driver's own: continuous"
    with pytest.warns(ActionTypeWarning):
        again = run_cruise(garages[:1], 1, CruiseSettings("waypoint", action_type="discrete", env=FAST), out,
                           compute=QUIET)
    assert again.tests_run == 0  # the same settings: resumed
    with pytest.raises(CruiseError, match='other settings \\(action_type "discrete" there, "continuous" now\\); '
                                          'use another --out or the same settings to resume it '
                                          '\\(--action-type discrete\\)'):
        run_cruise(garages[:1], 1, CruiseSettings("waypoint", env=FAST), out, compute=QUIET)


def test_a_run_json_without_action_type_from_resumes(garages, tmp_path):
    # a folder from before action types were the driver's own: its run.json has an explicit action_type only
    out = tmp_path / "old"
    run_cruise(garages[:1], 1, CruiseSettings("waypoint", action_type="continuous", env=FAST), out,
               compute=QUIET)
    run = json.loads((out / "run.json").read_text())
    assert run.pop("action_type_from") == "--action-type"
    (out / "run.json").write_text(json.dumps(run))
    assert run_cruise(garages[:1], 1, CruiseSettings("waypoint", env=FAST), out, compute=QUIET).tests_run == 0
    assert run_cruise(garages[:1], 1, CruiseSettings("waypoint", action_type="continuous", env=FAST), out,
                      compute=QUIET).tests_run == 0


def fake_row(source: CruiseSource, test: int, outcome: str, reason: str = "") -> dict:
    row = dict.fromkeys(TEST_COLUMNS, "")
    row.update(garage=source.name, garage_hash=source.hash, test=str(test), seed="1", driver="vision",
               target_stall="3", feasible="0" if outcome == "infeasible" else "1", outcome=outcome, reason=reason,
               time="20.0", path_length="10.0", route_length="12.0", difficulty=str(source.difficulty),
               wall_s="0.5")
    return row


def test_missed_goals_are_counted_and_old_deadlock_rows_load(garages, tmp_path):
    src = CruiseSource.from_garage(garages[0])
    old = [fake_row(src, 0, "deadlock", "no progress for 8.0 s, stopped 1.20 m and 0.40 rad from the goal pose"),
           fake_row(src, 1, "success")]  # a tests.csv from before missed_goal had a class of its own
    write_csv(tmp_path / "tests.csv", TEST_COLUMNS, old)
    rows = read_tests(tmp_path / "tests.csv") + [
        fake_row(src, 2, "missed_goal", "stopped 1.50 m and 0.40 rad from the goal pose (tolerance 1 m, 0.35 rad)"),
        fake_row(src, 3, "missed_goal", "stopped 2.00 m ..."), fake_row(src, 4, "collision")]
    assert [r["outcome"] for r in rows[:2]] == ["deadlock", "success"]
    summary, stats = write_outputs(tmp_path, rows, [src], CruiseSettings("vision"))
    header = (tmp_path / "summary.csv").read_text().splitlines()[0].split(",")
    assert header == list(SUMMARY_COLUMNS) and header.index("missed_goals") == header.index("deadlocks") + 1
    assert (summary[0]["deadlocks"], summary[0]["missed_goals"], summary[0]["success_pct"]) == (1, 2, 20.0)
    assert stats["failures"] == {"collision": 1, "timeout": 0, "deadlock": 1, "missed_goal": 2, "outside_stall": 0,
                                 "driver_crash": 0, "driver_timeout": 0}
    assert stats["paper_failures"] == {"collision": 1, "timeout": 0, "deadlock": 3}  # missed goals are deadlocks


def test_videos_show_failures_first(garages):
    a, b = (CruiseSource.from_garage(g) for g in garages)
    rows = [fake_row(b, 0, "collision"), fake_row(a, 1, "success"), fake_row(a, 0, "infeasible"),
            fake_row(a, 2, "missed_goal"), fake_row(a, 0, "success") | {"garage_hash": "elsewhere"},
            fake_row(a, 3, "driver_crash"), fake_row(b, 1, "driver_timeout")]
    picked = pick_tests(rows, [a, b], 5)
    assert [(r["garage_hash"], r["outcome"]) for r in picked] == [
        (a.hash, "missed_goal"), (b.hash, "collision"), (a.hash, "success")]  # never an infeasible one, nor one
    # whose driver crashed or hung (driven again, it would again)
    assert pick_tests(rows, [a, b], 1) == picked[:1]
    assert video_name({"garage": "m5#12", "test": 3, "outcome": "missed_goal"}) == "m5-12_00003_missed_goal.mp4"


def test_a_torn_last_line_is_dropped_and_rerun(garages, tmp_path):
    out = tmp_path / "torn"
    run_cruise(garages[:1], 2, CruiseSettings("waypoint", env=FAST), out, compute=QUIET)
    good = rows_of(out / "tests.csv")
    text = (out / "tests.csv").read_text()
    (out / "tests.csv").write_text(text[: len(text) - 20])  # crash in the middle of the last row
    assert len(read_tests(out / "tests.csv")) == 1
    again = run_cruise(garages[:1], 2, CruiseSettings("waypoint", env=FAST), out, compute=QUIET)
    assert again.tests_run == 1
    assert [r["outcome"] for r in rows_of(out / "tests.csv")] == [r["outcome"] for r in good]


def test_occupancy_is_a_setting_not_an_env_keyword():
    with pytest.raises(CruiseError, match="occupancy is a cruise setting of its own"):
        CruiseSettings("waypoint", env={"occupancy": 0.2})
    split = CruiseSettings.from_env_kwargs("waypoint", {"occupancy": 0.2, "camera": False}, seed=3)
    assert (split.occupancy, split.env, split.seed) == (0.2, {"camera": False}, 3)
    assert CruiseSettings.from_env_kwargs("waypoint", None).occupancy == CruiseSettings().occupancy


def test_other_settings_are_refused(garages, tmp_path):
    run_cruise(garages[:1], 1, CruiseSettings("waypoint", env=FAST), tmp_path, compute=QUIET)
    with pytest.raises(CruiseError, match="other settings .*driver"):
        run_cruise(garages[:1], 1, CruiseSettings("vision", env=FAST), tmp_path, compute=QUIET)


def test_results_do_not_depend_on_the_worker_count(garages, tmp_path):
    one = run_cruise(garages, 2, CruiseSettings("vision", env=FAST), tmp_path / "w1",
                     compute=Compute(workers=1, progress=False))
    two = run_cruise(garages, 2, CruiseSettings("vision", env=FAST), tmp_path / "w2",
                     compute=Compute(workers=2, progress=False))

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
                 "waypoint", "--out", str(tmp_path / "c"), "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "Pearson r" in out and "feasible (continuous actions, the driver's own), Pearson" in out
    assert "Pearson r(difficulty, success) = too few garages (2) for a correlation (paper -0.638)" in out
    assert "warning" not in err
    assert len(rows_of(tmp_path / "c" / "tests.csv")) == 2
    assert main(["cruise", "--library", str(library), "--tests", "1", "--driver", "nope:Nothing",
                 "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("garage-mj cruise: error: driver 'nope:Nothing'") and "\n" not in err
    assert main(["cruise", "--packs", str(tmp_path / "missing"), "--out", str(tmp_path / "e")]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_cli_another_action_type_is_one_warning_line(library, tmp_path, capsys):
    assert main(["cruise", "--library", str(library), "--limit", "1", "--tests", "1", "--driver", "oracle",
                 "--action-type", "discrete", "--out", str(tmp_path / "c"), "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert err.splitlines() == [
        "garage-mj cruise: warning: driver 'oracle' is made for continuous actions but runs with discrete ones: "
        "its [throttle, steer] commands are rounded to the paper's 4 actions, which costs precision (the waypoint "
        "driver succeeds in 24% of feasible tests that way, 99% with its own); leave out --action-type to use its own"]
    assert "(discrete actions from --action-type; the driver's own: continuous)" in out


@pytest.mark.parametrize("command", ["cruise", "hunt"])
def test_help_says_the_action_type_defaults_to_the_drivers_own(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "(default: the driver's own;" in " ".join(capsys.readouterr().out.split())


def test_cli_videos_of_the_batch_in_out(library, tmp_path, capsys):
    out = tmp_path / "v"
    argv = ["cruise", "--library", str(library), "--tests", "2", "--driver", "waypoint", "--videos", "3",
            "--out", str(out), "--quiet"]
    assert main(argv) == 0
    printed = capsys.readouterr().out.splitlines()
    rows = rows_of(out / "tests.csv")
    assert len(rows) == 4
    videos = sorted((out / "videos").glob("*.mp4"))
    assert len(videos) == 3 and printed[1] == f"3 video(s) in {out / 'videos'}:"
    by_name = {video_name(r): r for r in rows}
    for line in printed[2:]:
        name, outcome = line.strip().split(": ")[:2]
        assert by_name[name]["outcome"] == outcome.split(" (")[0]  # the outcome of tests.csv, in the name too
    assert {p.name for p in videos} == {ln.strip().split(": ")[0] for ln in printed[2:]} <= set(by_name)
    cap = cv2.VideoCapture(str(videos[0]))
    frames = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames += 1
        assert frame.shape == (240, 320, 3)
    cap.release()
    assert frames > 5
    stamps = {p: p.stat().st_mtime_ns for p in videos}
    assert main(argv) == 0  # a re-run: no test, the videos kept
    assert "(0 new)" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in videos} == stamps


def test_cli_video_file_name_is_one_line(library, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["cruise", "--library", str(library), "--videos", str(tmp_path / "one.mp4")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith(("usage:", " "))]
    assert len(err) == 1 and "give how many tests to record into OUT/videos/ (e.g. --videos 3)" in err[0]
    with pytest.raises(SystemExit):  # no prefix matching: --video is not --videos
        main(["cruise", "--library", str(library), "--video", "3"])
    assert capsys.readouterr().err.strip().endswith("unrecognized arguments: --video 3; did you mean --videos?")


def test_sources_carry_the_metrics(garages):
    s = CruiseSource.from_garage(garages[0])
    assert 0 <= s.difficulty <= 1 and s.mean_road_length > 0 and s.name.startswith("tiny_7x11-")


def test_no_one_difficulty_beats_the_joint_bound_of_two_drivers():
    """joint_r_bound: whatever a difficulty is, it cannot have r <= -x with both drivers' success for x above
    sqrt((1 + r_ab) / 2)."""
    import math

    import numpy as np

    from garage_mj.driving.difficulty.fit import driver_agreement
    from garage_mj.driving.difficulty.regression import joint_r_bound, pearson

    rng = np.random.default_rng(0)
    for _ in range(200):
        a, b = rng.normal(size=30), rng.normal(size=30)
        bound = joint_r_bound(pearson(a, b))
        for w in np.linspace(0, 1, 21):  # the best difficulties lie between the two (here: blends of them)
            d = w * (a - a.mean()) / a.std() + (1 - w) * (b - b.mean()) / b.std() + 0.1 * rng.normal(size=30)
            assert min(-pearson(d, a), -pearson(d, b)) <= bound + 1e-9  # r <= -x with both: x <= bound
            assert min(pearson(d, a), pearson(d, b)) <= bound + 1e-9
    ua, ub = rng.normal(size=30), rng.normal(size=30)  # the bisector of the normalized vectors reaches it
    ua, ub = (ua - ua.mean()) / np.linalg.norm(ua - ua.mean()), (ub - ub.mean()) / np.linalg.norm(ub - ub.mean())
    assert pearson(ua + ub, ua) == pytest.approx(joint_r_bound(pearson(ua, ub)))
    assert joint_r_bound(1.0) == 1.0 and joint_r_bound(0.0) == pytest.approx(0.7071, abs=1e-4)
    assert math.isnan(joint_r_bound(math.nan))
    # from test records: per-garage success of each driver over the garages both drove
    recs = [{"driver": d, "garage_hash": f"g{g}", "failed": int(t < k)}
            for g, (ka, kb) in enumerate([(0, 5), (2, 3), (5, 0), (1, 1)]) for d, k in (("a", ka), ("b", kb))
            for t in range(10)]
    recs.append({"driver": "a", "garage_hash": "only_a", "failed": 0})
    got = driver_agreement(recs)["a+b"]
    r = pearson([100, 80, 50, 90], [50, 70, 100, 90])
    assert got["garages"] == 4 and got["r_between"] == pytest.approx(r, abs=1e-4)
    assert got["best_joint_abs_r"] == pytest.approx(joint_r_bound(r), abs=1e-4)


def test_a_driver_with_non_finite_actions_fails_as_the_drivers_error_not_a_deadlock(garages, tmp_path, capsys,
                                                                                    monkeypatch):
    """A NaN action is the driver's error, reported as one line like a driver that raises; no row is written."""
    import sys
    import textwrap

    from garage_mj.cli import main
    from garage_mj.export.pack import export_pack

    (tmp_path / "nan_driver.py").write_text(textwrap.dedent("""
        class NaNDriver:
            action_type = "continuous"

            def reset(self, info):
                self.steps = 0

            def act(self, obs):
                self.steps += 1
                return [0.5, 0.0] if self.steps < 5 else [float("nan"), 0.0]
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    packs = tmp_path / "packs"
    export_pack(garages[0], packs)
    out = tmp_path / "run"
    assert main(["cruise", "--packs", str(packs), "--tests", "1", "--driver", "nan_driver:NaNDriver", "--quiet",
                 "--out", str(out)]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and "driver 'nan_driver:NaNDriver' failed on" in lines[0], lines
    assert "ValueError: the driver's action [nan, 0.0] is not finite" in lines[0]
    tests_csv = out / "tests.csv"
    assert not tests_csv.exists() or "deadlock" not in tests_csv.read_text()
    sys.modules.pop("nan_driver", None)


def test_library_ids_export_and_cruise_and_export_json_lists(library, tmp_path, capsys):
    """export --garage reads what library export-json writes; --ids picks library rows for export and cruise."""
    dump = tmp_path / "lib.json"
    assert main(["library", "export-json", str(library), "--out", str(dump)]) == 0
    assert main(["export", "--garage", str(dump), "--out", str(tmp_path / "from_json"), "--quiet"]) == 0
    assert main(["export", "--library", str(library), "--out", str(tmp_path / "from_lib"), "--quiet"]) == 0
    packs = sorted(p.name for p in (tmp_path / "from_json").iterdir() if p.is_dir())
    assert len(packs) == 2 and packs == sorted(p.name for p in (tmp_path / "from_lib").iterdir() if p.is_dir())
    assert main(["export", "--library", str(library), "--ids", "2", "--out", str(tmp_path / "two"), "--quiet"]) == 0
    assert [p.name for p in (tmp_path / "two").iterdir() if p.is_dir()] == [packs[1]]
    capsys.readouterr()
    assert main(["cruise", "--library", str(library), "--ids", "2", "2", "--tests", "1", "--driver", "waypoint",
                 "--out", str(tmp_path / "c"), "--quiet"]) == 0
    assert {r["garage"] for r in rows_of(tmp_path / "c" / "tests.csv")} == {"tiny_7x11#2"}
    assert not list(tmp_path.rglob(".garage-mj.lock"))  # export's and cruise's locks go when they end
    capsys.readouterr()
    for argv, message in (
        (["export", "--library", str(library), "--ids", "9", "--out", str(tmp_path / "x")], "has no garage with id 9"),
        (["cruise", "--library", str(library), "--ids", "1", "--map", "tiny_7x11", "--out", str(tmp_path / "x")],
         "--ids picks garages by row id; leave out --map"),
        (["export", "--garage", str(dump), "--ids", "1", "--out", str(tmp_path / "x")], "pick garages of a --library"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err
    data = json.loads(dump.read_text())
    data[1]["hash"] = "0" * 64
    dump.write_text(json.dumps(data))
    assert main(["export", "--garage", str(dump), "--out", str(tmp_path / "y")]) == 2
    assert f"{dump}, garage 2 of 2: the grid does not match its stored hash" in capsys.readouterr().err


def test_a_tests_wall_time_leaves_out_loading_the_driver(tmp_path, monkeypatch):
    """``wall_s`` is the test's own time: a worker's first test does not pay for building its driver (a model load)."""
    import sys
    import textwrap

    from garage_mj.driving.cruise import run_test
    from garage_mj.driving.episode import forget_cached
    from garage_mj.driving.sources import painted_sources

    (tmp_path / "slow_driver.py").write_text(textwrap.dedent("""
        import time

        class SlowToLoad:
            action_type = "continuous"

            def __init__(self):
                time.sleep(3.0)  # a large model's load

            def reset(self, info):
                pass

            def act(self, obs):
                return [0.0, 0.0]
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    (source,) = painted_sources("tiny_7x11", 1, seed=0)
    settings = CruiseSettings(driver="slow_driver:SlowToLoad", seed=0, action_type="continuous")
    forget_cached()  # as in a fresh worker process: no driver built yet
    try:
        row = run_test(source, 0, settings)
    finally:
        forget_cached()
        sys.modules.pop("slow_driver", None)
    assert row["outcome"] == "deadlock" and 0 < float(row["wall_s"]) < 3.0, row
