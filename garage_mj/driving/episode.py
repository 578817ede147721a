"""One cruise test driven to its ``tests.csv`` row, and the scene and driver a process keeps between tests.

Building a scene (compiling MuJoCo) is the slow part of a test, so a process keeps one env, for
the garage it tested last, and one driver (:func:`cached_env`); the runner sends a worker its
tests grouped by garage, so each scene is built at most once per worker and garage.
:func:`drive_test` drives an env that was just reset to a test and returns the row; the runner
(:mod:`garage_mj.driving.cruise`) and the replay of a ``.xosc`` (:mod:`garage_mj.driving.replay`)
both use it.
"""

from __future__ import annotations

import json
import math
import time
import traceback
from typing import Any

from garage_mj.core.errors import GarageMJError
from garage_mj.driving.results import HAZARD_COLUMNS, PARK_COLUMNS, ROOM_COLUMNS, vehicle_cells
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.driving.sources import CruiseError, CruiseSettings, CruiseSource

_CACHE: dict[str, Any] = {}


def cached_env(source: CruiseSource, settings: CruiseSettings):
    """This process's env for ``source`` (built once; the previous garage's env is closed)."""
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    key = (source.hash, json.dumps(settings.env, sort_keys=True), settings.task, settings.maneuver, settings.stall)
    if _CACHE.get("hash") != key:
        if "env" in _CACHE:
            _CACHE.pop("env").close()
        _CACHE["env"] = GarageDriveEnv(garage=source.garage, action_type=settings.action_type,
                                       occupancy=settings.occupancy, infeasible="report", **settings.task_kwargs(),
                                       **settings.env)
        _CACHE["hash"] = key
    return _CACHE["env"]


def close_cached_env() -> None:
    """Close the scene this process keeps for :func:`garage_mj.driving.cruise.run_test` (tests run in-process,
    then done)."""
    if "env" in _CACHE:
        _CACHE.pop("env").close()
        _CACHE.pop("hash", None)


def forget_cached() -> None:
    """Close the scene and drop the driver this process keeps: a test that ran past its time limit was
    interrupted inside them, so neither is used again."""
    close_cached_env()
    _CACHE.pop("driver", None)
    _CACHE.pop("driver_key", None)


def _driver_for(settings: CruiseSettings):
    """This process's driver for ``settings`` (built once); one that cannot be built is a :class:`CruiseError`
    naming it and its error (its traceback kept for ``--debug``), in a worker process too."""
    from garage_mj.driving.drivers import load_driver

    key = (settings.driver, json.dumps(settings.driver_kwargs, sort_keys=True))
    if _CACHE.get("driver_key") != key:
        try:
            _CACHE["driver"] = load_driver(settings.driver, **settings.driver_kwargs)
        except GarageMJError:
            raise  # a bad spec or model file: its message names it already
        except Exception as exc:  # a user's driver's __init__ may raise anything
            err = CruiseError(f"driver {settings.driver!r} cannot be built: {type(exc).__name__}: {exc} "
                              "(put --debug before the command for its traceback)")
            err.details = "".join(traceback.format_exception(exc))
            raise err from exc
        _CACHE["driver_key"] = key
    return _CACHE["driver"]


def check_driver(settings: CruiseSettings) -> None:
    """Build the driver of ``settings`` in this process now, before a run writes anything or starts workers:
    a missing or corrupt model or a raising ``__init__`` is one line, and the tests run here reuse it."""
    _driver_for(settings)


def drive_test(env, obs, info, seed: int, settings: CruiseSettings, source: CruiseSource, index: int,
               start: float) -> dict[str, Any]:
    """Drive the reset ``env`` to the end of its test; the CSV row."""
    driver = _driver_for(settings)
    try:
        if info.get("outcome") not in NOT_DRIVEN:  # decided before the drive: never driven
            driver.reset(env.driver_info(seed))
            while True:
                obs, _, term, trunc, info = env.step(driver.act(obs))
                if term or trunc:
                    break
    except Exception as exc:  # a user's driver may raise anything; name it, keep the traceback
        err = CruiseError(f"driver {settings.driver!r} failed on {source.name} test {index}: "
                          f"{type(exc).__name__}: {exc} (put --debug before the command for its traceback)")
        err.details = "".join(traceback.format_exception(exc))  # text: survives a worker process
        raise err from exc
    return {
        "garage": source.name, "garage_hash": source.hash, "test": index, "seed": seed,
        "driver": settings.driver, "target_stall": info["target_stall"],
        "feasible": int(info["outcome"] not in NOT_DRIVEN), "outcome": info["outcome"],
        "hit": info["hit"] or "", "hit_geom": info["hit_geom"] or "", "reason": info["reason"],
        "time": round(info["time"], 3),
        "path_length": round(info["path_length"], 3), "route_length": round(info["route_length"], 3),
        "difficulty": source.difficulty, "mean_road_length": source.mean_road_length,
        "mean_intersection_degree": source.mean_intersection_degree,
        "pedestrians": info["actors"]["pedestrian"], "moving_cars": info["actors"]["moving_car"],
        "clutter": info["actors"]["clutter"],
        "wall_s": round(time.perf_counter() - start, 3),
        **park_cells(info),
        **vehicle_cells(settings.env),
    }


def _cell(value: Any, digits: int = 3) -> Any:
    """A number for a CSV cell, rounded; "" for None, NaN or an infinity."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return round(value, digits) if isinstance(value, float) else value


def park_cells(info: dict[str, Any]) -> dict[str, Any]:
    """The park columns of a test's row (:data:`~garage_mj.driving.results.PARK_COLUMNS`, the room of
    :data:`~garage_mj.driving.results.ROOM_COLUMNS` but ``park_difficulty``, which the runner fills, and the
    pedestrians by behaviour of :data:`~garage_mj.driving.results.HAZARD_COLUMNS`) from the env's last info: for a
    cruise test its task only; the parking metrics where the test was driven, the plan's where one was found."""
    cells: dict[str, Any] = dict.fromkeys((*PARK_COLUMNS, *ROOM_COLUMNS, *HAZARD_COLUMNS), "")
    if "task" not in info:
        return {**cells, "task": "cruise"}
    found = info["plan_cusps"] >= 0
    walking = info.get("pedestrian_behaviours", {})
    cells |= {"task": info["task"], "maneuver": info["maneuver"],
             "pedestrians_behind": walking.get("behind_stall", 0), "pedestrians_beside": walking.get("beside_stall", 0),
             "plan_length_m": _cell(info["plan_length"]) if found else "",
             "plan_cusps": info["plan_cusps"] if found else "",
             "plan_clearance_m": _cell(info["plan_clearance"]) if found else "",
             "park_level": info["park_level"], "stall_angle_deg": _cell(info["stall_angle"]),
             "bay_margin_m": _cell(info["bay_margin"]), "aisle_width_m": _cell(info["aisle_width"]),
             "start_distance_m": _cell(info["start_distance"])}
    if "position_error" in info:  # driven: the metrics at its end
        cells.update(position_error_m=_cell(info["position_error"]), heading_error_deg=_cell(info["heading_error"], 2),
                     lateral_offset_m=_cell(info["lateral_offset"]), direction_changes=info["direction_changes"],
                     park_time_s=_cell(info["park_time"]), min_clearance_m=_cell(info["min_clearance"]),
                     inner_margin_m=_cell(info["inner_margin"]), outline_clearance_m=_cell(info["outline_clearance"]),
                     guide_replans=info.get("guide_replans", 0))
    return cells
