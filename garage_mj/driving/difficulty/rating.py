"""The route difficulty of many garages, computed once each and kept: a library's, and a cruise run's.

:func:`rate_library` (``garage-mj library rate``) computes the route difficulty
(:func:`garage_mj.scene.route_difficulty.route_difficulty`) of every garage of a library not rated
under a model yet and stores each value as it comes (:meth:`Library.set_route_difficulty`, the
library's ``route_difficulty`` side table), over a process pool
(:func:`garage_mj.core.backends.map_unordered`): a kill loses only the garages in flight, a re-run
rates the rest, and the values do not depend on the worker count (the computation has no randomness).

:func:`cruise_route_difficulty` gives a cruise run the route difficulty of its garages for
``summary.csv``: computed in the parent once per garage and kept in the run folder
(``route_difficulty.json``, per model key and garage hash, each value with its checksum), so a
re-run reads it back (and in memory, so the many runs of one process compute each garage once).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from garage_mj.core.backends import DEFAULT_COMPUTE, Compute, map_unordered
from garage_mj.core.fsutil import write_json
from garage_mj.generation.library import Library
from garage_mj.generation.library_format import route_checksum
from garage_mj.scene.route_difficulty import (
    SHIPPED_MODELS,
    RouteDifficulty,
    load_route_model,
    route_difficulty,
)

if TYPE_CHECKING:
    from garage_mj.driving.sources import CruiseSource
    from garage_mj.grid.garage import Garage

#: (model key, garage hash) -> route difficulty computed in this process (a hunt or a test session runs many
#: cruise runs on the same garages).
_MEMO: dict[tuple[str, str], float] = {}
#: A cruise run's cache of its garages' route difficulty, beside ``summary.csv``.
CACHE_FILE = "route_difficulty.json"
CACHE_FORMAT = "garage-mj route difficulty cache"


def resolve_route_model(model: RouteDifficulty | str | Path | None = None) -> RouteDifficulty:
    """``model`` itself, the model file it names, or the shipped model when None."""
    return model if isinstance(model, RouteDifficulty) else load_route_model(model)


@dataclass(frozen=True)
class RouteModelChoice:
    """The route difficulty model of a cruise run, the name it goes by and what it was fitted for; or, with
    ``model`` None, why the run has no route difficulty (``note``)."""

    model: RouteDifficulty | None
    name: str | None = None  # a shipped model's name ("route", "learned"), a model file, or "given"
    note: str | None = None

    def record(self, rated: bool) -> dict[str, Any]:
        """What ``summary.json`` says of the route difficulty (``rated``: whether any garage got one)."""
        if self.model is None or not rated:
            return {"route_model": None, "route_model_name": None, "route_model_fitted_for": None,
                    "route_note": self.note}
        return {"route_model": self.model.key, "route_model_name": self.name,
                "route_model_fitted_for": fitted_for(self.model), "route_note": self.note}


def fitted_for(model: RouteDifficulty) -> dict[str, list[str]]:
    """The drivers and action types ``model`` was fitted on (its ``fit`` metadata; empty lists when it does
    not say, as a model fitted by an older garage-mj)."""
    return {"drivers": list(model.fit.get("drivers", [])), "action_types": list(model.fit.get("action_types", []))}


def choose_route_model(route_model: RouteDifficulty | str | Path | bool | None, driver: Any, action_type: str,
                       driver_kwargs: dict[str, Any] | None = None) -> RouteModelChoice:
    """The route difficulty model of a cruise run of ``driver`` with ``action_type`` actions.

    ``route_model`` True or None: the shipped model fitted on that driver with that action type (``"learned"``
    for the shipped learned driver with its discrete actions, ``"route"`` for ``vision`` and ``waypoint`` with
    discrete ones), or none when no shipped model was fitted for them: its failure rate would not be this
    driver's (``vision`` with its own continuous actions succeeds where the default model reads 0.8). Drivers
    fail for different reasons: on fresh garages the learned driver's success and ``vision``'s are
    uncorrelated (r -0.05), so no one difficulty predicts both (``docs/route_difficulty/fresh.json``).
    A model, a model file or a shipped model's name: that one, whatever it was fitted on. False: none.
    """
    if route_model is False:
        return RouteModelChoice(None, note="no route difficulty asked for")
    if route_model is not True and route_model is not None:
        name = "given" if isinstance(route_model, RouteDifficulty) else str(route_model)
        return RouteModelChoice(resolve_route_model(route_model), name)
    own = None if (driver_kwargs or {}).get("model") else driver  # another learned model is not the shipped one
    for name in SHIPPED_MODELS:
        model = load_route_model(name)
        fit = fitted_for(model)
        if own in fit["drivers"] and action_type in fit["action_types"]:
            return RouteModelChoice(model, name)
    shipped = "; ".join(f"{n}: {', '.join(f['drivers'])} with {' or '.join(f['action_types'])} actions"
                        for n, f in ((n, fitted_for(load_route_model(n))) for n in SHIPPED_MODELS))
    return RouteModelChoice(None, note=f"no route difficulty: no shipped route model was fitted on driver {driver!r} "
                                       f"with {action_type} actions ({shipped}); give --route-model FILE "
                                       "(garage-mj difficulty fit) to use one")


def _rate(job: tuple[int, Garage, RouteDifficulty]) -> tuple[int, float]:
    """One garage's route difficulty, in a worker: (library id, value; NaN without a feasible stall)."""
    id_, garage, model = job
    return id_, route_difficulty(garage, model)


@dataclass(frozen=True)
class RatingResult:
    """What :func:`rate_library` did."""

    model_key: str
    rated: int  # garages rated by this call
    left: int  # garages (of the map) still without a value under the model (a --limit left them)
    seconds: float  # wall time of the rating
    workers: int

    @property
    def seconds_per_garage(self) -> float | None:
        return self.seconds / self.rated if self.rated else None


def rate_library(path: str | Path, model: RouteDifficulty | str | Path | None = None, map: str | None = None, *,
                 limit: int | None = None, compute: Compute = DEFAULT_COMPUTE) -> RatingResult:
    """Rate every garage of the library ``path`` (of ``map``; at most ``limit``) not rated under ``model``.

    ``model``: a :class:`RouteDifficulty`, a model file, or None for the shipped one. ``compute``: the
    workers that rate and the progress bar (the values do not depend on it). Each value is stored as
    its garage ends (the library's own short transaction), so the rating is resumable. Each row is
    first checked against its hash and metrics (:meth:`Library.verified`): an altered row is a
    :class:`LibraryError` naming its id, and nothing is stored.
    """
    from tqdm import tqdm

    m = resolve_route_model(model)
    key = m.key
    with Library(path, create=False, readonly=False) as lib:
        ids = lib.unrated(key, map=map, limit=limit)
        # each row checked against its hash and metrics first (as export and cruise do): an altered row is
        # refused, naming its id, before any value is stored
        jobs = [(r.id, r.garage, m) for r in lib.verified([lib.get(i) for i in ids])]
        start = time.perf_counter()
        with tqdm(total=len(jobs), desc="route difficulty", unit="garage", disable=not compute.progress) as bar:
            for id_, value in map_unordered(_rate, jobs, compute=compute):
                lib.set_route_difficulty(id_, key, value)
                bar.update()
        seconds = time.perf_counter() - start
        left = len(lib.unrated(key, map=map))
    return RatingResult(key, len(jobs), left, seconds, compute.workers)


# -- a cruise run's garages -----------------------------------------------------------------------------
def _read_cache(path: Path) -> dict[str, dict[str, Any]]:
    """model key -> {garage hash: [value or None, checksum]}; an unreadable or foreign file is treated as empty."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return {}
    if not isinstance(data, dict) or data.get("format") != CACHE_FORMAT or not isinstance(data.get("models"), dict):
        return {}
    return {k: v for k, v in data["models"].items() if isinstance(v, dict)}


def _cached(entry: Any, model_key: str, garage_hash: str) -> float | None | str:
    """The value of a cache entry ``[value, checksum]`` (None: no feasible stall), or ``"missing"`` when the
    entry is absent, not of that form, or its checksum is not that of (garage hash, model key, value)."""
    if not isinstance(entry, list) or len(entry) != 2:
        return "missing"
    v, check = entry
    if isinstance(v, bool) or not (v is None or isinstance(v, float)) or check != route_checksum(garage_hash, model_key, v):
        return "missing"
    return v


def cruise_route_difficulty(out_dir: str | Path, sources: Sequence[CruiseSource],
                            model: RouteDifficulty | str | Path | None = None) -> dict[str, float]:
    """garage hash -> route difficulty under ``model`` (NaN: no feasible stall) of every source; values
    not in the run folder's ``route_difficulty.json`` yet are computed here and added to it.

    Each value is kept with its checksum over (garage hash, model key, value)
    (:func:`~garage_mj.generation.library_format.route_checksum`, as a library stores it): a value
    edited by hand does not match and is computed again."""
    m = resolve_route_model(model)
    path = Path(out_dir) / CACHE_FILE
    cache = _read_cache(path)
    mine = cache.setdefault(m.key, {})
    out: dict[str, float] = {}
    new = False
    for s in sources:
        v = _cached(mine.get(s.hash), m.key, s.hash)
        if v == "missing":
            value = _MEMO.get((m.key, s.hash))
            if value is None:
                value = _MEMO[(m.key, s.hash)] = route_difficulty(s.garage, m)
            v = None if math.isnan(value) else round(value, 6)
            mine[s.hash] = [v, route_checksum(s.hash, m.key, v)]
            new = True
        out[s.hash] = math.nan if v is None else float(v)
    if new:
        write_json(path, {"format": CACHE_FORMAT, "models": cache}, indent=1, sort_keys=True)
    return out
