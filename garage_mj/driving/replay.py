"""A cruise, park or AVP test as OpenSCENARIO: written from the env (:func:`write_test_xosc`) and replayed
(:func:`replay_xosc`).

``cruise --xosc`` writes each test the env was just reset to as one ``.xosc``
(:func:`garage_mj.export.xosc.write_xosc`), referring to the garage's asset pack. Such a file holds
exactly enough to drive the test again: :func:`garage_mj.export.xosc_read.read_xosc` parses it,
and the drive env (``GarageDrive-v0``) is reset to its target stall, parked cars, start pose and
actors, then driven like any cruise test (``cruise --scenario-file``). A park or AVP test's file also holds its
task, its maneuver and the reference park plan (reverse stretches as vertices facing away from the next
one); the replay resets a park or AVP env of that task and maneuver to the same stall, parked cars and
start, whose seeded planner plans the same reference again. The writer, the reader and
the drive env pull in MuJoCo and lxml: they are imported where they are used, so importing this
module (the cruise runner does, for :func:`write_test_xosc`) stays light.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.driving.actors.config import load_scenario_config
from garage_mj.driving.episode import drive_test
from garage_mj.driving.sources import CruiseError, CruiseSettings, CruiseSource


def _park_route(env, info: dict[str, Any]) -> tuple[np.ndarray, int]:
    """A park or AVP test's route for the ``.xosc`` as (x, y, yaw) rows and the row where its park plan begins
    (-1: no plan, the reference line alone): the plan's car poses, after the cruise route in an AVP test."""
    from garage_mj.export.xosc import travel_headings

    poses = np.asarray(info["park_plan"]["poses"], dtype=float).reshape(-1, 3)
    if len(poses) < 2:
        pts = np.asarray(env.route.points, dtype=float)
        return np.column_stack([pts, travel_headings(pts)]), -1
    if info["task"] == "park":
        return poses, 0
    cruise = np.asarray(env.test_plan.centre, dtype=float)
    return np.vstack([np.column_stack([cruise, travel_headings(cruise)]), poses]), len(cruise)


def write_test_xosc(env, info: dict[str, Any], path: Path, source: CruiseSource, index: int, seed: int,
                    settings: CruiseSettings) -> Path:
    """The test ``env`` was just reset to, as OpenSCENARIO (:func:`garage_mj.export.xosc.write_xosc`)."""
    from garage_mj.export.xosc import write_xosc

    if not source.pack:
        raise CruiseError(f"{source.name}: no asset pack to refer to; run_cruise exports one with xosc=True")
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {"garage_hash": source.hash, "garage": source.name, "test": index, "seed": seed,
            "driver": settings.driver, "action_type": settings.action_type, "occupancy": settings.occupancy,
            "env": settings.env, "driver_kwargs": settings.driver_kwargs}
    route = env.route.points
    if settings.task != "cruise":  # a cruise test's file stays as it was
        route, plan_start = _park_route(env, info)
        meta.update(task=settings.task, maneuver=info["maneuver"], plan_start=plan_start)
    # the parked cars as they stand (a mixed fleet's classes, a jitter's poses), else the scene's own
    parked = env.scene.layout.parked_cars if env.parked_fleet.default else env.parked_bodies
    return write_xosc(
        path, pack_dir=source.pack, target_stall=env.target, occupied=env.occupied, start=env.start_pose,
        route=route, goal=env.monitor.goal_pose, actors=env.scenario.actors, parked_poses=parked, meta=meta)


def replay_xosc(path: str | Path, driver: str | None = None, driver_kwargs: dict[str, Any] | None = None
                ) -> dict[str, Any]:
    """Replay the cruise, park or AVP test of a ``.xosc`` written by :func:`write_test_xosc`; returns its
    tests.csv row.

    Everything comes from the file: the pack (checked against its hash), target stall, parked
    cars, start pose and actors; the env settings, the driver and its action type are the ones
    recorded, unless ``driver`` names another (a test engineer's own stack on a found scenario),
    which then runs with the action type it declares.
    """
    from garage_mj.driving.drivers import action_type_of
    from garage_mj.export.xosc_read import read_xosc

    test = read_xosc(path)
    pack = test.pack()
    meta = test.meta
    env_kwargs = dict(meta.get("env") or {})
    scenario = load_scenario_config(env_kwargs.get("scenario"))
    need = {}
    for a in test.actors:  # room for every replayed actor (names are kind_index)
        k = int(a.name.rsplit("_", 1)[1]) + 1
        need[a.kind] = max(need.get(a.kind, 0), k)
    scenario = dataclasses.replace(scenario, pedestrians=max(scenario.pedestrians, need.get("pedestrian", 0)),
                                   moving_cars=max(scenario.moving_cars, need.get("moving_car", 0)),
                                   clutter=max(scenario.clutter, need.get("clutter", 0)))
    env_kwargs["scenario"] = scenario
    name = driver or test.driver or "vision"
    same = name == test.driver and test.action_type
    settings = CruiseSettings(name, int(test.seed or 0), test.action_type if same else action_type_of(name),
                              float(meta.get("occupancy", 0.5)), {},
                              dict(driver_kwargs if driver_kwargs is not None else meta.get("driver_kwargs") or {}),
                              task=test.task, maneuver=str(meta.get("maneuver", "reverse")))
    source = dataclasses.replace(CruiseSource.from_garage(pack.garage, str(meta.get("garage") or Path(pack.path).name)),
                                 pack=str(pack.path))
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    env = GarageDriveEnv(garage=pack.garage, action_type=settings.action_type, occupancy=settings.occupancy,
                         infeasible="report", **settings.task_kwargs(), **env_kwargs)
    try:
        start = time.perf_counter()
        seed = int(test.seed or 0)
        obs, info = env.reset(seed=seed, options={"target": test.target_stall, "occupied": test.occupied,
                                                  "start": test.start, "actors": test.actors})
        row = drive_test(env, obs, info, seed, settings, source, int(meta.get("test", 0)), start)
    finally:
        env.close()
    return row
