"""Park problems as files: JSON and TPCAP cases written per park test, read back, a malformed file refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from garage_mj.cli import main
from garage_mj.export.park_problems import (
    INDEX,
    ParkProblemError,
    read_park_problem,
    read_tpcap_case,
    write_park_problems,
)
from garage_mj.scene.car import car_geometry
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import centre_to_rear, park_pose


@pytest.fixture(scope="module")
def written(painted_tiny, tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("park_problems")
    index = write_park_problems([painted_tiny], out)
    return out, json.loads(index.read_text())


def test_every_stall_with_a_cruise_test_gives_two_problems(painted_tiny, written):
    out, index = written
    scene = GarageScene(painted_tiny)
    feasible = [p.stall for p in drive_planner(scene).plans() if p.feasible]
    assert sorted((e["stall"], e["maneuver"]) for e in index["problems"]) == \
        sorted((s, m) for s in feasible for m in ("reverse", "forward"))
    assert len(index["skipped"]) == len(scene.stalls.stalls) - len(feasible)
    car = car_geometry()
    for entry in index["problems"][:6]:
        problem = read_park_problem(out / entry["json"])
        stall = scene.stalls.stalls[problem.stall]
        assert problem.goal_centre == pytest.approx(park_pose(stall, car, problem.maneuver))
        assert problem.goal == pytest.approx(tuple(centre_to_rear(problem.goal_centre, car)))
        assert problem.start_centre == pytest.approx(drive_planner(scene).plan(problem.stall).goal)
        assert {c for c, _ in problem.obstacles} <= {"wall", "obstacle", "pillar", "parked_car"}
        assert problem.obstacles  # walls at least


def test_json_and_tpcap_files_round_trip(written):
    out, index = written
    for entry in index["problems"][:6]:
        path = out / entry["json"]
        problem = read_park_problem(path)
        assert problem.to_json() == json.loads(path.read_text())
        text = (out / entry["csv"]).read_text()
        lines = text.splitlines()
        assert all("," not in line for line in lines)  # an N-row, one-column vector
        n = len(problem.obstacles)
        assert len(lines) == 7 + n + 2 * sum(len(v) for _, v in problem.obstacles) and int(lines[6]) == n
        start, goal, polygons = read_tpcap_case(out / entry["csv"])
        assert start == problem.start and goal == problem.goal  # exact: every float to its last bit
        assert polygons == [list(v) for _, v in problem.obstacles]


@pytest.mark.parametrize(("text", "says"), [
    ("{not json", "is not JSON"),
    ("[1, 2]", "no JSON object"),
    ('{"format": "something else", "version": 1}', "format 'something else'"),
    (None, "no 'obstacles' key"),
    ("NaN", "not a finite number"),
])
def test_a_malformed_problem_is_refused_in_one_line(written, tmp_path, text, says):
    out, index = written
    good = json.loads((out / index["problems"][0]["json"]).read_text())
    if text is None:
        del good["obstacles"]
        text = json.dumps(good)
    elif text == "NaN":
        good["start"][0] = float("nan")
        text = json.dumps(good)
    bad = tmp_path / "bad.json"
    bad.write_text(text)
    with pytest.raises(ParkProblemError) as err:
        read_park_problem(bad)
    message = str(err.value)
    assert says in message and str(bad) in message and "\n" not in message
    with pytest.raises(ParkProblemError, match="cannot read park problem"):
        read_park_problem(tmp_path / "missing.json")


def test_a_tpcap_case_with_wrong_counts_is_refused(tmp_path):
    bad = tmp_path / "Case1.csv"
    bad.write_text("\n".join(["0", "0", "0", "1", "1", "0", "1", "4", "0", "0", "1", "0"]) + "\n")
    with pytest.raises(ParkProblemError, match="does not hold the vertices"):
        read_tpcap_case(bad)


def test_export_cli_writes_park_problems(painted_tiny, tmp_path, capsys):
    garage = tmp_path / "garage.json"
    garage.write_text(painted_tiny.to_json())
    assert main(["export", "--garage", str(garage), "--park-problems", str(tmp_path / "park")]) == 0
    index = json.loads((tmp_path / "park" / INDEX).read_text())
    assert f"{len(index['problems'])} park problem(s) of 1 garage(s)" in capsys.readouterr().out
