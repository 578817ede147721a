"""The garages a user's tests run on, made deterministically, and what a ``garages`` argument may name.

The pytest plugin's fixtures hand these out: :func:`tiny_garage` (``tiny_7x11`` painted by the
scripted painter, no training), :func:`painted_garages` (a few distinct garages of a map),
:func:`write_library` (an SQLite scenario library of them) and :func:`write_packs` (their asset
packs). :func:`cruise_sources` turns what a test names into the garages a cruise run tests: a map
name or map file (painted garages of it), an asset pack folder or a folder of packs, a library file
(every garage in it, verified), a :class:`~garage_mj.grid.garage.Garage`, a library record or a
:class:`~garage_mj.driving.sources.CruiseSource`.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from garage_mj.core.errors import GarageMJError
from garage_mj.driving.garage_set import is_sqlite_file, load_garage_set
from garage_mj.driving.sources import CruiseSource, painted_sources
from garage_mj.export.artefacts import MANIFEST
from garage_mj.generation.library import Library
from garage_mj.generation.library_format import GarageRecord
from garage_mj.grid.garage import Garage


class GarageChoiceError(GarageMJError, ValueError):
    """A ``garages`` or ``per_map`` argument that names no garage to test; the message says what to give."""


#: The most painted garages per map a call may ask for (each paints a dozen candidates).
MAX_PER_MAP = 1000

TINY_MAP = "tiny_7x11"
TINY_SEED = 1  # the painter's seed of the tiny_7x11 fixture (the project's own tests paint the same garage)
LIBRARY_GARAGES = 3  # garages in the library fixture (and the packs fixture)
LIBRARY_RUN = "pytest"  # the library's provenance column for the garages written here


def tiny_garage(seed: int = TINY_SEED) -> Garage:
    """``tiny_7x11`` painted by the scripted painter with ``seed``: usable, the same every run."""
    from garage_mj.grid.painters import paint_garage  # gymnasium

    return paint_garage(TINY_MAP, seed=seed)


def painted_garages(map: str = TINY_MAP, count: int = LIBRARY_GARAGES, seed: int = 0) -> list[Garage]:
    """``count`` distinct usable garages of ``map`` (a shipped map's name or a map file), spread over
    difficulty (:func:`garage_mj.driving.sources.painted_sources`)."""
    return [s.garage for s in painted_sources(map, count, seed)]


def write_library(path: str | Path, garages: Iterable[Garage]) -> Path:
    """An SQLite scenario library at ``path`` holding ``garages`` (run :data:`LIBRARY_RUN`, seed = position)."""
    path = Path(path)
    with Library(path) as lib:
        for k, g in enumerate(garages):
            lib.add(g, map=g.name or "garage", run=LIBRARY_RUN, seed=k, episode=0, timestep=0)
    return path


def write_packs(garages: Iterable[Garage], out_dir: str | Path) -> Path:
    """Asset packs of ``garages`` in ``out_dir`` (one folder each and ``index.json``); returns ``out_dir``."""
    from garage_mj.export.pack import export_packs  # MuJoCo, trimesh

    export_packs(list(garages), out_dir, progress=False)
    return Path(out_dir)


def _from_path(path: Path) -> list[CruiseSource]:
    """The garages of one asset pack folder, or what :func:`~garage_mj.driving.garage_set.load_garage_set` reads
    (a folder of packs, a library file: every garage, verified)."""
    if path.is_dir() and (path / MANIFEST).is_file():
        return [CruiseSource.from_pack(path)]
    return list(load_garage_set(path))


def _sources_of(item: Any, per_map: int, seed: int) -> list[CruiseSource]:
    if isinstance(item, CruiseSource):
        return [item]
    if isinstance(item, Garage):
        return [CruiseSource.from_garage(item)]
    if isinstance(item, GarageRecord):
        return [CruiseSource.from_record(item)]
    if isinstance(item, (str, Path)):
        path = Path(item)
        if path.is_dir() or is_sqlite_file(path):
            return _from_path(path)
        return painted_sources(str(item), per_map, seed)  # a map name or map file; MapError names a bad one
    raise GarageChoiceError(f"garages: cannot test {type(item).__name__} {item!r}; give map names, map files, pack "
                            "folders, a library file, Garage objects or library records")


def cruise_sources(garages: Any, per_map: int = 1, seed: int = 0) -> list[CruiseSource]:
    """The garages a cruise run tests, from one item or a list of items (see the module docstring).

    A map gives ``per_map`` painted garages of it (drawn with ``seed``, spread over difficulty).
    """
    if isinstance(per_map, bool) or not isinstance(per_map, numbers.Integral) or not 1 <= per_map <= MAX_PER_MAP:
        raise GarageChoiceError(f"per_map must be an integer from 1 to {MAX_PER_MAP:,}, got {per_map!r}")
    single = (str, Path, Garage, CruiseSource, GarageRecord)
    if not isinstance(garages, single) and not isinstance(garages, Iterable):
        raise GarageChoiceError(f"garages: cannot test {type(garages).__name__} {garages!r}; give map names, map "
                                "files, pack folders, a library file, Garage objects or library records")
    items: Sequence[Any] = [garages] if isinstance(garages, single) else list(garages)
    if not items:
        raise GarageChoiceError("garages: the list is empty; name at least one map, pack or garage")
    return [s for item in items for s in _sources_of(item, per_map, seed)]
