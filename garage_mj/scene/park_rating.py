"""A garage's park difficulty: the mean failure probability of a few of its park tests, from the scene alone.

:func:`garage_park_difficulty` draws ``stalls`` target stalls of a garage (seeded, among those a cruise route
reaches), and for each one the park test a park run would draw there (docs/spec.md section 8): the parked cars
(each other stall occupied with probability ``occupancy``, the scene's own cars, centred), the start (the cruise
plan's goal beside the stall, moved by the drive env's default start noise), the maneuver (reverse and forward in
turn) and the reference plan of :class:`~garage_mj.scene.park_planning.ParkPlanner` around those cars. Each test's
features are what its ``tests.csv`` row would say (:func:`park_row`: plan length, cusps and clearance, stall angle,
bay margin, aisle width, start distance; no actors, no jitter, the uniform fleet), and the garage's park difficulty
is the mean of the model's failure probabilities over the tests that have a plan (NaN when none has).

This is what ``garage-mj generate --metric park`` rates garages by (:class:`ParkRater`, injected into the
generation stage as a :class:`~garage_mj.generation.generator.RouteMetric`). It drives nothing: the numbers are a
park run's before its drives, so they come out as a driven run's ``park_difficulty`` column would for the same
tests, without MuJoCo.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.generation.conditioned import GenerationError
from garage_mj.generation.generator import GenerateResult, RouteMetric, generate
from garage_mj.grid.garage import Garage
from garage_mj.scene.car import CarGeometry, car_geometry
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_difficulty import ParkDifficulty, load_park_model
from garage_mj.scene.park_planning import MANEUVERS, ParkPlanner
from garage_mj.scene.parked_fleet import ParkedFleet, body_obstacles, draw_parked
from garage_mj.scene.world import DEFAULT_WORLD, GeometryError, WorldConfig, geometry

PARK_STALLS = 6  # target stalls rated per garage (their tests' mean is the garage's park difficulty)
PARK_OCCUPANCY = 0.5  # probability that another stall holds a parked car (the drive env's default)
START_NOISE = (0.3, 0.05)  # [m, rad] the start's lateral and yaw offset bounds (the drive env's default)
ORDER = ("reverse", "forward")  # the maneuvers, in turn over the drawn stalls
assert set(ORDER) == set(MANEUVERS)


def _noisy(pose: tuple[float, float, float], lateral: float, dyaw: float) -> tuple[float, float, float]:
    """``pose`` moved ``lateral`` metres to its left and turned by ``dyaw`` (as the drive env moves a start)."""
    x, y, yaw = (float(v) for v in pose)
    return x - math.sin(yaw) * lateral, y + math.cos(yaw) * lateral, yaw + dyaw


def park_row(scene: GarageScene, car: CarGeometry, planner: ParkPlanner, stall_id: int, maneuver: str,
             rng: np.random.Generator, occupancy: float = PARK_OCCUPANCY) -> dict[str, Any] | None:
    """The ``tests.csv`` cells a park test into ``stall_id`` has before its drive (park features), drawn from ``rng``
    (parked cars, then lateral and yaw noise, in the drive env's order); None when no cruise route reaches the stall
    or the reference planner finds no park plan."""
    stalls = scene.stalls.stalls
    draw = rng.random(len(stalls)) < occupancy
    occupied = [s.id for s, o in zip(stalls, draw, strict=True) if o and s.id != stall_id]
    lateral = rng.uniform(-1.0, 1.0) * START_NOISE[0]
    dyaw = rng.uniform(-1.0, 1.0) * START_NOISE[1]
    cruise = drive_planner(scene, car).plan(stall_id)
    if not cruise.feasible:
        return None
    start = _noisy(cruise.goal, lateral, dyaw)
    bodies = draw_parked(stalls, occupied, stall_id, ParkedFleet("uniform", 0.0), None, scene.world.marking_width)
    plan = planner.plan(start, stall_id, maneuver, occupied=occupied,
                        obstacles=body_obstacles(planner.obstacles(), stall_id, bodies))
    if not plan.found:
        return None
    stall = stalls[stall_id]
    across = car.front - car.rear if float(stall.angle) == 0.0 else 2 * car.half_width
    return {"plan_length_m": plan.length, "plan_cusps": plan.cusps, "plan_clearance_m": plan.min_clearance,
            "stall_angle_deg": float(stall.angle), "maneuver": maneuver,
            "bay_margin_m": float(stall.width) - across, "aisle_width_m": float(scene.world.aisle_width),
            "start_distance_m": math.hypot(start[0] - stall.x, start[1] - stall.y),
            "pedestrians": 0, "moving_cars": 0, "clutter": 0, "pedestrians_behind": 0, "pedestrians_beside": 0,
            "parked_jitter_m": 0.0, "parked_fleet": "uniform"}


def garage_park_difficulty(garage: Garage | GarageScene, world: WorldConfig = DEFAULT_WORLD,
                           model: ParkDifficulty | None = None, stalls: int = PARK_STALLS, seed: int = 0,
                           occupancy: float = PARK_OCCUPANCY, car: CarGeometry | None = None) -> float:
    """The park difficulty of ``garage`` in the park geometry ``world`` (module docstring): the mean of ``model``'s
    failure probability (default: the shipped ``park_assist`` one) over the park tests of ``stalls`` seeded target
    stalls; NaN when none of them has a park plan. A garage the geometry cannot build raises its
    :class:`~garage_mj.scene.world.GeometryError`."""
    scene = garage if isinstance(garage, GarageScene) else GarageScene(garage, world)
    model = model or load_park_model()
    car = car or car_geometry()
    planner = ParkPlanner(scene, car)
    ids = [s.id for s in scene.stalls.stalls]  # a GeometryError here: the geometry cannot build the garage
    order = np.random.default_rng([seed, 0]).permutation(len(ids))
    cruise = drive_planner(scene, car)
    probs: list[float] = []
    drawn = 0
    for i in order:
        if drawn == stalls:
            break
        sid = ids[int(i)]
        if not cruise.plan(sid).feasible:  # a target a park run never draws
            continue
        row = park_row(scene, car, planner, sid, ORDER[drawn % 2], np.random.default_rng([seed, 1, drawn]), occupancy)
        drawn += 1
        if row is not None:
            probs.append(model.of_row(row))
    return float(np.mean(probs)) if probs else math.nan


class ParkRater:
    """``garage -> park difficulty`` in one park geometry under one model, for ``garage-mj generate --metric park``.

    A garage the geometry cannot build rates NaN (never stored) and is counted in :attr:`unbuildable`. :attr:`key`
    names the model and the geometry (``park:<model key>:<geometry key>``), so a library value is only read back for
    both.
    """

    def __init__(self, world: WorldConfig = DEFAULT_WORLD, model: ParkDifficulty | None = None,
                 stalls: int = PARK_STALLS, seed: int = 0) -> None:
        self.world, self.model, self.stalls, self.seed = world, model or load_park_model(), stalls, seed
        self.car = car_geometry()
        self.unbuildable = 0  # garages rated that the geometry cannot build
        self.rated = 0

    @property
    def key(self) -> str:
        return f"park:{self.model.key}:{geometry_key(self.world)}"

    def __call__(self, garage: Garage) -> float:
        self.rated += 1
        try:
            return garage_park_difficulty(garage, self.world, self.model, self.stalls, self.seed, car=self.car)
        except GeometryError:
            self.unbuildable += 1
            return math.nan


PROBE_GARAGES = 4  # painted garages per geometry that order the geometries of generate_in_geometries


@dataclass
class GeometryGeneration:
    """What :func:`generate_in_geometries` did in one park geometry (``result``: None when it was not tried)."""

    name: str
    rater: ParkRater
    probe: float  # median park difficulty of the painted probe garages in this geometry (NaN: none rated)
    result: GenerateResult | None = None


def generate_in_geometries(map: str, band: tuple[float, float], count: int, library: str | Path,
                           raters: dict[str, ParkRater], *, max_seconds: float | None = None,
                           max_episodes: int | None = None, seed: int = 0,
                           **kwargs: Any) -> list[GeometryGeneration]:
    """``garage-mj generate --metric park --geometries``: ``count`` garages of ``map`` whose park difficulty lies in
    ``band`` in one of the park geometries of ``raters`` (name -> :class:`ParkRater`), each stored under its
    geometry's key. The geometries are tried nearest first: a geometry's distance is that of the median rating of
    :data:`PROBE_GARAGES` painted garages of the map from the band. Each try is a
    :func:`~garage_mj.generation.generator.generate` for the garages still missing, with half of what is left of
    ``max_seconds`` and ``max_episodes`` (the last one: all of it), so the nearest geometry gets the most; the
    geometries after the band is filled are not tried. Raises
    :class:`~garage_mj.generation.conditioned.GenerationError` (``tried`` on it: this list) when all of them
    together fall short. ``kwargs`` go to ``generate`` (``model``, ``progress``, ``search``, ``clock``)."""
    from garage_mj.grid.painters import paint_garage

    clock = kwargs.get("clock", time.perf_counter)
    start = clock()  # the probes count against max_seconds too
    probes = [paint_garage(map, seed=seed * PROBE_GARAGES + k) for k in range(PROBE_GARAGES)]
    tried = []
    for name, rater in raters.items():
        probe = ParkRater(rater.world, rater.model, rater.stalls, rater.seed)  # its counts stay the rater's own
        values = [v for v in (probe(g) for g in probes) if not math.isnan(v)]
        tried.append(GeometryGeneration(name, rater, float(np.median(values)) if values else math.nan))
    lo, hi = band
    tried.sort(key=lambda t: math.inf if math.isnan(t.probe) else max(lo - t.probe, t.probe - hi, 0.0))
    missing, episodes = count, 0
    for i, t in enumerate(tried):
        part = 1 if i == len(tried) - 1 else 2  # half of what is left (the last: all of it)
        seconds = None if max_seconds is None else (max_seconds - (clock() - start)) / part
        if seconds is not None and seconds <= 0.0:
            break  # the time is spent: the geometries left are not tried
        share = None if max_episodes is None else max((max_episodes - episodes) // part, 1)
        try:
            t.result = generate(map, band, missing, library, seed=seed, max_seconds=seconds, max_episodes=share,
                                route=RouteMetric(t.rater, t.rater.key, "park difficulty"), **kwargs)
        except GenerationError as exc:
            if getattr(exc, "result", None) is None:
                raise
            t.result = exc.result
        missing -= t.result.found
        episodes += t.result.episodes
        if missing <= 0:
            return tried
    found = count - missing
    err = GenerationError(f"{found} of {count} garages with park difficulty {lo:g}-{hi:g} in "
                          f"{len(tried)} park geometries ({', '.join(_said(t) for t in tried)}); widen the band, "
                          "add a geometry or raise --max-seconds")
    err.tried = tried
    raise err


def _said(t: GeometryGeneration) -> str:
    probe = "none rated" if math.isnan(t.probe) else f"probe median {t.probe:.2f}"
    return f"{t.name}: {t.result.found if t.result else 0} found, {probe}"


def geometry_key(world: WorldConfig) -> str:
    """8 hex digits naming the park geometry of ``world`` (``default`` for today's default geometry)."""
    if world.is_default_geometry:
        return "default"
    return hashlib.sha256(json.dumps(geometry(world), sort_keys=True).encode()).hexdigest()[:8]


__all__ = ["PARK_OCCUPANCY", "PARK_STALLS", "PROBE_GARAGES", "GeometryGeneration", "ParkRater", "garage_park_difficulty",
           "generate_in_geometries", "geometry_key", "park_row"]
