"""Batch cruise evaluation (SPEC section 7): N tests per garage with a driver, over a process pool.

Each test is one episode of ``garage_mj/GarageDrive-v0`` whose seed derives from (run seed,
garage hash, test index), so results do not depend on the worker count or order. A worker keeps
one env (one compiled MuJoCo scene) per garage and tests arrive grouped by garage, so a scene is
built at most once per worker and garage.

Outputs in ``out_dir``: ``tests.csv`` (one row per test, appended and flushed as each test ends,
so a crash or Ctrl-C loses nothing and a re-run skips what is there), ``summary.csv`` (the
paper's table columns per garage), ``summary.json`` and ``regression.png`` (Pearson r and the
linear regression of success rate on difficulty), and ``run.json`` (the settings; a re-run
with other settings is refused).
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import FolderLock, atomic_write, clean_temp, ensure_dir
from garage_mj.grid.garage import Garage
from garage_mj.grid.metrics import evaluate
from garage_mj.reporting.analysis import PAPER_R, regression, regression_plot

TEST_COLUMNS = ("garage", "garage_hash", "test", "seed", "driver", "target_stall", "feasible", "outcome", "hit",
                "hit_geom", "reason", "time", "path_length", "route_length", "difficulty", "mean_road_length",
                "mean_intersection_degree", "pedestrians", "moving_cars", "clutter", "wall_s")
#: What a collision can hit (``hit`` column): the summary counts collisions per class.
HIT_CLASSES = ("parked_car", "wall", "pillar", "obstacle", "pedestrian", "moving_car", "clutter")
#: ``success_pct`` is over feasible tests; ``infeasible`` tests (never driven) are counted apart.
SUMMARY_COLUMNS = ("garage", "difficulty", "E[X]", "E[Y]", "tests", "infeasible", "feasible", "successes",
                   "collisions", "timeouts", "deadlocks", "success_pct", *(f"hit_{c}" for c in HIT_CLASSES))


class CruiseError(GarageMJError):
    """A cruise run cannot go on (settings differ from the out dir's run, a driver crashed)."""


@dataclass(frozen=True)
class CruiseSource:
    """One garage to test, with the metrics the summary reports."""

    name: str  # row key in the CSVs (pack folder, "map#id", or the garage's name)
    garage: Garage
    difficulty: float
    mean_road_length: float  # E[X]
    mean_intersection_degree: float  # E[Y]
    pack: str = ""  # its asset pack folder, when it came from one (the .xosc export refers to it)

    @property
    def hash(self) -> str:
        return self.garage.canonical_hash()

    @classmethod
    def from_garage(cls, garage: Garage, name: str | None = None) -> CruiseSource:
        m = evaluate(garage)
        name = name or f"{garage.name or 'garage'}-{garage.canonical_hash()[:8]}"
        return cls(name, garage, m.difficulty,
                   m.mean_road_length, m.mean_intersection_degree)

    @classmethod
    def from_pack(cls, path: str | Path) -> CruiseSource:
        from garage_mj.export.pack import load_pack

        pack = load_pack(path)
        src = cls.from_garage(pack.garage, Path(pack.path).name)
        return dataclasses.replace(src, pack=str(Path(pack.path).resolve()))

    @classmethod
    def from_record(cls, record: Any) -> CruiseSource:
        """From a :class:`garage_mj.generation.library.GarageRecord`."""
        return cls(f"{record.map}#{record.id}", record.garage, record.difficulty, record.mean_road_length,
                   record.mean_intersection_degree)


@dataclass(frozen=True)
class CruiseSettings:
    """What makes two runs comparable; stored in ``run.json``."""

    driver: str = "vision"  # built-in name or module:Class
    seed: int = 0
    action_type: str = "discrete"
    occupancy: float = 0.5
    env: dict[str, Any] = field(default_factory=dict)  # more GarageDriveEnv keyword arguments
    driver_kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class CruiseResult:
    """Where a run wrote its outputs, and its regression."""

    out_dir: Path
    tests_run: int  # tests run by this call (the rest were in tests.csv already)
    rows: list[dict[str, str]]
    summary: list[dict[str, Any]]
    stats: dict[str, Any]


def painted_sources(map: str, n: int, seed: int = 0, oversample: int = 4) -> list[CruiseSource]:
    """``n`` garages of ``map`` painted by the scripted painter, spread evenly over difficulty.

    Paints ``oversample * n`` candidates (distinct garages) and keeps the ones at evenly spaced
    difficulty ranks, standing in for a library's stratified sample when there is no library.
    """
    from garage_mj.grid.painters import paint_garage

    found: dict[str, CruiseSource] = {}
    for k in range(oversample * n * 3):
        if len(found) >= oversample * n:
            break
        g = paint_garage(map, seed=seed * 10_007 + k)
        found.setdefault(g.canonical_hash(), CruiseSource.from_garage(g, f"{map}-painted{k}"))
    ranked = sorted(found.values(), key=lambda s: (s.difficulty, s.name))
    if len(ranked) <= n:
        return ranked
    picks = np.linspace(0, len(ranked) - 1, n).round().astype(int)
    return [ranked[i] for i in picks]


def cruise_seed(seed: int, garage_hash: str, index: int) -> int:
    """The seed of test ``index`` on a garage: a function of (run seed, garage hash, index) only."""
    digest = hashlib.sha256(f"{seed}:{garage_hash}:{index}".encode()).digest()
    return int.from_bytes(digest[:4], "little")


# -- one test, in a worker ----------------------------------------------------------------------------
_CACHE: dict[str, Any] = {}


def _env_for(source: CruiseSource, settings: CruiseSettings):
    """The worker's env for ``source`` (built once; the previous garage's env is closed)."""
    from garage_mj.driving.drive_env import GarageDriveEnv

    key = (source.hash, json.dumps(settings.env, sort_keys=True))
    if _CACHE.get("hash") != key:
        if "env" in _CACHE:
            _CACHE.pop("env").close()
        _CACHE["env"] = GarageDriveEnv(garage=source.garage, action_type=settings.action_type,
                                       occupancy=settings.occupancy, infeasible="report", **settings.env)
        _CACHE["hash"] = key
    return _CACHE["env"]


def close_cached_env() -> None:
    """Close the scene this process keeps for :func:`run_test` (tests run in-process, then done)."""
    if "env" in _CACHE:
        _CACHE.pop("env").close()
        _CACHE.pop("hash", None)


def _driver_for(settings: CruiseSettings):
    from garage_mj.driving.drivers import load_driver

    key = (settings.driver, json.dumps(settings.driver_kwargs, sort_keys=True))
    if _CACHE.get("driver_key") != key:
        _CACHE["driver"] = load_driver(settings.driver, **settings.driver_kwargs)
        _CACHE["driver_key"] = key
    return _CACHE["driver"]


def run_test(source: CruiseSource, index: int, settings: CruiseSettings, xosc_dir: str | None = None,
             export_only: bool = False) -> dict[str, Any] | None:
    """Run test ``index`` on ``source``; returns its CSV row. With ``xosc_dir``, also write the test as a .xosc
    (``export_only``: only that, for a test driven before; returns None)."""
    env = _env_for(source, settings)
    seed = cruise_seed(settings.seed, source.hash, index)
    start = time.perf_counter()
    obs, info = env.reset(seed=seed)
    if xosc_dir is not None:
        write_test_xosc(env, info, Path(xosc_dir) / xosc_name(source, index), source, index, seed, settings)
    if export_only:
        return None
    return _drive(env, obs, info, seed, settings, source, index, start)


def _drive(env, obs, info, seed: int, settings: CruiseSettings, source: CruiseSource, index: int,
           start: float) -> dict[str, Any]:
    """Drive the reset ``env`` to the end of its test; the CSV row."""
    driver = _driver_for(settings)
    try:
        if info.get("outcome") != "infeasible":  # decided from the scene: never driven
            driver.reset(env.driver_info(seed))
            while True:
                obs, _, term, trunc, info = env.step(driver.act(obs))
                if term or trunc:
                    break
    except Exception as exc:  # a user's driver may raise anything; name it, keep the traceback
        raise CruiseError(f"driver {settings.driver!r} failed on {source.name} test {index}: "
                          f"{type(exc).__name__}: {exc}") from exc
    return {
        "garage": source.name, "garage_hash": source.hash, "test": index, "seed": seed,
        "driver": settings.driver, "target_stall": info["target_stall"],
        "feasible": int(info["outcome"] != "infeasible"), "outcome": info["outcome"],
        "hit": info["hit"] or "", "hit_geom": info["hit_geom"] or "", "reason": info["reason"],
        "time": round(info["time"], 3),
        "path_length": round(info["path_length"], 3), "route_length": round(info["route_length"], 3),
        "difficulty": source.difficulty, "mean_road_length": source.mean_road_length,
        "mean_intersection_degree": source.mean_intersection_degree,
        "pedestrians": info["actors"]["pedestrian"], "moving_cars": info["actors"]["moving_car"],
        "clutter": info["actors"]["clutter"],
        "wall_s": round(time.perf_counter() - start, 3),
    }


def _task(job: tuple[CruiseSource, int, CruiseSettings, str | None, bool]) -> dict[str, Any] | None:
    return run_test(*job)


# -- OpenSCENARIO: export and replay --------------------------------------------------------------------
def xosc_name(source: CruiseSource, index: int) -> str:
    """File name of test ``index`` on ``source`` (``<garage hash 12>_<test>.xosc``)."""
    return f"{source.hash[:12]}_{index:05d}.xosc"


def write_test_xosc(env, info: dict[str, Any], path: Path, source: CruiseSource, index: int, seed: int,
                    settings: CruiseSettings) -> Path:
    """The test ``env`` was just reset to, as OpenSCENARIO (:func:`garage_mj.export.xosc.write_xosc`)."""
    from garage_mj.export.xosc import write_xosc

    if not source.pack:
        raise CruiseError(f"{source.name}: no asset pack to refer to; run_cruise exports one with xosc=True")
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_xosc(
        path, pack_dir=source.pack, target_stall=env.target, occupied=env.occupied, start=env.start_pose,
        route=env.route.points, goal=env.monitor.goal_pose, actors=env.scenario.actors,
        parked_poses=env.scene.layout.parked_cars,
        meta={"garage_hash": source.hash, "garage": source.name, "test": index, "seed": seed,
              "driver": settings.driver, "action_type": settings.action_type, "occupancy": settings.occupancy,
              "env": settings.env, "driver_kwargs": settings.driver_kwargs})


def replay_xosc(path: str | Path, driver: str | None = None, driver_kwargs: dict[str, Any] | None = None
                ) -> dict[str, Any]:
    """Replay the cruise test of a ``.xosc`` written by :func:`write_test_xosc`; returns its tests.csv row.

    Everything comes from the file: the pack (checked against its hash), target stall, parked
    cars, start pose and actors; the env settings and the driver are the ones recorded, unless
    ``driver`` names another (a test engineer's own stack on a found scenario).
    """
    from garage_mj.driving.actors import load_scenario_config
    from garage_mj.export.xosc import read_xosc

    test = read_xosc(path)
    pack = test.pack()
    meta = test.meta
    env_kwargs = dict(meta.get("env") or {})
    scenario = load_scenario_config(env_kwargs.get("scenario"))
    need = {}
    for a in test.actors:  # room for every replayed actor (names are kind_index)
        k = int(a.name.rsplit("_", 1)[1]) + 1
        need[a.kind] = max(need.get(a.kind, 0), k)
    scenario = dataclasses.replace(scenario, pedestrians=max(scenario.pedestrians, need.get("pedestrian", 0)),
                                   moving_cars=max(scenario.moving_cars, need.get("moving_car", 0)),
                                   clutter=max(scenario.clutter, need.get("clutter", 0)))
    env_kwargs["scenario"] = scenario
    settings = CruiseSettings(driver or test.driver or "vision", int(test.seed or 0), test.action_type or "discrete",
                              float(meta.get("occupancy", 0.5)), {},
                              dict(driver_kwargs if driver_kwargs is not None else meta.get("driver_kwargs") or {}))
    source = dataclasses.replace(CruiseSource.from_garage(pack.garage, str(meta.get("garage") or Path(pack.path).name)),
                                 pack=str(pack.path))
    from garage_mj.driving.drive_env import GarageDriveEnv

    env = GarageDriveEnv(garage=pack.garage, action_type=settings.action_type, occupancy=settings.occupancy,
                         infeasible="report", **env_kwargs)
    try:
        start = time.perf_counter()
        seed = int(test.seed or 0)
        obs, info = env.reset(seed=seed, options={"target": test.target_stall, "occupied": test.occupied,
                                                  "start": test.start, "actors": test.actors})
        row = _drive(env, obs, info, seed, settings, source, int(meta.get("test", 0)), start)
    finally:
        env.close()
    return row


# -- files ------------------------------------------------------------------------------------------
def _is_header(fields: Sequence[str]) -> bool:
    return "garage_hash" in fields and "outcome" in fields


def _complete(row: dict[str, str]) -> bool:
    """A row a test wrote in full: every field present, an outcome, a wall time and a test index."""
    if any(v is None for v in row.values()) or row.get("outcome", "") == "" or row.get("wall_s", "") == "":
        return False
    return row.get("garage_hash", "") != "" and row.get("test", "").isdigit()


def read_tests(path: Path) -> list[dict[str, str]]:
    """The complete rows of ``tests.csv``, each (garage_hash, test) once; the file is repaired in place.

    Repairs what a crash, a second run or a careless edit can leave, never dropping a complete
    row: an empty file or a missing header (the header is written back), a torn last line (a
    ``kill -9`` mid-write: dropped), a header of other columns (rewritten with
    :data:`TEST_COLUMNS`), and duplicate (garage_hash, test) rows (the first one is kept).
    """
    if not path.is_file():
        return []
    text = path.read_bytes().decode("utf-8", errors="replace")
    parts = text.split("\n")  # not splitlines(): it also breaks at \r, \x0b, \u2028... inside fields
    lines = [p + "\n" for p in parts[:-1]] + ([parts[-1]] if parts[-1] else [])
    first = next(csv.reader(lines[:1]), [])
    has_header = bool(lines) and lines[0].endswith("\n") and _is_header(first)
    columns = first if has_header else list(TEST_COLUMNS)
    body = lines[1:] if has_header else lines
    torn = bool(body) and not body[-1].endswith("\n")
    if torn:
        body = body[:-1]
    good: list[dict[str, str]] = []
    seen: set[tuple[str, str]] = set()
    dropped = 0
    for fields in csv.reader(body):
        row = dict(zip(columns, fields)) if len(fields) == len(columns) else None
        if row is None or not _complete(row) or (row["garage_hash"], row["test"]) in seen:
            dropped += 1
            continue
        seen.add((row["garage_hash"], row["test"]))
        good.append(row)
    if torn or dropped or not has_header or tuple(columns) != TEST_COLUMNS:
        _write_csv(path, TEST_COLUMNS, good)
    return good


def _csv_text(columns: Sequence[str], rows: Iterable[dict[str, Any]]) -> str:
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", restval="")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _write_csv(path: Path, columns: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    atomic_write(path, _csv_text(columns, rows))


def _check_settings(out: Path, settings: CruiseSettings) -> None:
    """Store the settings in ``run.json`` (atomically), or refuse a run whose settings differ."""
    path = out / "run.json"
    mine = json.loads(json.dumps(asdict(settings)))
    if path.is_file():
        try:
            theirs = json.loads(path.read_bytes().decode("utf-8"))
            if not isinstance(theirs, dict):
                raise ValueError("not an object")
        except (ValueError, UnicodeDecodeError, RecursionError) as exc:
            if read_tests(out / "tests.csv"):
                raise CruiseError(f"{path} is damaged ({type(exc).__name__}: {exc}); it holds the settings "
                                  f"of the tests in {out / 'tests.csv'}: restore it, or use another --out") from None
            theirs = mine  # no test was recorded under it: nothing to lose, write it afresh
            atomic_write(path, json.dumps(mine, indent=2) + "\n")
        if theirs != mine:
            diff = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
            raise CruiseError(f"{out} holds a run with other settings ({', '.join(diff)}); "
                              "use another --out or the same settings to resume it")
    else:
        atomic_write(path, json.dumps(mine, indent=2) + "\n")


def summarize(rows: Sequence[dict[str, Any]], sources: Sequence[CruiseSource]) -> list[dict[str, Any]]:
    """One row per garage with tests: the paper's table columns."""
    out = []
    for s in sources:
        mine = [r for r in rows if r["garage_hash"] == s.hash]
        if not mine:
            continue
        kinds = [r["outcome"] for r in mine]
        feasible = len(mine) - kinds.count("infeasible")
        hits = _hits(mine)
        out.append({
            "garage": s.name, "difficulty": round(s.difficulty, 4), "E[X]": round(s.mean_road_length, 3),
            "E[Y]": round(s.mean_intersection_degree, 3), "tests": len(mine),
            "infeasible": kinds.count("infeasible"), "feasible": feasible,
            "successes": kinds.count("success"), "collisions": kinds.count("collision"),
            "timeouts": kinds.count("timeout"), "deadlocks": kinds.count("deadlock"),
            "success_pct": round(100.0 * kinds.count("success") / feasible, 2) if feasible else None,
            **{f"hit_{c}": hits.get(c, 0) for c in HIT_CLASSES},
        })
    return out


def _hits(rows: Sequence[dict[str, Any]]) -> dict[str, int]:
    """Collisions by the class of what was hit."""
    out: dict[str, int] = {}
    for r in rows:
        if r["outcome"] == "collision":
            out[r["hit"] or "?"] = out.get(r["hit"] or "?", 0) + 1
    return dict(sorted(out.items()))


def write_outputs(out: Path, rows: Sequence[dict[str, Any]], sources: Sequence[CruiseSource],
                  settings: CruiseSettings) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``summary.csv``, ``summary.json`` and ``regression.png`` from the test rows."""
    summary = summarize(rows, sources)
    _write_csv(out / "summary.csv", SUMMARY_COLUMNS, summary)
    rated = [r for r in summary if r["success_pct"] is not None]  # garages with a feasible test
    fit = regression([r["difficulty"] for r in rated], [r["success_pct"] for r in rated])
    driven = [r for r in rows if r["outcome"] != "infeasible"]
    walls = [float(r["wall_s"]) for r in driven]
    sims = [float(r["time"]) for r in driven]
    kinds = [r["outcome"] for r in rows]
    stats = {**fit.as_dict(), "paper_r": PAPER_R, "garages": len(summary), "tests": len(rows),
             "infeasible": kinds.count("infeasible"), "feasible": len(driven),
             "driver": settings.driver, "seed": settings.seed,
             "success_pct": round(100.0 * kinds.count("success") / len(driven), 2) if driven else None,
             "failures": {k: kinds.count(k) for k in ("collision", "timeout", "deadlock")},
             "hits": _hits(driven),
             "seconds_per_test": round(float(np.mean(walls)), 4) if walls else None,
             "sim_seconds_per_wall_second": round(sum(sims) / sum(walls), 2) if walls and sum(walls) else None}
    atomic_write(out / "summary.json", json.dumps(stats, indent=2) + "\n")
    regression_plot([r["difficulty"] for r in rated], [r["success_pct"] for r in rated],
                    out / "regression.png", title=f"Cruise success vs. difficulty ({settings.driver})")
    return summary, stats


# -- the run ----------------------------------------------------------------------------------------
def _jobs(sources: Sequence[CruiseSource], tests: int, done: set[tuple[str, int]], settings: CruiseSettings,
          xosc_dir: str | None = None, exported: set[tuple[str, int]] | None = None) -> list[tuple]:
    """Tests not in ``done``; with ``xosc_dir``, also export-only jobs for done tests not in ``exported``."""
    out = []
    for s in sources:
        for i in range(tests):
            if (s.hash, i) not in done:
                out.append((s, i, settings, xosc_dir, False))
            elif xosc_dir is not None and exported is not None and (s.hash, i) not in exported:
                out.append((s, i, settings, xosc_dir, True))
    return out


def _results(jobs: list, workers: int, backend: str = "local", address: str | None = None
             ) -> Iterator[dict[str, Any] | None]:
    """Rows as tests end (:func:`garage_mj.core.backends.map_unordered`: this process, a spawn pool or Ray actors);
    jobs come in garage order, so each worker builds each scene at most once."""
    from garage_mj.core.backends import map_unordered

    if backend == "ray":  # paths as this machine sees them (a cluster needs them on a shared filesystem)
        jobs = [(s, i, st, os.path.abspath(x) if x is not None else None, e) for s, i, st, x, e in jobs]
    try:
        yield from map_unordered(_task, jobs, workers, backend, address)
    finally:
        close_cached_env()  # the in-process loop's scene


def run_cruise(
    sources: Sequence[CruiseSource | Garage],
    tests: int,
    driver: str = "vision",
    workers: int = 1,
    seed: int = 0,
    out_dir: str | Path = "cruise",
    *,
    action_type: str = "discrete",
    occupancy: float = 0.5,
    env: dict[str, Any] | None = None,
    driver_kwargs: dict[str, Any] | None = None,
    max_tests: int | None = None,
    progress: bool = True,
    xosc: bool = False,
    backend: str = "local",
    address: str | None = None,
) -> CruiseResult:
    """Run ``tests`` tests on every source with ``driver``; resumable (see the module docstring).

    ``max_tests`` stops after that many new tests (a deliberate partial run); ``progress``
    shows a tqdm bar. ``xosc`` also writes every test as OpenSCENARIO into ``out_dir/xosc/``
    (``<garage hash 12>_<test>.xosc``, see :func:`replay_xosc`); garages without an asset pack get
    one in ``out_dir/packs/`` for it to refer to. ``backend`` runs the tests in this process or a
    spawn pool of ``workers`` (``"local"``) or on ``workers`` Ray actors (``"ray"``; ``address``: a
    running cluster's ``HOST:PORT``, else a private local Ray), see :mod:`garage_mj.core.backends`;
    tests.csv gets the same rows either way. Raises :class:`CruiseError`, ``DriverError`` (bad
    driver), ``BackendError`` (bad backend, Ray missing) before any test.
    """
    from garage_mj.core.backends import check_backend
    from garage_mj.driving.drivers import resolve_driver

    if tests < 1:
        raise ValueError(f"tests must be >= 1, got {tests}")
    resolve_driver(driver)  # fail fast, in this process, with the loader's one-line message
    check_backend(backend, address)
    srcs = [s if isinstance(s, CruiseSource) else CruiseSource.from_garage(s) for s in sources]
    hashes = [s.hash for s in srcs]
    if len(set(hashes)) != len(hashes):
        raise CruiseError("the same garage is listed twice; give each garage once")
    settings = CruiseSettings(driver, int(seed), action_type, float(occupancy), dict(env or {}),
                              dict(driver_kwargs or {}))
    out = ensure_dir(out_dir, "--out")
    with FolderLock(out, "garage-mj cruise"):  # a second run into `out` is refused, naming this one
        return _run_locked(srcs, tests, workers, out, settings, max_tests, progress, xosc, backend, address)


def _with_packs(srcs: Sequence[CruiseSource], out: Path) -> list[CruiseSource]:
    """Every source with an asset pack: those without one get it in ``out/packs``."""
    from garage_mj.export.pack import export_pack

    return [s if s.pack else dataclasses.replace(s, pack=str(export_pack(s.garage, out / "packs").resolve()))
            for s in srcs]


def _run_locked(srcs: Sequence[CruiseSource], tests: int, workers: int, out: Path, settings: CruiseSettings,
                max_tests: int | None, progress: bool, xosc: bool = False, backend: str = "local",
                address: str | None = None) -> CruiseResult:
    """The body of :func:`run_cruise`, holding the lock of ``out``."""
    clean_temp(out)  # temp files of a killed run's atomic writes
    _check_settings(out, settings)
    csv_path = out / "tests.csv"
    rows = read_tests(csv_path)
    done = {(r["garage_hash"], int(r["test"])) for r in rows}
    xosc_dir, exported = None, None
    if xosc:
        srcs = _with_packs(srcs, out)
        xosc_dir = str(out / "xosc")
        have = {p.name for p in (out / "xosc").glob("*.xosc")} if (out / "xosc").is_dir() else set()
        exported = {(s.hash, i) for s in srcs for i in range(tests) if xosc_name(s, i) in have}
    jobs = _jobs(srcs, tests, done, settings, xosc_dir, exported)
    if max_tests is not None:
        jobs = jobs[:max_tests]
    new = 0
    if jobs:
        from tqdm import tqdm

        if not csv_path.is_file():  # read_tests left an existing file with its header and whole lines
            _write_csv(csv_path, TEST_COLUMNS, [])
        with csv_path.open("a", newline="") as f, tqdm(total=len(jobs), disable=not progress,
                                                       desc="cruise", unit="test") as bar:
            writer = csv.DictWriter(f, fieldnames=TEST_COLUMNS)
            for row in _results(jobs, workers, backend, address):
                if row is None:  # an export-only job
                    bar.update()
                    continue
                writer.writerow(row)
                f.flush()
                os.fsync(f.fileno())  # a kill -9 or power cut after this line keeps the row
                rows.append({k: str(v) for k, v in row.items()})
                new += 1
                bar.update()
    wanted = {(s.hash, i) for s in srcs for i in range(tests)}
    mine = [r for r in rows if (r["garage_hash"], int(r["test"])) in wanted]
    summary, stats = write_outputs(out, mine, srcs, settings)
    return CruiseResult(out, new, mine, summary, stats)
