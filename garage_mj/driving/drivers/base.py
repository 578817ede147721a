"""The driver protocol, driver noise and the shared base class of the built-in drivers.

A driver is the algorithm under test. The drive env calls ``reset(info)`` at the start of a test
and ``act(obs) -> action`` once per control step. The observation dict holds ``depth`` (H x W
float32 metres), ``segmentation`` (H x W uint8 :class:`garage_mj.scene.semantics.Semantic` ids),
optionally ``rgb``, ``waypoint`` (the route point a lookahead distance ahead, in the car frame:
x forward, y left, metres) and ``speed`` (forward speed, m/s). An action is either the paper's
discrete index (:class:`garage_mj.driving.sim.vehicle.DiscreteAction`) or ``[throttle, steer]`` in [-1, 1].

A driver class declares the action type it is made for in a class attribute ``action_type``
("continuous" or "discrete"; none: "discrete"); cruise and hunt run it with that type by default.
``info`` at reset may carry ``seed`` (int), ``action_type`` ("continuous" or "discrete"),
``dt`` (control period, s), ``camera`` (a dict of :class:`CameraGeometry` fields) and ``car``
(a :class:`garage_mj.scene.car.CarGeometry`).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from garage_mj.core.config import load_config
from garage_mj.driving.sim.vehicle import DISCRETE_COMMANDS, DiscreteAction, clip
from garage_mj.scene.car import FRONT_CAMERA, CarGeometry, car_camera, car_geometry


@runtime_checkable
class Driver(Protocol):
    """What the drive env and ``garage-mj cruise --driver module:Class`` need from a driver."""

    def reset(self, info: dict[str, Any]) -> None: ...

    def act(self, obs: dict[str, Any]) -> Any: ...


@dataclass(frozen=True)
class DriverNoiseConfig:
    """Imperfections of a driver, so that garage difficulty can show (all zero = perfect)."""

    steer_std: float = 0.0  # std of Gaussian noise on the steer command (range [-1, 1])
    throttle_std: float = 0.0  # std of Gaussian noise on the throttle command (range [-1, 1])
    delay_steps: int = 0  # [control steps] reaction delay: commands act this many steps late


def _from_car_model(key: str):
    """A field whose default is read from ``models/car``'s compiled model (:func:`car_camera`)."""
    return dataclasses.field(default_factory=lambda: car_camera()[key])


@dataclass(frozen=True)
class CameraGeometry:
    """The forward camera in the car frame (defaults: the ``front`` camera of ``models/car``, read from its
    compiled model, so moving the camera there moves it here too)."""

    x: float = _from_car_model("x")  # [m] forward of the car centre
    z: float = _from_car_model("z")  # [m] above the ground
    pitch: float = _from_car_model("pitch")  # [rad] downward tilt
    fovy: float = _from_car_model("fovy")  # [deg] vertical field of view (square pixels)

    @classmethod
    def from_model(cls, camera: str = FRONT_CAMERA, path: str | Path | None = None) -> CameraGeometry:
        """Camera ``camera`` of the car model (``path``: another car MJCF than ``models/car/car.xml``)."""
        return cls(**car_camera(camera, path))


def _car(car: CarGeometry | dict[str, Any] | None) -> CarGeometry:
    """A :class:`CarGeometry`: as given, or ``models/car``'s with the fields of a dict replaced."""
    if isinstance(car, CarGeometry):
        return car
    load_config(CarGeometry, car or {})  # unknown keys are an error
    return dataclasses.replace(car_geometry(), **(car or {}))


def discretize(throttle: float, steer: float, deadband: float = 0.15) -> int:
    """The paper action closest to ``(throttle, steer)``: brake first, then turning, else accelerate."""
    if throttle < -0.3:
        return int(DiscreteAction.BRAKE)
    if steer > deadband:
        return int(DiscreteAction.TURN_LEFT)
    if steer < -deadband:
        return int(DiscreteAction.TURN_RIGHT)
    return int(DiscreteAction.ACCELERATE)


class BaseDriver:
    """Common machinery: config loading, seeded noise, reaction delay, continuous/discrete output.

    Subclasses implement :meth:`command` returning ``(throttle, steer)``. They are made for
    continuous actions (``action_type``); with discrete ones the command is rounded to the
    nearest paper action (:func:`discretize`), which costs precision.
    """

    config_class: type = object
    action_type: str = "continuous"  # what the driver is made for (see garage_mj.driving.drivers)

    def __init__(self, config=None, noise=None, car=None, **overrides) -> None:
        self.config = config if isinstance(config, self.config_class) else load_config(
            self.config_class, config, **overrides)
        self.noise = noise if isinstance(noise, DriverNoiseConfig) else load_config(DriverNoiseConfig, noise)
        self.car = _car(car)
        self.camera = CameraGeometry()
        self.discrete = False
        self.dt = 0.1  # [s]
        self._rng = np.random.default_rng(0)
        self._queue: collections.deque = collections.deque()

    def reset(self, info: dict[str, Any]) -> None:
        """Start a test: seed the noise, learn the action type, control period and camera."""
        self._rng = np.random.default_rng(int(info.get("seed", 0)))
        self.discrete = info.get("action_type", "continuous") == "discrete"
        self.dt = float(info.get("dt", self.dt))
        if "camera" in info:
            self.camera = load_config(CameraGeometry, info["camera"])
        if "car" in info:  # the env's car (one source: models/car and its CarConfig)
            car = info["car"]
            self.car = _car(car)
        self._queue = collections.deque([(0.0, 0.0)] * self.noise.delay_steps)

    def command(self, obs: dict[str, Any]) -> tuple[float, float]:
        raise NotImplementedError

    def delayed(self, throttle: float, steer: float) -> tuple[float, float]:
        """``(throttle, steer)`` with the driver's noise added, clipped, and through its delay queue."""
        if self.noise.throttle_std > 0:
            throttle += float(self._rng.normal(0.0, self.noise.throttle_std))
        if self.noise.steer_std > 0:
            steer += float(self._rng.normal(0.0, self.noise.steer_std))
        self._queue.append((clip(throttle, -1.0, 1.0), clip(steer, -1.0, 1.0)))
        return self._queue.popleft()

    def act(self, obs: dict[str, Any]):
        """The action for this step: command, plus noise and delay, in the env's action type."""
        throttle, steer = self.delayed(*self.command(obs))
        if self.discrete:
            return self.to_discrete(throttle, steer, obs)
        return np.array([throttle, steer], dtype=np.float32)

    def to_discrete(self, throttle: float, steer: float, obs: dict[str, Any]) -> int:
        """The paper action for ``(throttle, steer)``: :func:`discretize` (drivers may know better)."""
        return discretize(throttle, steer)

    def track_discrete(self, throttle: float, steer: float, obs: dict[str, Any]) -> int:
        """The paper action whose next-step effect comes closest to ``(throttle, steer)``.

        Knows how the car answers a discrete action (:data:`~garage_mj.driving.sim.vehicle.DISCRETE_COMMANDS`):
        a turn moves the road wheels one rate-limited step toward full lock and holds the cruise
        speed; accelerate and brake move them one step back toward straight and change the speed.
        Reads the road-wheel angle from ``obs["steer"]`` (fraction of full lock); picks the action
        minimising (steer error in steps)^2 + (pedal error)^2. Without ``steer``: :func:`discretize`.
        """
        if "steer" not in obs:
            return discretize(throttle, steer)
        car = self.car
        now = float(np.asarray(obs["steer"]).reshape(-1)[0]) * car.max_steer
        want = steer * car.max_steer
        step = max(car.steer_rate * self.dt, 1e-6)

        def toward(target: float) -> float:
            return now + min(max(target - now, -step), step)

        best, best_cost = int(DiscreteAction.ACCELERATE), math.inf
        for action, (u, s) in DISCRETE_COMMANDS.items():
            cost = ((toward(s * car.max_steer) - want) / step) ** 2 + (u - throttle) ** 2
            if cost < best_cost - 1e-9:
                best, best_cost = int(action), cost
        return best

    # -- shared control laws ------------------------------------------------------------------
    def pursuit_curvature(self, target) -> float:
        """Pure-pursuit curvature [1/m] toward ``target`` (car frame), from the rear axle."""
        x = float(target[0]) - self.car.rear_axle
        y = float(target[1])
        d2 = x * x + y * y
        return 2.0 * y / d2 if d2 > 1e-6 else 0.0

    def steer_for(self, curvature: float) -> float:
        """Steer command in [-1, 1] that drives ``curvature``."""
        return clip(math.atan(self.car.wheelbase * curvature) / self.car.max_steer, -1.0, 1.0)

    @staticmethod
    def curve_speed(kappa: float, cruise_speed: float, min_speed: float, lateral_accel: float) -> float:
        """[m/s] ``cruise_speed`` capped on a curve of curvature ``kappa`` [1/m] by the comfort limit
        v <= sqrt(lateral_accel / |kappa|), never below ``min_speed``."""
        if abs(kappa) > 1e-6:
            return min(cruise_speed, max(min_speed, math.sqrt(lateral_accel / abs(kappa))))
        return cruise_speed

    def drive_at(self, target_speed: float, speed: float, kappa: float) -> tuple[float, float]:
        """``(throttle, steer)`` toward ``target_speed`` on curvature ``kappa``; full brake at target 0."""
        if target_speed == 0.0:
            return -1.0, self.steer_for(kappa)
        return self.throttle_for(target_speed, speed), self.steer_for(kappa)

    @staticmethod
    def approach_speed(obs: dict[str, Any], decel: float, creep: float = 0.3, stop_within: float = 0.2) -> float:
        """[m/s] the fastest speed that still stops at the goal at ``decel`` [m/s^2].

        Reads ``obs["remaining"]`` (route length left to the goal); 0 within ``stop_within``
        metres; never below ``creep`` before that, so the car does not stall short of the goal.
        """
        if "remaining" not in obs:
            return math.inf
        left = float(np.asarray(obs["remaining"]).reshape(-1)[0])
        if left <= stop_within:
            return 0.0
        return max(min(creep, left), math.sqrt(2.0 * decel * max(left - stop_within, 0.0)))

    def throttle_for(self, target_speed: float, speed: float, gain: float = 1.0) -> float:
        """Pedal command toward ``target_speed`` [m/s] (the car's pedal is an acceleration request)."""
        err = target_speed - speed
        if err >= 0:
            return clip(gain * err / (self.car.max_accel * self.dt * 2), 0.0, 1.0)
        return clip(gain * err / (self.car.max_decel * self.dt * 2), -1.0, 0.0)
