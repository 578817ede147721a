"""The route-aware difficulty: route features of planned tests, the monotone model, its file, fit and score."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.route_difficulty import RouteModelError, fit, load_route_model, route_difficulty
from garage_mj.scene.route_features import CLEAR_CAP, FEATURES, garage_features, mean_features, plan_features


@pytest.fixture(scope="module")
def tiny_features(painted_tiny):
    return garage_features(GarageScene(painted_tiny))


def test_route_features_describe_the_planned_route(painted_tiny, tiny_features):
    planner = drive_planner(GarageScene(painted_tiny))
    feasible = {p.stall: p for p in planner.plans() if p.feasible}
    assert set(k for k, v in tiny_features.items() if v is not None) == set(feasible)
    for sid, f in tiny_features.items():
        if f is None:
            continue
        assert set(f) == set(FEATURES)
        assert f["left_turns"] + f["right_turns"] == f["turns"]
        assert 0.0 <= f["heading_change"] <= f["turns"] * math.pi / 2 + 1e-6
        assert 0.0 <= f["tightness"] <= 1.0
        assert 0.0 <= f["squeeze"] <= CLEAR_CAP and f["turn_squeeze"] <= f["squeeze"] + 1e-9
        assert f["length"] == pytest.approx(feasible[sid].length - _start_length(feasible[sid]), abs=0.05)
        if f["turns"] == 0:  # a straight drive: no heading change, no curvature
            assert f["heading_change"] == 0.0 and f["tightness"] == 0.0
        assert f["goal_left"] == (feasible[sid].stall_side == "left")
    assert any(f and f["turns"] >= 2 for f in tiny_features.values())
    assert any(f and f["turns"] == 0 for f in tiny_features.values())
    means = mean_features(tiny_features)
    assert means["length"] == pytest.approx(np.mean([f["length"] for f in tiny_features.values() if f]))


def test_garage_terms_are_the_paper_s_difficulty_split_in_two(painted_tiny, tiny_features):
    from garage_mj.grid.metrics import DEFAULT_DIFFICULTY, evaluate

    rows = [f for f in tiny_features.values() if f]
    assert len({(f["short_roads"], f["few_way"]) for f in rows}) == 1  # the whole garage's: one value per garage
    f, c, m = rows[0], DEFAULT_DIFFICULTY, evaluate(painted_tiny)
    assert 0.0 <= f["short_roads"] <= 1.0 and 0.0 <= f["few_way"] <= 1.0
    assert c.w_road_length * f["short_roads"] + c.w_intersection * f["few_way"] == pytest.approx(m.difficulty)
    assert f["short_roads"] == pytest.approx((6 - m.mean_road_length) / 4)  # E[X] of 2 cells -> 1, 6 -> 0


def _start_length(plan) -> float:
    """Length of the planned centre path before the start pose."""
    c = plan.centre[: plan.drive_from + 1]
    return float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum())


def test_route_features_refuse_an_infeasible_plan(painted_tiny):
    from garage_mj.scene.drivable import TestPlan

    with pytest.raises(ValueError, match="no feasible route"):
        plan_features(drive_planner(GarageScene(painted_tiny)), TestPlan(3, False, "blocked"))


def _synthetic(n: int = 400, seed: int = 0):
    """Tests whose failure depends on length and squeeze only."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n):
        row = {k: float(rng.random()) for k in FEATURES}
        row["length"] = float(rng.uniform(5, 150))
        rows.append(row)
    z = -3.0 + 0.04 * np.array([r["length"] for r in rows]) + 2.0 * np.array([r["squeeze"] for r in rows])
    failed = rng.random(n) < 1 / (1 + np.exp(-z))
    return rows, failed


def test_fit_is_monotone_and_finds_what_makes_tests_fail(tmp_path):
    rows, failed = _synthetic()
    model = fit(rows, failed)
    assert all(w >= 0 for w in model.weights)
    top = [name for name, _ in model.coefficients()[:2]]
    assert set(top) == {"length", "squeeze"}
    # monotone: making any feature larger never makes a test easier
    base = dict(rows[0])
    p0 = model.test_probability(base)
    for k in FEATURES:
        assert model.test_probability({**base, k: base[k] + 1.0}) >= p0 - 1e-12
    # the file gives back the same model
    model.save(tmp_path / "m.json")
    again = load_route_model(tmp_path / "m.json")
    assert np.allclose(again.test_probability(rows), model.test_probability(rows))
    with pytest.raises(ValueError, match="same outcome"):
        fit(rows, [True] * len(rows))


@pytest.mark.parametrize("content, match", [
    (None, "does not exist"),
    ("{not json", "not valid JSON"),
    ('{"format": "something else"}', "not a route difficulty model"),
    ('{"format": "garage-mj route difficulty", "version": 99}', "version 99"),
])
def test_a_bad_model_file_is_one_clear_error(tmp_path, content, match):
    path = tmp_path / "model.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(RouteModelError, match=match) as err:
        load_route_model(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_a_negative_weight_is_refused(tmp_path):
    rows, failed = _synthetic(100)
    d = fit(rows, failed).to_dict()
    d["weights"][0] = -1.0
    (tmp_path / "m.json").write_text(json.dumps(d))
    with pytest.raises(RouteModelError, match="damaged"):
        load_route_model(tmp_path / "m.json")


@pytest.mark.parametrize("key, value", [("mean", "NaN"), ("scale", "Infinity"), ("weights", "NaN"),
                                        ("intercept", "NaN"), ("weights", "-Infinity"), ("features", "[]")])
def test_a_model_with_nan_inf_or_empty_values_is_refused(tmp_path, key, value):
    rows, failed = _synthetic(100)
    d = fit(rows, failed).to_dict()
    text = json.dumps({**d, key: "@"}).replace('"@"', value if key in ("intercept", "features") else f"[{value}]")
    if key == "features":
        text = text.replace(json.dumps(d["mean"]), "[]").replace(json.dumps(d["scale"]), "[]")
        text = text.replace(json.dumps(d["weights"]), "[]")
    (tmp_path / "m.json").write_text(text)
    with pytest.raises(RouteModelError) as err:
        load_route_model(tmp_path / "m.json")
    msg = str(err.value)
    assert msg.startswith(f"{tmp_path / 'm.json'}: its {key} ") and "fit it again" in msg and "\n" not in msg


def test_a_nan_difficulty_is_never_no_feasible_stall(painted_tiny, tiny_features):
    """A model that computes NaN (a NaN feature value) fails loudly instead of claiming no feasible stall."""
    model = load_route_model()
    per_stall = {k: (None if v is None else {**v, model.features[0]: math.nan}) for k, v in tiny_features.items()}
    with pytest.raises(RouteModelError, match="gives NaN for a garage with feasible stalls"):
        model.of_features(per_stall)
    assert math.isnan(model.of_features({k: None for k in tiny_features}))


def test_shipped_model_rates_a_garage(painted_tiny, tiny_features):
    model = load_route_model()
    d = route_difficulty(painted_tiny, model)
    assert 0.0 < d < 1.0
    assert d == pytest.approx(model.of_features(tiny_features))
    assert model.fit["drivers"] and model.fit["tests"] > 100


def test_shipped_models_load_by_name(tmp_path, monkeypatch, painted_tiny):
    default, learned = load_route_model(), load_route_model("learned")
    assert load_route_model("route") == default and learned.key != default.key
    assert learned.fit["drivers"] == ["learned"] and {"short_roads", "few_way"} <= set(learned.features)
    assert default.fit["action_types"] == learned.fit["action_types"] == ["discrete"]
    assert 0.0 < route_difficulty(painted_tiny, learned) < 1.0
    monkeypatch.chdir(tmp_path)  # a file of that name wins over the shipped model
    learned.save(tmp_path / "route")
    assert load_route_model("route") == learned
    with pytest.raises(RouteModelError, match="does not exist"):
        load_route_model("no_such_model")


@pytest.mark.filterwarnings("ignore::garage_mj.driving.drivers.ActionTypeWarning")
def test_fit_and_score_from_a_cruise_run(tmp_path, painted_tiny, junction_garage, capsys):
    from garage_mj.core.backends import Compute
    from garage_mj.driving.sources import CruiseSettings
    from garage_mj.reporting.cruise import run_cruise

    run = tmp_path / "run"
    run_cruise([painted_tiny, junction_garage], 8, CruiseSettings("waypoint", seed=0, action_type="discrete"),
               run, compute=Compute(workers=1, progress=False))
    assert (run / "garages.json").is_file()
    out = tmp_path / "mine.json"
    assert main(["difficulty", "fit", str(run), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "route difficulty = P(fail)" in text and "per-garage r" in text
    assert "per-garage r = too few garages (2) for a correlation" in text  # no r over 2 garages
    model = load_route_model(out)
    assert model.fit["drivers"] == ["waypoint"] and model.fit["garages"] == 2
    assert model.fit["action_types"] == ["discrete"]  # what a cruise run's default route model is matched on
    assert (tmp_path / "mine.fit.csv").read_text().startswith("run,driver,garage")
    assert main(["difficulty", "score", str(run), "--model", str(out), "--json", str(tmp_path / "s.json")]) == 0
    score = json.loads((tmp_path / "s.json").read_text())
    assert score["waypoint"]["garages"] == 2 and 0.0 <= score["waypoint"]["route"]["auc"] <= 1.0
    assert "attainable_r" in score["waypoint"] and len(score["waypoint"]["attainable_r_ci95"]) == 2
    assert "between_drivers" not in score  # one driver: nothing to compare
    other = tmp_path / "oracle"
    run_cruise([painted_tiny, junction_garage], 4, CruiseSettings("oracle", seed=0), other,
               compute=Compute(workers=1, progress=False))
    assert main(["difficulty", "score", str(run), str(other), "--json", str(tmp_path / "s2.json")]) == 0
    assert "between drivers" in capsys.readouterr().out
    pair = json.loads((tmp_path / "s2.json").read_text())["between_drivers"]["oracle+waypoint"]
    assert pair["garages"] == 2 and pair["r_between"] is None  # r needs 3 garages
    # a folder that is not a cruise run: one line naming it
    assert main(["difficulty", "fit", str(tmp_path), "--out", str(out)]) == 2
    assert "holds no tests.csv" in capsys.readouterr().err
    # an --out that cannot be written: one line, and neither the model nor its .fit.csv is written
    (tmp_path / "taken").mkdir()
    (tmp_path / "other.fit.csv").mkdir()
    before = sorted(p for p in tmp_path.rglob("*"))
    for bad in (tmp_path / "taken", tmp_path / "other.json", tmp_path / "mine.json" / "m.json"):
        assert main(["difficulty", "fit", str(run), "--out", str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--out {bad}" in err and ("is a folder" in err or "is a file" in err), err
    assert sorted(p for p in tmp_path.rglob("*")) == before


def test_generate_by_route_difficulty_stores_rated_garages_in_the_band(tmp_path, capsys):
    from garage_mj.generation.library import Library

    lib = tmp_path / "lib.sqlite"
    argv = ["generate", "--map", "tiny_7x11", "--metric", "route", "--difficulty", "0.55", "0.75", "--count", "3",
            "--library", str(lib), "--no-progress", "--seed", "4"]
    assert main(argv) == 0
    assert "route difficulty" in capsys.readouterr().out
    model = load_route_model()
    with Library(lib, create=False) as db:
        records = db.query()
        values = db.route_difficulties([r.id for r in records], model.key)
    assert len(records) == 3 and set(values) == {r.id for r in records}
    for r in records:  # what is stored is what the shipped model says of the garage
        assert 0.55 <= values[r.id] <= 0.75
        assert values[r.id] == pytest.approx(route_difficulty(r.garage, model), abs=1e-9)
    # the same seed gives the same garages
    assert main([*argv[:-5], "--library", str(tmp_path / "again.sqlite"), "--no-progress", "--seed", "4"]) == 0
    with Library(tmp_path / "again.sqlite", create=False) as db:
        assert [r.hash for r in db.query()] == [r.hash for r in records]
    assert main(["generate", "--map", "tiny_7x11", "--difficulty", "0.5", "0.6", "--count", "1", "--library",
                 str(lib), "--route-model", str(tmp_path / "m.json")]) == 2
    assert "--route-model needs --metric route" in capsys.readouterr().err


def test_difficulty_show_explains_a_garage(capsys):
    assert main(["difficulty", "show", "tiny_7x11", "-n", "1", "--stalls", "2"]) == 0
    out = capsys.readouterr().out
    model = load_route_model()
    assert model.key in out and "tiny_7x11" in out
    line = next(ln for ln in out.splitlines() if "route difficulty" in ln and "stalls feasible" in ln)
    value = float(line.split("route difficulty ")[1].split()[0])
    from garage_mj.driving.sources import painted_sources

    assert value == pytest.approx(route_difficulty(painted_sources("tiny_7x11", 1, 0)[0].garage, model), abs=5e-4)
    assert "hardest target stalls" in out and out.count("tightness") >= 2
    assert main(["difficulty", "show", "no_such_map"]) == 2
