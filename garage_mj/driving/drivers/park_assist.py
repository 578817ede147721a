"""``park_assist``: a non-privileged parking baseline, a fixed template as early parking assistants drove it.

It sees only what a car's own sensors give: ``obs["stall"]`` (the stall pose to park in, car frame:
x forward, y left [m], cos and sin of its yaw relative to the car's), the speed, the gear and the
road-wheel angle; never the car's pose or the reference plan. From the lane beside the stall it drives
one template, the same for every stall (docs/spec.md section 8):

- **position**: straight along the lane (holding the heading parallel to the stall row) until the stall
  pose lies where one full-lock quarter turn lands the rear axle (reverse-in) or the front (nose-in) on
  the stall's axis; forward past the stall for reverse-in, backward if it went too far;
- **turn**: at rest, the wheels to full lock towards the stall, then a quarter turn at full lock, in R
  for reverse-in, in D for nose-in;
- **enter**: the wheels straightened a little before the car is parallel to the stall, then straight
  in along the axis (holding the heading), braking to stop where its estimate puts the stall pose;
- **done**: brake held.

No lateral correction after the turn, no second try: where the turn circle does not fit (tight stalls,
a narrow aisle, a parked car close by) it fails, which is what separates it from the ``oracle``.
Both maneuvers are supported (reverse-in and nose-in, from the reset info's ``maneuver``, else read off
the stall pose's direction). In an AVP test it first cruises by pure pursuit on ``obs["waypoint"]`` until
the stall is beside the car. It is made for continuous park actions ``[pedal, steer, gear]``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from garage_mj.driving.drivers.base import BaseDriver
from garage_mj.driving.sim.vehicle import Gear, clip


@dataclass(frozen=True)
class ParkAssistConfig:
    """Speeds and thresholds of the template (units in the comments)."""

    speed: float = 1.2  # [m/s] along the lane and in the turn
    enter_speed: float = 0.6  # [m/s] straight into the stall
    cruise_speed: float = 2.0  # [m/s] an AVP test's route, by pure pursuit
    stop_decel: float = 0.6  # [m/s^2] planned braking to each stop
    creep: float = 0.15  # [m/s] least speed before a stop
    brake_time: float = 0.27  # [s] braking distance = speed x this
    k_heading: float = 1.0  # steer per radian of heading error on the straights
    straighten: float = 0.12  # [rad] start straightening the wheels this far before parallel
    lock_settle: float = 0.1  # wheels within this fraction of full lock before the turn starts
    at_rest: float = 0.08  # [m/s] below this the car is at rest
    beside: float = 0.35  # [rad] AVP: the stall is beside the car when its axis is this close to square
    beside_range: float = 12.0  # [m] AVP: ... its pose at most this far sideways
    beside_min: float = 2.0  # [m] AVP: ... at least this far sideways (off the lane, not ahead on it)
    beside_along: float = 5.0  # [m] AVP: ... and at most this far ahead or behind


def _rel(obs: dict[str, Any]) -> tuple[float, float, float]:
    """The stall pose in the car frame: (x [m], y [m], yaw [rad])."""
    x, y, c, s = (float(v) for v in np.asarray(obs["stall"]).reshape(-1)[:4])
    return x, y, math.atan2(s, c)


class ParkAssistDriver(BaseDriver):
    """Reverse-in (or nose-in) by a fixed full-lock template from the lane, from the ``stall`` observation."""

    config_class = ParkAssistConfig
    action_type = "continuous"  # made for [pedal, steer, gear]
    tasks = ("park", "avp")  # it parks; a cruise test is an error (no stall observation)

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        self.maneuver: str | None = info.get("maneuver")
        self.phase = "cruise" if info.get("task") == "avp" else "position"
        self.side = 0.0  # +1: the stall is on the car's left, -1 on its right (set by the first look)
        self.lane_yaw = 0.0  # [rad] the stall's yaw relative to the car when the car is parallel to the lane
        self.gear = Gear.D

    # -- geometry ------------------------------------------------------------------------------------
    @property
    def radius(self) -> float:
        """[m] the rear axle's turning radius at full lock."""
        return self.car.wheelbase / math.tan(self.car.max_steer)

    def _look(self, obs: dict[str, Any]) -> None:
        """Fix the side of the stall and the maneuver from the stall pose, once the template starts."""
        _, y, yaw = _rel(obs)
        self.side = 1.0 if y >= 0 else -1.0
        if self.maneuver not in ("reverse", "forward"):  # reverse-in faces the aisle: away from the car's side
            self.maneuver = "reverse" if yaw * self.side < 0 else "forward"
        self.lane_yaw = -self.side * math.pi / 2 if self.maneuver == "reverse" else self.side * math.pi / 2

    def _turn_point(self) -> float:
        """[m] the stall pose's x (car frame) at which the full-lock quarter turn starts."""
        if self.maneuver == "reverse":  # the rear axle ends on the axis after backing round the circle
            return self.car.rear_axle - self.radius
        return self.car.rear_axle + self.radius  # nose-in: forward round the circle

    # -- commands ------------------------------------------------------------------------------------
    def _drive(self, gear: Gear, target: float, speed: float) -> tuple[float, Gear]:
        """(pedal, gear) toward ``target`` [m/s] along ``gear``'s direction."""
        v = gear.sign * speed
        if self.gear is not gear:
            return -1.0, gear
        return self.throttle_for(target, v), gear

    def _to_stop(self, remaining: float, top: float) -> float:
        cfg = self.config
        return max(min(top, math.sqrt(2.0 * cfg.stop_decel * max(remaining, 0.0))), cfg.creep)

    def _cruise(self, obs: dict[str, Any], speed: float) -> tuple[float, float, Gear]:
        """AVP: pure pursuit on the route until the stall is beside the car."""
        cfg = self.config
        x, y, yaw = _rel(obs)
        square = abs(abs(yaw) - math.pi / 2) < cfg.beside
        if square and abs(x) < cfg.beside_along and cfg.beside_min <= abs(y) <= cfg.beside_range:
            self.phase = "position"  # the stall is beside the car, off the lane
            return self._position(obs, speed)
        kappa = self.pursuit_curvature(np.asarray(obs["waypoint"], dtype=float))
        v = self.curve_speed(kappa, cfg.cruise_speed, 0.5, 1.5)
        if math.hypot(x, y) < 2 * cfg.beside_range:  # the stall is near: slow to the template's speed
            v = min(v, cfg.speed)
        pedal, gear = self._drive(Gear.D, v, speed)
        return pedal, self.steer_for(kappa), gear

    def _position(self, obs: dict[str, Any], speed: float) -> tuple[float, float, Gear]:
        """Straight along the lane to the turn point (forward, or back when past it)."""
        cfg = self.config
        if not self.side:
            self._look(obs)
        x, _, yaw = _rel(obs)
        ahead = x - self._turn_point()  # > 0: drive forward this far
        gear = Gear.D if ahead >= 0 else Gear.R
        steer = gear.sign * cfg.k_heading * math.remainder(yaw - self.lane_yaw, math.tau)
        left = abs(ahead)
        if left <= abs(speed) * cfg.brake_time + 0.02:
            if abs(speed) < cfg.at_rest:
                self.phase = "turn"
            return -1.0, clip(steer, -1.0, 1.0), self.gear
        pedal, gear = self._drive(gear, self._to_stop(left, cfg.speed), speed)
        return pedal, clip(steer, -1.0, 1.0), gear

    def _turn(self, obs: dict[str, Any], speed: float) -> tuple[float, float, Gear]:
        """The full-lock quarter turn towards the stall; straighten just before parallel."""
        cfg = self.config
        gear = Gear.R if self.maneuver == "reverse" else Gear.D
        _, _, yaw = _rel(obs)
        if abs(yaw) <= cfg.straighten:
            self.phase = "enter"
            return self._enter(obs, speed)
        wheel = float(np.asarray(obs.get("steer", [self.side])).reshape(-1)[0])
        if abs(speed) < cfg.at_rest and (self.gear is not gear or abs(wheel - self.side) > cfg.lock_settle):
            return -1.0, self.side, gear  # at rest: engage the gear and turn the wheels first
        pedal, gear = self._drive(gear, cfg.speed, speed)
        return pedal, self.side, gear

    def _enter(self, obs: dict[str, Any], speed: float) -> tuple[float, float, Gear]:
        """Straight along the stall's axis, holding the heading, to the stall pose."""
        cfg = self.config
        gear = Gear.R if self.maneuver == "reverse" else Gear.D
        x, _, yaw = _rel(obs)
        steer = clip(gear.sign * cfg.k_heading * yaw, -1.0, 1.0)
        remaining = gear.sign * x  # the stall pose ahead along the direction of travel
        if remaining <= abs(speed) * cfg.brake_time:
            self.phase = "done"
            return -1.0, steer, gear
        pedal, gear = self._drive(gear, self._to_stop(remaining, cfg.enter_speed), speed)
        return pedal, steer, gear

    def _done(self, obs: dict[str, Any], speed: float) -> tuple[float, float, Gear]:
        return -1.0, 0.0, self.gear

    def act(self, obs: dict[str, Any]):
        """``[pedal, steer, gear]`` for this step (``gear`` < 0 requests R)."""
        if "stall" not in obs:
            raise ValueError("the park_assist driver parks: it needs the stall observation of a park or AVP test "
                             "(GarageDriveEnv(task='park') or task='avp')")
        speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
        if "gear" in obs:
            self.gear = Gear.R if float(np.asarray(obs["gear"]).reshape(-1)[0]) < 0 else Gear.D
        step: Callable[[dict[str, Any], float], tuple[float, float, Gear]] = getattr(self, "_" + self.phase)
        pedal, steer, gear = step(obs, speed)
        return np.array([clip(pedal, -1.0, 1.0), clip(steer, -1.0, 1.0), gear.sign], dtype=np.float32)
