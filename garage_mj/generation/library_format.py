"""What a library file holds and how it is checked before use.

The file is SQLite with the garage-mj application id and a schema version in its header
(:data:`APPLICATION_ID`, :data:`SCHEMA_VERSION`), the table ``garages`` (:data:`SCHEMA`) and,
once ``garage-mj check --store`` ran, ``drivability`` (:data:`DRIVABILITY_SCHEMA`), and once
``garage-mj library rate`` ran, ``route_difficulty`` (:data:`ROUTE_SCHEMA`). Both are optional side
tables: a library without them is complete (no schema bump; older readers ignore them).

Three checks stand between a damaged or foreign file and the rest of garage-mj:
:func:`check_header` reads the 100-byte header without SQLite (magic, application id, schema
version), :func:`check_body` reads the schema through an ``immutable`` connection (which writes
nothing), and :func:`record_from_row` turns a row into a :class:`GarageRecord` only when every
column holds its kind; :meth:`GarageRecord.verify` recomputes a row's hash and metrics from its grid.
"""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError, control_character
from garage_mj.grid.garage import Garage, MapError, decode_json, validate_garage
from garage_mj.grid.metrics import evaluate

#: Schema version written to ``PRAGMA user_version``; bump it with a migration.
SCHEMA_VERSION = 1
#: ``PRAGMA application_id`` of a garage-mj library ("GMJL" in ASCII).
APPLICATION_ID = 0x474D4A4C
SQLITE_MAGIC = b"SQLite format 3\x00"

SCHEMA = """
CREATE TABLE IF NOT EXISTS garages (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    map TEXT NOT NULL,
    run TEXT NOT NULL,
    seed INTEGER NOT NULL,
    episode INTEGER NOT NULL,
    timestep INTEGER NOT NULL,
    hash TEXT NOT NULL UNIQUE,
    rows INTEGER NOT NULL,
    cols INTEGER NOT NULL,
    grid TEXT NOT NULL,
    initial TEXT NOT NULL,
    six_stall_axis TEXT NOT NULL CHECK (six_stall_axis IN ('NS', 'EW')),
    coverage REAL NOT NULL,
    difficulty REAL NOT NULL,
    stalls INTEGER NOT NULL,
    mean_road_length REAL NOT NULL,
    mean_intersection_degree REAL NOT NULL,
    created_at TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS garages_map_difficulty ON garages (map, difficulty);
CREATE INDEX IF NOT EXISTS garages_run ON garages (run);
"""
#: Optional table written by ``garage-mj check --store`` (older readers ignore it: no schema bump).
DRIVABILITY_SCHEMA = """
CREATE TABLE IF NOT EXISTS drivability (
    garage_id INTEGER PRIMARY KEY REFERENCES garages (id),
    car TEXT NOT NULL,
    feasible_share REAL NOT NULL,
    feasible_stalls INTEGER NOT NULL,
    stalls INTEGER NOT NULL,
    min_clearance REAL,
    max_curvature REAL,
    checked_at TEXT NOT NULL
)
"""
#: Optional table written by ``garage-mj library rate``: the route difficulty of a garage
#: (:mod:`garage_mj.scene.route_difficulty`) under one fitted model, named by its 12-hex ``key``.
#: ``value`` is NULL for a garage rated without a feasible stall (no route to rate); a garage
#: without a row for a model is not rated under it yet. ``checksum`` (:func:`route_checksum`) binds
#: the value to the model and to the garage's content hash: a row whose checksum does not match
#: (a value edited by hand, a garage row changed since, a table of an older garage-mj without the
#: column) is read as not rated, so ``library rate`` rates that garage again.
ROUTE_SCHEMA = """
CREATE TABLE IF NOT EXISTS route_difficulty (
    garage_id INTEGER NOT NULL REFERENCES garages (id),
    model TEXT NOT NULL,
    value REAL,
    rated_at TEXT NOT NULL,
    checksum TEXT,
    PRIMARY KEY (garage_id, model)
)
"""
#: The rows of ``route_difficulty`` whose checksum matches their garage's current hash (``route_checksum``
#: is registered on every library connection): the only ones a library reads.
VERIFIED_ROUTE_ROWS = ("SELECT r.garage_id AS garage_id, r.model AS model, r.value AS value FROM route_difficulty r "
                       "JOIN garages g ON g.id = r.garage_id WHERE r.checksum = route_checksum(g.hash, r.model, r.value)")
NO_ROUTE_ROWS = "SELECT NULL AS garage_id, NULL AS model, NULL AS value WHERE 0"  # a table without checksums


def route_checksum(garage_hash: str | None, model: str | None, value: float | None) -> str:
    """16 hex digits of SHA-256 over (garage content hash, model key, value): what a stored rating is checked by."""
    return hashlib.sha256(json.dumps([garage_hash, model, value]).encode()).hexdigest()[:16]


COLUMNS = (
    "id, map, run, seed, episode, timestep, hash, grid, initial, six_stall_axis, coverage, "
    "difficulty, stalls, mean_road_length, mean_intersection_degree, created_at"
)

KINDS: dict[str, type] = {
    "id": int, "map": str, "run": str, "seed": int, "episode": int, "timestep": int, "hash": str,
    "grid": list, "initial": list, "six_stall_axis": str, "coverage": float, "difficulty": float,
    "stalls": int, "mean_road_length": float, "mean_intersection_degree": float, "created_at": str,
}


class LibraryError(GarageMJError):
    """A library file cannot be used (foreign, corrupt, newer schema, missing)."""


@dataclass(frozen=True)
class GarageRecord:
    """One row of the library; :attr:`garage` rebuilds the :class:`Garage`."""

    id: int
    map: str
    run: str
    seed: int
    episode: int
    timestep: int
    hash: str
    grid: list[list[int]]
    initial: list[list[int]]
    six_stall_axis: str
    coverage: float
    difficulty: float
    stalls: int
    mean_road_length: float
    mean_intersection_degree: float
    created_at: str

    @property
    def garage(self) -> Garage:
        return Garage(
            np.array(self.grid), np.array(self.initial), six_stall_axis=self.six_stall_axis,  # type: ignore[arg-type]
            name=f"{self.map}#{self.id}",
        )

    def verify(self, where: str = "library") -> GarageRecord:
        """Recompute the garage's hash and metrics from the stored grid; :class:`LibraryError` if any differ.

        SQLite's own checks pass when one digit of a stored grid flips; this catches it before
        the row is exported or driven. Also checks the garage with :func:`validate_garage`.
        """
        fix = "the row was altered after it was stored; delete it or restore the library from a backup"
        try:
            garage = validate_garage(self.garage)
        except MapError as exc:
            raise LibraryError(f"{where}, row id {self.id}: {exc}; {fix}") from None
        if garage.canonical_hash() != self.hash:
            raise LibraryError(f"{where}, row id {self.id}: the grid does not match its stored hash; {fix}")
        m = evaluate(garage)
        for col in ("coverage", "difficulty", "stalls", "mean_road_length", "mean_intersection_degree"):
            if not math.isclose(getattr(m, col), getattr(self, col), rel_tol=1e-9, abs_tol=1e-9):
                raise LibraryError(f"{where}, row id {self.id}: stored {col} {getattr(self, col)} is not the "
                                   f"grid's ({getattr(m, col)}); {fix}")
        return self

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def check_header(path: Path) -> int:
    """Validate the file header without SQLite; returns its schema version (0: empty file)."""
    try:
        with path.open("rb") as f:
            head = f.read(100)
    except OSError as exc:
        raise LibraryError(f"{path}: cannot read the library: {exc.strerror}") from None
    if not head:
        return 0
    if len(head) < 100 or not head.startswith(SQLITE_MAGIC):
        raise LibraryError(
            f"{path} is not an SQLite database (corrupt, or another kind of file); "
            "pass a garage-mj library.sqlite or a new path"
        )
    user_version, application_id = struct.unpack(">I4xI", head[60:72])
    if application_id != APPLICATION_ID:
        raise LibraryError(
            f"{path} is an SQLite database but not a garage-mj library; "
            "pass a garage-mj library.sqlite or a new path"
        )
    if user_version > SCHEMA_VERSION:
        raise LibraryError(
            f"{path} has library schema version {user_version}, newer than this garage-mj "
            f"understands ({SCHEMA_VERSION}); upgrade garage-mj to read it"
        )
    return user_version


def check_body(path: Path) -> None:
    """Read the schema through an ``immutable`` connection (writes nothing, not even -wal/-shm)."""
    if Path(f"{path}-wal").exists():
        return  # a writer is live or crashed: SQLite must replay the WAL, the normal open checks
    for attempt in range(2):
        try:
            con = sqlite3.connect(f"{path.resolve().as_uri()}?immutable=1", uri=True)
            try:
                con.execute("SELECT name FROM sqlite_master").fetchall()
                con.execute("SELECT count(*) FROM garages").fetchone()
            finally:
                con.close()
            return
        except sqlite3.DatabaseError as exc:
            if attempt == 0:
                time.sleep(0.2)  # a checkpoint in another process may have torn our read
                continue
            raise LibraryError(
                f"{path} is a damaged garage-mj library ({exc}); restore it from a backup or "
                "pass a new path"
            ) from None


def record_from_row(row: tuple, path: Path) -> GarageRecord:
    """A row (the columns :data:`COLUMNS`) of the library ``path`` as a record; a damaged row (bad JSON,
    text in a numeric column) is a one-line :class:`LibraryError`."""
    values = list(row)
    where = f"{path}, row id {values[0]}"
    fix = "the library is damaged: delete that row or restore the file from a backup"
    for i, name in ((7, "grid"), (8, "initial")):
        try:
            values[i] = json.loads(values[i]) if isinstance(values[i], str) else None
        except (ValueError, RecursionError):
            values[i] = None
        if not isinstance(values[i], list):
            raise LibraryError(f"{where}: column {name} is not a JSON list of rows; {fix}")
    for i, name in enumerate(COLUMNS.split(", ")):
        kind = KINDS[name]
        v = values[i]
        ok = (isinstance(v, str) if kind is str else isinstance(v, list) if kind is list
              else isinstance(v, int) if kind is int
              else isinstance(v, (int, float)) and math.isfinite(v))
        if not ok:
            raise LibraryError(f"{where}: column {name} holds {str(v)[:30]!r}, not a "
                               f"{kind.__name__}; {fix}")
        if kind is str and control_character(v) is not None:
            raise LibraryError(f"{where}: column {name} holds {v[:30]!r}, with the control character "
                               f"{control_character(v)!r}; {fix}")
    return GarageRecord(*values)


def garages_from_json(text: str | bytes, source: str = "garage JSON") -> list[Garage]:
    """The garages of a JSON file: one garage (:meth:`Garage.to_json`) or the list ``garage-mj library
    export-json`` writes (each row named ``<map>#<id>`` as the library names it, checked against its hash).

    Each garage is checked as export and cruise need (:func:`validate_garage`); a problem is a
    :class:`MapError` naming the file and the garage's place in the list.
    """
    data = decode_json(text, source)
    if isinstance(data, dict):
        return [Garage.from_json(data, source, usable=True)]
    if not isinstance(data, list) or not data:
        raise MapError(f"{source}: expected a garage (an object with grid and initial) or a non-empty list of "
                       "them, as 'garage-mj library export-json' writes")
    garages = []
    for i, item in enumerate(data):
        where = f"{source}, garage {i + 1} of {len(data)}"
        if isinstance(item, dict) and "name" not in item and isinstance(item.get("map"), str) \
                and isinstance(item.get("id"), int):
            item = {**item, "name": f"{item['map']}#{item['id']}"}
        garage = Garage.from_json(item, where, usable=True) if isinstance(item, dict) else None
        if garage is None:
            raise MapError(f"{where}: expected an object with grid and initial, not {type(item).__name__}")
        if "hash" in item and garage.canonical_hash() != item["hash"]:
            raise MapError(f"{where}: the grid does not match its stored hash; the file was altered after it "
                           "was written: export it again with garage-mj library export-json")
        garages.append(garage)
    return garages
