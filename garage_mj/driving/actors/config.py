"""How many adverse events a cruise, park or AVP test gets, and the rules they are drawn by: :class:`ScenarioConfig`.

A config lists behaviours of both tasks (:data:`~garage_mj.scene.actor_spec.BEHAVIOURS`, all by default); a cruise
test draws among the cruise behaviours it lists, a park or AVP test among the park ones
(:data:`~garage_mj.scene.actor_spec.PARK_BEHAVIOURS`). :data:`SCENARIOS` names ready-made configs
(``cruise --scenario NAME``).

The actors themselves (:class:`~garage_mj.scene.actor_spec.ActorSpec`) are placed by
:mod:`garage_mj.driving.actors.placement` and judged by :mod:`garage_mj.driving.actors.judging`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from garage_mj.core.config import ConfigError, bounded, check_bounds, load_config, read_toml
from garage_mj.scene.actor_spec import BEHAVIOURS

#: Most actors of each kind a test may ask for. A 13x13 garage's route takes about 21 pedestrians (32 asked,
#: 21 placed); 64 leaves room for the largest (64x64) garages while a scene with 64 of each kind still builds
#: in seconds. Far more would only fill memory building bodies that cannot be placed.
MAX_ACTORS = 64
_CAP = "per test"


def _behaviours(kind: str) -> tuple[str, ...]:
    """A field of the behaviours actors of ``kind`` are drawn from: a non-empty subset of those there are."""
    return bounded(BEHAVIOURS[kind], choices=BEHAVIOURS[kind], min_items=1)


@dataclass(frozen=True)
class ScenarioConfig:
    """Actors per test and the rules they are drawn by (TOML-loadable: ``[scenario]`` or top level)."""

    pedestrians: int = bounded(0, ge=0, le=MAX_ACTORS, why=_CAP)
    moving_cars: int = bounded(0, ge=0, le=MAX_ACTORS, why=_CAP)
    clutter: int = bounded(0, ge=0, le=MAX_ACTORS, why=_CAP)
    pedestrian_behaviours: tuple[str, ...] = _behaviours("pedestrian")  # drawn uniformly
    moving_car_behaviours: tuple[str, ...] = _behaviours("moving_car")
    clutter_behaviours: tuple[str, ...] = _behaviours("clutter")
    pedestrian_speed: tuple[float, float] = bounded((0.8, 1.5), gt=0.0)  # [m/s] walking speed, uniform
    moving_car_speed: tuple[float, float] = bounded((1.0, 2.5), gt=0.0)  # [m/s]
    lead: tuple[float, float] = (0.5, 8.0)  # [m] the trigger lies this much beyond the stopping distance
    trigger_radius: float = bounded(2.0, ge=0.0)  # [m] the ego's centre this close to the trigger point starts the actor
    reaction_time: float = bounded(0.5, ge=0.0)  # [s] feasibility: a driver reacts within this
    brake_decel: float = bounded(3.0, gt=0.0)  # [m/s^2] feasibility: a driver brakes at least this hard
    dwell: tuple[float, float] = bounded((1.0, 3.0), ge=0.0)  # [s] a reversing car waits this long in the aisle
    park_speed: float = bounded(1.5, gt=0.0)  # [m/s] feasibility of park actors: a parking car drives at most this fast

    def __post_init__(self) -> None:
        check_bounds(self)  # types, finiteness and the ranges above (load_config checked a loaded one already)
        for name in ("pedestrian_behaviours", "moving_car_behaviours", "clutter_behaviours"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        for name in ("pedestrian_speed", "moving_car_speed", "lead", "dwell"):
            lo, hi = (float(x) for x in getattr(self, name))
            if lo > hi:
                raise ConfigError(f"ScenarioConfig: {name} = [{lo}, {hi}]: needs lo <= hi")
            object.__setattr__(self, name, (lo, hi))

    @property
    def count(self) -> int:
        return self.pedestrians + self.moving_cars + self.clutter

    def stopping_distance(self, speed: float) -> float:
        """[m] a driver at ``speed`` needs this far to stop (reaction, then braking)."""
        return speed * self.reaction_time + speed * speed / (2.0 * self.brake_decel)


NO_ACTORS = ScenarioConfig()

_PARK_PEDESTRIANS = ("behind_stall", "beside_stall")
#: Named scenarios (``cruise --scenario NAME``): the ScenarioConfig fields each sets (the rest keep their defaults).
SCENARIOS: dict[str, dict[str, Any]] = {
    "park_pedestrian_behind": {"pedestrians": 1, "pedestrian_behaviours": ("behind_stall",)},
    "park_pedestrian_beside": {"pedestrians": 1, "pedestrian_behaviours": ("beside_stall",)},
    "park_car_pulling_out": {"moving_cars": 1, "moving_car_behaviours": ("pull_out",)},
    "park_clutter": {"clutter": 1, "clutter_behaviours": ("cone", "trolley")},
    "park_mixed": {"pedestrians": 1, "pedestrian_behaviours": _PARK_PEDESTRIANS, "moving_cars": 1,
                   "moving_car_behaviours": ("pull_out",), "clutter": 1, "clutter_behaviours": ("cone", "trolley")},
}


def load_scenario_config(source: str | dict[str, Any] | ScenarioConfig | None, **overrides: Any) -> ScenarioConfig:
    """A :class:`ScenarioConfig` from a TOML file (``[scenario]`` table or top level), a name of :data:`SCENARIOS`,
    a dict or None.

    ``overrides`` (e.g. ``pedestrians=2``; None values ignored) replace the file's values.
    """
    if isinstance(source, ScenarioConfig):
        data: dict[str, Any] = {f: getattr(source, f) for f in source.__dataclass_fields__}
    elif isinstance(source, dict):
        data = dict(source)
    elif source is None:
        data = {}
    elif isinstance(source, str) and source in SCENARIOS:
        data = dict(SCENARIOS[source])
    else:
        raw = read_toml(source)
        data = dict(raw.get("scenario", raw)) if isinstance(raw.get("scenario", raw), dict) else {}
        if "scenario" in raw and set(raw) - {"scenario"}:
            raise ConfigError(f"{source}: unknown table(s) {sorted(set(raw) - {'scenario'})}; known: scenario")
    given = {k: v for k, v in overrides.items() if v is not None}
    where = f"{source}" if isinstance(source, (str, Path)) else None  # a bad value names the file it came from
    try:
        return load_config(ScenarioConfig, data, where=where, **given)
    except ConfigError as exc:
        if where is not None and "unknown key" in str(exc):
            raise ConfigError(f"{exc}; see garage_mj.driving.actors.config.ScenarioConfig for the keys") from None
        raise
