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

**Park and AVP hunts** (``settings.task`` ``park`` or ``avp``) search the park geometry too, and count only the
failures the reference driver would not make:

- A candidate is a (garage, park geometry) pair, the geometry one of ``geometries`` (names of
  :data:`~garage_mj.driving.park_geometries.PARK_GEOMETRIES`; default :data:`PARK_HUNT_GEOMETRIES`). The start
  pairs each starting garage with a geometry drawn uniformly from those that can build it; a child is, with
  probability :data:`GEOMETRY_SWITCH`, its parent's garage in another geometry, else a mutation of its parent's
  garage in the parent's geometry. A garage a geometry cannot build (a :class:`~garage_mj.scene.world.GeometryError`
  from its stall layout) is never drawn, so never tested. A candidate's tests run in its geometry (the geometry's
  env keyword arguments over ``settings.env``), each geometry a resumable cruise run of its own in
  ``OUT/cruise/<geometry>``.
- Every failing test is driven again by ``oracle`` (the same garage, geometry and test seed: the same stall,
  parked cars, start and actors); ``OUT/oracle.csv`` keeps those outcomes, so a resumed hunt drives none twice. A
  failure counts (ranking, fitness, the worst garages) only when the oracle parks that test: the driver fails
  where parking was shown possible. ``failures.csv`` gains ``geometry``, ``oracle_parks`` (the failing tests the
  oracle parks) and ``confirmed_pct`` (those, as % of the feasible tests); packs, ``.xosc`` files and videos go
  into a folder per geometry.
- **Stalls** are searched too: a park test's outcome turns mostly on its stall (its neighbours, its place beside a
  junction or a pillar), which a test otherwise draws from its seed. A child of a parent with confirmed failures is,
  with probability :data:`STALL_FOCUS`, the parent's garage and geometry with every test aimed at one stall: a stall
  where the parent failed, or for a parent aimed at a stall already, a stall beside it (same block and side, the
  next id). Such a candidate's tests draw their seeds (parked neighbours, maneuver, start) as any test does; its
  geometry is the *variant* ``<geometry>@stall<id>`` (:func:`variant`), its own cruise run in
  ``OUT/cruise/<geometry>@stall<id>``; ``failures.csv`` names it in its ``geometry`` and ``stall`` columns. A child
  made from it by a geometry switch or a mutation draws its stalls again (another geometry or garage numbers its
  stalls anew).
- **Actor placements** are searched in a hunt with actors (``settings.env["scenario"]``): a child of a parent with a
  confirmed failure in which the car hit an actor (a pedestrian, a moving car, clutter) is, with probability
  :data:`ACTOR_FOCUS`, that failing test's scene (its garage, geometry, stall, parked cars, maneuver and start: the
  draws of its test seed) with the actors placed anew by each of its tests' seeds (``GarageDriveEnv(scene_seed=)``;
  the tests' seeds are those of a run seeded by the scene's seed, so none is the failing test again). Its geometry
  is the variant ``<geometry>@scene<seed>``, its own cruise run, named in ``failures.csv``'s ``stall`` and
  ``scene`` columns. As an elite it is re-tested with more seeds, so more placements around that scene.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import numbers
import os
from collections.abc import Sequence
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
from garage_mj.driving.park_geometries import PARK_GEOMETRIES, geometry_names
from garage_mj.driving.results import COUNT_COLUMNS, driven_tests, failed_tests, failure_counts, read_tests
from garage_mj.driving.sources import DEFAULT_TEST_TIMEOUT, MAX_TESTS, CruiseSettings, CruiseSource
from garage_mj.generation.library import Library, LibraryError
from garage_mj.generation.search import mutate, replay
from garage_mj.grid.garage import Garage
from garage_mj.scene.stalls import stall_layout
from garage_mj.scene.world import GeometryError, world_with

if TYPE_CHECKING:
    from garage_mj.driving.drivers import ActionChoice

#: The failure classes' count columns of ``failures.csv``, in alphabetical order (not the display order of the rest).
_COUNTS = tuple(sorted(COUNT_COLUMNS.values()))
FAILURE_COLUMNS = ("rank", "garage", "garage_hash", "library_id", "difficulty", "tests", "feasible", "failures",
                   "failure_pct", *_COUNTS, "hit", "failure_progress", "failing_tests", "failing_seeds", "parent")
#: ``failures.csv`` of a park or AVP hunt: the candidate's geometry, and the failures the oracle parks.
PARK_FAILURE_COLUMNS = (*FAILURE_COLUMNS[:3], "geometry", "stall", "scene", *FAILURE_COLUMNS[3:8], "oracle_parks",
                        "confirmed_pct", *FAILURE_COLUMNS[8:])

#: The park geometries a park or AVP hunt searches when none are given (``--geometries``): bays at 90 and 60
#: degrees, a narrow aisle with a mixed fleet, parallel slots with and without it.
PARK_HUNT_GEOMETRIES = ("default", "tight", "angled60", "parallel", "parallel_mixed")
#: A park hunt's child of a parent with a stall to aim at: the chance that it is the parent's garage and geometry
#: with its tests aimed at that stall (else a geometry switch or a mutation, as for any parent).
STALL_FOCUS = 0.5
#: A park hunt's child of a parent with a failure in which the car hit an actor: the chance that it is that test's
#: scene with its actors placed anew (before the stall and the other kinds of child are drawn).
ACTOR_FOCUS = 0.5
#: What a car hits (``tests.csv``'s ``hit``) when it hits an actor.
ACTOR_HITS = ("pedestrian", "moving_car", "clutter")
#: A park hunt's child: the chance that it is its parent's garage in another geometry (else a mutated garage).
GEOMETRY_SWITCH = 0.5
#: What joins a park geometry and a stall in a candidate's variant name (``tight@stall17``).
_STALL_MARK = "@stall"
#: ... and a park geometry and a test seed whose scene the candidate keeps (``tight@scene1861353168``).
_SCENE_MARK = "@scene"
#: The driver that confirms a park hunt's failures (a failure counts when it parks that test).
ORACLE = "oracle"
_ORACLE_COLUMNS = ("geometry", "garage_hash", "test", "seed", "outcome")
#: Keys of ``settings.env`` that a park hunt's geometries set (given as well, they are refused).
_GEOMETRY_KEYS = ("world", "parked_fleet", "parked_jitter")


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
    parent: str = ""  # key of the candidate it was made from ("" for a starting one)
    rows: list[dict[str, str]] = field(default_factory=list)
    geometry: str = ""  # a park or AVP hunt's park geometry or variant (tight@stall17, tight@scene8812; "": cruise)
    oracle_parks: set[int] | None = None  # failing tests (indices) the oracle parks; None: not confirmed (cruise)

    @property
    def key(self) -> str:
        """The candidate: its garage's hash, and ``:<geometry>`` in a park or AVP hunt."""
        return candidate_key(self.source.hash, self.geometry)

    @property
    def park_geometry(self) -> str:
        """The park geometry its tests run in ("" in a cruise hunt), without the stall of a variant."""
        return split_variant(self.geometry)[0]

    @property
    def stall(self) -> int | None:
        """The stall its tests are aimed at (None: each test draws its stall): a stall variant's, or the stall of a
        scene variant's scene (None before its tests ran)."""
        _, stall, scene = split_variant(self.geometry)
        if scene is not None and self.rows and str(self.rows[0].get("target_stall", "")).isdigit():
            return int(self.rows[0]["target_stall"])
        return stall

    @property
    def scene(self) -> int | None:
        """The test seed whose scene its tests keep, their actors placed anew (None: each test draws its scene)."""
        return split_variant(self.geometry)[2]

    @property
    def feasible(self) -> list[dict[str, str]]:
        return driven_tests(self.rows)

    @property
    def failures(self) -> list[dict[str, str]]:
        return failed_tests(self.rows)

    @property
    def confirmed(self) -> list[dict[str, str]]:
        """The failures that count: in a park or AVP hunt those the oracle parks, in a cruise hunt all."""
        fails = self.failures
        return fails if self.oracle_parks is None else [r for r in fails if int(r["test"]) in self.oracle_parks]

    @property
    def score(self) -> float:
        """Laplace-smoothed failure rate (counted failures) on feasible tests."""
        return (len(self.confirmed) + 1) / (len(self.feasible) + 2)

    @property
    def rate(self) -> float:
        f = len(self.feasible)
        return len(self.confirmed) / f if f else math.nan


def variant(geometry: str, stall: int | None = None, scene: int | None = None) -> str:
    """A park hunt candidate's geometry with its tests aimed at ``stall``, ``<geometry>@stall<id>``, or keeping the
    scene of the test seed ``scene`` with the actors placed anew, ``<geometry>@scene<seed>`` (both None: the geometry,
    every test drawing its own)."""
    if scene is not None:
        return f"{geometry}{_SCENE_MARK}{int(scene)}"
    return geometry if stall is None else f"{geometry}{_STALL_MARK}{int(stall)}"


def split_variant(name: str) -> tuple[str, int | None, int | None]:
    """``(geometry, stall, scene)`` of a :func:`variant` name (None where the tests draw it)."""
    for mark in (_STALL_MARK, _SCENE_MARK):
        geometry, found, number = name.partition(mark)
        if found and number.isdigit():
            return (geometry, int(number), None) if mark == _STALL_MARK else (geometry, None, int(number))
    return name, None, None


def variant_label(name: str) -> str:
    """A variant as a person reads it: ``tight, stall 17``, ``tight, scene of seed 8812`` (or the geometry alone)."""
    geometry, stall, scene = split_variant(name)
    if scene is not None:
        return f"{geometry}, scene of seed {scene}"
    return geometry if stall is None else f"{geometry}, stall {stall}"


def candidate_key(garage_hash: str, geometry: str = "") -> str:
    """A hunt candidate's key: the garage's hash, with ``:<geometry>`` in a park or AVP hunt."""
    return f"{garage_hash}:{geometry}" if geometry else garage_hash


def hunt_geometries(task: str, geometries: Sequence[str] | None) -> tuple[str, ...]:
    """The park geometries a hunt of ``task`` searches: ``geometries`` checked (None: :data:`PARK_HUNT_GEOMETRIES`);
    a cruise hunt has none (given some, a :class:`HuntError` line)."""
    if task == "cruise":
        if geometries:
            raise HuntError("hunt: --geometries is for park and AVP hunts (give --task park or avp); a cruise hunt's "
                            "garages keep the default geometry")
        return ()
    try:
        return geometry_names(PARK_HUNT_GEOMETRIES if geometries is None else geometries, "hunt: --geometries")
    except ValueError as exc:
        raise HuntError(str(exc)) from None


def candidate_settings(settings: CruiseSettings, geometry: str) -> CruiseSettings:
    """``settings`` with the park geometry ``geometry``'s env keyword arguments over its env ("": as they are); a
    :func:`variant`'s tests aimed at its stall, or keeping its scene (``scene_seed``; the scene's seed seeds its
    run, so that no test of it is the failing test itself, whose seed is the hunt's)."""
    if not geometry:
        return settings
    base, stall, scene = split_variant(geometry)
    env = {**(settings.env or {}), **PARK_GEOMETRIES[base].env_kwargs()}
    if scene is not None:
        env["scene_seed"] = scene
    mine = dataclasses.replace(settings, env=env, seed=settings.seed if scene is None else scene)
    return mine if stall is None else dataclasses.replace(mine, stall=stall)


def cruise_dir(out: Path, geometry: str = "") -> Path:
    """The cruise run of a hunt's candidates in ``geometry``: ``OUT/cruise`` (cruise hunt), ``OUT/cruise/<geometry>``."""
    return out / "cruise" / geometry if geometry else out / "cruise"


def buildable(garage: Garage, geometry: str) -> bool:
    """Whether the park geometry ``geometry`` can build ``garage`` (its stall layout raises no GeometryError)."""
    try:
        stall_layout(garage, world_with(PARK_GEOMETRIES[geometry].world))
    except GeometryError:
        return False
    return True


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


def _start_pairs(sources: list[CruiseSource], geometries: Sequence[str], seed: int, n: int,
                 can_build: Any) -> list[tuple[CruiseSource, str]]:
    """A park hunt's start: the first ``n`` of ``sources`` that some geometry builds, each with one of those drawn
    uniformly (seeded by the hunt's seed)."""
    rng = np.random.default_rng([seed, 0])
    pairs = []
    for src in sources:
        if len(pairs) >= n:
            break
        ok = [g for g in geometries if can_build(src.garage, g)]
        if ok:
            pairs.append((src, ok[int(rng.integers(len(ok)))]))
    return pairs


def stall_targets(parent: Scored, seen: set[str]) -> list[int]:
    """The stalls a park hunt's child of ``parent`` may aim its tests at (:data:`STALL_FOCUS`), none already a
    candidate in ``seen``: those of the parent's confirmed failures, and for a parent aimed at a stall the stalls
    beside it (same block and side, the next id); none in a cruise hunt."""
    geometry, fixed, _ = split_variant(parent.geometry)
    if not geometry:
        return []
    ids = {int(r["target_stall"]) for r in parent.confirmed if str(r.get("target_stall", "")).isdigit()}
    if fixed is not None:
        stalls = stall_layout(parent.source.garage, world_with(PARK_GEOMETRIES[geometry].world)).stalls
        me = next((s for s in stalls if s.id == fixed), None)
        ids |= {s.id for s in stalls if me is not None and abs(s.id - fixed) == 1
                and (s.block, s.side) == (me.block, me.side)}
    return sorted(k for k in ids if candidate_key(parent.source.hash, variant(geometry, k)) not in seen)


def scene_targets(parent: Scored, seen: set[str]) -> list[int]:
    """The test seeds whose scenes a park hunt's child of ``parent`` may keep with its actors placed anew
    (:data:`ACTOR_FOCUS`), none already a candidate in ``seen``: those of the parent's confirmed failures in which
    the car hit an actor (:data:`ACTOR_HITS`); none for a parent that keeps a scene already (its failures are of
    that scene) or in a cruise hunt."""
    geometry, _, scene = split_variant(parent.geometry)
    if not geometry or scene is not None:
        return []
    seeds = {int(r["seed"]) for r in parent.confirmed
             if r.get("hit") in ACTOR_HITS and str(r.get("seed", "")).isdigit()}
    return sorted(k for k in seeds if candidate_key(parent.source.hash, variant(geometry, scene=k)) not in seen)


def _child(parents: list[Scored], rng: np.random.Generator, seen: set[str], tries: int,
           geometries: Sequence[str] = (), can_build: Any = None) -> tuple[Garage, str, Scored] | None:
    """A new candidate from a tournament-picked parent: a garage mutated from the parent's, re-painted by the painter
    env, or in a park hunt the parent's garage keeping the scene of a failing test with its actors placed anew
    (:func:`scene_targets`, with probability :data:`ACTOR_FOCUS` where there is one), with its tests aimed at a
    stall (:func:`stall_targets`, with probability :data:`STALL_FOCUS` where there is one) or in another of
    ``geometries`` that builds it (with probability :data:`GEOMETRY_SWITCH`); (garage, geometry or variant,
    parent), None if none found."""
    targets_of: dict[str, tuple[list[int], list[int]]] = {}  # per parent: seen does not change while a child is drawn
    for _ in range(tries):
        a, b = rng.choice(len(parents), size=2, replace=len(parents) < 2)
        parent = parents[a] if parents[a].score >= parents[b].score else parents[b]
        base = parent.park_geometry
        if parent.key not in targets_of:
            targets_of[parent.key] = scene_targets(parent, seen), stall_targets(parent, seen)
        scenes, targets = targets_of[parent.key]
        if scenes and rng.random() < ACTOR_FOCUS:
            return parent.source.garage, variant(base, scene=scenes[int(rng.integers(len(scenes)))]), parent
        if targets and rng.random() < STALL_FOCUS:
            return parent.source.garage, variant(base, targets[int(rng.integers(len(targets)))]), parent
        if len(geometries) > 1 and rng.random() < GEOMETRY_SWITCH:
            garage = parent.source.garage
            others = [g for g in geometries if candidate_key(parent.source.hash, g) not in seen
                      and can_build(garage, g)]
            if others:
                return garage, others[int(rng.integers(len(others)))], parent
            continue
        g = mutate(parent.source.garage, rng)
        if g is None:
            continue
        h = g.canonical_hash()
        if candidate_key(h, base) in seen:
            continue
        painted, info = replay(g)
        if not info.get("usable") or painted.canonical_hash() != h:
            continue
        if base and not can_build(painted, base):
            continue
        return painted, base, parent
    return None


def _state_file(out: Path) -> Path:
    return out / "hunt.json"


def hunt(settings: CruiseSettings, out_dir: str | Path, *, map: str | None = None, library: str | Path | None = None,
         config: HuntConfig | None = None, compute: Compute = DEFAULT_COMPUTE,
         geometries: Sequence[str] | None = None, **cruise_kwargs: Any) -> HuntResult:
    """Hunt the garages where ``settings.driver`` fails (module docstring); resumable in ``out_dir``.

    ``settings``: the driver, the hunt's seed (start garages, mutations, test seeds), action type,
    occupancy and env of every test. ``settings.action_type``: None runs the driver with the one it
    declares; another one than that is an ``ActionTypeWarning`` (once). ``hunt.json`` records the type
    and where it came from. ``compute``: where the tests run (:mod:`garage_mj.core.backends`; one Ray
    session for the whole hunt) and the hunt's progress bar. The results do not depend on it. No
    videos: :func:`garage_mj.reporting.hunt.hunt` records them after this. ``geometries``: a park or AVP hunt's
    park geometries (None: :data:`PARK_HUNT_GEOMETRIES`; a cruise hunt refuses them), stored in ``hunt.json``.
    """
    from garage_mj.driving.drivers import choose_action_type

    cfg = config or HuntConfig()
    if map is None and library is None:
        raise HuntError("hunt: give a map (--map) or a library (--library)")
    # a bad driver fails here; one warning for all the runs
    choice = choose_action_type(settings.driver, settings.action_type)
    raw_env = dict(settings.env or {})  # without the driver's sensors: the oracle's re-drives need none
    settings = settings.resolved(choice.action_type)
    if settings.stall is not None:
        raise HuntError(f"hunt: stall {settings.stall}: the hunt's garages change, so each test draws its stall; "
                        "leave stall out")
    check_task(settings)  # a driver made for other tasks is refused before anything is written
    names = hunt_geometries(settings.task, geometries)
    given = [k for k in _GEOMETRY_KEYS if k in (settings.env or {})]
    if names and given:
        raise HuntError(f"hunt: env {', '.join(given)}: a park hunt's geometries set these; leave them out and name "
                        "the geometries (--geometries)")
    check_backend(compute, reach=True)  # Ray missing or its cluster unreachable: before any write
    check_driver(settings)  # a driver that cannot be built stops the hunt before hunt.json is written
    start = _starting(map, library, cfg.population, settings.seed)  # a bad map or library: before any write
    can_build = _build_cache()
    pairs = [(s, "") for s in start]
    if names:
        pairs = _start_pairs(start, names, settings.seed, cfg.population, can_build)
        if len(pairs) < cfg.population:  # some garages no geometry builds: draw more
            more = _starting(map, library, 4 * cfg.population, settings.seed)
            pairs = _start_pairs(more, names, settings.seed, cfg.population, can_build)
        if not pairs:
            raise HuntError(f"hunt: none of the starting garages can be built in {', '.join(names)}; give other "
                            "--geometries or another map")
    out = ensure_dir(out_dir, "--out")
    stored = {"driver": settings.driver, "map": map, "library": str(Path(library).resolve()) if library else None,
              "seed": settings.seed, "action_type": settings.action_type, "occupancy": settings.occupancy,
              "env": settings.env, "test_timeout": settings.test_timeout, "config": asdict(cfg)}
    if settings.task != "cruise":  # a cruise hunt's hunt.json stays as it was
        stored.update(task=settings.task, maneuver=settings.maneuver, geometries=list(names))
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
        result = _hunt(settings, choice, out, pairs, cfg, compute, cruise_kwargs, names, can_build, raw_env)
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


def _build_cache() -> Any:
    """:func:`buildable`, remembered per (garage hash, geometry)."""
    known: dict[tuple[str, str], bool] = {}

    def can_build(garage: Garage, geometry: str) -> bool:
        key = (garage.canonical_hash(), geometry)
        if key not in known:
            known[key] = buildable(garage, geometry)
        return known[key]

    return can_build


def _hunt(settings: CruiseSettings, choice: ActionChoice, out: Path, start: list[tuple[CruiseSource, str]],
          cfg: HuntConfig, compute: Compute, cruise_kwargs: dict[str, Any], geometries: Sequence[str] = (),
          can_build: Any = None, raw_env: dict[str, Any] | None = None) -> HuntResult:
    from tqdm import tqdm

    seed = settings.seed
    quiet = dataclasses.replace(compute, progress=False)  # the hunt's own bar counts the tests
    scored: dict[str, Scored] = {}
    spent = 0  # tests asked for so far (finished or read back)
    oracle = _Oracle(out, settings, raw_env or {}) if geometries else None

    def run(batch: list[tuple[Scored, int]]) -> None:
        """Test each (candidate, first index) pair ``cfg.tests`` times from that index; rows into ``scored``; a park
        hunt's new failures driven again by the oracle."""
        nonlocal spent
        groups: dict[tuple[str, int], list[Scored]] = {}
        for s, first in batch:
            groups.setdefault((s.geometry, first + cfg.tests), []).append(s)
        for (geometry, count), group in sorted(groups.items()):
            res = run_cruise([s.source for s in group], count, candidate_settings(settings, geometry),
                             cruise_dir(out, geometry), compute=quiet, choice=choice, **cruise_kwargs)
            for s in group:
                s.rows = [r for r in res.rows if r["garage_hash"] == s.source.hash]
                if oracle is not None:
                    s.oracle_parks = oracle.parks(s)
        spent += cfg.tests * len(batch)
        bar.update(cfg.tests * len(batch))

    bar = tqdm(total=cfg.budget, disable=not compute.progress, unit="test",
               desc="hunt" if settings.task == "cruise" else f"hunt ({settings.task})")
    for src, geometry in start:
        c = Scored(src, geometry=geometry)
        scored[c.key] = c
    run([(s, 0) for s in scored.values()])
    generation = 0
    while spent + cfg.tests <= cfg.budget:
        generation += 1
        rng = np.random.default_rng([seed, generation])
        ranked = sorted(scored.values(), key=lambda s: (-s.score, s.key))
        elites = ranked[: cfg.elites]
        batch = [(e, len(e.rows)) for e in elites]
        room = (cfg.budget - spent) // cfg.tests - len(batch)
        if room < 0:
            batch = batch[: (cfg.budget - spent) // cfg.tests]
            room = 0
        children: list[Scored] = []
        for _ in range(min(cfg.population - cfg.elites, room)):
            got = _child(elites, rng, set(scored) | {c.key for c in children}, cfg.max_tries, geometries, can_build)
            if got is None:
                break
            g, geometry, parent = got
            if g is parent.source.garage:  # the parent's garage in another geometry
                src = parent.source
            else:
                src = CruiseSource.from_garage(g, f"{g.name or 'garage'}-g{generation}-{g.canonical_hash()[:8]}")
            children.append(Scored(src, parent.key, geometry=geometry))
        for c in children:
            scored[c.key] = c
        if not batch and not children:
            break
        run(batch + [(c, 0) for c in children])
    bar.close()
    if oracle is not None:
        oracle.close()
    ranked = sorted(scored.values(), key=lambda s: (-(s.rate if s.feasible else -1.0), -len(s.feasible), s.key))
    files, worst, table = _write_outputs(out, ranked, cfg, settings)
    state = _read_state(_state_file(out))
    state.update({"action_type_from": choice.source, "generations": generation,
                  "tests": sum(len(s.rows) for s in scored.values()),
                  "garages": len(scored), "files": {k: str(v) for k, v in files.items() if not isinstance(v, list)}})
    if geometries:
        state["oracle"] = {"failures": sum(len(s.failures) for s in scored.values()),
                           "oracle_parks": sum(len(s.confirmed) for s in scored.values())}
    write_json(_state_file(out), state)
    return HuntResult(out, state["tests"], generation, ranked, files, worst, table)


def oracle_settings(settings: CruiseSettings, env: dict[str, Any], geometry: str) -> CruiseSettings:
    """The settings that drive a park hunt's test again with the oracle: the hunt's seed, occupancy, task, maneuver
    and ``env`` (the hunt's, without the driver's sensors) in ``geometry``, the oracle's own action type."""
    from garage_mj.driving.drivers import choose_action_type

    base = CruiseSettings(ORACLE, settings.seed, None, settings.occupancy, dict(env), test_timeout=settings.test_timeout,
                          task=settings.task, maneuver=settings.maneuver)
    return candidate_settings(base.resolved(choose_action_type(ORACLE, None).action_type), geometry)


class _Oracle:
    """A park hunt's failing tests driven again by the oracle, kept in ``OUT/oracle.csv`` (appended as each ends, read
    back on a resume): the oracle's outcome of the same garage, geometry and test seed."""

    def __init__(self, out: Path, settings: CruiseSettings, env: dict[str, Any]) -> None:
        self.path = out / "oracle.csv"
        self.settings, self.env = settings, env
        self.outcomes: dict[tuple[str, str, int], str] = {}
        if self.path.is_file():
            with self.path.open(newline="") as f:
                for r in csv.DictReader(f):
                    if all(r.get(c) for c in _ORACLE_COLUMNS[1:]) and r["test"].isdigit():  # a torn last line: again
                        self.outcomes[(r["geometry"] or "", r["garage_hash"], int(r["test"]))] = r["outcome"]
        self.used = False

    def parks(self, s: Scored) -> set[int]:
        """The failing tests of ``s`` that the oracle parks (each driven once, ever)."""
        settings = oracle_settings(self.settings, self.env, s.geometry)
        parked = set()
        for r in s.failures:
            i = int(r["test"])
            key = (s.geometry, s.source.hash, i)
            if key not in self.outcomes:
                row = run_test(s.source, i, settings)
                self.used = True
                self._append({"geometry": s.geometry, "garage_hash": s.source.hash, "test": i, "seed": row["seed"],
                              "outcome": row["outcome"]})
                self.outcomes[key] = str(row["outcome"])
            if self.outcomes[key] == "success":
                parked.add(i)
        return parked

    def _append(self, row: dict[str, Any]) -> None:
        new = not self.path.is_file()
        with self.path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=_ORACLE_COLUMNS)
            if new:
                w.writeheader()
            w.writerow(row)
            f.flush()
            os.fsync(f.fileno())  # a killed hunt keeps the oracle's outcomes so far

    def close(self) -> None:
        if self.used:
            close_cached_env()  # the scenes the re-drives kept


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
    park = any(s.geometry for s in ranked)
    rows = []
    for k, s in enumerate(ranked, 1):
        fails = s.confirmed if park else s.failures
        counts = {COUNT_COLUMNS[kind]: n for kind, n in failure_counts(fails).items()}
        hits: dict[str, int] = {}
        for r in fails:
            if r["hit"]:
                hits[r["hit"]] = hits.get(r["hit"], 0) + 1
        rows.append({
            "rank": k, "garage": s.source.name, "garage_hash": s.source.hash, "library_id": ids.get(s.source.hash, -1),
            "difficulty": round(s.source.difficulty, 4), "tests": len(s.rows), "feasible": len(s.feasible),
            "failures": len(s.failures),
            "failure_pct": round(100.0 * len(s.failures) / len(s.feasible), 2) if s.feasible else "",
            **{c: counts[c] for c in _COUNTS},
            "hit": " ".join(f"{c}:{n}" for c, n in sorted(hits.items())), "failure_progress": _where(fails),
            "failing_tests": " ".join(r["test"] for r in fails), "failing_seeds": " ".join(r["seed"] for r in fails),
            "parent": _short(s.parent),
        })
        if park:  # the class counts, hits and failing tests above are of the failures the oracle parks
            rows[-1].update(geometry=s.park_geometry, stall="" if s.stall is None else s.stall,
                            scene="" if s.scene is None else s.scene, oracle_parks=len(s.confirmed),
                            confirmed_pct=round(100.0 * s.rate, 2) if s.feasible else "")
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=PARK_FAILURE_COLUMNS if park else FAILURE_COLUMNS)
    w.writeheader()
    w.writerows(rows)
    atomic_write(out / "failures.csv", buf.getvalue())
    worst = [s for s in ranked if s.confirmed][: cfg.worst]
    packs, xoscs = _export_worst(out, worst, settings)
    return {"library": lib_path, "failures": out / "failures.csv", "packs": packs, "xosc": xoscs}, worst, rows


def _export_worst(out: Path, worst: list[Scored], settings: CruiseSettings) -> tuple[list[Path], list[Path]]:
    """Pack and .xosc of every failing test, for each of the worst garages (``settings``: the hunt's, resolved)."""
    from garage_mj.export.pack import export_pack

    packs, xoscs = [], []
    try:
        for s in worst:
            mine = candidate_settings(settings, s.geometry)
            pack = export_pack(s.source.garage, out / "packs", world=world_with((mine.env or {}).get("world")))
            packs.append(pack)
            src = dataclasses.replace(s.source, pack=str(pack.resolve()))
            folder = out / "xosc" / s.geometry if s.geometry else out / "xosc"
            for r in s.confirmed:
                i = int(r["test"])
                path = folder / xosc_name(src, i)
                if not path.is_file():
                    run_test(src, i, mine, str(folder), export_only=True)
                xoscs.append(path)
    finally:
        close_cached_env()  # the scene run_test kept for the exports
    return packs, xoscs


def _short(key: str) -> str:
    """A candidate's key as ``failures.csv`` names a parent: 12 hex digits of the hash (and ``:<geometry>``)."""
    h, _, geometry = key.partition(":")
    return candidate_key(h[:12], geometry)


def hunt_settings(out_dir: str | Path, geometry: str = "") -> CruiseSettings:
    """The settings the hunt in ``out_dir`` ran its tests in ``geometry`` with (a cruise hunt's: "")."""
    return candidate_settings(CruiseSettings.from_stored(read_settings(out_dir)), geometry)


def run_dirs(out_dir: str | Path) -> list[Path]:
    """The hunt's cruise runs: ``OUT/cruise``, or one per geometry of a park or AVP hunt, then one per variant
    (a geometry with its tests aimed at a stall, ``OUT/cruise/<geometry>@stall<id>``, or keeping a test's scene,
    ``OUT/cruise/<geometry>@scene<seed>``), by geometry, stall and scene."""
    return [cruise_dir(Path(out_dir), name) for name in run_variants(out_dir)]


def run_variants(out_dir: str | Path) -> list[str]:
    """The geometries and variants (:func:`variant`) the hunt in ``out_dir`` ran tests in ("" for a cruise hunt)."""
    out = Path(out_dir)
    geometries = read_settings(out).get("geometries") or [""]
    if geometries == [""]:
        return [""] if (cruise_dir(out) / "tests.csv").is_file() else []
    found = [d.name for d in cruise_dir(out).iterdir() if (d / "tests.csv").is_file()] \
        if cruise_dir(out).is_dir() else []
    order = {g: k for k, g in enumerate(geometries)}
    parsed = [(n, *split_variant(n)) for n in found]
    ranked = sorted((order[g], -1 if stall is None else stall, -1 if scene is None else scene, n)
                    for n, g, stall, scene in parsed if g in order)
    return [r[-1] for r in ranked]


def read_settings(out_dir: str | Path) -> dict[str, Any]:
    """The settings of the hunt in ``out_dir`` (``hunt.json``): driver, seed, action type, occupancy, env, ..."""
    return json.loads(_state_file(Path(out_dir)).read_text())["settings"]


def add_file(out_dir: str | Path, name: str, path: Path) -> None:
    """Name one more of the hunt's files in ``hunt.json`` (the reporting stage adds ``report``)."""
    state_path = _state_file(Path(out_dir))
    state = json.loads(state_path.read_text())
    state["files"][name] = str(path)
    write_json(state_path, state)


def rerun(out_dir: str | Path, garage_hash: str, test: int, geometry: str | None = None,
          stall: int | None = None, scene: int | None = None) -> dict[str, Any]:
    """Re-run one listed (garage, test) of a hunt in ``out_dir``: the cruise row (same seed, same outcome). A park or
    AVP hunt's garage tested in several geometries needs ``geometry``, one tested with its tests aimed at a stall
    ``stall`` too, one tested keeping a test's scene ``scene``: the ``geometry``, ``stall`` and ``scene`` columns of
    ``failures.csv`` (``geometry`` may also be the variant, ``tight@stall17``, ``tight@scene8812``)."""
    out = Path(out_dir)
    state = read_settings(out)
    names = run_variants(out)
    if geometry is not None:  # that geometry's own run, or the variant's that aimed at a stall or kept a scene
        base, aimed, kept = split_variant(geometry)
        geometry = variant(base, aimed if aimed is not None else stall, kept if kept is not None else scene)
        names = [n for n in names if n == geometry]
    found = []
    for g in names:
        path = cruise_dir(out, g) / "tests.csv"
        rows = [r for r in read_tests(path) if r["garage_hash"].startswith(garage_hash)] if path.is_file() else []
        if rows:
            found.append((g, rows))
    if not found:
        raise HuntError(f"{out}: no hunted garage with hash {garage_hash}"
                        + (f" in geometry {variant_label(geometry)}" if geometry else ""))
    if len(found) > 1:
        raise HuntError(f"{out}: garage {garage_hash} was tested in {', '.join(variant_label(g) for g, _ in found)}; "
                        "name one (geometry= and stall=, the columns of failures.csv)")
    geometry, rows = found[0]
    with Library(out / "hunt.sqlite", create=False) as lib:
        gid = lib.id_of(rows[0]["garage_hash"])
        if gid is None:
            raise HuntError(f"{out}/hunt.sqlite: garage {garage_hash} is not stored; run the hunt again to finish it")
        garage = lib.get(gid).garage
    src = CruiseSource.from_garage(garage, rows[0]["garage"])
    settings = candidate_settings(CruiseSettings.from_stored(state), geometry)
    try:
        return run_test(src, int(test), settings)
    finally:
        close_cached_env()
