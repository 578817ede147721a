"""The oracle parks (SPEC 8): its plan tracker follows forward and reverse segments with the real car dynamics."""

from __future__ import annotations

import inspect
import math

import mujoco
import numpy as np
import pytest

from garage_mj.driving.drivers import BaseDriver, load_driver
from garage_mj.driving.drivers.park_tracking import ParkTracker
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.vehicle import Gear
from garage_mj.scene.car import car_geometry
from garage_mj.scene.park_planning import rear_to_centre
from tests._scenes import build

CAR = car_geometry()
DT = 0.1  # [s] control period


def synthetic_plan(parts: list[tuple[int, float, float]], step: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Car-centre poses and gears of a rear-axle path made of ``(gear, length [m], yaw change per metre)`` parts."""
    x = y = yaw = 0.0
    rear, gears = [(x, y, yaw)], []
    for gear, length, kyaw in parts:
        for _ in range(round(length / step)):
            yaw0 = yaw
            yaw += kyaw * step
            mid = (yaw0 + yaw) / 2
            x += gear * step * math.cos(mid)
            y += gear * step * math.sin(mid)
            rear.append((x, y, yaw))
            gears.append(gear)
    return rear_to_centre(np.array(rear), CAR), np.array([*gears, gears[-1]], dtype=np.int8)


def track(poses: np.ndarray, gears: np.ndarray, max_time: float = 60.0):
    """Drive the real car along the plan with the tracker; (final pose, tracker, gears engaged, max lateral error)."""
    model, data, car = build(pose=tuple(poses[0]))
    tracker = ParkTracker(poses, gears, CAR, dt=DT)
    n = round(DT / model.opt.timestep)
    engaged, worst = [], 0.0
    while data.time < max_time and not tracker.done:
        pedal, steer, gear = tracker.command(car.pose(data), car.speed(data))
        worst = max(worst, abs(tracker.errors(car.pose(data))[1]))
        car.park_control(data, pedal, steer, gear, DT)
        if not engaged or engaged[-1] is not car.gear:
            engaged.append(car.gear)
        for _ in range(n):
            mujoco.mj_step(model, data)
    return car.pose(data), tracker, engaged, worst


def test_the_tracker_drives_forward_then_reverses_through_a_cusp_onto_the_end_pose():
    # forward: a straight and a left curve; cusp; reverse: a right curve (seen from the car) and a straight
    poses, gears = synthetic_plan([(1, 3.0, 0.0), (1, 2.0, 0.25), (-1, 2.5, -0.3), (-1, 2.0, 0.0)])
    pose, tracker, engaged, worst = track(poses, gears)
    assert tracker.done and [s.gear for s in tracker.segments] == [Gear.D, Gear.R]
    assert engaged == [Gear.D, Gear.R]  # one gear change, at the cusp
    gx, gy, gyaw = poses[-1]
    assert math.hypot(pose[0] - gx, pose[1] - gy) <= 0.1
    assert abs(math.degrees(math.remainder(pose[2] - gyaw, math.tau))) <= 3.0
    assert worst < 0.15  # it stays on the path all along, not only at the end


def test_the_oracle_tracks_a_park_plan_from_its_reset_info_with_park_actions():
    poses, gears = synthetic_plan([(1, 2.0, 0.0), (1, 1.5, -0.3), (-1, 3.0, 0.3)])
    driver = load_driver("oracle")
    driver.reset({"seed": 0, "dt": DT, "task": "park", "park_plan": {"poses": poses, "directions": gears,
                                                                      "stall_pose": tuple(poses[-1])}})
    model, data, car = build(pose=tuple(poses[0]))
    n = round(DT / model.opt.timestep)
    reversed_ = False
    while data.time < 60.0:
        x, y, yaw = car.pose(data)
        action = driver.act({"pose": np.array([x, y, yaw]), "speed": np.array([car.speed(data)]),
                             "gear": np.array([car.gear.value], dtype=np.float32)})
        assert action.shape == (3,)  # [pedal, steer, gear]
        car.park_act(data, action, DT)
        reversed_ |= car.gear is Gear.R
        for _ in range(n):
            mujoco.mj_step(model, data)
        if driver.tracker.done:
            break
    assert driver.tracker.done and reversed_
    x, y, yaw = car.pose(data)
    assert math.hypot(x - poses[-1, 0], y - poses[-1, 1]) <= 0.1


def test_without_a_park_plan_the_oracle_acts_exactly_as_in_cruise(painted_tiny):
    """Cruise parity: the oracle's actions are BaseDriver.act's (its cruise path) at every step of a test."""
    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous")
    try:
        obs, _ = env.reset(seed=2)
        driver, twin = load_driver("oracle"), load_driver("oracle")
        driver.reset(env.driver_info(2))
        twin.reset(env.driver_info(2))
        assert driver.tracker is None
        while True:
            action = driver.act(obs)
            assert action.shape == (2,) and np.array_equal(action, BaseDriver.act(twin, obs))
            obs, _, term, trunc, info = env.step(action)
            if term or trunc:
                break
        assert info["outcome"] == "success"
    finally:
        env.close()


# -- end to end in the drive env's park and AVP tasks ----------------------------------------------------
needs_park_env = pytest.mark.skipif("task" not in inspect.signature(GarageDriveEnv).parameters,
                                    reason="the drive env has no park task yet")


def _drive(env: GarageDriveEnv, driver: str, seed: int) -> dict:
    obs, info = env.reset(seed=seed)
    d = load_driver(driver)
    d.reset(env.driver_info(seed))
    while "outcome" not in info:
        obs, _, _, _, info = env.step(d.act(obs))
    return info


@needs_park_env
@pytest.mark.parametrize("task", ["park", "avp"])
def test_the_oracle_parks_on_the_tiny_garage(painted_tiny, task):
    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", task=task, maneuver="any")
    try:
        for seed in range(3):
            info = _drive(env, "oracle", seed)
            assert info["outcome"] == "success", (seed, info["reason"])
            assert info["position_error"] < 0.15
    finally:
        env.close()


@needs_park_env
@pytest.mark.parametrize("maneuver", ["reverse", "forward"])
def test_park_assist_runs_a_park_test_to_an_outcome(painted_tiny, maneuver):
    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", task="park", maneuver=maneuver)
    try:
        info = _drive(env, "park_assist", 0)
        assert info["outcome"] in ("success", "collision", "outside_stall", "deadlock", "timeout")
    finally:
        env.close()


def test_park_assist_says_it_parks_only():
    driver = load_driver("park_assist")
    driver.reset({"seed": 0})
    with pytest.raises(ValueError, match="park_assist driver parks"):
        driver.act({"speed": np.array([0.0])})
