"""The scenario library: every usable garage met during training, in one SQLite file.

One file (``library.sqlite``) in WAL mode holds the table ``garages``; a garage found twice is
stored once (``hash`` is UNIQUE). Several training processes may write to the same file at the
same time: each insert is its own short transaction and writers wait up to
:data:`BUSY_TIMEOUT_S` for the lock.

Opening a file checks it before SQLite touches it (:mod:`garage_mj.generation.library_format`):
the 100-byte header must carry the SQLite magic, the garage-mj application id and a schema
version this code knows. A foreign, corrupt or newer file raises :class:`LibraryError` naming
the file and the fix, and nothing on disk changes (the check reads bytes, then opens the file
``immutable``, which writes nothing).

Beside ``garages`` a library may hold the side table ``route_difficulty`` (a number per garage and
route difficulty model, the model named by its 12-hex key): ``garage-mj library rate`` computes the
values in the later stages and stores them here (:meth:`Library.set_route_difficulty`); this module
only stores and filters numbers. Each value is stored with a checksum over the garage's hash, the
model key and the value, and only values whose checksum matches are read: a value edited by hand, or
one left from before its garage row changed, reads as not rated (``library rate`` rates it again).
A library without the table (an older one) opens, lists and gets rated as any other; filtering it
on the route difficulty asks for ``garage-mj library rate`` first.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
from collections.abc import Iterable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import control_character
from garage_mj.generation.library_format import (
    APPLICATION_ID,
    COLUMNS,
    DRIVABILITY_SCHEMA,
    KINDS,
    NO_ROUTE_ROWS,
    ROUTE_SCHEMA,
    SCHEMA,
    SCHEMA_VERSION,
    VERIFIED_ROUTE_ROWS,
    GarageRecord,
    LibraryError,
    check_body,
    check_header,
    garages_from_json,  # noqa: F401  (re-exported: export --garage reads library export-json lists)
    record_from_row,
    route_checksum,
)
from garage_mj.grid.garage import Garage
from garage_mj.grid.metrics import evaluate

BUSY_TIMEOUT_S = 60.0  # [s] a writer waits this long for another writer's lock
DIFFICULTY_BIN = 0.1  # width of the difficulty strata of :meth:`Library.sample`


def on_read_only_mount(path: Path) -> bool:
    """Whether ``path`` (or, for a path not made yet, its nearest existing folder) lies on a file system
    mounted read-only, where no ``chmod`` helps (``EROFS``)."""
    for where in (path, *path.absolute().parents):
        try:
            return bool(os.statvfs(where).f_flag & os.ST_RDONLY)
        except FileNotFoundError:
            continue
        except OSError:
            return False
    return False


def read_only_mount_error(path: Path) -> LibraryError:
    """The one-line refusal of a library to be written on a read-only file system."""
    fix = ("copy the library to a writable place and pass the copy (or another library path)" if path.exists()
           else "pass a library path in a writable place")
    return LibraryError(f"{path} is on a read-only file system (mounted read-only); {fix}")


def check_writable(path: str | Path, *, contents: bool = True) -> None:
    """Refuse, before anything is written, a library file (or its folder) this process may not write.

    SQLite writes the file and, in WAL mode, ``-wal``/``-shm`` files beside it; without this check a
    read-only file or folder fails at the first insert, after the work before it. A folder at ``path``,
    a file where one of its folders should be and (``contents``) a file that is not a garage-mj
    library are refused too.
    """
    path = Path(path)
    if path.is_dir():
        raise LibraryError(f"{path} is a folder; pass the library file (library.sqlite)")
    above = next((p for p in path.parents if p.exists()), None)  # "." or "/" at the end
    if above is not None and not above.is_dir():
        raise LibraryError(f"{path}: {above} is a file, not a folder; pass a library path in a folder")
    if contents and path.exists() and check_header(path):
        check_body(path)
    if on_read_only_mount(path):
        raise read_only_mount_error(path)
    if path.exists() and not os.access(path, os.W_OK):
        raise LibraryError(f"{path} is read-only; make it writable (chmod u+w {path}) or copy the library "
                           "to a file you may write")
    folder = path.parent
    if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
        raise LibraryError(f"{path}: its folder {folder} is read-only (SQLite writes its journal files beside "
                           "the library); make the folder writable or copy the library to a writable folder")


class Library:
    """The scenario library in one SQLite file.

    Args:
        path: the ``library.sqlite`` file.
        create: make the file if it does not exist (readers pass ``False`` to get a clear error).
        readonly: open for reading only (default: ``not create``), so a read-only file or folder
            can be listed; writing through such a library is refused by SQLite.
    """

    def __init__(self, path: str | Path, *, create: bool = True, readonly: bool | None = None) -> None:
        self.path = Path(path)
        self.readonly = (not create) if readonly is None else readonly
        exists = self.path.exists()
        if not exists and not create:
            raise LibraryError(f"no library at {self.path}; check the path, or make one with garage-mj train or "
                               "garage-mj generate (both write library.sqlite)")
        if exists and self.path.is_dir():
            raise LibraryError(f"{self.path} is a folder; pass the library file (library.sqlite)")
        version = check_header(self.path) if exists else 0
        if version:
            check_body(self.path)
        if self.readonly:
            if not exists or not version:
                raise LibraryError(f"{self.path} is an empty file, not a library; train first (garage-mj train)")
            self._con = self._connect_readonly()
            return
        if not exists:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        check_writable(self.path, contents=False)  # the header and body are checked above
        try:
            self._con = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
            _register_functions(self._con)
            self._con.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
            if version < SCHEMA_VERSION:
                self._create_schema()
            if self._con.execute("PRAGMA journal_mode").fetchone()[0] != "wal":
                self._con.execute("PRAGMA journal_mode = WAL")
            self._con.execute("PRAGMA synchronous = NORMAL")  # WAL + NORMAL: durable across a process kill
        except sqlite3.DatabaseError as exc:
            if on_read_only_mount(self.path):  # "attempt to write a readonly database": the mount, not the file
                raise read_only_mount_error(self.path) from None
            raise LibraryError(f"{self.path}: cannot open the library ({exc})") from None

    def _connect_readonly(self) -> sqlite3.Connection:
        """A connection that writes nothing, not even ``-wal``/``-shm`` files.

        With no ``-wal`` beside the file (no writer is live, none crashed) the file is opened
        ``immutable``; otherwise ``mode=ro``, which reads the writer's WAL (and falls back to
        ``immutable`` where SQLite cannot use the ``-shm``, e.g. in a read-only folder).
        """
        uri = self.path.resolve().as_uri()
        live = Path(f"{self.path}-wal").exists()
        for query in ("mode=ro", "immutable=1") if live else ("immutable=1",):
            try:
                con = sqlite3.connect(f"{uri}?{query}", uri=True, timeout=BUSY_TIMEOUT_S, isolation_level=None)
                con.execute("SELECT count(*) FROM garages").fetchone()
                _register_functions(con)
                return con
            except sqlite3.DatabaseError as exc:
                err = exc
        raise LibraryError(f"{self.path}: cannot open the library for reading ({err})") from None

    def _create_schema(self) -> None:
        con = self._con
        con.execute("BEGIN IMMEDIATE")
        try:
            app, ver = (con.execute(f"PRAGMA {p}").fetchone()[0] for p in ("application_id", "user_version"))
            if (app, ver) == (APPLICATION_ID, SCHEMA_VERSION):
                con.execute("COMMIT")  # another process created it first
                return
            tables = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
            if app == 0 and tables:
                raise LibraryError(f"{self.path} is an SQLite database but not a garage-mj library")
            for statement in SCHEMA.split(";"):
                if statement.strip():
                    con.execute(statement)
            con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            con.execute("COMMIT")
        except BaseException:
            con.execute("ROLLBACK")
            raise

    # -- context manager --------------------------------------------------------------------------
    def close(self) -> None:
        self._con.close()

    def __enter__(self) -> Library:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- writing ----------------------------------------------------------------------------------
    def add(self, garage: Garage, *, map: str, run: str, seed: int, episode: int, timestep: int) -> int | None:
        """Store ``garage`` with its provenance; returns the new id, or ``None`` if already stored.

        The metrics are recomputed from the grid (:func:`garage_mj.grid.metrics.evaluate`), so what
        the library says about a garage is what the rest of garage-mj computes for it.
        """
        cur = self._con.execute(_INSERT, _row(garage, map, run, seed, episode, timestep))
        return int(cur.lastrowid) if cur.rowcount == 1 and cur.lastrowid is not None else None

    def credit(self, garage: Garage, *, map: str, run: str, seed: int, episode: int, timestep: int) -> int | None:
        """:meth:`add`, except that a garage stored already from a run of the same map with a higher seed is
        credited to this run instead (its provenance replaced, its id kept). Returns the id when the garage
        was stored or credited, ``None`` when it stays with its run.

        So a library that parallel runs fill holds the same rows whichever run met a garage first: each
        garage is credited to the lowest seed that met it, at that run's first meeting (the protocol's rule).
        """
        row = _row(garage, map, run, seed, episode, timestep)
        con = self._con
        con.execute("BEGIN IMMEDIATE")
        try:
            old = con.execute("SELECT id, map, seed FROM garages WHERE hash = ?", (row[5],)).fetchone()
            if old is None:
                cur = con.execute(_INSERT, row)
                got: int | None = int(cur.lastrowid) if cur.lastrowid is not None else None
            elif old[1] == map and old[2] > int(seed):
                con.execute("UPDATE garages SET run = ?, seed = ?, episode = ?, timestep = ?, created_at = ? "
                            "WHERE id = ?", (run, int(seed), int(episode), int(timestep), row[-1], old[0]))
                got = int(old[0])
            else:
                got = None
            con.execute("COMMIT")
        except BaseException:
            con.execute("ROLLBACK")
            raise
        return got

    # -- reading ----------------------------------------------------------------------------------
    def id_of(self, garage_hash: str) -> int | None:
        """The id of the stored garage with this :meth:`~garage_mj.grid.garage.Garage.canonical_hash`, or None."""
        row = self._con.execute("SELECT id FROM garages WHERE hash = ?", (garage_hash,)).fetchone()
        return None if row is None else int(row[0])

    def _check_numbers(self) -> None:
        """Refuse, naming the row, a library where text stands in a numeric column (aggregates would lie)."""
        cols = [c for c, k in KINDS.items() if k in (int, float)]
        cond = " OR ".join(f"typeof({c}) NOT IN ('integer', 'real')" for c in cols)
        row = self._con.execute(f"SELECT id, {', '.join(cols)} FROM garages WHERE {cond} LIMIT 1").fetchone()
        if row is not None:
            bad = next(c for c, v in zip(cols, row[1:]) if not isinstance(v, (int, float)))
            raise LibraryError(f"{self.path}, row id {row[0]}: column {bad} holds {str(row[1 + cols.index(bad)])[:30]!r}, "
                               "not a number; the library is damaged: delete that row or restore the file from a backup")

    def verified(self, records: list[GarageRecord]) -> list[GarageRecord]:
        """``records``, each checked by :meth:`GarageRecord.verify` (for export and cruise)."""
        return [r.verify(str(self.path)) for r in records]

    def get(self, id: int) -> GarageRecord:
        """The record with ``id``; :class:`LibraryError` if there is none."""
        if not -(2**63) <= int(id) < 2**63:
            raise LibraryError(f"{self.path} has no garage with id {id}; list them with garage-mj library ls")
        row = self._con.execute(f"SELECT {COLUMNS} FROM garages WHERE id = ?", (int(id),)).fetchone()
        if row is None:
            raise LibraryError(f"{self.path} has no garage with id {id}; list them with garage-mj library ls")
        return record_from_row(row, self.path)

    # -- drivability (garage-mj check --store) ---------------------------------------------------
    def has_drivability(self) -> bool:
        """Whether ``garage-mj check --library FILE --store`` has stored drivability here."""
        row = self._con.execute("SELECT name FROM sqlite_master WHERE type = 'table' AND name = 'drivability'")
        return row.fetchone() is not None

    def set_drivability(self, id: int, figures: dict[str, Any], car: str) -> None:
        """Store garage ``id``'s drivability (:func:`garage_mj.scene.drivable.drivability`) for ``car``."""
        self._con.execute(DRIVABILITY_SCHEMA)
        self._con.execute(
            "INSERT OR REPLACE INTO drivability VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (int(id), car, float(figures["feasible_share"]), int(figures["feasible_stalls"]), int(figures["stalls"]),
             figures["min_clearance"], figures["max_curvature"], datetime.now(timezone.utc).isoformat(timespec="seconds")),
        )

    def drivability(self, id: int) -> dict[str, Any] | None:
        """Garage ``id``'s stored drivability, or None."""
        if not self.has_drivability():
            return None
        row = self._con.execute("SELECT car, feasible_share, feasible_stalls, stalls, min_clearance, max_curvature, "
                                "checked_at FROM drivability WHERE garage_id = ?", (int(id),)).fetchone()
        keys = ("car", "feasible_share", "feasible_stalls", "stalls", "min_clearance", "max_curvature", "checked_at")
        return None if row is None else dict(zip(keys, row))

    # -- route difficulty (garage-mj library rate) -------------------------------------------------
    def has_route_difficulty(self) -> bool:
        """Whether ``garage-mj library rate`` has stored route difficulties here (under any model)."""
        row = self._con.execute("SELECT name FROM sqlite_master WHERE type = 'table' AND name = 'route_difficulty'")
        return row.fetchone() is not None

    def _route_rows(self) -> str:
        """The ``route_difficulty`` rows to read: those whose checksum matches (none in a table without one)."""
        cols = {r[1] for r in self._con.execute("PRAGMA table_info(route_difficulty)")}
        return VERIFIED_ROUTE_ROWS if "checksum" in cols else NO_ROUTE_ROWS

    def set_route_difficulty(self, id: int, model: str, value: float) -> None:
        """Store garage ``id``'s route difficulty under the model with key ``model`` (NaN: no feasible stall),
        with its checksum over the garage's stored hash (so it is read only while the garage is that one).

        Each value is its own transaction, so a rating killed midway keeps every value stored before.
        """
        self._con.execute(ROUTE_SCHEMA)
        if "checksum" not in {r[1] for r in self._con.execute("PRAGMA table_info(route_difficulty)")}:
            self._con.execute("ALTER TABLE route_difficulty ADD COLUMN checksum TEXT")  # an older library's table
        v = float(value)
        v_or_null = None if math.isnan(v) else v
        key = _model_key(model)
        self._con.execute("INSERT OR REPLACE INTO route_difficulty (garage_id, model, value, rated_at, checksum) "
                          "SELECT id, ?, ?, ?, route_checksum(hash, ?, ?) FROM garages WHERE id = ?",
                          (key, v_or_null, datetime.now(timezone.utc).isoformat(timespec="seconds"), key, v_or_null,
                           int(id)))

    def route_difficulties(self, ids: Iterable[int], model: str) -> dict[int, float]:
        """id -> route difficulty under ``model`` of those of ``ids`` rated under it (NaN: no feasible stall).

        An id missing from the result is not rated under ``model`` yet.
        """
        key = _model_key(model)
        ids = [int(i) for i in ids]
        if not ids or not self.has_route_difficulty():
            return {}
        out: dict[int, float] = {}
        for k in range(0, len(ids), _BATCH):
            chunk = ids[k:k + _BATCH]
            rows = self._con.execute(
                f"SELECT garage_id, value FROM ({self._route_rows()}) WHERE model = ? AND garage_id IN "
                f"({', '.join('?' * len(chunk))})", [key, *chunk])
            out.update((int(i), math.nan if v is None else float(v)) for i, v in rows)
        return out

    def unrated(self, model: str, map: str | None = None, run: str | None = None, limit: int | None = None
                ) -> list[int]:
        """Ids (oldest first) of the garages of ``map`` and ``run`` (None: all) not rated under ``model`` yet."""
        key = _model_key(model)
        where, params = self._where(map, None, None, run)
        if self.has_route_difficulty():
            where += (" AND " if where else " WHERE ") + (
                f"id NOT IN (SELECT garage_id FROM ({self._route_rows()}) WHERE model = ?)")
            params.append(key)
        sql = f"SELECT id FROM garages{where} ORDER BY id"
        if limit is not None:
            if limit < 0:
                raise ValueError(f"limit must be >= 0, got {limit}")
            sql += f" LIMIT {int(limit)}"
        return [int(r[0]) for r in self._con.execute(sql, params)]

    def _where(
        self, map: str | None, difficulty: tuple[float, float] | None, coverage: tuple[float, float] | None,
        run: str | None = None, feasible: tuple[float, float] | None = None,
        route: tuple[float, float] | None = None, route_model: str | None = None,
    ) -> tuple[str, list[Any]]:
        clauses, params = [], []
        if feasible is not None:
            lo, hi = feasible
            if lo > hi:
                raise ValueError(f"feasible range ({lo}, {hi}) is empty; give LO <= HI")
            if not self.has_drivability():
                raise LibraryError(f"{self.path} holds no drivability figures; run "
                                   f"'garage-mj check --library {self.path} --store' first")
            clauses.append("id IN (SELECT garage_id FROM drivability WHERE feasible_share BETWEEN ? AND ?)")
            params += [float(lo), float(hi)]
        if map is not None:
            clauses.append("map = ?")
            params.append(map)
        if run is not None:
            clauses.append("run = ?")
            params.append(run)
        for col, rng in (("difficulty", difficulty), ("coverage", coverage)):
            if rng is not None:
                lo, hi = rng
                if lo > hi:
                    raise ValueError(f"{col} range ({lo}, {hi}) is empty; give LO <= HI")
                clauses.append(f"{col} BETWEEN ? AND ?")
                params += [float(lo), float(hi)]
        if route is not None:
            clause, more = self._route_clause(route, route_model, clauses, params)
            clauses.append(clause)
            params += more
        return (" WHERE " + " AND ".join(clauses)) if clauses else "", params

    def _route_clause(self, route: tuple[float, float], model: str | None, clauses: list[str], params: list[Any]
                      ) -> tuple[str, list[Any]]:
        """The route difficulty range as a clause; :class:`LibraryError` when a garage matching the other
        filters (``clauses``) is not rated under ``model`` yet (a filter must not drop it silently)."""
        lo, hi = route
        if lo > hi:
            raise ValueError(f"route difficulty range ({lo}, {hi}) is empty; give LO <= HI")
        if model is None:
            raise ValueError("a route difficulty range needs route_model, the key of the model its values are rated "
                             "with (RouteDifficulty.key)")
        key = _model_key(model)
        other = (" WHERE " + " AND ".join(clauses)) if clauses else ""
        if self.has_route_difficulty():
            joiner = " AND " if other else " WHERE "
            missing = self._con.execute(
                f"SELECT count(*) FROM garages{other}{joiner}id NOT IN "
                f"(SELECT garage_id FROM ({self._route_rows()}) WHERE model = ?)", [*params, key]).fetchone()[0]
        else:
            missing = self._con.execute(f"SELECT count(*) FROM garages{other}", params).fetchone()[0]
        if missing:
            raise LibraryError(f"{self.path}: {missing} garage(s) matching the filters have no route difficulty under "
                               f"model {key} yet (or one that no longer matches its garage); run "
                               f"'garage-mj library rate {self.path}' first (with --model FILE for a model other than "
                               "the shipped one)")
        if not self.has_route_difficulty():
            return "0", []  # no garage matches the other filters: none matches
        return (f"id IN (SELECT garage_id FROM ({self._route_rows()}) WHERE model = ? AND value BETWEEN ? AND ?)",
                [key, float(lo), float(hi)])

    def query(
        self,
        map: str | None = None,
        difficulty: tuple[float, float] | None = None,
        coverage: tuple[float, float] | None = None,
        limit: int | None = None,
        run: str | None = None,
        feasible: tuple[float, float] | None = None,
        route: tuple[float, float] | None = None,
        route_model: str | None = None,
    ) -> list[GarageRecord]:
        """Records matching every given filter (ranges are inclusive), oldest first.

        ``feasible`` filters on the share of stalls with a feasible cruise test, as stored by
        ``garage-mj check --library FILE --store``; ``route`` on the route difficulty under the
        model with key ``route_model``, as stored by ``garage-mj library rate`` (a garage rated
        without a feasible stall has none and never matches; one not rated yet is a
        :class:`LibraryError`).
        """
        where, params = self._where(map, difficulty, coverage, run, feasible, route, route_model)
        sql = f"SELECT {COLUMNS} FROM garages{where} ORDER BY id"
        if limit is not None:
            if limit < 0:
                raise ValueError(f"limit must be >= 0, got {limit}")
            sql += f" LIMIT {int(limit)}"
        return [record_from_row(r, self.path) for r in self._con.execute(sql, params)]

    def count(self, map: str | None = None, run: str | None = None, route: tuple[float, float] | None = None,
              route_model: str | None = None) -> int:
        where, params = self._where(map, None, None, run, route=route, route_model=route_model)
        return int(self._con.execute(f"SELECT count(*) FROM garages{where}", params).fetchone()[0])

    def points(self, map: str | None = None, route_model: str | None = None) -> np.ndarray:
        """An N x 2 array of (difficulty, coverage), for the heatmaps: the paper's difficulty, or with
        ``route_model`` the route difficulty under that model (garages without a feasible stall left out;
        :class:`LibraryError` when a garage of ``map`` is not rated under it yet)."""
        self._check_numbers()
        if route_model is None:
            where, params = self._where(map, None, None)
            x = "difficulty"
        else:
            where, params = self._where(map, None, None, route=(0.0, 1.0), route_model=route_model)
            x = f"(SELECT value FROM ({self._route_rows()}) WHERE garage_id = garages.id AND model = ?)"
            params = [_model_key(route_model), *params]
        rows = self._con.execute(f"SELECT {x}, coverage FROM garages{where} ORDER BY id", params).fetchall()
        return np.array(rows, dtype=float).reshape(-1, 2)

    def maps(self) -> list[str]:
        return self._printable_maps([r[0] for r in self._con.execute("SELECT DISTINCT map FROM garages ORDER BY map")])

    def _printable_maps(self, maps: list[str]) -> list[str]:
        """``maps``; refuses, naming a row, a map name with a control character (it would act on the terminal)."""
        for m in maps:
            if isinstance(m, str) and control_character(m) is not None:
                id_ = self._con.execute("SELECT id FROM garages WHERE map = ? LIMIT 1", (m,)).fetchone()[0]
                raise LibraryError(f"{self.path}, row id {id_}: column map holds {m[:30]!r}, with the control "
                                   f"character {control_character(m)!r}; the library is damaged: delete that row "
                                   "or restore the file from a backup")
        return maps

    def sample(
        self,
        n: int,
        seed: int,
        stratify: str | None = "difficulty",
        map: str | None = None,
        difficulty: tuple[float, float] | None = None,
        coverage: tuple[float, float] | None = None,
        feasible: tuple[float, float] | None = None,
        route: tuple[float, float] | None = None,
        route_model: str | None = None,
    ) -> list[GarageRecord]:
        """``n`` distinct records drawn with ``seed`` (all of them when fewer match), sorted by id.

        ``stratify="difficulty"`` spreads the draw evenly over difficulty bins of width
        :data:`DIFFICULTY_BIN` (a bin with too few garages gives all it has and the rest go to
        the others), so rare hard or easy garages are not drowned out; ``None`` draws uniformly.
        The filters are :meth:`query`'s.
        """
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        if stratify not in (None, "difficulty"):
            raise ValueError(f"stratify must be 'difficulty' or None, got {stratify!r}")
        self._check_numbers()
        where, params = self._where(map, difficulty, coverage, feasible=feasible, route=route, route_model=route_model)
        rows = self._con.execute(f"SELECT id, difficulty FROM garages{where} ORDER BY id", params).fetchall()
        rng = np.random.default_rng(seed)
        if n >= len(rows):
            chosen = [r[0] for r in rows]
        elif stratify is None:
            chosen = [rows[i][0] for i in rng.choice(len(rows), size=n, replace=False)]
        else:
            chosen = stratified_ids(rows, n, rng)
        return [self.get(i) for i in sorted(chosen)]

    def stats(self, route_model: str | None = None) -> dict[str, Any]:
        """Per-map counts and the range and mean of the metrics, plus the runs that fed it.

        With ``route_model``, a map with garages rated under that model also gets ``route_difficulty``:
        the model key, how many are rated, how many of them have a value (a feasible stall) and its range.
        """
        self._check_numbers()
        out: dict[str, Any] = {"path": str(self.path), "schema_version": SCHEMA_VERSION, "total": self.count()}
        per_map = {}
        for row in self._con.execute(
            "SELECT map, count(*), count(DISTINCT run), min(difficulty), avg(difficulty), max(difficulty), "
            "min(coverage), avg(coverage), max(coverage), avg(stalls), max(stalls) FROM garages "
            "GROUP BY map ORDER BY map"
        ):
            per_map[row[0]] = {
                "garages": row[1], "runs": row[2],
                "difficulty": {"min": row[3], "mean": row[4], "max": row[5]},
                "coverage": {"min": row[6], "mean": row[7], "max": row[8]},
                "stalls": {"mean": row[9], "max": row[10]},
            }
        if route_model is not None and self.has_route_difficulty():
            key = _model_key(route_model)
            for row in self._con.execute(
                "SELECT g.map, count(*), count(r.value), min(r.value), avg(r.value), max(r.value) FROM garages g "
                f"JOIN ({self._route_rows()}) r ON r.garage_id = g.id AND r.model = ? GROUP BY g.map ORDER BY g.map",
                (key,)
            ):
                if row[0] in per_map:
                    per_map[row[0]]["route_difficulty"] = {"model": key, "rated": row[1], "with_value": row[2],
                                                           "min": row[3], "mean": row[4], "max": row[5]}
        self._printable_maps(list(per_map))
        out["maps"] = per_map
        return out


_BATCH = 500  # ids per IN (...) query (SQLite allows at least 999 parameters)


def _register_functions(con: sqlite3.Connection) -> None:
    """The SQL functions a library's queries use: ``route_checksum`` (:func:`route_checksum`)."""
    con.create_function("route_checksum", 3, route_checksum, deterministic=True)


def _model_key(model: str) -> str:
    """A route difficulty model's key as stored (``RouteDifficulty.key``); a ValueError if it is not one."""
    if not isinstance(model, str) or not model.strip():
        raise ValueError(f"a route difficulty model key is a non-empty string (RouteDifficulty.key), not {model!r}")
    return model.strip()


def stratified_ids(rows: list[tuple[int, float]], n: int, rng: np.random.Generator) -> list[int]:
    """``n`` of the ids of ``rows`` (``(id, difficulty)``, in id order) spread over difficulty bins of
    :data:`DIFFICULTY_BIN`: a bin with too few gives all it has and the rest go to the others
    (:meth:`Library.sample`'s draw)."""
    bins: dict[int, list[int]] = {}
    n_bins = round(1 / DIFFICULTY_BIN)
    for id_, d in rows:
        bins.setdefault(min(int(d / DIFFICULTY_BIN), n_bins - 1), []).append(id_)
    quota = _allocate(n, {b: len(ids) for b, ids in bins.items()})
    chosen = []
    for b in sorted(bins):
        ids = bins[b]
        chosen += [ids[i] for i in rng.choice(len(ids), size=quota[b], replace=False)]
    return chosen


def _allocate(n: int, sizes: dict[int, int]) -> dict[int, int]:
    """Split ``n`` draws as evenly as possible over bins of the given sizes (sum(sizes) >= n)."""
    quota = dict.fromkeys(sizes, 0)
    left = n
    open_bins = sorted(sizes)
    while left > 0:
        share, extra = divmod(left, len(open_bins))
        for i, b in enumerate(open_bins):
            take = min(share + (i < extra), sizes[b] - quota[b])
            quota[b] += take
            left -= take
        open_bins = [b for b in open_bins if quota[b] < sizes[b]]
    return quota


_INSERT = (
    "INSERT OR IGNORE INTO garages (map, run, seed, episode, timestep, hash, rows, cols, grid, initial, six_stall_axis, "
    "coverage, difficulty, stalls, mean_road_length, mean_intersection_degree, created_at) "
    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"
)


def _row(garage: Garage, map: str, run: str, seed: int, episode: int, timestep: int) -> tuple:
    """The ``garages`` row of ``garage`` and its provenance (metrics recomputed), in :data:`_INSERT`'s order."""
    for what, text in (("map", map), ("run", run)):
        if control_character(text) is not None:
            raise LibraryError(f"{what} name {text[:40]!r} holds the control character {control_character(text)!r}; "
                               "give it a name of printable characters")
    m = evaluate(garage)
    h, w = garage.shape
    return (
        map, run, int(seed), int(episode), int(timestep), garage.canonical_hash(), h, w,
        json.dumps(garage.grid.tolist()), json.dumps(garage.initial.tolist()), garage.six_stall_axis,
        m.coverage, m.difficulty, m.stalls, m.mean_road_length, m.mean_intersection_degree,
        datetime.now(timezone.utc).isoformat(timespec="seconds"),
    )
