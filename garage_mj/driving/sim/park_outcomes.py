"""Outcome of one park or AVP test (docs/spec.md sections 8 and 9), decided by the environment, never by the driver.

:class:`ParkMonitor` is the park tests' twin of :class:`~garage_mj.driving.sim.outcomes.OutcomeMonitor`
(which cruise tests keep, untouched), with the same interface (``update``, ``progress``, ``time_limit``,
``goal_pose``) and the same end and collision check (their base,
:class:`~garage_mj.driving.sim.outcomes.BaseMonitor`). It watches the car along a reference path: the park plan's poses (park test) or the
cruise route followed by the park plan (AVP test, scored as one test). Checks, in this order:

- collision: ego touches a wall, pillar, obstacle, parked car or actor (as in cruise);
- success (SPEC 9): at rest (``|speed| < rest_speed``) for ``dwell`` seconds on end, all that time with the
  footprint inside the paint's inner edges of the target stall and the heading within 10 degrees of its axis
  in the maneuver's direction (:func:`~garage_mj.scene.park_planning.in_stall` ``.parked``, the scene's marking
  width); a car that stops there and moves off sooner starts its dwell again. A contact ends the test first,
  so a success had none at any time. While the car dwells it is not stuck;
- no progress for ``stuck_time``: neither along the reference path nor towards the stall pose by
  ``stuck_progress``, nor along a new plan the car was shown (:meth:`ParkMonitor.follow`: the park guide plans
  again from where a car stands outside the stall), nor a new direction change (a cusp driven: a multi-point turn of short shuffles,
  each with the wheels turned at rest, is progress; the time limit still bounds it): ``outside_stall`` within ``outside_radius`` of the stall pose (stopped, but not
  parked: the reason gives the errors and names the line crossed), ``deadlock`` farther away;
- timeout: ``time_limit`` from the reference length (``park_time_limit``, the dwell included), set by the env.

It also records what ``tests.csv`` reports of the drive: the driven poses (one per control step, for the
minimum clearance along the driven path), the direction changes (the sign of the speed flipping between
two stretches of motion faster than :data:`MOVING_SPEED`: cusps driven) and when the parking began
(``park_from`` metres along the reference: 0 for a park test, the cruise route for an AVP test).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from garage_mj.driving.sim.outcomes import BaseMonitor, Contact, Outcome, OutcomeKind
from garage_mj.scene.body_outlines import BodyOutlines, body_clearance
from garage_mj.scene.car import CarGeometry
from garage_mj.scene.clearance import Obstacles, nearest_obstacle
from garage_mj.scene.park_planning import ParkFit, centre_to_rear, in_stall, park_pose
from garage_mj.scene.route_line import Route
from garage_mj.scene.stalls import Stall
from garage_mj.scene.world import DEFAULT_WORLD

MOVING_SPEED = 0.1  # [m/s] faster than this the car is moving (a direction change counts between two such stretches)


@dataclass(frozen=True)
class ParkOutcomeConfig:
    """Thresholds of the park and AVP outcomes (units in the comments)."""

    rest_speed: float = 0.1  # [m/s] slower than this the car is at rest (SPEC 8's gear-change speed)
    min_mean_speed: float = 0.3  # [m/s] slowest mean speed along the park plan still in time
    time_slack: float = 15.0  # [s] added to the time limit (starting, aligning)
    cusp_time: float = 5.0  # [s] added per cusp of the plan (stop, change gear, start again)
    stuck_time: float = 8.0  # [s] window in which the car must make progress
    stuck_progress: float = 0.3  # [m] progress along the reference, or towards the stall pose, needed in it
    outside_radius: float = 6.0  # [m] no progress this close to the stall pose: outside_stall, not deadlock
    dwell: float = 1.0  # [s] a success stands parked at rest this long on end (SPEC 9; 0: the first parked step)

    def __post_init__(self) -> None:
        for name in ("rest_speed", "min_mean_speed", "stuck_time", "stuck_progress"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ParkOutcomeConfig.{name} must be > 0, got {getattr(self, name)}")
        if not (math.isfinite(self.dwell) and self.dwell >= 0):
            raise ValueError(f"ParkOutcomeConfig.dwell must be a number of seconds >= 0, got {self.dwell}")


def park_time_limit(config: ParkOutcomeConfig, length: float, cusps: int) -> float:
    """[s] the time limit of parking along a plan of ``length`` [m] with ``cusps`` gear changes, and dwelling at rest."""
    return length / config.min_mean_speed + config.time_slack + cusps * config.cusp_time + config.dwell


class ParkMonitor(BaseMonitor):
    """Watches one park (or AVP) test along ``reference`` and says when and how it ended (module docstring).

    ``reference``: the reference path of the car's centre; ``stall`` and ``maneuver``: the target;
    ``time_limit`` [s]; ``park_from`` [m]: where along ``reference`` the parking begins; ``marking`` [m]: the width of
    the stall's painted lines (the scene's ``WorldConfig.marking_width``).
    """

    def __init__(self, reference: Route, stall: Stall, car: CarGeometry, maneuver: str, time_limit: float,
                 config: ParkOutcomeConfig | None = None, park_from: float = 0.0,
                 marking: float = DEFAULT_WORLD.marking_width) -> None:
        self.route = reference
        self.stall = stall
        self.car = car
        self.maneuver = maneuver
        self.config = config or ParkOutcomeConfig()
        self.time_limit = float(time_limit)
        self.park_from = float(park_from)
        self.marking = float(marking)
        self.target = park_pose(stall, car, maneuver)
        self.goal = np.array(self.target[:2])
        self.reset()

    @property
    def fit(self) -> ParkFit | None:
        """The car in the stall at the last update (None before the first): worked out when asked for, which a car
        that moves faster than ``rest_speed`` never needs for its outcome."""
        if self._fit is None and self._fit_pose is not None:
            self._fit = in_stall(self.stall, self.car, self._fit_pose, self.maneuver, self.marking)
        return self._fit

    @property
    def goal_pose(self) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) of the stall pose (car centre)."""
        return self.target

    def reset(self) -> None:
        self.progress = 0.0  # [m] furthest arc length reached along the reference
        self.outcome: Outcome | None = None
        self._fit: ParkFit | None = None  # the car in the stall at the last update (:attr:`fit`, worked out on demand)
        self._fit_pose: tuple[float, float, float] | None = None  # the pose it is of
        self.poses: list[tuple[float, float, float]] = []  # driven poses, one per update
        self.direction_changes = 0
        self.park_start: float | None = None  # [s] when the parking began
        self.rest_since: float | None = None  # [s] since when the car stands parked at rest (None: it does not)
        self._sign = 0  # direction of the last stretch of motion
        self._mark_time = 0.0
        self._mark_progress = 0.0
        self._mark_dist = math.inf
        self._mark_changes = 0  # direction changes at the mark
        self.new_plan: Route | None = None  # a new plan the car was shown from where it stood (:meth:`follow`)
        self._plan_progress = 0.0  # [m] furthest reached along it
        self._mark_plan = 0.0  # ... at the mark

    def follow(self, plan: Route) -> None:
        """A new plan shown to the car from where it stands (the park guide's): from now on, progress along it counts
        as progress too, so a car driving it out of the stall to come in again is not stuck. The reference, the time
        limit and what success is stay the test's."""
        self.new_plan, self._plan_progress, self._mark_plan = plan, 0.0, 0.0

    def start(self, pose, progress: float = 0.0) -> None:
        """The car at rest at ``pose`` (car centre), ``progress`` metres along the reference: before the first step."""
        self.progress = self._mark_progress = float(progress)
        self.poses.append(tuple(float(v) for v in pose))
        self._mark_dist = math.dist(pose[:2], self.target[:2])
        if self.progress >= self.park_from:
            self.park_start = 0.0

    def _update(self, time: float, position, speed: float, contacts: Iterable[Contact], yaw: float | None,
                hold: bool) -> Outcome | None:
        cfg = self.config
        x, y = float(position[0]), float(position[1])
        yaw = self.target[2] if yaw is None else float(yaw)
        self.poses.append((x, y, yaw))
        hit = self._collision(time, speed, contacts)  # before the direction (the bounce of a hit is no change)
        if hit is not None:
            return hit
        if abs(speed) > MOVING_SPEED:
            sign = 1 if speed > 0 else -1
            self.direction_changes += self._sign != 0 and sign != self._sign
            self._sign = sign
        self._fit, self._fit_pose = None, (x, y, yaw)
        dwelling = abs(speed) < cfg.rest_speed and self.fit.parked
        if not dwelling:
            self.rest_since = None
        elif self.rest_since is None:
            self.rest_since = float(time)
        if dwelling and time - self.rest_since >= cfg.dwell - 1e-9:
            fit = self.fit
            return self._end(OutcomeKind.SUCCESS, time, f"parked ({fit.position_error:.2f} m, "
                             f"{fit.heading_error:.1f} deg from the stall pose, {fit.margin:.2f} m inside the "
                             f"{fit.line}), at rest {time - self.rest_since:.1f} s")
        s, _ = self.route.project((x, y), self.progress - 1.0, self.progress + 2.0 + abs(speed))
        self.progress = max(self.progress, s)
        if self.park_start is None and self.progress >= self.park_from:
            self.park_start = float(time)
        dist = math.dist((x, y), self.target[:2])
        if self.new_plan is not None:
            p = self._plan_progress
            self._plan_progress = max(p, self.new_plan.project((x, y), p - 1.0, p + 2.0 + abs(speed))[0])
        if hold or dwelling or self.progress - self._mark_progress >= cfg.stuck_progress or \
                self._mark_dist - dist >= cfg.stuck_progress or self.direction_changes > self._mark_changes or \
                self._plan_progress - self._mark_plan >= cfg.stuck_progress:
            self._mark_time, self._mark_progress, self._mark_dist = time, self.progress, min(dist, self._mark_dist)
            self._mark_changes, self._mark_plan = self.direction_changes, self._plan_progress
        elif time - self._mark_time >= cfg.stuck_time:
            why = f"no progress for {time - self._mark_time:.1f} s"
            if dist <= cfg.outside_radius:
                fit = self.fit
                where = f"inside the lines ({fit.margin:.2f} m from the {fit.line})" if fit.inside else \
                    f"{fit.overhang:.2f} m over the {fit.line}"
                return self._end(OutcomeKind.OUTSIDE_STALL, time,
                                 f"not parked: {fit.position_error:.2f} m and {fit.heading_error:.1f} deg from the "
                                 f"stall pose, lateral offset {fit.lateral_offset:+.2f} m, {where}, {why}")
            return self._end(OutcomeKind.DEADLOCK, time, f"{why}, {dist:.1f} m from the stall pose")
        if time >= self.time_limit:
            return self._end(OutcomeKind.TIMEOUT, time, f"time limit {self.time_limit:.1f} s reached")
        return None

    def min_clearance(self, obstacles: Obstacles) -> float:
        """[m] the footprint's smallest distance to ``obstacles`` over the driven poses (as the planner measures: stall
        outlines for parked cars)."""
        if not self.poses or not len(obstacles.boxes):
            return math.nan
        rear = centre_to_rear(np.array(self.poses), self.car)
        dist, _ = nearest_obstacle(obstacles, self.car, rear[:, :2], rear[:, 2])
        return float(dist.min())

    def body_clearance(self, bodies: BodyOutlines) -> float:
        """[m] the footprint's smallest distance to the solid ``bodies`` over the driven poses (SPEC 9; 0: touching)."""
        if not self.poses or not len(bodies):
            return math.nan
        rear = centre_to_rear(np.array(self.poses), self.car)
        dist, _ = body_clearance(bodies, self.car, rear[:, :2], rear[:, 2])
        return float(dist.min())
