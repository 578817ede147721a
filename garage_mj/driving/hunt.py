"""Hunt: spend a budget of cruise tests to find the garages where a driver fails.

The search is an elitist evolution over garages, with the driver's failure rate as fitness:

1. **Start**: ``population`` garages, drawn uniformly from a library (``--library``) or painted
   by the scripted painter on a map (``--map``), each tested ``tests`` times.
2. **Each generation**: rank every garage tested so far by its failure rate on feasible tests,
   Laplace-smoothed (``(failures + 1) / (feasible + 2)``, so one lucky failure does not beat a
   garage that failed 4 of 5); the ``elites`` best are *re-tested* with ``tests`` more test seeds
   (a garage's rate then rests on more tests, so noise does not keep a false elite), and
   ``population - elites`` children are made from them (tournament of two) by a mutation of
   the road set under the painter's rules (:func:`garage_mj.generation.search.mutate`: grow or cut a road,
   the stall rule re-applied, connectivity and the 2x2 rule kept), each re-painted through the
   painter env (:func:`garage_mj.generation.search.replay`) so only garages the generator could make
   are tested, each new garage tested ``tests`` times.
3. **Stop** when the budget of tests is spent.

Everything is a resumable cruise run (``OUT/cruise``, :func:`garage_mj.driving.cruise.run_cruise`): a
generation's garages and mutations are drawn from ``(seed, generation)`` and the results so far,
which a re-run reads back from ``tests.csv``, so an interrupted hunt continues where it stopped
and the same seed gives the same hunt. Outputs in ``OUT``: ``hunt.sqlite`` (every garage tested,
run ``hunt:<driver>``), ``failures.csv`` (garages ranked by failure rate: tests, failures and
their classes, what was hit, where on the route the failures happened, the failing test seeds),
``packs/`` (asset pack of the worst ``--worst`` garages), ``xosc/`` (each of their failing tests
as OpenSCENARIO: ``garage-mj cruise --scenario-file`` replays it). What a person reads of it,
``report.html``, ``videos/`` (an MP4 of the first failing test of each) and
``OUT/cruise/regression.png``, is the reporting stage's: :func:`garage_mj.reporting.hunt.hunt`
(what ``garage-mj hunt`` runs) adds them.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import numbers
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.core.backends import DEFAULT_COMPUTE, Compute, check_backend, ray_session
from garage_mj.core.config import refuse_other_settings
from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import FolderLock, atomic_write, ensure_dir, write_json
from garage_mj.driving.cruise import check_task, run_cruise, run_test, xosc_name
from garage_mj.driving.episode import check_driver, close_cached_env
from garage_mj.driving.results import COUNT_COLUMNS, driven_tests, failed_tests, failure_counts, read_tests
from garage_mj.driving.sources import DEFAULT_TEST_TIMEOUT, MAX_TESTS, CruiseSettings, CruiseSource
from garage_mj.generation.library import Library, LibraryError
from garage_mj.generation.search import mutate, replay
from garage_mj.grid.garage import Garage

if TYPE_CHECKING:
    from garage_mj.driving.drivers import ActionChoice

#: The failure classes' count columns of ``failures.csv``, in alphabetical order (not the display order of the rest).
_COUNTS = tuple(sorted(COUNT_COLUMNS.values()))
FAILURE_COLUMNS = ("rank", "garage", "garage_hash", "library_id", "difficulty", "tests", "feasible", "failures",
                   "failure_pct", *_COUNTS, "hit", "failure_progress", "failing_tests", "failing_seeds", "parent")


#: The most cruise tests a hunt may spend (``--budget``), and the most garages of a generation (``--population``).
MAX_BUDGET = 100_000_000
MAX_POPULATION = 100_000


class HuntError(GarageMJError):
    """A hunt cannot run (no garages to start from, a budget too small, settings of another hunt)."""


@dataclass(frozen=True)
class HuntConfig:
    """How the budget is spent."""

    budget: int = 1000  # cruise tests in all
    tests: int = 5  # tests per garage per evaluation (an elite gets this many more each generation)
    population: int = 20  # garages per generation
    elites: int = 5  # best garages kept, re-tested and mutated
    worst: int = 5  # garages exported with packs, .xosc files (and videos, by the reporting stage)
    max_tries: int = 50  # mutation draws per child before giving up on a parent

    def __post_init__(self) -> None:
        ranges = {"budget": (1, MAX_BUDGET), "tests": (1, MAX_TESTS), "population": (1, MAX_POPULATION),
                  "elites": (1, MAX_POPULATION), "worst": (0, MAX_POPULATION), "max_tries": (1, MAX_BUDGET)}
        for name, (low, high) in ranges.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not low <= value <= high:
                raise HuntError(f"hunt: {name} must be an integer from {low} to {high:,}, got {value!r}")
        if self.elites >= self.population:
            raise HuntError(f"hunt: elites ({self.elites}) must be fewer than the population ({self.population})")
        if self.budget < self.population * self.tests:
            raise HuntError(f"hunt: a budget of {self.budget} tests does not cover the first generation "
                            f"({self.population} garages x {self.tests} tests); raise --budget or lower --population")


@dataclass
class Scored:
    """A garage and what the tests so far say of it."""

    source: CruiseSource
    parent: str = ""  # hash of the garage it was mutated from ("" for a starting garage)
    rows: list[dict[str, str]] = field(default_factory=list)

    @property
    def feasible(self) -> list[dict[str, str]]:
        return driven_tests(self.rows)

    @property
    def failures(self) -> list[dict[str, str]]:
        return failed_tests(self.rows)

    @property
    def score(self) -> float:
        """Laplace-smoothed failure rate on feasible tests."""
        return (len(self.failures) + 1) / (len(self.feasible) + 2)

    @property
    def rate(self) -> float:
        f = len(self.feasible)
        return len(self.failures) / f if f else math.nan


@dataclass
class HuntResult:
    out_dir: Path
    tests: int  # tests in tests.csv for this hunt
    generations: int
    ranked: list[Scored]
    files: dict[str, Any]  # library, failures, packs, xosc (reporting.hunt adds report, videos)
    worst: list[Scored] = field(default_factory=list)  # the garages exported (packs, .xosc), worst first
    table: list[dict[str, Any]] = field(default_factory=list)  # the rows of failures.csv
    action_type: str = ""  # the action type the tests ran with
    action_label: str = ""  # e.g. "continuous actions, the driver's own" (ActionChoice.label)


def _starting(map_name: str | None, library: str | Path | None, n: int, seed: int) -> list[CruiseSource]:
    if library is not None:
        if not Path(library).is_file():
            raise LibraryError(f"{library}: no such library file; build one with garage-mj train or generate")
        with Library(library, create=False) as lib:
            records = lib.sample(n, seed, stratify=None, map=map_name)
            records = lib.verified(records)
        if not records:
            raise HuntError(f"{library}: no garages{' of ' + map_name if map_name else ''} to start the hunt from")
        return [CruiseSource.from_record(r) for r in records]
    from garage_mj.grid.painters import paint_garage

    found: dict[str, CruiseSource] = {}
    for k in range(20 * n):
        if len(found) >= n:
            break
        g = paint_garage(map_name, seed=seed * 100_003 + k)
        found.setdefault(g.canonical_hash(), CruiseSource.from_garage(g, f"{map_name}-hunt{len(found)}"))
    return list(found.values())


def _child(parents: list[Scored], rng: np.random.Generator, seen: set[str], tries: int) -> tuple[Garage, str] | None:
    """A new garage mutated from a tournament-picked parent, re-painted by the painter env; None if none found."""
    for _ in range(tries):
        a, b = rng.choice(len(parents), size=2, replace=len(parents) < 2)
        parent = parents[a] if parents[a].score >= parents[b].score else parents[b]
        g = mutate(parent.source.garage, rng)
        if g is None:
            continue
        h = g.canonical_hash()
        if h in seen:
            continue
        painted, info = replay(g)
        if not info.get("usable") or painted.canonical_hash() != h:
            continue
        return painted, parent.source.hash
    return None


def _state_file(out: Path) -> Path:
    return out / "hunt.json"


def hunt(settings: CruiseSettings, out_dir: str | Path, *, map: str | None = None, library: str | Path | None = None,
         config: HuntConfig | None = None, compute: Compute = DEFAULT_COMPUTE, **cruise_kwargs: Any) -> HuntResult:
    """Hunt the garages where ``settings.driver`` fails (module docstring); resumable in ``out_dir``.

    ``settings``: the driver, the hunt's seed (start garages, mutations, test seeds), action type,
    occupancy and env of every test. ``settings.action_type``: None runs the driver with the one it
    declares; another one than that is an ``ActionTypeWarning`` (once). ``hunt.json`` records the type
    and where it came from. ``compute``: where the tests run (:mod:`garage_mj.core.backends`; one Ray
    session for the whole hunt) and the hunt's progress bar. The results do not depend on it. No
    videos: :func:`garage_mj.reporting.hunt.hunt` records them after this.
    """
    from garage_mj.driving.drivers import choose_action_type

    cfg = config or HuntConfig()
    if map is None and library is None:
        raise HuntError("hunt: give a map (--map) or a library (--library)")
    # a bad driver fails here; one warning for all the runs
    choice = choose_action_type(settings.driver, settings.action_type)
    settings = settings.resolved(choice.action_type)
    if settings.stall is not None:
        raise HuntError(f"hunt: stall {settings.stall}: the hunt's garages change, so each test draws its stall; "
                        "leave stall out")
    check_task(settings)  # a driver made for other tasks is refused before anything is written
    check_backend(compute, reach=True)  # Ray missing or its cluster unreachable: before any write
    check_driver(settings)  # a driver that cannot be built stops the hunt before hunt.json is written
    start = _starting(map, library, cfg.population, settings.seed)  # a bad map or library: before any write
    out = ensure_dir(out_dir, "--out")
    stored = {"driver": settings.driver, "map": map, "library": str(Path(library).resolve()) if library else None,
              "seed": settings.seed, "action_type": settings.action_type, "occupancy": settings.occupancy,
              "env": settings.env, "test_timeout": settings.test_timeout, "config": asdict(cfg)}
    if settings.task != "cruise":  # a cruise hunt's hunt.json stays as it was
        stored.update(task=settings.task, maneuver=settings.maneuver)
    session = ray_session(compute) if compute.backend == "ray" else contextlib.nullcontext()
    with FolderLock(out, "garage-mj hunt", remove=True), session:
        state_path = _state_file(out)
        if state_path.is_file():
            old = _read_state(state_path).get("settings") or {}
            if not isinstance(old, dict):
                raise HuntError(f"{state_path} is damaged (its settings are not an object); restore it, or use "
                                "another --out")
            old.setdefault("test_timeout", DEFAULT_TEST_TIMEOUT)  # a hunt.json from before the setting: the default
            refuse_other_settings(old, stored, lambda diff: HuntError(
                f"{out} holds a hunt with other settings ({', '.join(diff)}); use another --out or the same settings"))
        else:
            write_json(state_path, {"settings": stored, "action_type_from": choice.source})
        result = _hunt(settings, choice, out, start, cfg, compute, cruise_kwargs)
    result.action_type, result.action_label = choice.action_type, choice.label
    return result


def _read_state(path: Path) -> dict[str, Any]:
    """``hunt.json``; a damaged one is a :class:`HuntError` line naming it and the fix."""
    try:
        state = json.loads(path.read_bytes().decode("utf-8"))
        if not isinstance(state, dict):
            raise ValueError("not an object")
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise HuntError(f"{path} is damaged ({type(exc).__name__}: {exc}); it holds the hunt's settings: restore "
                        "it, or use another --out") from None
    return state


def _hunt(settings: CruiseSettings, choice: ActionChoice, out: Path, start: list[CruiseSource], cfg: HuntConfig,
          compute: Compute, cruise_kwargs: dict[str, Any]) -> HuntResult:
    from tqdm import tqdm

    seed = settings.seed
    cruise_dir = out / "cruise"
    quiet = dataclasses.replace(compute, progress=False)  # the hunt's own bar counts the tests
    scored: dict[str, Scored] = {}
    spent = 0  # tests asked for so far (finished or read back)

    def run(batch: list[tuple[Scored, int]]) -> None:
        """Test each (garage, first index) pair ``cfg.tests`` times from that index; rows into ``scored``."""
        nonlocal spent
        by_count: dict[int, list[Scored]] = {}
        for s, first in batch:
            by_count.setdefault(first + cfg.tests, []).append(s)
        for count, group in sorted(by_count.items()):
            res = run_cruise([s.source for s in group], count, settings, cruise_dir, compute=quiet, choice=choice,
                             **cruise_kwargs)
            for s in group:
                s.rows = [r for r in res.rows if r["garage_hash"] == s.source.hash]
        spent += cfg.tests * len(batch)
        bar.update(cfg.tests * len(batch))

    bar = tqdm(total=cfg.budget, disable=not compute.progress, unit="test",
               desc="hunt" if settings.task == "cruise" else f"hunt ({settings.task})")
    for s in start:
        scored[s.hash] = Scored(s)
    run([(scored[s.hash], 0) for s in start])
    generation = 0
    while spent + cfg.tests <= cfg.budget:
        generation += 1
        rng = np.random.default_rng([seed, generation])
        ranked = sorted(scored.values(), key=lambda s: (-s.score, s.source.hash))
        elites = ranked[: cfg.elites]
        batch = [(e, len(e.rows)) for e in elites]
        room = (cfg.budget - spent) // cfg.tests - len(batch)
        if room < 0:
            batch = batch[: (cfg.budget - spent) // cfg.tests]
            room = 0
        children = []
        for _ in range(min(cfg.population - cfg.elites, room)):
            got = _child(elites, rng, set(scored) | {c.source.hash for c in children}, cfg.max_tries)
            if got is None:
                break
            g, parent = got
            src = CruiseSource.from_garage(g, f"{g.name or 'garage'}-g{generation}-{g.canonical_hash()[:8]}")
            children.append(Scored(src, parent))
        for c in children:
            scored[c.source.hash] = c
        if not batch and not children:
            break
        run(batch + [(c, 0) for c in children])
    bar.close()
    ranked = sorted(scored.values(), key=lambda s: (-(s.rate if s.feasible else -1.0), -len(s.feasible),
                                                      s.source.hash))
    files, worst, table = _write_outputs(out, ranked, cfg, settings)
    state = _read_state(_state_file(out))
    state.update({"action_type_from": choice.source, "generations": generation,
                  "tests": sum(len(s.rows) for s in scored.values()),
                  "garages": len(scored), "files": {k: str(v) for k, v in files.items() if not isinstance(v, list)}})
    write_json(_state_file(out), state)
    return HuntResult(out, state["tests"], generation, ranked, files, worst, table)


def _where(rows: list[dict[str, str]]) -> str:
    """Where on the route the failures happened: progress as % of the route length, e.g. '35 80 100'."""
    out = []
    for r in rows:
        try:
            out.append(f"{100.0 * float(r['path_length']) / max(float(r['route_length']), 1e-9):.0f}")
        except (ValueError, KeyError):
            pass
    return " ".join(out)


def _write_outputs(out: Path, ranked: list[Scored], cfg: HuntConfig, settings: CruiseSettings
                   ) -> tuple[dict[str, Any], list[Scored], list[dict[str, Any]]]:
    """``hunt.sqlite``, ``failures.csv``, the worst garages' packs and .xosc files; the files, the worst
    garages and the rows of failures.csv."""
    lib_path = out / "hunt.sqlite"
    ids: dict[str, int] = {}
    with Library(lib_path) as lib:
        for s in ranked:
            gid = lib.add(s.source.garage, map=s.source.garage.name or "garage", run=f"hunt:{settings.driver}",
                          seed=settings.seed,
                          episode=0, timestep=0)
            ids[s.source.hash] = gid if gid is not None else (lib.id_of(s.source.hash) or -1)
    rows = []
    for k, s in enumerate(ranked, 1):
        fails = s.failures
        counts = {COUNT_COLUMNS[kind]: n for kind, n in failure_counts(fails).items()}
        hits: dict[str, int] = {}
        for r in fails:
            if r["hit"]:
                hits[r["hit"]] = hits.get(r["hit"], 0) + 1
        rows.append({
            "rank": k, "garage": s.source.name, "garage_hash": s.source.hash, "library_id": ids.get(s.source.hash, -1),
            "difficulty": round(s.source.difficulty, 4), "tests": len(s.rows), "feasible": len(s.feasible),
            "failures": len(fails),
            "failure_pct": round(100.0 * s.rate, 2) if s.feasible else "",
            **{c: counts[c] for c in _COUNTS},
            "hit": " ".join(f"{c}:{n}" for c, n in sorted(hits.items())), "failure_progress": _where(fails),
            "failing_tests": " ".join(r["test"] for r in fails), "failing_seeds": " ".join(r["seed"] for r in fails),
            "parent": s.parent[:12],
        })
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=FAILURE_COLUMNS)
    w.writeheader()
    w.writerows(rows)
    atomic_write(out / "failures.csv", buf.getvalue())
    worst = [s for s in ranked if s.failures][: cfg.worst]
    packs, xoscs = _export_worst(out, worst, settings)
    return {"library": lib_path, "failures": out / "failures.csv", "packs": packs, "xosc": xoscs}, worst, rows


def _export_worst(out: Path, worst: list[Scored], settings: CruiseSettings) -> tuple[list[Path], list[Path]]:
    """Pack and .xosc of every failing test, for each of the worst garages (``settings``: the hunt's, resolved)."""
    from garage_mj.export.pack import export_pack

    packs, xoscs = [], []
    try:
        for s in worst:
            pack = export_pack(s.source.garage, out / "packs")
            packs.append(pack)
            src = dataclasses.replace(s.source, pack=str(pack.resolve()))
            for r in s.failures:
                i = int(r["test"])
                path = out / "xosc" / xosc_name(src, i)
                if not path.is_file():
                    run_test(src, i, settings, str(out / "xosc"), export_only=True)
                xoscs.append(path)
    finally:
        close_cached_env()  # the scene run_test kept for the exports
    return packs, xoscs


def read_settings(out_dir: str | Path) -> dict[str, Any]:
    """The settings of the hunt in ``out_dir`` (``hunt.json``): driver, seed, action type, occupancy, env, ..."""
    return json.loads(_state_file(Path(out_dir)).read_text())["settings"]


def add_file(out_dir: str | Path, name: str, path: Path) -> None:
    """Name one more of the hunt's files in ``hunt.json`` (the reporting stage adds ``report``)."""
    state_path = _state_file(Path(out_dir))
    state = json.loads(state_path.read_text())
    state["files"][name] = str(path)
    write_json(state_path, state)


def rerun(out_dir: str | Path, garage_hash: str, test: int) -> dict[str, Any]:
    """Re-run one listed (garage, test) of a hunt in ``out_dir``: the cruise row (same seed, same outcome)."""
    out = Path(out_dir)
    state = read_settings(out)
    rows = [r for r in read_tests(out / "cruise" / "tests.csv") if r["garage_hash"].startswith(garage_hash)]
    if not rows:
        raise HuntError(f"{out}: no hunted garage with hash {garage_hash}")
    with Library(out / "hunt.sqlite", create=False) as lib:
        gid = lib.id_of(rows[0]["garage_hash"])
        if gid is None:
            raise HuntError(f"{out}/hunt.sqlite: garage {garage_hash} is not stored; run the hunt again to finish it")
        garage = lib.get(gid).garage
    src = CruiseSource.from_garage(garage, rows[0]["garage"])
    settings = CruiseSettings.from_stored(state)
    try:
        return run_test(src, int(test), settings)
    finally:
        close_cached_env()
