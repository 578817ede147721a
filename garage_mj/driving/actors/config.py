"""How many adverse events a cruise test gets, and the rules they are drawn by: :class:`ScenarioConfig`.

The actors themselves (:class:`~garage_mj.scene.actor_spec.ActorSpec`) are placed by
:mod:`garage_mj.driving.actors.placement` and judged by :mod:`garage_mj.driving.actors.judging`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from garage_mj.core.config import ConfigError, load_config, read_toml
from garage_mj.scene.actor_spec import BEHAVIOURS


@dataclass(frozen=True)
class ScenarioConfig:
    """Actors per test and the rules they are drawn by (TOML-loadable: ``[scenario]`` or top level)."""

    pedestrians: int = 0
    moving_cars: int = 0
    clutter: int = 0
    pedestrian_behaviours: tuple[str, ...] = BEHAVIOURS["pedestrian"]  # drawn uniformly
    moving_car_behaviours: tuple[str, ...] = BEHAVIOURS["moving_car"]
    clutter_behaviours: tuple[str, ...] = BEHAVIOURS["clutter"]
    pedestrian_speed: tuple[float, float] = (0.8, 1.5)  # [m/s] walking speed, uniform
    moving_car_speed: tuple[float, float] = (1.0, 2.5)  # [m/s]
    lead: tuple[float, float] = (0.5, 8.0)  # [m] the trigger lies this much beyond the stopping distance
    trigger_radius: float = 2.0  # [m] the ego's centre this close to the trigger point starts the actor
    reaction_time: float = 0.5  # [s] feasibility: a driver reacts within this
    brake_decel: float = 3.0  # [m/s^2] feasibility: a driver brakes at least this hard
    dwell: tuple[float, float] = (1.0, 3.0)  # [s] a reversing car waits this long in the aisle

    def __post_init__(self) -> None:
        for name in ("pedestrians", "moving_cars", "clutter"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise ConfigError(f"ScenarioConfig: {name} must be an integer >= 0, got {v!r}")
        for kind, name in (("pedestrian", "pedestrian_behaviours"), ("moving_car", "moving_car_behaviours"),
                           ("clutter", "clutter_behaviours")):
            got = tuple(getattr(self, name))
            bad = [b for b in got if b not in BEHAVIOURS[kind]]
            if bad or not got:
                raise ConfigError(f"ScenarioConfig: {name} must be a non-empty subset of {list(BEHAVIOURS[kind])}, "
                                  f"got {list(got)}")
            object.__setattr__(self, name, got)
        for name in ("pedestrian_speed", "moving_car_speed", "lead", "dwell"):
            v = getattr(self, name)
            try:
                lo, hi = (float(x) for x in v)
            except (TypeError, ValueError):
                raise ConfigError(f"ScenarioConfig: {name} must be a pair [lo, hi], got {v!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ConfigError(f"ScenarioConfig: {name} needs finite lo <= hi, got {v!r}")
            if name != "lead" and lo < 0:
                raise ConfigError(f"ScenarioConfig: {name} must be >= 0, got {v!r}")
            if name.endswith("speed") and lo <= 0:
                raise ConfigError(f"ScenarioConfig: {name} must be > 0, got {v!r}")
            object.__setattr__(self, name, (lo, hi))
        for name in ("trigger_radius", "reaction_time", "brake_decel"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"ScenarioConfig: {name} must be a finite number >= 0, got {v!r}")
        if self.brake_decel <= 0:
            raise ConfigError("ScenarioConfig: brake_decel must be > 0")

    @property
    def count(self) -> int:
        return self.pedestrians + self.moving_cars + self.clutter

    def stopping_distance(self, speed: float) -> float:
        """[m] a driver at ``speed`` needs this far to stop (reaction, then braking)."""
        return speed * self.reaction_time + speed * speed / (2.0 * self.brake_decel)


NO_ACTORS = ScenarioConfig()


def load_scenario_config(source: str | dict[str, Any] | ScenarioConfig | None, **overrides: Any) -> ScenarioConfig:
    """A :class:`ScenarioConfig` from a TOML file (``[scenario]`` table or top level), a dict or None.

    ``overrides`` (e.g. ``pedestrians=2``; None values ignored) replace the file's values.
    """
    if isinstance(source, ScenarioConfig):
        data: dict[str, Any] = {f: getattr(source, f) for f in source.__dataclass_fields__}
    elif isinstance(source, dict):
        data = dict(source)
    elif source is None:
        data = {}
    else:
        raw = read_toml(source)
        data = dict(raw.get("scenario", raw)) if isinstance(raw.get("scenario", raw), dict) else {}
        if "scenario" in raw and set(raw) - {"scenario"}:
            raise ConfigError(f"{source}: unknown table(s) {sorted(set(raw) - {'scenario'})}; known: scenario")
    data.update({k: v for k, v in overrides.items() if v is not None})
    try:
        return load_config(ScenarioConfig, data)
    except ConfigError as exc:
        if isinstance(source, (str, Path)):  # name the file the bad value came from
            raise ConfigError(f"{source}: {exc}; see garage_mj.driving.actors.config.ScenarioConfig for the keys") \
                from None
        raise
