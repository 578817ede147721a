"""The oracle parks (SPEC 8): its plan tracker follows forward and reverse segments with the real car dynamics."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from garage_mj.driving.drivers.park_tracking import ParkTracker
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
