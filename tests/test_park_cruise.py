"""Park runs of ``garage-mj cruise`` (docs/spec.md section 8): the park columns, the settings, old tests.csv files."""

from __future__ import annotations

import csv
import json

import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.driving.results import (
    LEGACY_TEST_COLUMNS,
    PARK_COLUMNS,
    PARK_SUMMARY_COLUMNS,
    SUMMARY_COLUMNS,
    TEST_COLUMNS,
    read_tests,
    write_csv,
)
from garage_mj.driving.sources import CruiseError, CruiseSettings
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.cruise import run_cruise
from garage_mj.scene.park_levels import LEVELS

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short cruise time limits keep tests quick
QUIET = Compute(progress=False)


@pytest.fixture(scope="module")
def garage():
    return paint_garage("tiny_7x11", seed=1)


def rows_of(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_cli_cruise_task_park_writes_the_park_columns_and_warns_of_a_cruise_driver(garage, tmp_path, capsys):
    from garage_mj.export.pack import export_pack

    packs = tmp_path / "packs"
    export_pack(garage, packs)
    out = tmp_path / "park"
    assert main(["cruise", "--packs", str(packs), "--tests", "2", "--driver", "waypoint", "--task", "park",
                 "--maneuver", "forward", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr()
    err = printed.err
    assert "success by level: " in printed.out and "success by stall angle [deg]: 90 " in printed.out
    warning = [line for line in err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "'waypoint'" in warning[0] and "cannot select reverse" in warning[0]
    rows = rows_of(out / "tests.csv")
    assert list(rows[0]) == list(TEST_COLUMNS) and len(rows) == 2
    for r in rows:
        assert r["task"] == "park" and r["maneuver"] == "forward" and r["feasible"] == "1"
        assert r["outcome"] in ("success", "collision", "timeout", "deadlock", "outside_stall")
        assert float(r["plan_length_m"]) > 0 and int(r["plan_cusps"]) >= 0 and float(r["plan_clearance_m"]) >= 0
        assert r["position_error_m"] != "" and r["heading_error_deg"] != "" and r["lateral_offset_m"] != ""
        assert int(r["direction_changes"]) >= 0 and float(r["park_time_s"]) > 0 and r["min_clearance_m"] != ""
        assert r["park_level"] in LEVELS and r["stall_angle_deg"] == "90.0"  # docs/spec.md section 9
        assert r["inner_margin_m"] != "" and r["outline_clearance_m"] != ""
        if r["outcome"] == "success":
            assert float(r["min_clearance_m"]) > 0 and float(r["inner_margin_m"]) >= 0
    summary = rows_of(out / "summary.csv")
    assert list(summary[0]) == [*SUMMARY_COLUMNS, *PARK_SUMMARY_COLUMNS]
    assert summary[0]["mean_position_error_m"] != ""
    stats = json.loads((out / "summary.json").read_text())
    assert sum(g["tests"] for g in stats["by_level"].values()) == 2 and list(stats["by_maneuver"]) == ["forward"]
    run = json.loads((out / "run.json").read_text())
    assert (run["task"], run["maneuver"]) == ("park", "forward")
    # a resume with another task is refused by the settings check, naming it
    assert main(["cruise", "--packs", str(packs), "--tests", "2", "--driver", "waypoint", "--out", str(out),
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "other settings" in err and "task" in err
    assert main(["cruise", "--packs", str(packs), "--tests", "1", "--driver", "waypoint", "--task", "park",
                 "--stall", "9999", "--out", str(tmp_path / "bad"), "--quiet"]) != 0
    assert "stall 9999 does not exist" in capsys.readouterr().err


def test_a_cruise_run_keeps_its_files_and_an_old_tests_csv_resumes(garage, tmp_path):
    out = tmp_path / "cruise"
    first = run_cruise([garage], 1, CruiseSettings("waypoint", env=FAST), out, compute=QUIET, route_model=False)
    run = json.loads((out / "run.json").read_text())
    assert not {"task", "maneuver", "stall"} & set(run)  # a cruise run.json as before park tests
    assert list(rows_of(out / "summary.csv")[0]) == list(SUMMARY_COLUMNS)
    row = first.rows[0]
    assert row["task"] == "cruise" and all(row[c] == "" for c in PARK_COLUMNS if c != "task")
    # the file as garage-mj wrote it before park tests: the legacy columns only
    write_csv(out / "tests.csv", LEGACY_TEST_COLUMNS, first.rows)
    again = run_cruise([garage], 2, CruiseSettings("waypoint", env=FAST), out, compute=QUIET, route_model=False)
    assert again.tests_run == 1  # the old row was kept, one new test ran
    rows = rows_of(out / "tests.csv")
    assert list(rows[0]) == list(TEST_COLUMNS) and [r["task"] for r in rows] == ["cruise", "cruise"]
    assert {k: rows[0][k] for k in LEGACY_TEST_COLUMNS} == {k: str(first.rows[0][k]) for k in LEGACY_TEST_COLUMNS}
    # without its header too
    with open(out / "tests.csv", "w", newline="") as f:
        csv.DictWriter(f, LEGACY_TEST_COLUMNS, extrasaction="ignore").writerows(rows)
    assert len(read_tests(out / "tests.csv")) == 2


def test_park_settings_are_checked():
    with pytest.raises(CruiseError, match="task 'valet'"):
        CruiseSettings("oracle", task="valet")
    CruiseSettings("oracle", task="park", env={"scenario": {"pedestrians": 1}})  # park tests take actors too
    stored = CruiseSettings.from_stored({"driver": "oracle", "seed": 0, "action_type": "continuous",
                                         "occupancy": 0.5})  # a run.json from before park tests
    assert (stored.task, stored.maneuver, stored.stall) == ("cruise", "reverse", None)
