"""The park difficulty: how likely a park or AVP test is to fail for a driver, from what is known before the drive.

A :class:`ParkDifficulty` is the route difficulty's model (:class:`~garage_mj.scene.route_difficulty.RouteDifficulty`:
a logistic regression on standardized features with every weight >= 0, fitted by the same
:func:`~garage_mj.scene.route_difficulty.fit`) on the park features of a test's ``tests.csv`` row
(:data:`PARK_FEATURES`, :func:`park_features`), each oriented so that larger is harder: a tighter bay, a narrower
aisle, a tighter, longer plan with more cusps, a farther start, an angled or a parallel stall, a reverse maneuver,
more actors, more pedestrians crossing behind the stall or walking beside it, more jitter of the parked cars. A test's
park difficulty is its fitted failure probability, in [0, 1]. A model reads only the features it was fitted on.

Its file has a format of its own (:data:`FORMAT`): a route model is never read as a park model, nor the other way.
The shipped ones are in ``models/difficulty`` (:data:`SHIPPED_PARK_MODELS`, per driver, each fitted on the park tests
of its driver by ``eval/park_difficulty.py``: ``park_assist.json``, also the default for a driver without one of its
own, and ``learned_park.json``, the shipped learned parking driver's).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from garage_mj.core.errors import GarageMJError
from garage_mj.scene.route_difficulty import L2, RouteDifficulty, fit

FORMAT = "garage-mj park difficulty"
VERSION = 1
#: The shipped park models by name (``--park-model park_assist``), each fitted on the driver of its name; the
#: first is the default of a driver without one of its own.
SHIPPED_PARK_MODELS = {"park_assist": "park_assist.json", "learned_park": "learned_park.json"}
DEFAULT_PARK_MODEL = "park_assist"
FIT_COMMAND = "garage-mj difficulty fit --task park"
PLAN_CLEAR_CAP = 3.0  # [m] a plan's clearance counts up to this: farther obstacles make no test harder


def _cell(row: Mapping[str, Any], column: str) -> float:
    value = row.get(column, "")
    if value is None or value == "":
        raise KeyError(column)
    return float(value)


def _plan_clearance(row: Mapping[str, Any]) -> float:
    """The plan's least clearance, at most :data:`PLAN_CLEAR_CAP`: a plan with nothing near it (an infinite clearance,
    an empty cell beside a plan length) reads as the cap."""
    _cell(row, "plan_length_m")  # no plan: no feature
    value = row.get("plan_clearance_m", "")
    return PLAN_CLEAR_CAP if value is None or value == "" else min(float(value), PLAN_CLEAR_CAP)


def _angle(row: Mapping[str, Any]) -> float:
    return _cell(row, "stall_angle_deg")


def _actors(row: Mapping[str, Any]) -> float:
    return sum(_cell(row, c) for c in ("pedestrians", "moving_cars", "clutter"))


#: feature -> (what it is, how it is read from a ``tests.csv`` row); each oriented larger = harder.
PARK_FEATURE_TABLE = {
    "tight_bay": ("the room the stall leaves across the car, negated (-bay_margin_m)",
                  lambda r: -_cell(r, "bay_margin_m")),
    "narrow_aisle": ("the aisle's width, negated (-aisle_width_m)", lambda r: -_cell(r, "aisle_width_m")),
    "tight_plan": ("the reference plan's least clearance up to 3 m, negated (-plan_clearance_m)",
                   lambda r: -_plan_clearance(r)),
    "cusps": ("the reference plan's direction changes (plan_cusps)", lambda r: _cell(r, "plan_cusps")),
    "plan_length": ("the reference plan's length [m] (plan_length_m)", lambda r: _cell(r, "plan_length_m")),
    "start_distance": ("the start's straight-line distance to the stall [m] (start_distance_m)",
                       lambda r: _cell(r, "start_distance_m")),
    "angled": ("1 for an angled stall (neither 90 nor 0 degrees)",
               lambda r: float(_angle(r) not in (0.0, 90.0))),
    "parallel": ("1 for a parallel slot (0 degrees)", lambda r: float(_angle(r) == 0.0)),
    "reverse": ("1 for a reverse-in maneuver", lambda r: float(str(r.get("maneuver", "")) == "reverse")),
    "actors": ("pedestrians + moving cars + clutter", _actors),
    "behind_stall": ("pedestrians that cross behind the stall (pedestrians_behind)",
                     lambda r: _cell(r, "pedestrians_behind")),
    "beside_stall": ("pedestrians that walk beside the stall (pedestrians_beside)",
                     lambda r: _cell(r, "pedestrians_beside")),
    "jitter": ("the parked cars' jitter bound [m] (parked_jitter_m)", lambda r: _cell(r, "parked_jitter_m")),
    "mixed_fleet": ("1 for a mixed parked fleet", lambda r: float(str(r.get("parked_fleet", "")) == "mixed")),
}
PARK_FEATURES = tuple(PARK_FEATURE_TABLE)
#: HOPE's levels as a number, the predictor the park difficulty is scored against.
LEVEL_RANK = {"normal": 0, "complex": 1, "extreme": 2}


class ParkModelError(GarageMJError):
    """A park difficulty model file is missing, unreadable or not one this version reads."""


class ParkFeatureError(GarageMJError):
    """A test's row lacks a cell a park feature is read from (a cruise row, or a run of an older garage-mj)."""


def park_features(row: Mapping[str, Any], features: Sequence[str] = PARK_FEATURES) -> dict[str, float]:
    """The ``features`` (default: every one of :data:`PARK_FEATURES`) of a park or AVP test's row (cells as
    ``tests.csv`` holds them, text or numbers); a :class:`ParkFeatureError` naming the empty or missing column (a run
    of an older garage-mj lacks the pedestrians' behaviours: a model without them still rates its rows)."""
    out = {}
    for name in features:
        read = PARK_FEATURE_TABLE[name][1]
        try:
            out[name] = read(row)
        except KeyError as exc:
            raise ParkFeatureError(f"column {exc.args[0]} is empty") from None
        except ValueError:
            raise ParkFeatureError(f"a column of feature {name} is not a number") from None
    return out


@dataclass(frozen=True)
class ParkDifficulty(RouteDifficulty):
    """A fitted park difficulty: the route difficulty's logistic model on :data:`PARK_FEATURES`, saved as a park model."""

    @property
    def key(self) -> str:
        """12 hex digits naming the fitted parameters (and that it is a park model)."""
        params = [FORMAT, list(self.features), list(self.mean), list(self.scale), list(self.weights), self.intercept]
        return hashlib.sha256(json.dumps(params).encode()).hexdigest()[:12]

    def of_row(self, row: Mapping[str, Any]) -> float:
        """The park difficulty of one test's row (a :class:`ParkFeatureError` where a feature's cell is empty)."""
        return float(self.test_probability(park_features(row, self.features)))

    def describe(self) -> str:
        """The formula and its weights, one feature a line, largest weight first."""
        return super().describe().replace("route difficulty", "park difficulty", 1)

    def to_dict(self) -> dict[str, Any]:
        return {**super().to_dict(), "format": FORMAT, "version": VERSION}


def fit_park(rows: Sequence[Mapping[str, float]], failed: Sequence[bool], features: Sequence[str] = PARK_FEATURES,
             l2: float = L2, info: dict[str, Any] | None = None) -> ParkDifficulty:
    """Fit a park difficulty on per-test feature rows (:func:`park_features`) and whether each test failed
    (:func:`~garage_mj.scene.route_difficulty.fit`: weights >= 0, a fixed L2 penalty; a ``ValueError`` on too
    few tests or one outcome alone)."""
    unknown = [f for f in features if f not in PARK_FEATURES]
    if unknown:
        raise ValueError(f"unknown park features {unknown}; choose among {', '.join(PARK_FEATURES)}")
    m = fit(rows, failed, features, l2, info)  # type: ignore[arg-type]
    return ParkDifficulty(m.features, m.mean, m.scale, m.weights, m.intercept, m.fit)


def load_park_model(path: str | Path | None = None) -> ParkDifficulty:
    """The model in ``path`` (a file of :meth:`ParkDifficulty.save`), the default shipped one when None, or a
    shipped one by its name in :data:`SHIPPED_PARK_MODELS` (when no file of that name exists)."""
    name = DEFAULT_PARK_MODEL if path is None else (
        str(path) if str(path) in SHIPPED_PARK_MODELS and not Path(path).exists() else None)
    if name is not None:
        ref = resources.files("garage_mj.models") / "difficulty" / SHIPPED_PARK_MODELS[name]
        where = f"the shipped park difficulty model {name!r}"
        try:
            text = ref.read_text()
        except OSError:
            raise ParkModelError(f"{where} is missing from this installation (models/difficulty/"
                                 f"{SHIPPED_PARK_MODELS[name]}); reinstall garage-mj or give a model file") from None
    else:
        p = Path(path)  # type: ignore[arg-type]
        if not p.is_file():
            raise ParkModelError(f"park difficulty model {p} does not exist; fit one with {FIT_COMMAND} "
                                 f"or name a shipped one ({', '.join(SHIPPED_PARK_MODELS)})")
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ParkModelError(f"cannot read park difficulty model {p} ({exc}); fit it again") from None
        where = str(p)
    try:
        d = json.loads(text)
    except ValueError:
        raise ParkModelError(f"{where} is not valid JSON; fit it again with {FIT_COMMAND}") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        what = " (it is a route difficulty model)" if isinstance(d, dict) and "route" in str(d.get("format")) else ""
        raise ParkModelError(f"{where} is not a park difficulty model{what}; fit one with {FIT_COMMAND}")
    if d.get("version") != VERSION:
        raise ParkModelError(f"{where} is version {d.get('version')!r}; this garage-mj reads version {VERSION}: "
                             "fit it again")
    try:
        feats = tuple(str(f) for f in d["features"])
        vals = [tuple(float(v) for v in d[k]) for k in ("mean", "scale", "weights")]
        intercept = float(d["intercept"])
    except (KeyError, TypeError, ValueError):
        raise ParkModelError(f"{where} is damaged (features, mean, scale, weights, intercept); fit it again") from None
    unknown = [f for f in feats if f not in PARK_FEATURES]
    numbers = [*vals[0], *vals[1], *vals[2], intercept]
    if not feats or unknown or any(len(v) != len(feats) for v in vals) or not all(map(math.isfinite, numbers)) \
            or any(s <= 0 for s in vals[1]) or any(w < 0 for w in vals[2]):
        why = f"unknown park features {unknown}" if unknown else "no features, a length, a NaN, a scale <= 0 or a " \
                                                                 "negative weight"
        raise ParkModelError(f"{where} is damaged ({why}); fit it again with {FIT_COMMAND}")
    return ParkDifficulty(feats, *vals, intercept, dict(d.get("fit", {})))
