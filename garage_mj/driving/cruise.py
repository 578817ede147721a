"""Batch cruise evaluation (docs/spec.md section 7): N tests per garage with a driver, over a process pool.

Each test is one episode of ``garage_mj/GarageDrive-v0`` whose seed derives from (run seed,
garage hash, test index) (:mod:`garage_mj.driving.sources`), so results do not depend on the
worker count or order. A worker keeps one env (one compiled MuJoCo scene) per garage and tests
arrive grouped by garage, so a scene is built at most once per worker and garage
(:mod:`garage_mj.driving.episode`).

A test whose process dies on every try (a segfault in the driver, the OOM killer, ``kill -9``;
a worker pool gives it once more to a fresh worker) is a ``driver_crash`` row, and one that runs
past ``settings.test_timeout`` seconds of wall time a ``driver_timeout`` row (:func:`lost_row`);
the run goes on.

Outputs in ``out_dir`` (:mod:`garage_mj.driving.results`): ``tests.csv`` (one row per test,
appended and flushed as each test ends, so a crash or Ctrl-C loses nothing and a re-run skips
what is there), ``summary.csv`` (the paper's table columns per garage, and each garage's route difficulty beside the
paper's difficulty), ``garages.json`` (the run's garages), ``summary.json`` (Pearson r and the linear regression of
success rate on the paper's difficulty and on the route difficulty), ``route_difficulty.json`` (the garages' route
difficulty, computed once in this process and read back by a re-run, :mod:`garage_mj.driving.difficulty.rating`), and
``run.json`` (the settings; a
re-run with other settings is refused). Both JSON files record the action type used and where it
came from (``action_type_from``: ``"driver"``, the driver's own, or ``"--action-type"``, given). ``regression.png`` is the reporting stage's
(:func:`garage_mj.reporting.cruise.run_cruise` draws it after the run).
"""

from __future__ import annotations

import csv
import dataclasses
import numbers
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from garage_mj.core.backends import DEFAULT_COMPUTE, Compute, LostJob, check_backend, map_unordered
from garage_mj.core.fsutil import FolderLock, clean_temp, ensure_dir
from garage_mj.driving.difficulty.park_rating import ParkModelChoice, choose_park_model, park_difficulty_cell
from garage_mj.driving.difficulty.rating import RouteModelChoice, choose_route_model, cruise_route_difficulty
from garage_mj.driving.episode import cached_env, check_driver, close_cached_env, drive_test, forget_cached
from garage_mj.driving.garage_set import GarageSet, GarageSetError
from garage_mj.driving.replay import write_test_xosc
from garage_mj.driving.results import (
    TEST_COLUMNS,
    check_rows,
    check_settings,
    parse_tests,
    read_tests,  # noqa: F401  (imported from here by callers)
    repair_tests,
    vehicle_cells,
    write_csv,
    write_outputs,
)
from garage_mj.driving.sim.outcomes import OutcomeKind
from garage_mj.driving.sources import MAX_TESTS, CruiseError, CruiseSettings, CruiseSource, cruise_seed
from garage_mj.grid.garage import Garage
from garage_mj.scene.stalls import stall_layout
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig, world_with

GARAGES_FILE = "garages.json"  # the run's garages (GarageSet.to_json), for reading its tests back later

if TYPE_CHECKING:
    from garage_mj.driving.drivers import ActionChoice
    from garage_mj.scene.park_difficulty import ParkDifficulty
    from garage_mj.scene.route_difficulty import RouteDifficulty


@dataclass(frozen=True)
class CruiseResult:
    """Where a run wrote its outputs, and its regression."""

    out_dir: Path
    tests_run: int  # tests run by this call (the rest were in tests.csv already)
    rows: list[dict[str, str]]
    summary: list[dict[str, Any]]
    stats: dict[str, Any]
    action_label: str = ""  # the action type and where it came from, e.g. "continuous actions, the driver's own"


# -- one test, in a worker ----------------------------------------------------------------------------
def run_test(source: CruiseSource, index: int, settings: CruiseSettings, xosc_dir: str | None = None,
             export_only: bool = False) -> dict[str, Any] | None:
    """Run test ``index`` on ``source``; returns its CSV row. With ``xosc_dir``, also write the test as a .xosc
    (``export_only``: only that, for a test driven before; returns None)."""
    env = cached_env(source, settings)
    seed = cruise_seed(settings.seed, source.hash, index)
    if not export_only:
        check_driver(settings)  # built once per process, before the clock: loading a model is no part of a test
    start = time.perf_counter()
    obs, info = env.reset(seed=seed)
    if xosc_dir is not None:
        write_test_xosc(env, info, Path(xosc_dir) / xosc_name(source, index), source, index, seed, settings)
    if export_only:
        return None
    return drive_test(env, obs, info, seed, settings, source, index, start)


def _task(job: tuple[CruiseSource, int, CruiseSettings, str | None, bool]) -> dict[str, Any] | None:
    return run_test(*job)


def _time_limit(job: tuple[CruiseSource, int, CruiseSettings, str | None, bool]) -> float | None:
    """The wall time [s] a test may take (its settings' ``test_timeout``); an export-only job drives nothing: none."""
    return None if job[4] else job[2].test_timeout


def lost_row(job: tuple[CruiseSource, int, CruiseSettings, str | None, bool], why: LostJob) -> dict[str, Any] | None:
    """The row of a test the backend gave up on (:func:`garage_mj.core.backends.map_unordered`'s ``on_lost``):
    ``driver_crash`` when the process driving it died on every try (a segfault, the OOM killer, ``kill -9``),
    ``driver_timeout`` when it ran past ``settings.test_timeout``. Nothing of the drive is known, so the
    stall, feasibility, times and actors stay empty. The same test gives the same row with any worker count."""
    source, index, settings, _, export_only = job
    forget_cached()  # an interrupted driver or scene in this process is not used again
    if export_only:
        raise CruiseError(f"writing the .xosc of {source.name} test {index}: {why.reason}; run again to resume")
    kind = OutcomeKind.DRIVER_TIMEOUT if why.kind == "timeout" else OutcomeKind.DRIVER_CRASH
    return {**dict.fromkeys(TEST_COLUMNS, ""), "garage": source.name, "garage_hash": source.hash, "test": index,
            "seed": cruise_seed(settings.seed, source.hash, index), "driver": settings.driver,
            "outcome": kind.value, "reason": f"driver {settings.driver}: {why.reason}", "difficulty": source.difficulty,
            "mean_road_length": source.mean_road_length, "mean_intersection_degree": source.mean_intersection_degree,
            "wall_s": round(why.seconds, 3), "task": settings.task,
            "maneuver": settings.maneuver if settings.task != "cruise" and settings.maneuver != "any" else "",
            **vehicle_cells(settings.env)}


# -- OpenSCENARIO export --------------------------------------------------------------------------------
def xosc_name(source: CruiseSource, index: int) -> str:
    """File name of test ``index`` on ``source`` (``<garage hash 12>_<test>.xosc``)."""
    return f"{source.hash[:12]}_{index:05d}.xosc"


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


def _results(jobs: list, compute: Compute) -> Iterator[dict[str, Any] | None]:
    """Rows as tests end (:func:`garage_mj.core.backends.map_unordered`: this process, a spawn pool or Ray actors);
    jobs come in garage order, so each worker builds each scene at most once."""
    if compute.backend == "ray":  # paths as this machine sees them (a cluster needs them on a shared filesystem)
        jobs = [(s, i, st, os.path.abspath(x) if x is not None else None, e) for s, i, st, x, e in jobs]
    try:
        yield from map_unordered(_task, jobs, compute=compute, timeout=_time_limit, on_lost=lost_row)
    finally:
        close_cached_env()  # the in-process loop's scene


def run_cruise(
    sources: Sequence[CruiseSource | Garage],
    tests: int,
    settings: CruiseSettings | None = None,
    out_dir: str | Path = "cruise",
    *,
    compute: Compute = DEFAULT_COMPUTE,
    choice: ActionChoice | None = None,
    max_tests: int | None = None,
    xosc: bool = False,
    route_model: RouteDifficulty | str | Path | bool = True,
    park_model: ParkDifficulty | str | Path | bool = True,
) -> CruiseResult:
    """Run ``tests`` tests on every source with ``settings`` (default :class:`CruiseSettings`: the
    ``vision`` driver); resumable (see the module docstring).

    ``settings.action_type``: ``"continuous"`` or ``"discrete"``; None runs the driver with the one it
    declares (:func:`garage_mj.driving.drivers.action_type_of`); another one than that is an
    ``ActionTypeWarning``. ``choice``: an :class:`~garage_mj.driving.drivers.ActionChoice` made already
    (a caller that chose once for many runs, as the hunt does) is used as is instead.
    ``max_tests`` stops after that many new tests (a deliberate partial run). ``xosc`` also writes every
    test as OpenSCENARIO into ``out_dir/xosc/``
    (``<garage hash 12>_<test>.xosc``, see :func:`garage_mj.driving.replay.replay_xosc`); garages without an asset pack get
    one in ``out_dir/packs/`` for it to refer to. ``compute`` runs the tests in this process or a
    spawn pool of ``workers`` (backend ``"local"``) or on ``workers`` Ray actors (``"ray"``; ``address``: a
    running cluster's ``HOST:PORT``, else a private local Ray), see :mod:`garage_mj.core.backends`, with a
    tqdm bar when ``compute.progress``; tests.csv gets the same rows either way. ``route_model``: the route
    difficulty model of
    ``summary.csv``'s ``route_difficulty`` column and ``summary.json``'s ``route_r`` (True: the shipped
    one fitted on the driver with the run's action type,
    :func:`~garage_mj.driving.difficulty.rating.choose_route_model`, or none where no shipped model was:
    the column stays empty and ``summary.json``'s ``route_note`` says why; a ``RouteDifficulty``, a model
    file or a shipped model's name; False: none), planned for the
    default car and world as the model was fitted, whatever ``settings.env`` changes. ``park_model``: the park
    difficulty model of a park or AVP run's ``park_difficulty`` column (True: the driver's shipped one, else the
    default, :func:`~garage_mj.driving.difficulty.park.choose_park_model`; a ``ParkDifficulty``, a model file or a
    shipped model's name; False: none; a cruise run has none). Raises
    :class:`CruiseError`, ``DriverError`` (bad driver), ``BackendError`` (Ray missing),
    ``RouteModelError`` (a bad model file) before any test.
    """
    from garage_mj.driving.drivers import choose_action_type

    if isinstance(tests, bool) or not isinstance(tests, numbers.Integral) or not 1 <= tests <= MAX_TESTS:
        raise CruiseError(f"tests must be an integer from 1 to {MAX_TESTS:,}, got {tests!r}; give --tests N")
    settings = settings if settings is not None else CruiseSettings()
    # fails fast, in this process, with the loader's one-line message on a bad driver
    choice = choice if choice is not None else choose_action_type(settings.driver, settings.action_type)
    check_backend(compute, reach=True)  # Ray missing or its cluster unreachable: before any write
    route = choose_route_model(route_model, settings.driver, choice.action_type, settings.driver_kwargs)
    park = choose_park_model(park_model, settings.driver, settings.driver_kwargs) if settings.task != "cruise" else None
    srcs = [s if isinstance(s, CruiseSource) else CruiseSource.from_garage(s) for s in sources]
    hashes = [s.hash for s in srcs]
    if len(set(hashes)) != len(hashes):
        raise CruiseError("the same garage is listed twice; give each garage once")
    settings = settings.resolved(choice.action_type)
    check_task(settings)  # a driver made for other tasks, or a stall a garage lacks, is refused before any write
    check_stall(srcs, settings.stall, run_world(settings))
    check_driver(settings)  # a driver that cannot be built stops the run before anything is written
    out = ensure_dir(out_dir, "--out")
    with FolderLock(out, "garage-mj cruise", remove=True):  # a second run into `out` is refused, naming this one
        return _run_locked(srcs, tests, out, settings, choice, compute, max_tests, xosc, route, park)


def check_task(settings: CruiseSettings) -> None:
    """Refuse a driver whose class declares ``tasks`` without the run's task, unless it is a cruise driver in a park
    or AVP run (:func:`garage_mj.cli.cruise.task_warning` warns of that one: it drives them forward only). A
    :class:`CruiseError` line naming the driver, its tasks and the fix, before anything is written."""
    from garage_mj.driving.drivers import resolve_driver

    declared = getattr(resolve_driver(settings.driver), "tasks", ("cruise",))
    tasks = (declared,) if isinstance(declared, str) else tuple(map(str, declared))
    if settings.task in tasks or "cruise" in tasks:
        return
    fix = " or ".join(f"--task {t}" for t in tasks) or "another --task"
    raise CruiseError(f"driver {settings.driver!r} is not made for {settings.task} tests (its class declares tasks = "
                      f"{tasks!r}); give {fix}, or a --driver made for {settings.task} tests")


def run_world(settings: CruiseSettings) -> WorldConfig:
    """The world a run's garages are built in: its park geometry (``settings.env["world"]``; none: the defaults)."""
    return world_with((settings.env or {}).get("world"))


def check_stall(sources: Sequence[CruiseSource], stall: int | None, world: WorldConfig | None = None) -> None:
    """Refuse a ``stall`` id that a garage of ``sources`` lacks in ``world`` (a :class:`CruiseError` line naming the
    garage and the ids every garage has), before anything is written or any test runs."""
    if stall is None:
        return
    counts = [(s, len(stall_layout(s.garage, world or DEFAULT_WORLD).stalls)) for s in sources]
    lacking = [(s, n) for s, n in counts if not 0 <= stall < n]
    if not lacking:
        return
    s, n = lacking[0]
    common = min(n for _, n in counts)
    others = f" and {len(lacking) - 1} other garage(s)" if len(lacking) > 1 else ""
    fix = f"a --stall in 0..{common - 1} (every garage has those)" if common > 0 else "another garage"
    has = f"its stalls are 0..{n - 1}" if n else "it has no stall"
    raise CruiseError(f"stall {stall} does not exist in garage {s.name!r}{others} ({has}); "
                      f"give {fix}, or leave --stall out to draw one per test")


def _with_packs(srcs: Sequence[CruiseSource], out: Path, settings: CruiseSettings) -> list[CruiseSource]:
    """Every source with an asset pack: those without one get it in ``out/packs``, built in the run's park geometry
    (``settings.env["world"]``, docs/spec.md section 9)."""
    from garage_mj.export.pack import export_pack

    world = run_world(settings)
    return [s if s.pack else dataclasses.replace(s, pack=str(export_pack(s.garage, out / "packs", world=world)
                                                                .resolve()))
            for s in srcs]


def _write_garages(out: Path, srcs: Sequence[CruiseSource]) -> None:
    """Keep the run's garages in ``out/garages.json`` (those of earlier calls into ``out`` too), so that
    its tests can be read back with their garages (``garage-mj difficulty fit``)."""
    path = out / GARAGES_FILE
    have: list[CruiseSource] = []
    if path.is_file():
        try:
            have = list(GarageSet.from_json(path))
        except GarageSetError:
            pass  # damaged: written anew from this call's garages
    known = {s.hash for s in have}
    new = [s for s in srcs if s.hash not in known]
    if new or not path.is_file():
        GarageSet(tuple(have + new), f"cruise run {out}").to_json(path)


def _run_locked(srcs: Sequence[CruiseSource], tests: int, out: Path, settings: CruiseSettings, choice: ActionChoice,
                compute: Compute, max_tests: int | None, xosc: bool = False,
                route_choice: RouteModelChoice | None = None, park: ParkModelChoice | None = None) -> CruiseResult:
    """The body of :func:`run_cruise`, holding the lock of ``out``."""
    csv_path = out / "tests.csv"
    # refused before anything is written: a run of other settings, then a resumed row that is not one of this run
    check_settings(out, settings, choice.source, write=False)
    parsed = parse_tests(csv_path)
    check_rows(csv_path, parsed, settings)
    clean_temp(out)  # temp files of a killed run's atomic writes
    check_settings(out, settings, choice.source)
    _write_garages(out, srcs)
    rows = repair_tests(csv_path, parsed)
    done = {(r["garage_hash"], int(r["test"])) for r in rows}
    xosc_dir, exported = None, None
    if xosc:
        srcs = _with_packs(srcs, out, settings)
        xosc_dir = str(out / "xosc")
        have = {p.name for p in (out / "xosc").glob("*.xosc")} if (out / "xosc").is_dir() else set()
        exported = {(s.hash, i) for s in srcs for i in range(tests) if xosc_name(s, i) in have}
    jobs = _jobs(srcs, tests, done, settings, xosc_dir, exported)
    if max_tests is not None:
        jobs = jobs[:max_tests]
    new = 0
    if jobs:
        from tqdm import tqdm

        if not csv_path.is_file():  # repair_tests left an existing file with its header and whole lines
            write_csv(csv_path, TEST_COLUMNS, [])
        with csv_path.open("a", newline="") as f, tqdm(total=len(jobs), disable=not compute.progress,
                                                       desc=settings.task, unit="test") as bar:
            writer = csv.DictWriter(f, fieldnames=TEST_COLUMNS)
            for row in _results(jobs, compute):
                if row is None:  # an export-only job
                    bar.update()
                    continue
                if park is not None and park.model is not None:
                    row["park_difficulty"] = park_difficulty_cell(park.model, row)
                writer.writerow(row)
                f.flush()
                os.fsync(f.fileno())  # a kill -9 or power cut after this line keeps the row
                rows.append({k: str(v) for k, v in row.items()})
                new += 1
                bar.update()
    wanted = {(s.hash, i) for s in srcs for i in range(tests)}
    mine = [r for r in rows if (r["garage_hash"], int(r["test"])) in wanted]
    tested = {r["garage_hash"] for r in mine}
    model = route_choice.model if route_choice else None
    route = None if model is None else cruise_route_difficulty(out, [s for s in srcs if s.hash in tested], model)
    info = {**(route_choice.record(bool(route)) if route_choice else {}), **(park.record() if park else {})}
    summary, stats = write_outputs(out, mine, srcs, settings, choice.source, route, model.key if model else None,
                                   info or None)
    return CruiseResult(out, new, mine, summary, stats, choice.label)
