"""The route difficulty in the library: the side table, its filter, rating (resumable), old libraries, the CLI."""

from __future__ import annotations

import json
import math
import sqlite3

import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.driving.difficulty import rating as route_rating
from garage_mj.driving.difficulty.rating import rate_library
from garage_mj.generation.library import SCHEMA_VERSION, Library, LibraryError
from garage_mj.scene.route_difficulty import fit, load_route_model, route_difficulty
from tests._scenes import distinct_painted
from tests.test_route_difficulty import _synthetic


@pytest.fixture(scope="module")
def garages():
    """Four distinct usable tiny garages."""
    out = distinct_painted("tiny_7x11", range(20))
    assert len(out) >= 4
    return out[:4]
    raise AssertionError("the painter gave fewer than 4 distinct tiny garages")


@pytest.fixture(scope="module")
def shipped():
    return load_route_model()


def _library(path, garages) -> list[int]:
    with Library(path) as lib:
        return [lib.add(g, map="tiny_7x11", run="r", seed=0, episode=i, timestep=i) for i, g in enumerate(garages)]


def test_side_table_stores_reads_and_filters(tmp_path, garages):
    path = tmp_path / "library.sqlite"
    ids = _library(path, garages)
    with Library(path) as lib:
        assert not lib.has_route_difficulty() and lib.unrated("k1") == ids
        lib.set_route_difficulty(ids[0], "k1", 0.25)
        lib.set_route_difficulty(ids[1], "k1", math.nan)  # rated: no feasible stall
        assert lib.unrated("k1") == ids[2:] and lib.unrated("k2") == ids
        got = lib.route_difficulties(ids, "k1")
        assert got[ids[0]] == 0.25 and math.isnan(got[ids[1]]) and set(got) == set(ids[:2])
        # an unrated garage among those the other filters keep: refused with the file and the fix
        with pytest.raises(LibraryError, match=rf"{path}.*2 garage\(s\).*garage-mj library rate {path}"):
            lib.query(route=(0.0, 1.0), route_model="k1")
        lib.set_route_difficulty(ids[2], "k1", 0.75)
        lib.set_route_difficulty(ids[3], "k1", 0.5)
        lib.set_route_difficulty(ids[3], "k1", 0.55)  # rated again: replaced
        assert [r.id for r in lib.query(route=(0.5, 1.0), route_model="k1")] == ids[2:]
        assert lib.count(route=(0.0, 0.3), route_model="k1") == 1  # the no-feasible-stall garage never matches
        assert [r.id for r in lib.sample(10, 0, route=(0.2, 0.6), route_model="k1")] == [ids[0], ids[3]]
        assert lib.points(route_model="k1").tolist() == [
            [v, lib.get(i).coverage] for i, v in ((ids[0], 0.25), (ids[2], 0.75), (ids[3], 0.55))]
        st = lib.stats(route_model="k1")["maps"]["tiny_7x11"]["route_difficulty"]
        assert (st["rated"], st["with_value"], st["min"], st["max"]) == (4, 3, 0.25, 0.75)
        assert "route_difficulty" not in lib.stats(route_model="k2")["maps"]["tiny_7x11"]
        with pytest.raises(LibraryError, match="no route difficulty under model k2"):
            lib.count(route=(0.0, 1.0), route_model="k2")
        with pytest.raises(ValueError, match="needs route_model"):
            lib.query(route=(0.0, 1.0))
        assert lib.query(map="other", route=(0.0, 1.0), route_model="k2") == []  # nothing to rate: nothing matches


def test_an_old_library_without_the_table_opens_lists_and_gets_rated(tmp_path, garages, shipped, capsys):
    path = tmp_path / "library.sqlite"
    ids = _library(path, garages[:2])  # what an older garage-mj wrote: garages only
    with Library(path, create=False) as lib:  # read-only, as the browsing commands open it
        assert not lib.has_route_difficulty() and lib.route_difficulties(ids, shipped.key) == {}
        with pytest.raises(LibraryError, match="garage-mj library rate"):
            lib.query(route=(0.0, 1.0), route_model=shipped.key)
    assert main(["library", "ls", str(path)]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].split()[5:7] == ["diff", "route"] and all(r.split()[6] == "-" for r in rows[1:3])
    assert main(["library", "ls", str(path), "--route-difficulty", "0", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"garage-mj library rate {path}" in err
    assert main(["library", "rate", str(path), "--quiet"]) == 0
    assert "rated 2 garage(s)" in capsys.readouterr().out
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION  # no schema bump
    con.close()
    with Library(path, create=False) as lib:
        got = lib.route_difficulties(ids, shipped.key)
    assert got == {i: pytest.approx(route_difficulty(g, shipped), abs=1e-12) for i, g in zip(ids, garages[:2])}
    assert main(["library", "ls", str(path), "--route-difficulty", "0", "1"]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert [r.split()[6] for r in rows[1:3]] == [f"{got[i]:.3f}" for i in ids]


def _set(path, sql, *args) -> None:
    con = sqlite3.connect(path)
    con.execute(sql, args)
    con.commit()
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()


def test_a_hand_edited_or_outlived_rating_is_not_read(tmp_path, garages, shipped, capsys):
    path = tmp_path / "library.sqlite"
    ids = _library(path, garages[:2])
    assert main(["library", "rate", str(path), "--quiet"]) == 0
    with Library(path, create=False) as lib:
        true = lib.route_difficulties(ids, shipped.key)
    _set(path, "UPDATE route_difficulty SET value = 0.01 WHERE garage_id = ?", ids[0])  # forged by hand
    with Library(path, create=False) as lib:
        assert lib.route_difficulties(ids, shipped.key) == {ids[1]: true[ids[1]]} and lib.unrated(shipped.key) == ids[:1]
    capsys.readouterr()
    assert main(["cruise", "--library", str(path), "--route-difficulty", "0", "0.05", "--tests", "1",
                 "--driver", "waypoint", "--out", str(tmp_path / "c"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no longer matches its garage" in err and f"garage-mj library rate {path}" in err
    assert main(["library", "rate", str(path), "--quiet"]) == 0  # rated again: the true value is back
    assert "rated 1 garage(s)" in capsys.readouterr().out
    with Library(path, create=False) as lib:
        assert lib.route_difficulties(ids, shipped.key) == true
    # a row that now holds another garage (its grid, hash and metrics consistent): its old rating is not read
    other = tmp_path / "other.sqlite"
    _library(other, garages[2:3])
    cols = "grid, initial, hash, coverage, difficulty, stalls, mean_road_length, mean_intersection_degree"
    con = sqlite3.connect(other)
    row = con.execute(f"SELECT {cols} FROM garages").fetchone()
    con.close()
    _set(path, f"UPDATE garages SET ({cols}) = ({', '.join('?' * len(row))}) WHERE id = {ids[1]}", *row)
    with Library(path, create=False) as lib:
        assert lib.route_difficulties(ids, shipped.key) == {ids[0]: true[ids[0]]}


def test_an_older_rating_table_without_checksums_is_rated_again(tmp_path, garages, shipped, capsys):
    path = tmp_path / "library.sqlite"
    ids = _library(path, garages[:2])
    _set(path, "CREATE TABLE route_difficulty (garage_id INTEGER NOT NULL REFERENCES garages (id), model TEXT NOT "
               "NULL, value REAL, rated_at TEXT NOT NULL, PRIMARY KEY (garage_id, model))")
    _set(path, "INSERT INTO route_difficulty VALUES (?, ?, 0.01, 'then')", ids[0], shipped.key)
    with Library(path, create=False) as lib:
        assert lib.route_difficulties(ids, shipped.key) == {} and lib.unrated(shipped.key) == ids
    assert main(["library", "rate", str(path), "--quiet"]) == 0
    assert "rated 2 garage(s)" in capsys.readouterr().out
    with Library(path, create=False) as lib:
        got = lib.route_difficulties(ids, shipped.key)
    assert got == {i: pytest.approx(route_difficulty(g, shipped), abs=1e-12) for i, g in zip(ids, garages[:2])}


def test_rating_is_resumable_and_the_same_whatever_the_workers(tmp_path, garages, shipped, monkeypatch, capsys):
    path = tmp_path / "library.sqlite"
    ids = _library(path, garages)
    real, calls = route_rating._rate, []

    def killed_on_the_third(job):
        calls.append(job[0])
        if len(calls) == 3:
            raise KeyboardInterrupt  # a Ctrl-C or kill while the third garage is rated
        return real(job)

    monkeypatch.setattr(route_rating, "_rate", killed_on_the_third)
    with pytest.raises(KeyboardInterrupt):
        rate_library(path, compute=Compute(progress=False))
    monkeypatch.setattr(route_rating, "_rate", real)
    with Library(path, create=False) as lib:
        assert set(lib.route_difficulties(ids, shipped.key)) == set(ids[:2])  # both values before the kill kept
    assert main(["library", "rate", str(path), "--limit", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "rated 1 garage(s)" in out and "s per garage" in out and "1 left" in out
    assert main(["library", "rate", str(path), "--quiet"]) == 0
    assert "rated 1 garage(s)" in capsys.readouterr().out
    assert main(["library", "rate", str(path), "--quiet"]) == 0  # nothing left
    assert "rated 0 garage(s)" in capsys.readouterr().out
    with Library(path, create=False) as lib:
        one = lib.route_difficulties(ids, shipped.key)
    # the same values from two workers in a fresh library
    other = tmp_path / "two.sqlite"
    _library(other, garages)
    res = rate_library(other, shipped, compute=Compute(workers=2, progress=False))
    assert (res.rated, res.left, res.model_key) == (4, 0, shipped.key)
    with Library(other, create=False) as lib:
        assert lib.route_difficulties(ids, shipped.key) == one


def test_cli_shows_route_difficulty_beside_the_papers(tmp_path, garages, shipped, capsys):
    path = tmp_path / "library.sqlite"
    ids = _library(path, garages[:3])
    mine = tmp_path / "mine.json"
    fit(*_synthetic()).save(mine)
    assert main(["library", "rate", str(path), "--map", "tiny_7x11", "--limit", "2", "--quiet"]) == 0
    assert main(["library", "rate", str(path), "--model", str(mine), "--quiet"]) == 0
    capsys.readouterr()
    with Library(path, create=False) as lib:
        ours = lib.route_difficulties(ids, shipped.key)
    assert main(["library", "show", str(path), str(ids[0])]) == 0
    assert f"route difficulty {ours[ids[0]]:.3f} (model {shipped.key})" in capsys.readouterr().out
    assert main(["library", "show", str(path), str(ids[2])]) == 0
    assert "route difficulty - " in capsys.readouterr().out  # not rated under the shipped model
    assert main(["library", "stats", str(path)]) == 0
    lo, hi = min(ours.values()), max(ours.values())
    assert f"route difficulty {lo:.3f}-{hi:.3f}" in capsys.readouterr().out
    assert main(["library", "stats", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["maps"]["tiny_7x11"]["route_difficulty"]["rated"] == 2
    dump = tmp_path / "dump.json"
    assert main(["library", "export-json", str(path), "--out", str(dump)]) == 0
    rows = json.loads(dump.read_text())
    assert [r["route_difficulty"] for r in rows] == [ours[ids[0]], ours[ids[1]], None]
    assert {r["route_model"] for r in rows} == {shipped.key}
    # another model: its own values, filtered with --route-model
    assert main(["library", "sample", str(path), "-n", "3", "--route-difficulty", "0", "1", "--route-model",
                 str(mine)]) == 0
    assert "3 garage(s)" in capsys.readouterr().out
    assert main(["library", "rate", str(path), "--map", "nope"]) == 2
    assert "no garage of map 'nope'" in capsys.readouterr().err


def test_evaluate_gains_the_route_difficulty_on_request(junction_garage, shipped, tmp_path):
    import garage_mj
    from garage_mj.grid.metrics import evaluate as grid_evaluate

    plain = garage_mj.evaluate(junction_garage)
    assert plain == grid_evaluate(junction_garage) and plain.route_difficulty is None
    assert "route_difficulty" not in plain.to_dict()  # files written from the metrics stay as they were
    rated = garage_mj.evaluate(junction_garage, route=True)
    assert rated.route_difficulty == route_difficulty(junction_garage, shipped)
    assert 0.0 < rated.route_difficulty < 1.0 and rated.to_dict()["route_difficulty"] == rated.route_difficulty
    assert rated.difficulty == plain.difficulty  # the paper's difficulty is untouched
    mine = tmp_path / "mine.json"
    model = fit(*_synthetic())
    model.save(mine)
    assert garage_mj.evaluate(junction_garage, model=mine).route_difficulty == pytest.approx(
        route_difficulty(junction_garage, model), abs=1e-12)
    assert garage_mj.evaluate(junction_garage, model=model).route_difficulty == route_difficulty(junction_garage, model)


def test_garage_set_from_library_takes_a_route_range(tmp_path, garages, shipped):
    from garage_mj.driving.garage_set import GarageSet, GarageSetError

    path = tmp_path / "library.sqlite"
    ids = _library(path, garages)
    with pytest.raises(GarageSetError, match="garage-mj library rate"):
        GarageSet.from_library(path, route=(0.0, 1.0))
    rate_library(path, compute=Compute(progress=False))
    with Library(path, create=False) as lib:
        values = lib.route_difficulties(ids, shipped.key)
    lo = sorted(values.values())[1]
    chosen = GarageSet.from_library(path, route=(lo, 1.0))
    assert chosen.hashes == tuple(g.canonical_hash() for i, g in zip(ids, garages) if values[i] >= lo)
    assert f"route_difficulty={lo:g}-1@{shipped.key}" in chosen.origin
    with pytest.raises(GarageSetError, match="route difficulty 0.99-1"):
        GarageSet.from_library(path, route=(0.99, 1.0))
