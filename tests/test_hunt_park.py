"""garage-mj hunt --task park: (garage, geometry) candidates, children aimed at a failing stall or keeping a failing
test's scene with its actors placed anew, failures the oracle confirms, the same hunt per seed."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.driving.hunt import (
    PARK_FAILURE_COLUMNS,
    HuntConfig,
    HuntError,
    Scored,
    _build_cache,
    _child,
    _start_pairs,
    buildable,
    cruise_dir,
    hunt,
    hunt_geometries,
    rerun,
    scene_targets,
    split_variant,
    stall_targets,
    variant,
)
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.grid.painters import paint_garage

QUIET = Compute(progress=False)
CFG = HuntConfig(budget=10, tests=2, population=3, elites=1, worst=1)  # 3 start candidates, an elite and a child
GEOMETRIES = ("default", "tight", "parallel")


def _hunt(out):
    return hunt(CruiseSettings("park_assist", seed=1, task="park"), out, map="tiny_7x11", config=CFG, compute=QUIET,
                geometries=GEOMETRIES)


def _table(out):
    with open(out / "failures.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def hunted(tmp_path_factory):
    out = tmp_path_factory.mktemp("hunt_park") / "h"
    return out, _hunt(out)


def test_each_candidate_records_its_geometry_and_runs_in_it(hunted):
    out, res = hunted
    rows = _table(out)
    assert list(rows[0]) == list(PARK_FAILURE_COLUMNS)
    assert len(rows) == len(res.ranked) > CFG.population  # a child was made
    assert {r["geometry"] for r in rows} <= set(GEOMETRIES)
    assert json.loads((out / "hunt.json").read_text())["settings"]["geometries"] == list(GEOMETRIES)
    for s in res.ranked:  # each candidate's tests are in its geometry's run, built in that geometry
        run = json.loads((cruise_dir(out, s.geometry) / "run.json").read_text())
        assert run["env"].get("world", {}) == PARK_GEOMETRIES[s.park_geometry].world
        assert run.get("stall") == s.stall
        assert {r["garage_hash"] for r in s.rows} == {s.source.hash}
    assert sum(len(s.rows) for s in res.ranked) == res.tests <= CFG.budget


def test_a_child_aims_its_tests_at_a_stall_where_its_parent_failed(hunted):
    out, res = hunted
    aimed = [s for s in res.ranked if s.stall is not None]
    assert aimed  # this hunt's child is one (seeded: the same every run)
    by_key = {s.key: s for s in res.ranked}
    for s in aimed:
        parent = by_key[s.parent]
        assert s.source.hash == parent.source.hash and s.park_geometry == parent.park_geometry
        assert s.stall in {int(r["target_stall"]) for r in parent.confirmed}
        assert {int(r["target_stall"]) for r in s.rows} == {s.stall}  # every test aimed at it, seeds drawn anew
        assert len({r["seed"] for r in s.rows}) == len(s.rows)
    rows = {(r["garage_hash"], r["geometry"], r["stall"]) for r in _table(out)}
    assert {(s.source.hash, s.park_geometry, str(s.stall)) for s in aimed} <= rows
    s = aimed[0]  # its run is a variant's own folder; a test of it re-runs from the failures.csv columns
    assert cruise_dir(out, s.geometry).name == f"{s.park_geometry}@stall{s.stall}"
    again = rerun(out, s.source.hash[:12], int(s.rows[0]["test"]), geometry=s.park_geometry, stall=s.stall)
    assert (again["outcome"], again["target_stall"]) == (s.rows[0]["outcome"], s.stall)


def test_stall_targets_are_failing_stalls_then_their_neighbours():
    garage = paint_garage("m5_13x13_aligned", seed=1)
    src = CruiseSource.from_garage(garage, "m5")
    rows = [{"outcome": "collision", "test": "0", "target_stall": "9"},
            {"outcome": "outside_stall", "test": "1", "target_stall": "3"},
            {"outcome": "success", "test": "2", "target_stall": "4"}]
    parent = Scored(src, geometry="default", rows=rows, oracle_parks={0})  # only test 0's failure counts
    assert stall_targets(parent, set()) == [9]
    assert stall_targets(parent, {f"{src.hash}:default@stall9"}) == []
    aimed = Scored(src, geometry=variant("default", 9), rows=rows[:1], oracle_parks={0})
    assert (aimed.park_geometry, aimed.stall) == ("default", 9)
    assert stall_targets(aimed, {aimed.key}) == [8, 10]  # stalls 8-10 share a row; 11 is across the aisle
    assert split_variant("parallel_mixed@stall12") == ("parallel_mixed", 12, None)
    assert split_variant("parallel_mixed") == ("parallel_mixed", None, None)
    assert scene_targets(parent, set()) == []  # no failure hit an actor
    assert Scored(src, geometry="tight", rows=rows).stall is None
    assert stall_targets(Scored(src, rows=rows), set()) == []  # a cruise hunt aims at no stall
    rng = np.random.default_rng(0)
    kinds = [_child([parent], rng, {parent.key}, 50, ("default", "tight"), _build_cache())[1] for _ in range(40)]
    assert "default@stall9" in kinds and set(kinds) - {"default@stall9"}  # a stall child, and the other kinds too


def test_a_child_keeps_the_scene_of_a_failure_that_hit_an_actor_and_places_its_actors_anew(tmp_path):
    out = tmp_path / "h"
    res = hunt(CruiseSettings("park_assist", seed=1, task="park", env={"scenario": "park_pedestrian_behind"}), out,
               map="tiny_7x11", config=CFG, compute=QUIET, geometries=GEOMETRIES)
    kept = [s for s in res.ranked if s.scene is not None]
    assert kept  # this hunt's child is one (seeded: the same every run)
    by_key = {s.key: s for s in res.ranked}
    s = kept[0]
    parent = by_key[s.parent]
    failed = {int(r["seed"]): r for r in parent.confirmed}
    assert s.source.hash == parent.source.hash and s.park_geometry == parent.park_geometry
    assert failed[s.scene]["hit"] == "pedestrian"  # a failure that hit an actor
    assert {r["target_stall"] for r in s.rows} == {failed[s.scene]["target_stall"]} == {str(s.stall)}
    assert len({r["seed"] for r in s.rows}) == len(s.rows) and str(s.scene) not in {r["seed"] for r in s.rows}
    run = json.loads((cruise_dir(out, s.geometry) / "run.json").read_text())
    assert cruise_dir(out, s.geometry).name == f"{s.park_geometry}@scene{s.scene}" and run["env"]["scene_seed"] == s.scene
    row = next(r for r in _table(out) if r["scene"] == str(s.scene))
    assert (row["garage_hash"], row["geometry"], row["stall"]) == (s.source.hash, s.park_geometry, str(s.stall))
    again = rerun(out, s.source.hash[:12], int(s.rows[0]["test"]), geometry=s.park_geometry, scene=s.scene)
    assert (again["outcome"], again["target_stall"], again["seed"]) == \
        (s.rows[0]["outcome"], s.stall, int(s.rows[0]["seed"]))
    assert scene_targets(s, set()) == []  # its failures are of its own scene
    assert split_variant(s.geometry) == (s.park_geometry, None, s.scene)


def test_failures_are_confirmed_by_the_oracle(hunted):
    out, res = hunted
    rows = _table(out)
    with open(out / "oracle.csv", newline="") as f:
        oracle = list(csv.DictReader(f))
    assert sum(int(r["failures"]) for r in rows) == len(oracle) > 0  # every failure, and only those, re-driven once
    assert all(r["oracle_parks"] != "" and 0 <= int(r["oracle_parks"]) <= int(r["failures"]) for r in rows)
    assert sum(int(r["oracle_parks"]) for r in rows) == sum(o["outcome"] == "success" for o in oracle) > 0
    for s in res.ranked:  # the failing tests listed are those the oracle parks
        assert len(s.confirmed) == len(s.oracle_parks) and {int(r["test"]) for r in s.confirmed} == s.oracle_parks
    rates = [float(r["confirmed_pct"]) for r in rows if r["confirmed_pct"]]
    assert rates == sorted(rates, reverse=True)  # ranked by the failures that count
    worst = res.worst[0]
    row = worst.confirmed[0]  # a listed failure re-runs with its outcome, in its geometry
    again = rerun(out, worst.source.hash[:12], int(row["test"]), geometry=worst.geometry)
    assert (again["outcome"], again["time"]) == (row["outcome"], float(row["time"]))


def test_the_same_seed_gives_the_same_hunt(hunted, tmp_path):
    out, _ = hunted
    _hunt(tmp_path / "again")
    assert (tmp_path / "again" / "failures.csv").read_text() == (out / "failures.csv").read_text()
    before = (out / "oracle.csv").read_text()
    _hunt(out)  # resumed: nothing driven again
    assert (out / "oracle.csv").read_text() == before


def test_geometries_are_refused_in_one_line(tmp_path, capsys):
    assert main(["hunt", "--map", "tiny_7x11", "--geometries", "tight", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--geometries is for park and AVP hunts" in err[0]
    assert main(["hunt", "--map", "tiny_7x11", "--task", "park", "--driver", "park_assist", "--geometries",
                 "default,narrow", "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "narrow" in err[0] and "parallel_mixed" in err[0]
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    with pytest.raises(HuntError, match="twice"):
        hunt_geometries("park", ["tight", "tight"])
    assert hunt_geometries("avp", None)[0] == "default" and hunt_geometries("cruise", None) == ()


def test_the_hunt_takes_a_named_scenario_as_cruise_does(tmp_path, capsys):
    base = ["hunt", "--map", "tiny_7x11", "--task", "park", "--driver", "park_assist", "--out", str(tmp_path / "x")]
    assert main([*base, "--scenario", "park_mixed", "--budget", "1"]) == 2  # the name taken; the budget refused
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "budget" in err[0] and "scenario" not in err[0]
    assert main([*base, "--scenario", "park_crowd"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "park_crowd" in err[0] and "park_mixed" in err[0]
    assert not (tmp_path / "x").exists()


def test_a_garage_a_geometry_cannot_build_is_never_drawn():
    garage = paint_garage("m5_13x13_aligned", seed=5)  # its blocks hold no 60-degree rows
    assert buildable(garage, "default") and not buildable(garage, "angled60")
    src = CruiseSource.from_garage(garage, "m5")
    assert [g for _, g in _start_pairs([src] * 20, ("angled60", "default"), 0, 20, _build_cache())] == ["default"] * 20
    assert _start_pairs([src], ("angled60",), 0, 1, _build_cache()) == []
    parent = Scored(src, geometry="default", rows=[{"outcome": "collision", "test": "0"}])
    rng = np.random.default_rng(0)
    for _ in range(10):  # children: mutations in the parent's geometry, never the garage in angled60
        g, geometry, _ = _child([parent], rng, {parent.key}, 50, ("default", "angled60"), _build_cache())
        assert geometry == "default" and g.canonical_hash() != src.hash
    with pytest.raises(HuntError, match="env world"):
        hunt(CruiseSettings("park_assist", task="park", env={"world": {"stall_width": 2.3}}), "unused",
             map="tiny_7x11", config=CFG, compute=QUIET)


def test_the_closing_lines_count_the_failures_the_oracle_parks():
    from pathlib import Path

    from garage_mj.cli.hunt import failure_summary
    from garage_mj.driving.hunt import HuntResult

    src = CruiseSource.from_garage(paint_garage("tiny_7x11", seed=1), "g1")
    rows = [{"outcome": o, "test": str(i)} for i, o in enumerate(["collision", "outside_stall", "success"])]
    ranked = [Scored(src, rows=rows, geometry="tight", oracle_parks={1}),
              Scored(src, rows=rows[:1], geometry="parallel", oracle_parks=set())]
    res = HuntResult(Path("h"), 4, 1, ranked, {}, action_label="x")
    assert failure_summary(res, task="park").splitlines() == [
        "4 park tests on 2 garage-geometry pairs in 1 generation (x); 1 pair with a failure the oracle parks:",
        "  g1 (tight): 1 of 3 feasible tests failed (33%)"]
