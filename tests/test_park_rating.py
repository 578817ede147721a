"""A garage's park difficulty from its scene alone, and ``garage-mj generate --metric park`` storing it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.scene.car import car_geometry
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_difficulty import PARK_FEATURES, SHIPPED_PARK_MODELS, load_park_model, park_features
from garage_mj.scene.park_planning import ParkPlanner
from garage_mj.scene.park_rating import ParkRater, garage_park_difficulty, geometry_key, park_row
from garage_mj.scene.world import DEFAULT_WORLD, GeometryError, world_with

TIGHT = {"stall_width": 2.3, "aisle_width": 6.5}


def test_a_garage_park_difficulty_is_a_seeded_mean_of_its_park_tests(painted_tiny):
    value = garage_park_difficulty(painted_tiny)
    assert 0.0 < value < 1.0
    assert garage_park_difficulty(painted_tiny) == value  # the same seed, the same tests
    # a narrower aisle and bay make the same garage's tests harder
    assert garage_park_difficulty(painted_tiny, world_with(TIGHT)) > value
    # each test's row holds every park feature the model reads, as a park run's tests.csv row does
    scene = GarageScene(painted_tiny)
    car = car_geometry()
    row = next(r for sid in range(len(scene.stalls.stalls))
               if (r := park_row(scene, car, ParkPlanner(scene, car), sid, "reverse", np.random.default_rng(0))))
    assert set(park_features(row)) == set(PARK_FEATURES)  # every feature: any shipped model rates it
    assert all(set(load_park_model(name).features) <= set(PARK_FEATURES) for name in SHIPPED_PARK_MODELS)
    assert row["plan_length_m"] > 0 and row["aisle_width_m"] == DEFAULT_WORLD.aisle_width
    assert math.isnan(garage_park_difficulty(painted_tiny, stalls=0))  # no test: no value


def test_the_rater_key_names_model_and_geometry_and_counts_unbuildable_garages(painted_tiny, monkeypatch):
    model = load_park_model()
    assert ParkRater().key == f"park:{model.key}:default"
    tight = ParkRater(world_with(TIGHT))
    assert tight.key.startswith(f"park:{model.key}:") and tight.key != ParkRater().key
    assert geometry_key(world_with(TIGHT)) == geometry_key(world_with(dict(TIGHT)))

    def refuse(*args, **kwargs):
        raise GeometryError("cannot build")

    monkeypatch.setattr("garage_mj.scene.park_rating.garage_park_difficulty", refuse)
    assert math.isnan(tight(painted_tiny)) and tight.unbuildable == 1


def test_generate_by_park_difficulty_stores_the_value_in_the_band(tmp_path, capsys):
    from garage_mj.generation.library import Library

    lib = tmp_path / "lib.sqlite"
    argv = ["generate", "--map", "tiny_7x11", "--metric", "park", "--difficulty", "0.2", "0.5", "--count", "1",
            "--library", str(lib), "--no-progress", "--max-seconds", "60"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    key = ParkRater().key
    assert "park difficulty" in out and key in out
    with Library(lib, create=False) as db:
        records = db.query()
        values = db.route_difficulties([r.id for r in records], key)
    assert len(records) == 1 and set(values) == {records[0].id}
    value = values[records[0].id]
    assert 0.2 <= value <= 0.5
    assert value == pytest.approx(garage_park_difficulty(records[0].garage), abs=1e-12)
    # a library reader finds it by the key the closing line printed
    assert main(["library", "ls", str(lib), "--route-difficulty", "0.2", "0.5", "--route-model", key]) == 0
    out = capsys.readouterr().out
    assert f"{value:.3f}" in out and "1 garage(s)" in out and "park difficulty" in out
    other = key.replace(":default", ":0badc0de")  # another geometry's values are not this one's
    assert main(["library", "ls", str(lib), "--route-difficulty", "0.2", "0.5", "--route-model", other]) == 2
    assert f"no route difficulty under model {other}" in capsys.readouterr().err


def test_generate_by_park_difficulty_in_another_geometry_keys_it(tmp_path, capsys):
    from garage_mj.generation.library import Library

    lib = tmp_path / "lib.sqlite"
    assert main(["generate", "--map", "tiny_7x11", "--metric", "park", "--difficulty", "0.5", "0.9", "--count", "1",
                 "--library", str(lib), "--no-progress", "--max-seconds", "60", "--stall-width", "2.3",
                 "--aisle-width", "6.5"]) == 0
    key = ParkRater(world_with(TIGHT)).key
    assert key in capsys.readouterr().out
    with Library(lib, create=False) as db:
        (record,) = db.query()
        value = db.route_difficulties([record.id], key)[record.id]
    assert value == pytest.approx(garage_park_difficulty(record.garage, world_with(TIGHT)), abs=1e-12)


def test_generate_searches_the_named_geometries_nearest_first_and_keys_each_garage_by_its_own(tmp_path, capsys):
    """``--geometries``: a band only the tight geometry reaches on tiny_7x11 is filled there (tried first, its
    painted garages rating nearest the band), each garage stored under the tight geometry's key."""
    from garage_mj.driving.park_geometries import PARK_GEOMETRIES
    from garage_mj.generation.library import Library

    lib = tmp_path / "lib.sqlite"
    argv = ["generate", "--map", "tiny_7x11", "--metric", "park", "--difficulty", "0.6", "0.95", "--count", "2",
            "--library", str(lib), "--no-progress", "--max-seconds", "90", "--geometries", "default,tight"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    tight = ParkRater(world_with(PARK_GEOMETRIES["tight"].world))
    assert "2 distinct garages with park difficulty 0.6-0.95 in 1 of 2 park geometries" in out, out
    assert "  tight: 2 found" in out and tight.key in out and "  default:" not in out, out
    with Library(lib, create=False) as db:
        records = db.query()
        values = db.route_difficulties([r.id for r in records], tight.key)
        assert not db.route_difficulties([r.id for r in records], ParkRater().key)
    assert len(records) == 2 and set(values) == {r.id for r in records}
    for r in records:
        assert 0.6 <= values[r.id] <= 0.95
        assert values[r.id] == pytest.approx(tight(r.garage), abs=1e-12)


@pytest.mark.parametrize("extra, said", [
    (["--geometries", "tight"], "--geometries names the park geometries --metric park searches"),
    (["--metric", "park", "--geometries", "tight,narrow"], "narrow"),
    (["--metric", "park", "--geometries", "tight,tight"], "names a geometry twice"),
    (["--metric", "park", "--geometries", "tight", "--stall-width", "2.3"], "give one or the other"),
    (["--park-model", "park_assist"], "--park-model needs --metric park"),
    (["--stall-width", "2.3"], "--stall-width is a park geometry"),
    (["--metric", "route", "--aisle-width", "6.5"], "--aisle-width is a park geometry"),
    (["--metric", "park", "--stall-width", "9"], "stall_width"),
    (["--metric", "park", "--park-model", "nope.json"], "nope.json"),
    (["--metric", "park", "--route-model", "route"], "--route-model needs --metric route"),
])
def test_generate_refuses_bad_park_combinations_in_one_line(tmp_path, capsys, extra, said):
    lib = tmp_path / "lib.sqlite"
    assert main(["generate", "--map", "tiny_7x11", "--difficulty", "0.2", "0.4", "--count", "1", "--library",
                 str(lib), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err, err
    assert not lib.exists()


def test_generate_counts_the_garages_a_geometry_cannot_build(tmp_path, capsys, monkeypatch):
    def refuse(*args, **kwargs):
        raise GeometryError("cannot build")

    monkeypatch.setattr("garage_mj.scene.park_rating.garage_park_difficulty", refuse)
    assert main(["generate", "--map", "tiny_7x11", "--metric", "park", "--difficulty", "0.2", "0.4", "--count", "1",
                 "--library", str(tmp_path / "lib.sqlite"), "--no-progress", "--max-episodes", "30"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "found 0 of 1" in err and "the park geometry cannot build them" in err, err


def test_a_rated_test_has_the_features_a_park_run_would_write_for_it(painted_tiny):
    """The scene-only row of a test equals what the drive env's info says of the same test (stall, parked cars,
    start, maneuver): the rating plans what a park run plans."""
    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.scene.drivable import drive_planner
    from garage_mj.scene.park_rating import PARK_OCCUPANCY, START_NOISE, _noisy

    scene, car = GarageScene(painted_tiny), car_geometry()
    sid = next(s.id for s in scene.stalls.stalls if drive_planner(scene, car).plan(s.id).feasible)
    row = park_row(scene, car, ParkPlanner(scene, car), sid, "forward", np.random.default_rng(5))
    rng = np.random.default_rng(5)  # the same draws, in park_row's order: parked cars, lateral, yaw
    draw = rng.random(len(scene.stalls.stalls)) < PARK_OCCUPANCY
    occupied = [s.id for s, o in zip(scene.stalls.stalls, draw, strict=True) if o and s.id != sid]
    start = _noisy(drive_planner(scene, car).plan(sid).goal, rng.uniform(-1, 1) * START_NOISE[0],
                   rng.uniform(-1, 1) * START_NOISE[1])
    env = GarageDriveEnv(painted_tiny, task="park", maneuver="forward")
    _, info = env.reset(seed=0, options={"target": sid, "occupied": occupied, "start": start})
    assert row["plan_length_m"] == pytest.approx(info["plan_length"], abs=1e-9)
    assert row["plan_cusps"] == info["plan_cusps"]
    assert row["plan_clearance_m"] == pytest.approx(info["plan_clearance"], abs=1e-9)
    for cell, key in (("bay_margin_m", "bay_margin"), ("aisle_width_m", "aisle_width"),
                      ("start_distance_m", "start_distance"), ("stall_angle_deg", "stall_angle")):
        assert row[cell] == pytest.approx(info[key], abs=1e-9), cell
