"""The park difficulty: the room columns of park rows, the model and its file, fit and score, the CLI, a run's column."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.difficulty.park import load_park_runs, score_park
from garage_mj.driving.difficulty.park_rating import choose_park_model, park_difficulty_cell
from garage_mj.driving.results import ROOM_COLUMNS, TEST_COLUMNS, write_csv
from garage_mj.driving.sources import CruiseSettings
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.park_difficulty import (
    PARK_FEATURES,
    PLAN_CLEAR_CAP,
    ParkDifficulty,
    ParkModelError,
    fit_park,
    load_park_model,
    park_features,
)
from garage_mj.scene.route_difficulty import RouteModelError, load_route_model
from garage_mj.scene.world import DEFAULT_WORLD

QUIET = Compute(progress=False)
ROUTE_MODEL = Path(__file__).resolve().parents[1] / "models" / "difficulty" / "route.json"
FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}


@pytest.fixture(scope="module")
def garage():
    return paint_garage("tiny_7x11", seed=1)


def _row(i: int, outcome: str, *, task: str = "park", level: str = "complex", **cells) -> dict[str, str]:
    """A park test's tests.csv row with every park feature's cell."""
    row = dict.fromkeys(TEST_COLUMNS, "")
    row.update(garage=f"g{i % 4}", garage_hash=f"h{i % 4}", test=str(i), seed="1", driver="park_assist",
               target_stall=str(i % 7), feasible="0" if outcome in ("infeasible", "unproven") else "1",
               outcome=outcome, difficulty="0.5", mean_road_length="2", mean_intersection_degree="2", wall_s="0.1",
               task=task, maneuver="reverse" if i % 2 else "forward", park_level=level, stall_angle_deg="90.0",
               plan_length_m=str(8 + i % 5), plan_cusps=str(i % 3), plan_clearance_m=str(0.2 + 0.1 * (i % 4)),
               pedestrians="0", moving_cars="0", clutter=str(i % 2), pedestrians_behind="0", pedestrians_beside="0",
               vehicle="sedan", parked_fleet="uniform",
               parked_jitter_m="0", bay_margin_m="0.6", aisle_width_m="9.0", start_distance_m=str(5 + i % 6))
    row.update(cells)
    return row


def _run(folder, rows) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    write_csv(folder / "tests.csv", TEST_COLUMNS, rows)


def _park_run(folder, n: int = 40, seed: int = 0):
    """A park run folder whose failures follow the plan's length and cusps (and a parallel slot)."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        parallel = i % 5 == 0
        row = _row(i, "success", stall_angle_deg="0.0" if parallel else "90.0",
                   park_level="normal" if parallel else "complex")
        hard = float(row["plan_length_m"]) / 12 + int(row["plan_cusps"]) / 3 + parallel
        row["outcome"] = "collision" if rng.random() < hard / 2.5 else "success"
        rows.append(row)
    rows.append(_row(n, "infeasible"))  # never driven: left out
    _run(folder, rows)
    return rows


def test_park_rows_hold_the_room_and_the_park_difficulty_and_cruise_rows_do_not(garage, tmp_path):
    out = tmp_path / "park"
    res = run_cruise([garage], 2, CruiseSettings("park_assist", task="park", maneuver="any"), out, compute=QUIET,
                     route_model=False)
    with open(out / "tests.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(TEST_COLUMNS) and list(TEST_COLUMNS[-len(ROOM_COLUMNS):]) == list(ROOM_COLUMNS)
    model = load_park_model()
    for r in rows:
        assert float(r["bay_margin_m"]) == pytest.approx(2.5 - 1.9)  # the default stall's width less the sedan's
        assert float(r["aisle_width_m"]) > 0 and float(r["start_distance_m"]) > 0
        if r["feasible"] == "1":
            assert float(r["park_difficulty"]) == pytest.approx(model.of_row(r), abs=1e-4)
            assert 0 < float(r["park_difficulty"]) < 1
        else:
            assert r["park_difficulty"] == ""
    stats = json.loads((out / "summary.json").read_text())
    assert stats["park_model"] == model.key and stats["park_model_name"] == "park_assist" and res.rows
    cruise = run_cruise([garage], 1, CruiseSettings("waypoint", env=FAST), tmp_path / "cruise", compute=QUIET,
                        route_model=False)
    assert all(cruise.rows[0][c] == "" for c in ROOM_COLUMNS)


def test_a_parallel_slot_leaves_its_length_less_the_cars(garage, tmp_path):
    out = tmp_path / "parallel"
    run_cruise([garage], 1, CruiseSettings("oracle", task="park", env={"world": {"stall_angle": 0.0}}), out,
               compute=QUIET, route_model=False, park_model=False)
    with open(out / "tests.csv", newline="") as f:
        row = next(csv.DictReader(f))
    assert float(row["bay_margin_m"]) == pytest.approx(DEFAULT_WORLD.slot_length - 4.6)  # the slot less the sedan
    assert row["park_difficulty"] == ""  # park_model=False


def test_fit_round_trips_and_is_monotone_in_every_feature(tmp_path):
    rows = _park_run(tmp_path / "run")
    recs = load_park_runs([tmp_path / "run"])
    assert len(recs) == len(rows) - 1 and {r["level"] for r in recs} == {0, 1}
    model = fit_park(recs, [r["failed"] for r in recs])
    assert isinstance(model, ParkDifficulty) and all(w >= 0 for w in model.weights) and max(model.weights) > 0
    model.save(tmp_path / "m.json")
    back = load_park_model(tmp_path / "m.json")
    assert back == model and back.key == model.key
    base = park_features(rows[1])
    p0 = back.of_row(rows[1])
    for name in PARK_FEATURES:
        assert back.test_probability({**base, name: base[name] + 1.0}) >= p0 - 1e-12, name
    # a park model is not a route model, nor the other way
    with pytest.raises(RouteModelError, match="not a route difficulty model"):
        load_route_model(tmp_path / "m.json")
    with pytest.raises(ParkModelError, match="it is a route difficulty model"):
        load_park_model(ROUTE_MODEL)
    figures = score_park(back, recs)["park_assist"]
    assert figures["tests"] == len(recs) and figures["park"]["auc"] > 0.5 and figures["levels"]["auc"] is not None
    assert park_difficulty_cell(back, rows[-1]) == ""  # the infeasible test
    # a plan with nothing near it (an infinite clearance, written empty) reads as the cap, not as a missing cell
    assert park_features({**rows[1], "plan_clearance_m": ""})["tight_plan"] == -PLAN_CLEAR_CAP


def test_a_run_without_the_pedestrians_behaviours_is_rated_and_scored_by_a_model_without_them(tmp_path, capsys):
    """A run of an older garage-mj has no pedestrians_behind / pedestrians_beside cells: a model fitted without those
    features still rates and scores its tests; a fit on every feature names the missing column."""
    rows = [{**r, "pedestrians_behind": "", "pedestrians_beside": ""} for r in _park_run(tmp_path / "new")]
    _run(tmp_path / "old", rows)
    without = tuple(f for f in PARK_FEATURES if f not in ("behind_stall", "beside_stall"))
    recs = load_park_runs([tmp_path / "new"], without)
    model = fit_park(recs, [r["failed"] for r in recs], without)
    assert 0 < model.of_row(rows[1]) < 1 and set(park_features(rows[1], without)) == set(without)
    model.save(tmp_path / "old_model.json")
    assert main(["difficulty", "score", "--task", "park", str(tmp_path / "old"), "--model",
                 str(tmp_path / "old_model.json")]) == 0
    assert "per-test AUC" in capsys.readouterr().out
    assert main(["difficulty", "fit", "--task", "park", str(tmp_path / "old"), "--out", str(tmp_path / "m.json")]) == 2
    assert "column pedestrians_behind is empty" in capsys.readouterr().err
    assert park_difficulty_cell(load_park_model("learned_park"), rows[1]) == ""  # the shipped model reads them


def test_cli_fits_and_scores_park_runs_beside_the_levels(tmp_path, capsys):
    _park_run(tmp_path / "fit")
    _park_run(tmp_path / "other", seed=1)
    model = tmp_path / "park.json"
    assert main(["difficulty", "fit", "--task", "park", str(tmp_path / "fit"), "--out", str(model)]) == 0
    assert model.is_file() and (tmp_path / "park.fit.csv").is_file()
    capsys.readouterr()
    assert main(["difficulty", "score", "--task", "park", str(tmp_path / "other"), "--model", str(model),
                 "--json", str(tmp_path / "s.json")]) == 0
    out = capsys.readouterr().out
    assert "park difficulty" in out and "HOPE's levels (0/1/2)" in out and "per-test AUC" in out
    assert set(json.loads((tmp_path / "s.json").read_text())["park_assist"]) >= {"park", "levels", "by_level"}


def test_cli_refuses_runs_of_the_other_task_and_options_that_do_not_apply(garage, tmp_path, capsys):
    _run(tmp_path / "cruise", [_row(i, "success", task="cruise") for i in range(3)])
    _park_run(tmp_path / "park")
    (tmp_path / "empty").mkdir()

    def refused(*argv: str) -> str:
        assert main(list(argv)) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        return err[0]

    out = str(tmp_path / "m.json")
    assert "is a cruise run, not a park or AVP run" in refused("difficulty", "fit", "--task", "park",
                                                               str(tmp_path / "cruise"), "--out", out)
    assert "is a park run, not a cruise run" in refused("difficulty", "fit", str(tmp_path / "park"), "--out", out)
    assert "holds no tests.csv" in refused("difficulty", "score", "--task", "park", str(tmp_path / "empty"))
    assert "unknown park features ['length']" in refused("difficulty", "fit", "--task", "park",
                                                         str(tmp_path / "park"), "--out", out, "--features", "length")
    assert "--library" in refused("difficulty", "fit", "--task", "park", str(tmp_path / "park"), "--out", out,
                                  "--library", str(tmp_path / "lib.sqlite"))
    assert "not a park difficulty model" in refused("difficulty", "score", "--task", "park", str(tmp_path / "park"),
                                                    "--model", str(ROUTE_MODEL))
    assert "--park-model rates park and AVP tests" in refused("cruise", "--packs", str(tmp_path), "--tests", "1",
                                                             "--park-model", out, "--out", str(tmp_path / "o"))


def test_a_driver_without_a_model_of_its_own_gets_the_default_and_false_gets_none():
    own = choose_park_model(True, "park_assist")
    other = choose_park_model(True, "oracle")
    assert own.name == other.name == "park_assist" and own.note is None and "oracle" in other.note
    assert choose_park_model(False, "oracle").model is None


def test_the_shipped_learned_parking_driver_is_rated_by_its_own_model_and_another_model_file_by_the_default():
    own = choose_park_model(True, "learned:park")
    assert own.name == "learned_park" and own.note is None and own.model.fit["drivers"] == ["learned:park"]
    retrained = choose_park_model(True, "learned:park", {"model": "runs/mine/model.zip"})  # not the shipped model
    assert retrained.name == "park_assist" and "learned:park" in retrained.note
    assert choose_park_model("learned_park", "oracle").model.key == own.model.key  # a shipped model by its name
