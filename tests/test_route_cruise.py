"""The route difficulty in cruise outputs (summary.csv, summary.json, figures, report) and the library heatmap."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.driving.difficulty import rating as route_rating
from garage_mj.driving.difficulty.regression import pearson
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.cruise import cruise_figure, run_cruise
from garage_mj.scene.route_difficulty import fit, load_route_model, route_difficulty
from tests.test_route_difficulty import _synthetic

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick
QUIET = Compute(progress=False)  # one process, no progress bar


@pytest.fixture(scope="module")
def garages():
    return [paint_garage("tiny_7x11", seed=s) for s in (1, 2, 3)]


@pytest.fixture(scope="module")
def shipped():
    return load_route_model()


def _summary(out):
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_summary_has_route_difficulty_beside_the_papers_and_route_r(garages, shipped, tmp_path, monkeypatch):
    out = tmp_path / "run"
    res = run_cruise(garages, 2, CruiseSettings("waypoint", env=FAST), out, compute=QUIET, route_model="route")
    rows = _summary(out)
    header = list(rows[0])
    assert header[header.index("difficulty") + 1] == "route_difficulty"
    by_name = {s["garage"]: s for s in rows}
    for g in garages:
        row = next(r for n, r in by_name.items() if n.endswith(g.canonical_hash()[:8]))
        assert float(row["route_difficulty"]) == pytest.approx(route_difficulty(g, shipped), abs=1e-4)
    stats = json.loads((out / "summary.json").read_text())
    assert stats == res.stats and stats["route_model"] == shipped.key and stats["route_model_name"] == "route"
    rated = [r for r in rows if r["success_pct"] != ""]
    success = [float(r["success_pct"]) for r in rated]
    assert stats["r"] == res.stats["r"]  # the paper's r stays where it was
    if len(set(success)) > 1:
        assert stats["route_r"] == pytest.approx(pearson([float(r["route_difficulty"]) for r in rated], success))
    assert stats["route_n"] == len(rated) and {"route_slope", "route_intercept"} <= set(stats)
    assert (out / "regression.png").is_file() and (out / "regression_route.png").is_file()
    assert (out / route_rating.CACHE_FILE).is_file()

    # a re-run (here: a new process, nothing in memory) reads the values back instead of planning again
    monkeypatch.setattr(route_rating, "_MEMO", {})
    monkeypatch.setattr(route_rating, "route_difficulty", lambda *a: pytest.fail("route difficulty recomputed"))
    again = run_cruise(garages, 2, CruiseSettings("waypoint", env=FAST), out, compute=QUIET, route_model="route")
    assert again.tests_run == 0 and _summary(out) == rows and again.stats == stats

    # a value edited by hand in the cache does not match its checksum: computed again, not read
    cache = json.loads((out / route_rating.CACHE_FILE).read_text())
    first = garages[0].canonical_hash()
    cache["models"][shipped.key][first][0] = 0.01
    (out / route_rating.CACHE_FILE).write_text(json.dumps(cache))
    monkeypatch.setattr(route_rating, "route_difficulty", route_difficulty)
    got = route_rating.cruise_route_difficulty(out, [CruiseSource.from_garage(g) for g in garages], shipped)
    assert got[first] == pytest.approx(route_difficulty(garages[0], shipped), abs=1e-6) != 0.01
    assert json.loads((out / route_rating.CACHE_FILE).read_text())["models"][shipped.key][first][0] != 0.01


def test_summary_json_regresses_success_on_both_difficulties(garages, tmp_path):
    import math

    from garage_mj.driving.difficulty.regression import regression
    from garage_mj.driving.results import write_outputs
    from garage_mj.driving.sources import CruiseSource
    from tests.test_cruise import fake_row

    more = [*garages, *(paint_garage("tiny_7x11", seed=s) for s in (4, 5, 6, 7))]
    srcs = [CruiseSource.from_garage(g) for g in more]
    outcomes = (["success"] * 4, ["success", "success", "collision", "timeout"], ["collision"] * 3 + ["success"],
                ["success"] * 3 + ["timeout"], ["collision"] * 4, ["success"] * 2 + ["collision"] * 2,
                ["success"] * 4)
    rows = [fake_row(s, k, o) for s, os in zip(srcs, outcomes) for k, o in enumerate(os)]
    values = (0.1, 0.4, 0.7, 0.2, 0.9, 0.5)
    route = {**{s.hash: v for s, v in zip(srcs, values)}, srcs[6].hash: math.nan}  # the last: no feasible stall
    summary, stats = write_outputs(tmp_path, rows, srcs, CruiseSettings("vision"), route=route, route_model="k")
    assert [r["route_difficulty"] for r in summary] == [*values, None]
    assert [r["route_difficulty"] for r in _summary(tmp_path)] == [*map(str, values), ""]
    success = [100.0, 50.0, 25.0, 75.0, 0.0, 50.0, 100.0]
    paper = regression([round(s.difficulty, 4) for s in srcs], success)  # as summary.csv rounds it
    assert (stats["r"], stats["slope"], stats["n"]) == (pytest.approx(paper.r), pytest.approx(paper.slope), 7)
    on_route = regression(values, success[:6])
    assert (stats["route_r"], stats["route_slope"], stats["route_intercept"], stats["route_n"]) == (
        pytest.approx(on_route.r), pytest.approx(on_route.slope), pytest.approx(on_route.intercept), 6)
    assert stats["route_model"] == "k" and stats["r_note"] is None and stats["route_r_note"] is None
    assert json.loads((tmp_path / "summary.json").read_text())["route_r"] == pytest.approx(on_route.r)

    # over fewer than 5 garages: no r and no line, and a note saying why
    (tmp_path / "few").mkdir()
    _, few = write_outputs(tmp_path / "few", rows[:12], srcs[:3], CruiseSettings("vision"), route=route,
                           route_model="k")
    assert (few["r"], few["slope"], few["intercept"], few["n"]) == (None, None, None, 3)
    assert few["r_note"] == "too few garages (3) for a correlation"
    assert (few["route_r"], few["route_n"], few["route_r_note"]) == (None, 3, "too few garages (3) for a correlation")


def test_the_default_route_model_is_one_fitted_on_the_driver_and_its_action_type(garages, tmp_path):
    from garage_mj.driving.difficulty.rating import choose_route_model

    assert choose_route_model(True, "learned", "discrete").name == "learned"
    assert choose_route_model(None, "vision", "discrete").name == "route"
    assert choose_route_model(True, "waypoint", "discrete").name == "route"
    for driver, action_type, kwargs in (("vision", "continuous", None), ("learned", "continuous", None),
                                        ("learned", "discrete", {"model": "other.zip"}),  # another learned model
                                        ("learned:other.zip", "discrete", None), ("oracle", "continuous", None)):
        none = choose_route_model(True, driver, action_type, kwargs)
        assert none.model is None and f"no shipped route model was fitted on driver {driver!r} with " \
            f"{action_type} actions" in none.note
    assert choose_route_model("route", "vision", "continuous").name == "route"  # asked for: used as it is

    res = run_cruise(garages[:1], 1, CruiseSettings("learned", env=FAST), tmp_path / "l", compute=QUIET)
    own = load_route_model("learned")
    assert res.stats["route_model"] == own.key and res.stats["route_model_name"] == "learned"
    assert res.stats["route_model_fitted_for"] == {"drivers": ["learned"], "action_types": ["discrete"]}
    assert float(_summary(tmp_path / "l")[0]["route_difficulty"]) == pytest.approx(
        route_difficulty(garages[0], own), abs=1e-4)

    # vision with its own continuous actions: the shipped models were fitted on discrete ones, so none applies
    res = run_cruise(garages[:1], 1, CruiseSettings("vision", env=FAST), tmp_path / "v", compute=QUIET)
    assert _summary(tmp_path / "v")[0]["route_difficulty"] == ""
    stats = json.loads((tmp_path / "v" / "summary.json").read_text())
    assert stats["route_model"] is None and stats["route_model_fitted_for"] is None
    assert stats["route_note"].startswith("no route difficulty: no shipped route model was fitted on driver 'vision' "
                                          "with continuous actions (route: vision, waypoint with discrete actions")
    assert not (tmp_path / "v" / "regression_route.png").exists()


def test_another_model_or_none(garages, shipped, tmp_path):
    mine = tmp_path / "mine.json"
    model = fit(*_synthetic())
    model.save(mine)
    res = run_cruise(garages[:1], 1, CruiseSettings("waypoint", env=FAST), tmp_path / "mine", route_model=mine,
                     compute=QUIET)
    assert res.stats["route_model"] == model.key != shipped.key
    assert float(_summary(tmp_path / "mine")[0]["route_difficulty"]) == pytest.approx(
        route_difficulty(garages[0], model), abs=1e-4)
    none = run_cruise(garages[:1], 1, CruiseSettings("waypoint", env=FAST), tmp_path / "none",
                      route_model=False, compute=QUIET)
    assert _summary(tmp_path / "none")[0]["route_difficulty"] == ""
    assert none.stats["route_r"] is None and none.stats["route_model"] is None
    assert not (tmp_path / "none" / "regression_route.png").exists()


def test_an_old_run_folder_still_draws(garages, tmp_path):
    out = tmp_path / "old"
    run_cruise(garages[:2], 1, CruiseSettings("waypoint", env=FAST), out, compute=QUIET, route_model="route")
    rows = _summary(out)
    with open(out / "summary.csv", "w", newline="") as f:  # summary.csv as an older garage-mj wrote it
        w = csv.DictWriter(f, fieldnames=[k for k in rows[0] if k != "route_difficulty"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    (out / "regression.png").unlink()
    (out / "regression_route.png").unlink()
    assert cruise_figure(out) == out / "regression.png" and (out / "regression.png").is_file()
    assert cruise_figure(out, "route") is None and not (out / "regression_route.png").exists()
    with pytest.raises(ValueError, match="metric must be one of"):
        cruise_figure(out, "nope")


def test_cli_cruise_prints_both_r(tmp_path, garages, capsys):
    from garage_mj.generation.library import Library

    lib = tmp_path / "lib.sqlite"
    with Library(lib) as library:
        for i, g in enumerate(garages[:2]):
            library.add(g, map="tiny_7x11", run="test", seed=i, episode=0, timestep=0)
    assert main(["cruise", "--library", str(lib), "--tests", "1", "--driver", "waypoint", "--out",
                 str(tmp_path / "c"), "--quiet", "--route-difficulty", "0", "1"]) == 2  # not rated yet
    assert "garage-mj library rate" in capsys.readouterr().err
    assert main(["library", "rate", str(lib), "--quiet"]) == 0
    assert main(["cruise", "--library", str(lib), "--tests", "1", "--driver", "waypoint", "--out",
                 str(tmp_path / "c"), "--quiet", "--route-difficulty", "0", "1", "--route-model", "route"]) == 0
    out = capsys.readouterr().out
    assert "Pearson r(difficulty, success) = too few garages (2) for a correlation" in out
    assert ("r(route difficulty, success) = too few garages (2) for a correlation (model route, fitted on vision, "
            "waypoint with discrete actions)") in out
    assert main(["cruise", "--library", str(lib), "--tests", "1", "--driver", "waypoint", "--out",
                 str(tmp_path / "d"), "--quiet"]) == 0
    assert ("no route difficulty (no shipped model was fitted on this driver with these actions; --route-model FILE "
            "gives one)") in capsys.readouterr().out


def test_heatmap_of_either_metric(tmp_path, garages, shipped, capsys):
    from garage_mj.generation.library import Library
    from garage_mj.reporting.plots import heatmap

    lib = tmp_path / "lib.sqlite"
    with Library(lib) as library:
        for i, g in enumerate(garages):
            library.add(g, map="tiny_7x11", run="test", seed=i, episode=0, timestep=0)
    argv = ["plot", "heatmap", "--library", str(lib), "--map", "tiny_7x11", "--metric", "route",
            "--out", str(tmp_path / "route.png")]
    assert main(argv) == 2
    assert "garage-mj library rate" in capsys.readouterr().err
    assert main(["library", "rate", str(lib), "--quiet"]) == 0
    assert main(argv) == 0 and (tmp_path / "route.png").is_file()
    assert "route difficulty" in capsys.readouterr().out
    with Library(lib, create=False) as library:
        points = library.points("tiny_7x11", route_model=shipped.key)
        paper = library.points("tiny_7x11")
    assert points[:, 0].tolist() == pytest.approx([route_difficulty(g, shipped) for g in garages])
    assert np.array_equal(points[:, 1], paper[:, 1])  # the same coverage, another x
    with pytest.raises(ValueError, match="metric must be one of"):
        heatmap(points, tmp_path / "x.png", metric="nope")


def test_report_shows_both_regressions(tmp_path):
    from garage_mj.reporting.analysis import regression_plot
    from garage_mj.reporting.report import ReportData, render_html, write_report

    paper = regression_plot([0.2, 0.5, 0.8], [90.0, 70.0, 40.0], tmp_path / "regression.png")
    route = regression_plot([0.1, 0.3, 0.6], [90.0, 70.0, 40.0], tmp_path / "regression_route.png", metric="route")
    data = ReportData(title="t", regression_png=paper, regression_route_png=route,
                      regression_text="vision: Pearson r = -0.99 on the paper's difficulty, -1.00 on the route difficulty")
    html = render_html(data, tmp_path)
    assert 'src="regression.png"' in html and 'src="regression_route.png"' in html
    assert "on the paper&#x27;s difficulty" in html and "on the route difficulty" in html
    route.unlink()
    with pytest.raises(FileNotFoundError, match="regression_route.png"):
        write_report(data, tmp_path)
