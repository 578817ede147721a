"""Garage sets: made from a library (filters, seeded samples), packs, a painted map or JSON; written and read
back exactly; split, ordered by difficulty and filtered to drivable garages; one-line errors."""

from __future__ import annotations

import json

import pytest

from garage_mj.cli import main
from garage_mj.driving.garage_set import (
    GarageSet,
    GarageSetError,
    garage_map,
    load_garage_set,
    run_seed,
)
from garage_mj.driving.sources import CruiseSource
from garage_mj.export.pack import export_pack
from garage_mj.generation.library import Library
from garage_mj.grid.garage import Garage
from garage_mj.grid.map_io import load_map
from garage_mj.grid.rules import apply_stall_rule
from garage_mj.scene.car import CarConfig, car_geometry
from tests._scenes import distinct_painted

MAPS = ("tiny_7x11", "tiny_b")  # the library's map column is a label: two maps from one shape keep it tiny


def _run(map: str, seed: int) -> str:
    return f"{map}_s{seed}_20261123T22{seed:02d}00_abc{seed:03d}"


@pytest.fixture(scope="module")
def garages() -> list[Garage]:
    """Distinct usable tiny garages."""
    out = distinct_painted("tiny_7x11", range(30))
    assert len(out) >= 18
    return out[:18]


@pytest.fixture(scope="module")
def library(tmp_path_factory, garages):
    """18 garages: map tiny_7x11 runs s0, s1, s2 (4 each), map tiny_b runs s0, s1 (3 each)."""
    path = tmp_path_factory.mktemp("lib") / "library.sqlite"
    plan = [("tiny_7x11", 0)] * 4 + [("tiny_7x11", 1)] * 4 + [("tiny_7x11", 2)] * 4 + \
           [("tiny_b", 0)] * 3 + [("tiny_b", 1)] * 3
    with Library(path) as lib:
        for i, (g, (m, s)) in enumerate(zip(garages, plan)):
            assert lib.add(g, map=m, run=_run(m, s), seed=s, episode=i, timestep=10 * i) is not None
    return path


def test_run_seed_reads_the_training_seed_of_a_run_name():
    assert run_seed("m5_13x13_aligned_s3_20261123T232711_220ba8") == 3
    assert run_seed("m6_13x13_s_s12_20261123T233816_351b8b") == 12  # the map's own "_s" is no seed
    assert run_seed("tiny_7x11_s0") == 0
    assert run_seed("generate:model") is None and run_seed("r") is None


def test_from_library_takes_everything_sorted_by_id(library):
    gs = GarageSet.from_library(library)
    assert len(gs) == 18
    with Library(library, create=False) as lib:
        assert [s.name for s in gs] == [f"{r.map}#{r.id}" for r in lib.query()]
        rec = lib.query()[5]
    assert gs[5] == CruiseSource.from_record(rec) and gs[5].hash == rec.hash
    assert list(gs) == list(gs.sources) and isinstance(gs.sources, tuple)
    assert gs.origin == f"library {library} (all 18)"
    assert {garage_map(s) for s in gs} == set(MAPS)


def test_library_filters_map_difficulty_and_run_seeds(library):
    with Library(library, create=False) as lib:
        records = {f"{r.map}#{r.id}": r for r in lib.query()}
    tiny = GarageSet.from_library(library, map="tiny_7x11")
    assert len(tiny) == 12 and all(s.name.startswith("tiny_7x11#") for s in tiny)
    seeds = GarageSet.from_library(library, run_seeds=[0, 2])
    assert len(seeds) == 4 + 4 + 3
    assert {run_seed(records[s.name].run) for s in seeds} == {0, 2}
    both = GarageSet.from_library(library, map="tiny_b", run_seeds=(1,))
    assert [records[s.name].run for s in both] == [_run("tiny_b", 1)] * 3
    assert "map=tiny_b" in both.origin and "runs=s1" in both.origin
    ds = sorted(r.difficulty for r in records.values())
    lo, hi = ds[4], ds[12]
    mid = GarageSet.from_library(library, difficulty=(lo, hi))
    assert len(mid) == sum(lo <= d <= hi for d in ds) and all(lo <= s.difficulty <= hi for s in mid)
    assert f"difficulty={lo:g}-{hi:g}" in mid.origin


def test_a_sample_is_seeded_stratified_and_the_library_s_own(library):
    a = GarageSet.from_library(library, n=7, seed=3)
    assert a == GarageSet.from_library(library, n=7, seed=3)  # same args, same set, same order
    assert len(a) == 7 and len(set(a.hashes)) == 7
    assert [int(s.name.split("#")[1]) for s in a] == sorted(int(s.name.split("#")[1]) for s in a)
    assert "n=7 of 18, stratified by difficulty, seed 3" in a.origin
    with Library(library, create=False) as lib:  # no run filter: exactly `garage-mj library sample`
        assert [s.name for s in a] == [f"{r.map}#{r.id}" for r in lib.sample(7, 3)]
    others = {GarageSet.from_library(library, n=7, seed=s).hashes for s in range(6)}
    assert len(others) > 1  # the seed matters


def test_excluded_garages_are_left_out_before_the_draw(library):
    first = GarageSet.from_library(library, n=7, seed=3)
    fresh = GarageSet.from_library(library, n=7, seed=3, exclude=first.hashes)
    assert len(fresh) == 7 and not set(fresh.hashes) & set(first.hashes)  # a full, disjoint sample
    assert "excluding=7" in fresh.origin
    rest = GarageSet.from_library(library, exclude=first.hashes)
    assert set(rest.hashes) == set(GarageSet.from_library(library).hashes) - set(first.hashes)
    with pytest.raises(GarageSetError, match="among the 18 excluded"):
        GarageSet.from_library(library, exclude=GarageSet.from_library(library).hashes)
    sub = GarageSet.from_library(library, run_seeds=[1], n=5, seed=0)
    everything = GarageSet.from_library(library, run_seeds=[1])
    assert len(sub) == 5 and set(sub.hashes) < set(everything.hashes)
    assert len(GarageSet.from_library(library, map="tiny_b", n=50)) == 6  # fewer match: all of them


def test_json_round_trip_is_exact(library, tmp_path):
    gs = GarageSet.from_library(library, n=6, seed=1).by_difficulty()
    path = tmp_path / "sub" / "set.json"
    gs.to_json(path)
    back = GarageSet.from_json(path)
    assert back == gs  # names, garages, metrics, packs and origin
    assert back.hashes == gs.hashes and [s.difficulty for s in back] == [s.difficulty for s in gs]
    assert [s.garage.name for s in back] == [s.garage.name for s in gs]
    data = json.loads(path.read_text())
    entry = data["garages"][0]
    assert {"name", "hash", "difficulty", "mean_road_length", "mean_intersection_degree", "map", "grid",
            "initial", "six_stall_axis"} <= set(entry)
    assert entry["map"] in MAPS and data["origin"] == gs.origin
    back.to_json(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == path.read_text()
    assert not [p for p in path.parent.iterdir() if p.name != "set.json"]  # no temp file left behind


def test_library_export_json_is_read(library, tmp_path):
    out = tmp_path / "export.json"
    assert main(["library", "export-json", str(library), "--map", "tiny_b", "--out", str(out)]) == 0
    gs = GarageSet.from_json(out)
    ref = GarageSet.from_library(library, map="tiny_b")
    assert gs.sources == ref.sources
    assert gs.origin == f"json {out} (library export, all 6)"
    assert load_garage_set(str(out)).sources == ref.sources


def test_from_map_paints_a_seeded_set():
    a = GarageSet.from_map("tiny_7x11", 3, seed=1)
    assert len(a) == 3 and a == GarageSet.from_map("tiny_7x11", 3, seed=1)
    assert all(garage_map(s) == "tiny_7x11" for s in a)
    assert a.origin == "painted map=tiny_7x11 (n=3, seed 1)"
    assert load_garage_set("tiny_7x11", n=3, seed=1) == a


def test_from_packs_and_a_broken_pack_is_named(garages, tmp_path):
    paths = [export_pack(g, tmp_path / "packs") for g in garages[:2]]
    (tmp_path / "packs" / "notes").mkdir()  # a folder that is no pack is not one of them
    gs = GarageSet.from_packs(tmp_path / "packs")
    assert [s.name for s in gs] == sorted(p.name for p in paths)
    assert set(gs.hashes) == {g.canonical_hash() for g in garages[:2]}
    assert all(s.pack == str(p.resolve()) for s, p in zip(gs, sorted(paths)))
    assert gs.origin == f"packs {tmp_path / 'packs'} (all 2)"
    assert load_garage_set(tmp_path / "packs") == gs
    broken = sorted(paths)[1]
    (broken / "garage.xodr").write_text("altered")
    with pytest.raises(GarageSetError, match=rf"^pack {broken} is incomplete: garage.xodr does not match"):
        GarageSet.from_packs(tmp_path / "packs")
    with pytest.raises(GarageSetError, match="holds no asset packs.*garage-mj export"):
        GarageSet.from_packs(tmp_path / "packs" / "notes")


def test_split_is_seeded_and_disjoint_and_by_difficulty_orders(library):
    gs = GarageSet.from_library(library)
    train, val = gs.split(0.75, seed=4)
    assert (len(train), len(val)) == (14, 4)  # round(0.75 * 18) = 14
    assert not set(train.hashes) & set(val.hashes)
    assert sorted(train.hashes + val.hashes) == sorted(gs.hashes)
    assert (train, val) == gs.split(0.75, seed=4)
    assert train.hashes != gs.split(0.75, seed=5)[0].hashes
    assert list(train.hashes) == [h for h in gs.hashes if h in set(train.hashes)]  # the set's order is kept
    assert "split 0.75 seed 4: first 14 of 18" in train.origin
    assert [len(p) for p in GarageSet(gs.sources[:2], "two").split(0.99, 0)] == [1, 1]
    ordered = gs.by_difficulty()
    keys = [(s.difficulty, s.name) for s in ordered]
    assert keys == sorted(keys) and sorted(ordered.hashes) == sorted(gs.hashes)
    assert ordered.origin == gs.origin + ", by difficulty"


def _only_after_a_turn() -> Garage:
    """Hand-made 7x11: the road turns right just past the entrance; the one stall reached straight ahead
    (beside the entrance cell) is taken away, so a car that cannot turn reaches no stall."""
    base = load_map("tiny_7x11")
    grid = base.initial.copy()
    grid[5, 2:9] = 1
    grid[1:6, 8] = 1
    grid = apply_stall_rule(grid, "NS")
    grid[5, 1] = 0
    return Garage(grid=grid, initial=base.initial, six_stall_axis="NS", name="after_a_turn")


def test_drivable_drops_a_garage_with_no_feasible_stall(garages):
    painted = [CruiseSource.from_garage(g) for g in garages[:2]]
    blocked = CruiseSource.from_garage(_only_after_a_turn())
    gs = GarageSet((painted[0], blocked, painted[1]), "mixed")
    stiff = car_geometry(CarConfig(max_steer=0.25))  # needs a 12 m radius: straight drives only
    kept = gs.drivable(stiff)
    assert kept.sources == (painted[0], painted[1])
    assert kept.origin == "mixed, drivable (2 of 3)"
    assert gs.drivable().sources == gs.sources  # the shipped car turns into every one of them
    with pytest.raises(GarageSetError, match="none of the 1 garage"):
        GarageSet((blocked,), "one").drivable(stiff)


def test_drivable_shows_progress_on_stderr(garages, capsys):
    GarageSet((CruiseSource.from_garage(garages[0]),), "one").drivable(progress=True)
    assert "drivable" in capsys.readouterr().err


def _one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text and "Traceback" not in text
    return text


def test_errors_are_one_line_naming_the_thing_and_the_fix(library, tmp_path):
    cases = [
        (lambda: load_garage_set(tmp_path / "none.sqlite"), ["none.sqlite", "does not exist", "library.sqlite"]),
        (lambda: load_garage_set(tmp_path / "none.json"), ["none.json", "does not exist", "to_json"]),
        (lambda: load_garage_set("m9_nowhere"), ["'m9_nowhere'", "tiny_7x11", "check the path or the map name"]),
        (lambda: GarageSet.from_map("m9_nowhere", 2), ["m9_nowhere", "shipped maps"]),
        (lambda: GarageSet.from_library(library, map="tiny_b", run_seeds=[2]),
         ["map=tiny_b", "run seeds 2", "run seeds 0,1 for tiny_b", "loosen the filters"]),
        (lambda: GarageSet.from_library(library, difficulty=(2.0, 3.0)),
         ["difficulty 2-3", "holds maps tiny_7x11, tiny_b", "loosen the filters"]),
        (lambda: GarageSet.from_library(library, difficulty=(0.9, 0.1)), ["difficulty range (0.9, 0.1)", "LO <= HI"]),
        (lambda: GarageSet.from_library(library, n=0), ["n=0", ">= 1"]),
        (lambda: load_garage_set(library.parent / "x.json", map="tiny_b"), ["x.json", "map", "library"]),
        (lambda: GarageSet.from_library(library).split(1.0, 0), ["fraction 1.0", "0.8"]),
    ]
    for make, words in cases:
        with pytest.raises(GarageSetError) as exc:
            make()
        line = _one_line(exc)
        assert all(w in line for w in words), (line, words)


def test_bad_json_files_are_refused_by_name(library, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(GarageSetError, match=r"bad.json is not valid JSON .*to_json") as exc:
        GarageSet.from_json(bad)
    _one_line(exc)
    bad.write_text('{"hello": 1}')
    with pytest.raises(GarageSetError, match="neither a garage set"):
        load_garage_set(bad)
    good = tmp_path / "good.json"
    GarageSet.from_library(library, n=2, seed=0).to_json(good)
    data = json.loads(good.read_text())
    grid = data["garages"][1]["grid"]
    grid[3][3] = 0 if grid[3][3] else 1  # one interior cell flipped
    bad.write_text(json.dumps(data))
    with pytest.raises(GarageSetError, match=r"bad.json, garage 1 .*does not match its hash"):
        GarageSet.from_json(bad)
    data = json.loads(good.read_text())
    data["garages"][0]["difficulty"] = "hard"
    bad.write_text(json.dumps(data))
    with pytest.raises(GarageSetError, match="garage 0: difficulty is 'hard', not a number"):
        GarageSet.from_json(bad)
    data["garages"] = []
    bad.write_text(json.dumps(data))
    with pytest.raises(GarageSetError, match="holds no garages"):
        GarageSet.from_json(bad)


@pytest.mark.parametrize("key", ["difficulty", "mean_road_length", "mean_intersection_degree"])
def test_a_set_or_export_with_altered_metrics_is_refused_by_garage(library, tmp_path, key):
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    gs = GarageSet.from_library(library, n=2, seed=0)
    gs.to_json(good)
    data = json.loads(good.read_text())
    data["garages"][1][key] += 0.25  # a hand edit: the grid says otherwise
    bad.write_text(json.dumps(data))
    with pytest.raises(GarageSetError, match=rf"bad.json, garage 1 \({gs[1].name}\): stored {key} .* is not the "
                                             r"grid's .*the file was altered: write the file again") as exc:
        GarageSet.from_json(bad)
    _one_line(exc)
    assert GarageSet.from_json(good).hashes == gs.hashes  # the file as written still loads
    assert main(["library", "export-json", str(library), "--out", str(good)]) == 0
    rows = json.loads(good.read_text())
    rows[0][key] = 0.01
    bad.write_text(json.dumps(rows))
    with pytest.raises(GarageSetError, match=rf"bad.json, garage 0 \({rows[0]['map']}#{rows[0]['id']}\): stored "
                                             rf"{key} 0.01 is not the grid's .*export it again") as exc:
        GarageSet.from_json(bad)


def test_an_altered_library_row_is_refused_by_id(library, tmp_path):
    import shutil
    import sqlite3

    copy = tmp_path / "library.sqlite"
    shutil.copy(library, copy)
    con = sqlite3.connect(copy)
    grid = json.loads(con.execute("SELECT grid FROM garages WHERE id = 3").fetchone()[0])
    grid[3][3] = 0 if grid[3][3] else 1
    con.execute("UPDATE garages SET grid = ? WHERE id = 3", (json.dumps(grid),))
    con.commit()
    con.close()
    with pytest.raises(GarageSetError, match=r"row id 3: the grid does not match its stored hash") as exc:
        GarageSet.from_library(copy)
    _one_line(exc)
    assert len(GarageSet.from_library(copy, map="tiny_b")) == 6  # the other rows stay usable
