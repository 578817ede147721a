"""The garages a learned driver trains or is tested on (:class:`GarageSet`), and where they came from.

A set is an ordered, immutable tuple of :class:`~garage_mj.driving.sources.CruiseSource` with a
one-line ``origin`` that says how it was made (the library and its filters, the pack folder, the
painted map, the JSON file), so a training run can record what it trained on. It is made from:

- a library (:meth:`GarageSet.from_library`): filtered by map, difficulty, route difficulty and the
  training seed of the run that found each garage, all of them or a seeded sample spread evenly over difficulty;
- a folder of asset packs (:meth:`GarageSet.from_packs`);
- a shipped map painted by the scripted painter (:meth:`GarageSet.from_map`);
- a JSON file (:meth:`GarageSet.from_json`): what :meth:`GarageSet.to_json` writes, or the list
  ``garage-mj library export-json`` writes.

:func:`load_garage_set` picks the constructor from one string (a file, a folder, a map name), the
way a command line names a set. Every problem a user can cause is a one-line :class:`GarageSetError`
naming the thing and the fix. Everything random takes a seed: same arguments, same set, same order.
"""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import write_error, write_json
from garage_mj.driving.difficulty.rating import resolve_route_model
from garage_mj.driving.sources import CruiseSource, painted_sources
from garage_mj.export.artefacts import GARAGE_JSON, MANIFEST
from garage_mj.generation.library import Library, stratified_ids
from garage_mj.generation.library_format import GarageRecord, LibraryError
from garage_mj.grid.garage import Garage, MapError
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.grid.metrics import evaluate

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry
    from garage_mj.scene.drivable import DriveConfig
    from garage_mj.scene.route_difficulty import RouteDifficulty

#: ``format`` of the JSON :meth:`GarageSet.to_json` writes, and its version.
SET_FORMAT = "garage-mj garage set"
SET_VERSION = 1
#: Garages :func:`load_garage_set` paints from a map name when no ``n`` is given.
DEFAULT_PAINTED = 32
#: The training seed in a run name: ``<map>_s<seed>_<UTC stamp>_<digest>`` (the last ``_s<k>`` wins).
_RUN_SEED = re.compile(r"_s(\d+)(?=_|$)")
#: Keys of one garage in the set's JSON besides the grid (``GarageRecord.to_dict``'s grid form).
_ENTRY_KEYS = ("name", "hash", "difficulty", "mean_road_length", "mean_intersection_degree", "map")
#: The metrics a garage's JSON entry may state, each recomputed from its grid when the file is read
#: (:func:`~garage_mj.grid.metrics.evaluate`; equal within 1e-9, as a library row is checked).
_METRICS = ("coverage", "difficulty", "stalls", "mean_road_length", "mean_intersection_degree")


class GarageSetError(GarageMJError):
    """A garage set cannot be made (missing file, bad JSON, unknown map, nothing matches the filters)."""


def run_seed(run: str) -> int | None:
    """The training seed of a library run name (``m5_13x13_aligned_s3_20261123T232711_220ba8`` -> 3), or None."""
    found = _RUN_SEED.findall(run)
    return int(found[-1]) if found else None


def garage_map(source: CruiseSource) -> str:
    """The map a source's garage was painted on: its garage name up to ``#`` (library garages are ``map#id``)."""
    return source.garage.name.partition("#")[0]


@dataclass(frozen=True)
class GarageSet:
    """An ordered, immutable set of garages (CruiseSource) to train or test a driver on, and how it was made."""

    sources: tuple[CruiseSource, ...]
    origin: str  # one line: where the garages came from and how they were chosen

    def __post_init__(self) -> None:
        object.__setattr__(self, "sources", tuple(self.sources))
        bad = [type(s).__name__ for s in self.sources if not isinstance(s, CruiseSource)]
        if bad:
            raise TypeError(f"a GarageSet holds CruiseSource objects, not {bad[0]}")
        if "\n" in self.origin:
            raise ValueError("a GarageSet's origin is one line; remove the line breaks")

    def __len__(self) -> int:
        return len(self.sources)

    def __iter__(self) -> Iterator[CruiseSource]:
        return iter(self.sources)

    def __getitem__(self, index: int) -> CruiseSource:
        return self.sources[index]

    @property
    def hashes(self) -> tuple[str, ...]:
        """The canonical hash of each garage, in order."""
        return tuple(s.hash for s in self.sources)

    # -- constructors ------------------------------------------------------------------------------
    @classmethod
    def from_library(
        cls,
        path: str | Path,
        *,
        map: str | None = None,
        difficulty: tuple[float, float] | None = None,
        run_seeds: Iterable[int] | None = None,
        n: int | None = None,
        seed: int = 0,
        route: tuple[float, float] | None = None,
        route_model: RouteDifficulty | str | Path | None = None,
        exclude: Iterable[str] = (),
    ) -> GarageSet:
        """The garages of a library file that match every filter, sorted by library id.

        ``route`` is an inclusive range of the route difficulty under ``route_model`` (a model or its
        file; None: the shipped one), as ``garage-mj library rate`` stored it (garages not rated yet: a
        :class:`GarageSetError` that says to rate them).

        ``difficulty`` is an inclusive range; ``run_seeds`` keeps the garages whose run's training seed
        (the ``_s<k>`` of the run name, :func:`run_seed`) is one of them. ``n`` draws a seeded sample of
        ``n`` (all of them when fewer match), stratified by difficulty as ``garage-mj library sample``
        does (bins of :data:`~garage_mj.generation.library.DIFFICULTY_BIN`, spread evenly, so rare easy
        or hard garages are not drowned out); with no ``run_seeds`` it is exactly that command's sample.
        ``exclude`` holds garage hashes left out before the draw (for example the garages an earlier
        run already drove, so a new sample is disjoint from it).
        Each garage's grid is checked against its stored hash.
        """
        path = Path(path)
        if not path.is_file():
            why = "is a folder" if path.is_dir() else "does not exist"
            raise GarageSetError(f"library {path} {why}; pass a library.sqlite file (garage-mj train writes one)")
        if difficulty is not None:
            difficulty = _range(difficulty, "difficulty")
        key = None
        if route is not None:
            route = _range(route, "route difficulty")
            key = resolve_route_model(route_model).key
        seeds = None if run_seeds is None else sorted({int(s) for s in run_seeds})
        if seeds is not None and not seeds:
            raise GarageSetError("run_seeds is empty; give at least one training seed, or None for every run")
        _check_n(n)
        try:
            with Library(path, create=False) as lib:
                records = lib.query(map=map, difficulty=difficulty, route=route, route_model=key)
                if seeds is not None:
                    records = [r for r in records if run_seed(r.run) in seeds]
                excluded = frozenset(exclude)
                if excluded and records:
                    records = [r for r in records if r.hash not in excluded]
                    if not records:
                        raise GarageSetError(f"library {path}: every garage that matches the filters is among the "
                                             f"{len(excluded)} excluded; exclude fewer or loosen the filters")
                if not records:
                    raise GarageSetError(_no_match(lib, path, map, difficulty, seeds, route))
        except LibraryError as exc:
            raise GarageSetError(str(exc)) from None
        total = len(records)
        if n is not None and n < total:
            records = _stratified(records, n, seed)
        sources = tuple(CruiseSource.from_record(r) for r in records)
        for r, s in zip(records, sources):
            if s.hash != r.hash:
                raise GarageSetError(f"{path}, row id {r.id}: the grid does not match its stored hash; the row was "
                                     "altered after it was stored: delete it or restore the library from a backup")
        filters = [f"map={map}" if map is not None else "",
                   "runs=" + ",".join(f"s{s}" for s in seeds) if seeds is not None else "",
                   f"difficulty={difficulty[0]:g}-{difficulty[1]:g}" if difficulty is not None else "",
                   f"route_difficulty={route[0]:g}-{route[1]:g}@{key}" if route is not None else "",
                   f"excluding={len(excluded)}" if excluded else ""]
        drawn = (f"n={len(records)} of {total}, stratified by difficulty, seed {seed}" if len(records) < total
                 else f"all {total}")
        origin = " ".join(["library", str(path), *[f for f in filters if f], f"({drawn})"])
        return cls(sources, origin)

    @classmethod
    def from_packs(cls, folder: str | Path) -> GarageSet:
        """Every asset pack directly under ``folder`` (a folder holding ``manifest.json`` or ``garage.json``),
        sorted by folder name; each is verified by :func:`garage_mj.export.pack.load_pack`."""
        from garage_mj.export.pack import PackError  # the pack writers pull in the mesh libraries

        folder = Path(folder)
        if not folder.is_dir():
            why = "is a file" if folder.exists() else "does not exist"
            raise GarageSetError(f"pack folder {folder} {why}; pass the folder garage-mj export wrote the packs into")
        dirs = sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith(".")
                      and ((d / MANIFEST).exists() or (d / GARAGE_JSON).exists()))
        if not dirs:
            raise GarageSetError(f"{folder} holds no asset packs (folders with {MANIFEST}); "
                                 "export some with garage-mj export")
        try:
            sources = tuple(CruiseSource.from_pack(d) for d in dirs)
        except PackError as exc:
            raise GarageSetError(str(exc)) from None
        return cls(sources, f"packs {folder} (all {len(sources)})")

    @classmethod
    def from_map(cls, map: str, n: int, seed: int = 0) -> GarageSet:
        """``n`` garages of ``map`` painted by the scripted painter, spread evenly over difficulty
        (:func:`~garage_mj.driving.sources.painted_sources`), easiest first."""
        _check_n(n)
        try:
            load_map(map)
        except MapError as exc:
            raise GarageSetError(str(exc)) from None
        sources = painted_sources(map, n, seed)
        return cls(tuple(sources), f"painted map={map} (n={len(sources)}, seed {seed})")

    @classmethod
    def from_json(cls, path: str | Path) -> GarageSet:
        """Read what :meth:`to_json` writes, or the list ``garage-mj library export-json`` writes.

        Every garage's grid is checked against its stored hash, and the metrics the file states
        (difficulty, E[X], E[Y], and an export's coverage and stalls) are recomputed from the grid: a
        file whose stored metric differs is refused, naming the file and the garage.
        """
        path = Path(path)
        if not path.is_file():
            why = "is a folder" if path.is_dir() else "does not exist"
            raise GarageSetError(f"garage-set file {path} {why}; pass a file written by GarageSet.to_json or "
                                 "garage-mj library export-json")
        try:
            data = json.loads(path.read_bytes().decode("utf-8"))
        except (ValueError, UnicodeDecodeError, RecursionError) as exc:
            raise GarageSetError(f"{path} is not valid JSON ({str(exc)[:100]}); write it again with "
                                 "GarageSet.to_json or garage-mj library export-json") from None
        except OSError as exc:
            raise GarageSetError(f"cannot read {path}: {exc.strerror}; check its permissions") from None
        if isinstance(data, list):
            sources = tuple(_export_source(path, i, d) for i, d in enumerate(data))
            origin = f"json {path} (library export, all {len(sources)})"
        elif isinstance(data, dict) and data.get("format") == SET_FORMAT:
            if data.get("version") != SET_VERSION:
                raise GarageSetError(f"{path} is a garage set of version {data.get('version')!r}; this garage-mj "
                                     f"reads version {SET_VERSION}: write it again with this version")
            entries, origin = data.get("garages"), data.get("origin")
            if not isinstance(entries, list) or not isinstance(origin, str):
                raise GarageSetError(f"{path}: a garage set needs 'garages' (a list) and 'origin' (a string); "
                                     "write it again with GarageSet.to_json")
            sources = tuple(_set_source(path, i, d) for i, d in enumerate(entries))
            origin = origin.replace("\n", " ")
        else:
            raise GarageSetError(f"{path} is neither a garage set (an object with format {SET_FORMAT!r}) nor a "
                                 "garage-mj library export-json list; pass one of those")
        if not sources:
            raise GarageSetError(f"{path} holds no garages; pass a set with at least one")
        return cls(sources, origin)

    # -- writing -----------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON :meth:`to_json` writes: origin, then per garage its name, hash, metrics, map, pack and
        grid (``grid``, ``initial``, ``six_stall_axis`` as in a library record, plus the garage's own name)."""
        garages = []
        for s in self.sources:
            g = s.garage
            garages.append({
                "name": s.name, "hash": s.hash, "difficulty": s.difficulty, "mean_road_length": s.mean_road_length,
                "mean_intersection_degree": s.mean_intersection_degree, "map": garage_map(s), "pack": s.pack,
                "garage_name": g.name, "grid": g.grid.tolist(), "initial": g.initial.tolist(),
                "six_stall_axis": g.six_stall_axis,
            })
        return {"format": SET_FORMAT, "version": SET_VERSION, "origin": self.origin, "count": len(garages),
                "garages": garages}

    def to_json(self, path: str | Path) -> None:
        """Write the set to ``path`` atomically (:meth:`from_json` reads it back, same hashes and metrics)."""
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_json(path, self.to_dict(), indent=1)
        except OSError as exc:
            raise write_error(path, exc) from None

    # -- derived sets ------------------------------------------------------------------------------
    def by_difficulty(self) -> GarageSet:
        """The same garages, easiest first (ties by name): the order of a difficulty curriculum."""
        order = sorted(self.sources, key=lambda s: (s.difficulty, s.name))
        return GarageSet(tuple(order), f"{self.origin}, by difficulty")

    def split(self, fraction: float, seed: int) -> tuple[GarageSet, GarageSet]:
        """A seeded split into two disjoint sets (train, validation): the first holds ``round(fraction * len)``
        garages (at least one, and at least one is left for the second); both keep this set's order."""
        if not (isinstance(fraction, (int, float)) and 0.0 < fraction < 1.0):
            raise GarageSetError(f"split fraction {fraction!r} is not between 0 and 1; give e.g. 0.8 for 80% / 20%")
        if len(self) < 2:
            raise GarageSetError(f"cannot split a set of {len(self)} garage(s) in two; make a larger set ({self.origin})")
        k = min(max(round(fraction * len(self)), 1), len(self) - 1)
        first = set(np.random.default_rng(seed).permutation(len(self))[:k].tolist())
        a = tuple(s for i, s in enumerate(self.sources) if i in first)
        b = tuple(s for i, s in enumerate(self.sources) if i not in first)
        tag = f"split {fraction:g} seed {seed}"
        return (GarageSet(a, f"{self.origin}, {tag}: first {len(a)} of {len(self)}"),
                GarageSet(b, f"{self.origin}, {tag}: second {len(b)} of {len(self)}"))

    def drivable(self, car: CarGeometry | None = None, progress: bool = False, *,
                 config: DriveConfig | None = None) -> GarageSet:
        """The garages where at least one stall has a feasible planned drive for ``car`` (default: the
        shipped car) under ``config`` (default ``DriveConfig()``), the test the drive env makes before it
        will drive a garage (:mod:`garage_mj.scene.drivable`). A progress bar on stderr when ``progress``."""
        from tqdm import tqdm

        from garage_mj.scene.drivable import DriveConfig, drive_planner  # the scene pulls in networkx
        from garage_mj.scene.garage_scene import GarageScene

        config = config or DriveConfig()
        kept = []
        for s in tqdm(self.sources, desc="drivable", unit="garage", disable=not progress, file=sys.stderr):
            scene = GarageScene(s.garage)
            planner = drive_planner(scene, car, config)
            if any(planner.plan(stall.id).feasible for stall in scene.stalls.stalls):
                kept.append(s)
        if not kept:
            raise GarageSetError(f"none of the {len(self)} garage(s) of {self.origin} has a stall with a feasible "
                                 "drive for this car; check the car's steering, or pick other garages")
        return GarageSet(tuple(kept), f"{self.origin}, drivable ({len(kept)} of {len(self)})")


def load_garage_set(
    spec: str | Path,
    *,
    map: str | None = None,
    difficulty: tuple[float, float] | None = None,
    run_seeds: Iterable[int] | None = None,
    n: int | None = None,
    seed: int = 0,
) -> GarageSet:
    """The garage set ``spec`` names: a library file (``.sqlite``, or any garage-mj library file), a ``.json``
    set or library export, a folder of asset packs, or a shipped map name (painted: ``n`` garages,
    default :data:`DEFAULT_PAINTED`, drawn with ``seed``). ``map``, ``difficulty``, ``run_seeds`` and ``n``
    filter a library; a JSON file or a pack folder takes none of them.
    """
    text = str(spec)
    path = Path(spec)
    given = {k: v for k, v in (("map", map), ("difficulty", difficulty), ("run_seeds", run_seeds), ("n", n))
             if v is not None}

    def refuse(what: str, allowed: tuple[str, ...]) -> None:
        extra = [k for k in given if k not in allowed]
        if extra:
            raise GarageSetError(f"{text} is {what}: {', '.join(extra)} apply only to a library (.sqlite); "
                                 "drop them or pass a library")

    if path.is_dir():
        refuse("a folder of asset packs", ())
        return GarageSet.from_packs(path)
    if path.suffix == ".json":
        refuse("a JSON garage set", ())
        return GarageSet.from_json(path)
    if path.suffix == ".sqlite" or is_sqlite_file(path):
        return GarageSet.from_library(path, map=map, difficulty=difficulty, run_seeds=run_seeds, n=n, seed=seed)
    shipped = [m.name for m in list_maps()]
    if text in shipped:
        refuse("a shipped map (painted garages)", ("n",))
        return GarageSet.from_map(text, DEFAULT_PAINTED if n is None else n, seed)
    if path.exists():
        raise GarageSetError(f"{text} is neither a library (.sqlite) nor a garage-set JSON (.json); pass one of "
                             "those, a folder of asset packs, or a shipped map name")
    raise GarageSetError(f"no garage set at {text!r}: not a file or folder, nor a shipped map "
                         f"({', '.join(shipped)}); check the path or the map name")


# -- helpers -------------------------------------------------------------------------------------------
def _check_n(n: int | None) -> None:
    if n is not None and (isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1):
        raise GarageSetError(f"n={n!r}: give a whole number of garages >= 1 (or None for all)")


def _range(rng: tuple[float, float], what: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in rng)
    except (TypeError, ValueError):
        raise GarageSetError(f"{what} {rng!r} is not a range; give (LO, HI), e.g. (0.3, 0.9)") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise GarageSetError(f"{what} range ({lo:g}, {hi:g}) is empty; give LO <= HI")
    return lo, hi


def is_sqlite_file(path: Path) -> bool:
    """Whether ``path`` is a file that starts as an SQLite database (a library, whatever its suffix)."""
    if not path.is_file():
        return False
    try:
        with path.open("rb") as f:
            return f.read(16) == b"SQLite format 3\x00"
    except OSError:
        return False


def _no_match(lib: Library, path: Path, map: str | None, difficulty: tuple[float, float] | None,
              seeds: list[int] | None, route: tuple[float, float] | None = None) -> str:
    """One line: which filters left nothing, and what the library holds."""
    asked = [f"map={map}" if map is not None else "",
             f"difficulty {difficulty[0]:g}-{difficulty[1]:g}" if difficulty is not None else "",
             f"route difficulty {route[0]:g}-{route[1]:g}" if route is not None else "",
             "run seeds " + ",".join(str(s) for s in seeds) if seeds is not None else ""]
    asked = [a for a in asked if a]
    if not asked:
        return f"library {path} holds no garages; train first (garage-mj train)"
    maps = lib.maps()
    holds = f"it holds maps {', '.join(maps) or 'none'}"
    if seeds is not None and (map is None or map in maps):
        runs = sorted({run_seed(r.run) for r in lib.query(map=map)} - {None})
        holds += f" and run seeds {','.join(str(s) for s in runs) or 'none'}" + (f" for {map}" if map else "")
    return f"no garages in {path} match {', '.join(asked)}; {holds}: loosen the filters"


def _stratified(records: list[GarageRecord], n: int, seed: int) -> list[GarageRecord]:
    """``n`` of ``records`` (sorted by id) drawn as :meth:`Library.sample` draws them, sorted by id."""
    by_id = {r.id: r for r in records}
    chosen = stratified_ids([(r.id, r.difficulty) for r in records], n, np.random.default_rng(seed))
    return [by_id[i] for i in sorted(chosen)]


def _entry_garage(path: Path, i: int, d: Any, name: str) -> Garage:
    """Garage ``i`` of a JSON file, its grid checked against its ``hash``."""
    where = f"{path}, garage {i}"
    if not isinstance(d, dict):
        raise GarageSetError(f"{where} is not an object; write the file again with GarageSet.to_json")
    try:
        garage = Garage.from_json({"name": name, "grid": d.get("grid"), "initial": d.get("initial"),
                                   "six_stall_axis": d.get("six_stall_axis", "NS")}, source=where)
    except MapError as exc:
        raise GarageSetError(f"{exc}; write the file again with GarageSet.to_json") from None
    if d.get("hash") is not None and garage.canonical_hash() != d["hash"]:
        raise GarageSetError(f"{where} ({name}): the grid does not match its hash; the file was altered: "
                             "write it again")
    return garage


def _number(path: Path, i: int, d: dict, key: str) -> float:
    v = d.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise GarageSetError(f"{path}, garage {i}: {key} is {str(v)[:30]!r}, not a number; write the file again")
    return float(v)


def _check_metrics(path: Path, i: int, name: str, garage: Garage, d: dict, fix: str) -> None:
    """Refuse garage ``i`` when a metric its entry states is not the one its grid gives (the file was altered)."""
    m = evaluate(garage)
    for key in _METRICS:
        if key in d:
            v = _number(path, i, d, key)
            if not math.isclose(v, getattr(m, key), rel_tol=1e-9, abs_tol=1e-9):
                raise GarageSetError(f"{path}, garage {i} ({name}): stored {key} {v:g} is not the grid's "
                                     f"({getattr(m, key):g}); the file was altered: {fix}")


def _set_source(path: Path, i: int, d: Any) -> CruiseSource:
    """Garage ``i`` of a file :meth:`GarageSet.to_json` wrote."""
    if not isinstance(d, dict) or any(k not in d for k in _ENTRY_KEYS):
        missing = [k for k in _ENTRY_KEYS if not isinstance(d, dict) or k not in d]
        raise GarageSetError(f"{path}, garage {i}: missing {', '.join(missing)}; write the file again with "
                             "GarageSet.to_json")
    name, gname, pack = d["name"], d.get("garage_name", d["map"]), d.get("pack", "")
    if not all(isinstance(v, str) for v in (name, gname, pack)):
        raise GarageSetError(f"{path}, garage {i}: name, garage_name and pack must be strings; write the file again")
    garage = _entry_garage(path, i, d, gname)
    _check_metrics(path, i, name, garage, d, "write the file again with GarageSet.to_json")
    return CruiseSource(name, garage, *(_number(path, i, d, k) for k in _ENTRY_KEYS[2:5]), pack=pack)


def _export_source(path: Path, i: int, d: Any) -> CruiseSource:
    """Record ``i`` of a ``garage-mj library export-json`` list (named ``map#id`` as from the library)."""
    if not isinstance(d, dict) or not isinstance(d.get("map"), str) or isinstance(d.get("id"), bool) \
            or not isinstance(d.get("id"), int):
        raise GarageSetError(f"{path}, garage {i}: not a library record (needs map and id); export it again with "
                             "garage-mj library export-json")
    name = f"{d['map']}#{d['id']}"
    garage = _entry_garage(path, i, d, name)
    _check_metrics(path, i, name, garage, d, "export it again with garage-mj library export-json")
    return CruiseSource(name, garage, *(_number(path, i, d, k) for k in _ENTRY_KEYS[2:5]))
