"""Cruise tests of your own driver with garage-mj's pytest plugin: copy this file into your tests/.

The plugin comes with garage-mj (``pip install garage-mj``): nothing to configure. Run it as

    pytest test_my_driver.py                   # 3 cruise tests on a painted tiny_7x11 garage
    pytest test_my_driver.py --garage-maps m5_13x13_aligned --garage-per-map 5 --garage-tests 20 --garage-workers 2

A failing test lists each failed cruise test (outcome, reason, what was hit) with the path of its MP4
and its OpenSCENARIO file (.xosc) in pytest's tmp folder.
"""

from __future__ import annotations

import math

import numpy as np
import pytest


class MyDriver:
    """Your driving stack goes here. This one: pure pursuit toward the route's next waypoint, slower in
    curves, braking to stop on the goal. It sees only what a camera car knows (no privileged pose)."""

    action_type = "continuous"  # act() returns [throttle, steer] in [-1, 1]; "discrete": the paper's 4 actions

    def __init__(self, cruise_speed: float = 2.5) -> None:
        self.cruise_speed = cruise_speed  # [m/s]

    def reset(self, info: dict) -> None:
        """Start of a test: ``info`` holds the seed, ``dt`` [s] and the car's geometry (``car``)."""
        self.car = info["car"]

    def act(self, obs: dict) -> np.ndarray:
        """One control step: ``obs`` holds depth, segmentation, waypoint (car frame, m), remaining [m], speed."""
        x, y = float(obs["waypoint"][0]) - self.car.rear_axle, float(obs["waypoint"][1])
        curvature = 2.0 * y / max(x * x + y * y, 1e-6)  # pure pursuit from the rear axle [1/m]
        steer = math.atan(self.car.wheelbase * curvature) / self.car.max_steer
        left, speed = float(obs["remaining"][0]), float(obs["speed"][0])
        target = min(self.cruise_speed, math.sqrt(1.5 / max(abs(curvature), 1e-6)),  # 1.5 m/s^2 sideways
                     max(0.3, math.sqrt(2.0 * 1.0 * max(left - 0.2, 0.0))))  # stop on the goal at 1 m/s^2
        throttle = -1.0 if left < 0.2 else (target - speed) / 0.5
        return np.clip([throttle, steer], -1.0, 1.0).astype(np.float32)


@pytest.mark.garage_mj(maps=["tiny_7x11"], tests=3)  # the defaults of this test; --garage-* options override
def test_my_driver_parks(garage_cruise):
    results = garage_cruise(MyDriver)  # a results table: .rows (tests.csv), .summary, .stats, .failures
    print(results)  # pytest -s shows the per-garage table
    results.assert_success()  # every feasible test a success, else each failure with its MP4 and .xosc


@pytest.mark.parametrize("garage_drive_env", [{"action_type": "continuous"}], indirect=True)
def test_my_driver_in_the_env(garage_drive_env):
    """The drive env on tiny_7x11, stepped by hand: a gymnasium env, one cruise test per episode."""
    env, driver = garage_drive_env, MyDriver()
    obs, info = env.reset(seed=0)
    driver.reset(env.driver_info(seed=0))
    while "outcome" not in info:
        obs, reward, terminated, truncated, info = env.step(driver.act(obs))
    assert info["outcome"] == "success", info["reason"]
