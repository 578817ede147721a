"""The scenario library: storage, dedup, filters, sampling, and refusing files it must not touch."""

from __future__ import annotations

import multiprocessing as mp
import sqlite3
import struct
from pathlib import Path

import pytest

from garage_mj.generation.library import SCHEMA_VERSION, Library, LibraryError
from garage_mj.grid.metrics import evaluate
from tests._scenes import distinct_painted


@pytest.fixture(scope="module")
def garages():
    """Distinct usable tiny garages (the scripted painter repeats itself now and then)."""
    return distinct_painted("tiny_7x11", range(40))


def _fill(lib: Library, garages, map="tiny_7x11") -> list[int]:
    return [lib.add(g, map=map, run="r", seed=0, episode=i, timestep=10 * i) for i, g in enumerate(garages)]


def test_add_get_roundtrip_and_metrics(tmp_path, garages):
    with Library(tmp_path / "library.sqlite") as lib:
        ids = _fill(lib, garages[:3])
        assert all(isinstance(i, int) for i in ids)
        rec = lib.get(ids[1])
    assert rec.garage == garages[1]
    assert (rec.map, rec.run, rec.seed, rec.episode, rec.timestep) == ("tiny_7x11", "r", 0, 1, 10)
    m = evaluate(garages[1])
    assert (rec.coverage, rec.difficulty, rec.stalls) == (m.coverage, m.difficulty, m.stalls)
    assert (rec.mean_road_length, rec.mean_intersection_degree) == (m.mean_road_length, m.mean_intersection_degree)
    assert rec.hash == garages[1].canonical_hash()


def test_duplicate_is_stored_once(tmp_path, garages):
    with Library(tmp_path / "library.sqlite") as lib:
        first = lib.add(garages[0], map="tiny_7x11", run="a", seed=0, episode=0, timestep=5)
        again = lib.add(garages[0], map="tiny_7x11", run="b", seed=1, episode=7, timestep=99)
        assert first is not None and again is None
        assert lib.count() == 1
        assert lib.get(first).run == "a"  # the first finder keeps the credit


def test_file_survives_reopen_and_is_wal(tmp_path, garages):
    path = tmp_path / "library.sqlite"
    with Library(path) as lib:
        _fill(lib, garages[:4])
    with Library(path, create=False) as lib:
        assert lib.count() == 4
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    con.close()


def test_query_filters(tmp_path, garages):
    with Library(tmp_path / "library.sqlite") as lib:
        _fill(lib, garages[:10])
        _fill(lib, garages[10:14], map="other")
        everything = lib.query()
        assert len(everything) == 14
        assert [r.id for r in everything] == sorted(r.id for r in everything)
        assert {r.map for r in lib.query(map="other")} == {"other"}
        assert len(lib.query(map="tiny_7x11", limit=3)) == 3
        lo, hi = 0.7, 0.85
        hits = lib.query(difficulty=(lo, hi))
        assert hits and all(lo <= r.difficulty <= hi for r in hits)
        assert len(hits) == sum(lo <= r.difficulty <= hi for r in everything)
        cov = sorted(r.coverage for r in everything)[5]
        assert all(r.coverage >= cov for r in lib.query(coverage=(cov, 1.0)))
        assert lib.query(map="nope") == []
        with pytest.raises(ValueError, match="empty"):
            lib.query(difficulty=(0.9, 0.1))


def test_sample_deterministic_and_stratified(tmp_path, garages):
    with Library(tmp_path / "library.sqlite") as lib:
        _fill(lib, garages)
        a = [r.id for r in lib.sample(6, seed=3)]
        b = [r.id for r in lib.sample(6, seed=3)]
        assert a == b and len(set(a)) == 6
        assert [r.id for r in lib.sample(6, seed=4)] != a or lib.count() <= 6
        # stratified: every difficulty bin present in the library shows up when n allows
        bins = {min(int(r.difficulty / 0.1), 9) for r in lib.query()}
        got = {min(int(r.difficulty / 0.1), 9) for r in lib.sample(len(bins) * 2, seed=0)}
        assert got == bins
        assert len(lib.sample(10_000, seed=0)) == lib.count()
        assert len(lib.sample(5, seed=1, stratify=None)) == 5


def test_stats(tmp_path, garages):
    with Library(tmp_path / "library.sqlite") as lib:
        _fill(lib, garages[:5])
        s = lib.stats()
    assert s["total"] == 5
    t = s["maps"]["tiny_7x11"]
    assert t["garages"] == 5 and 0.0 <= t["difficulty"]["min"] <= t["difficulty"]["max"] <= 1.0


def test_get_missing_id(tmp_path):
    with Library(tmp_path / "library.sqlite") as lib, pytest.raises(LibraryError, match="no garage with id 42"):
        lib.get(42)


def test_reader_does_not_create(tmp_path):
    path = tmp_path / "missing.sqlite"
    with pytest.raises(LibraryError, match="no library at"):
        Library(path, create=False)
    assert not path.exists()


def _assert_refused(path: Path, match: str) -> None:
    before = {p.name: p.read_bytes() for p in path.parent.iterdir()}
    with pytest.raises(LibraryError, match=match) as info:
        Library(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    after = {p.name: p.read_bytes() for p in path.parent.iterdir()}
    assert after == before  # same bytes, and no -wal/-shm/journal file appeared


def test_foreign_sqlite_refused_untouched(tmp_path):
    path = tmp_path / "other.sqlite"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE people (name TEXT)")
    con.execute("INSERT INTO people VALUES ('ada')")
    con.commit()
    con.close()
    _assert_refused(path, "not a garage-mj library")


def test_foreign_wal_sqlite_refused_untouched(tmp_path):
    path = tmp_path / "other.sqlite"
    con = sqlite3.connect(path)
    con.execute("PRAGMA journal_mode = WAL")
    con.execute("CREATE TABLE t (x)")
    con.commit()
    con.close()
    _assert_refused(path, "not a garage-mj library")


def test_not_sqlite_refused_untouched(tmp_path):
    path = tmp_path / "library.sqlite"
    path.write_bytes(b"this is a text file, not a database\n" * 20)
    _assert_refused(path, "not an SQLite database")


def test_corrupt_library_refused_untouched(tmp_path, garages):
    path = tmp_path / "library.sqlite"
    with Library(path) as lib:
        _fill(lib, garages[:5])
    data = bytearray(path.read_bytes())
    data[100:] = bytes((i * 37) % 251 for i in range(len(data) - 100))  # keep the header, wreck the pages
    path.write_bytes(bytes(data))
    _assert_refused(path, "damaged")


def test_newer_schema_refused_untouched(tmp_path, garages):
    path = tmp_path / "library.sqlite"
    with Library(path) as lib:
        _fill(lib, garages[:2])
    data = bytearray(path.read_bytes())
    data[60:64] = struct.pack(">I", SCHEMA_VERSION + 1)  # the user_version field of the header
    path.write_bytes(bytes(data))
    _assert_refused(path, "newer")


def _writer(path: str, grids: list, worker: int) -> None:
    from garage_mj.grid.garage import Garage

    with Library(path) as lib:
        for i, g in enumerate(grids):
            lib.add(Garage.from_json(g), map="tiny_7x11", run=f"w{worker}", seed=worker, episode=i, timestep=i)


def test_concurrent_writers(tmp_path, garages):
    """Two processes writing overlapping garages to one file: each stored once, none lost."""
    path = tmp_path / "library.sqlite"
    Library(path).close()
    half = len(garages) // 2
    chunks = [[g.to_dict() for g in garages[: half + 3]], [g.to_dict() for g in garages[half - 3 :]]]
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(str(path), chunk, w)) for w, chunk in enumerate(chunks)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    with Library(path) as lib:
        assert lib.count() == len(garages)
        assert {r.hash for r in lib.query()} == {g.canonical_hash() for g in garages}
