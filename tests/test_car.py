"""The car model: compiles and steps without warnings, drives straight, turns the commanded way, stops."""

from __future__ import annotations

import importlib.resources
import math
import time

import mujoco
import numpy as np
import pytest

from garage_mj.driving.sim.vehicle import Car, DiscreteAction, command_from_action
from tests._scenes import build

DT = 0.1  # [s] control period


def drive(model, data, car, seconds, throttle, steer):
    n = round(DT / model.opt.timestep)
    for _ in range(round(seconds / DT)):
        car.control(data, throttle, steer, DT)
        for _ in range(n):
            mujoco.mj_step(model, data)


def assert_no_warnings(data):
    counts = {mujoco.mjtWarning(i).name: w.number for i, w in enumerate(data.warning) if w.number}
    assert not counts, counts


@pytest.mark.parametrize("xml", ["car.xml", "scene.xml"])
def test_model_files_compile_and_step(xml):
    path = importlib.resources.files("garage_mj.models") / "car" / xml
    with importlib.resources.as_file(path) as p:
        model = mujoco.MjModel.from_xml_path(str(p))
    data = mujoco.MjData(model)
    for _ in range(500):
        mujoco.mj_step(model, data)
    assert_no_warnings(data)
    assert {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)} >= {"front", "top"}
    assert model.nu == 8


@pytest.mark.parametrize("timestep", [0.002, 0.005])
def test_drives_straight_turns_and_stops(timestep):
    model, data, car = build(timestep=timestep)
    assert car.wheelbase == pytest.approx(2.7) and car.track == pytest.approx(1.6)
    drive(model, data, car, 4.0, 1.0, 0.0)
    x, y, yaw = car.pose(data)
    assert car.speed(data) == pytest.approx(car.config.max_speed, abs=0.15)
    assert x > 8.0 and abs(y) < 0.05 and abs(yaw) < 0.01
    drive(model, data, car, 2.0, 0.0, 1.0)  # full left at speed
    _, y_left, yaw_left = car.pose(data)
    assert yaw_left > 1.0 and y_left > 1.0
    x0, y0, _ = car.pose(data)
    drive(model, data, car, 2.5, -1.0, 0.0)
    x1, y1, _ = car.pose(data)
    assert abs(car.speed(data)) < 0.05
    assert math.hypot(x1 - x0, y1 - y0) < 3.5  # from 4 m/s
    assert_no_warnings(data)


def test_turns_right_and_respects_steer_rate():
    model, data, car = build()
    drive(model, data, car, 2.0, 1.0, 0.0)
    car.control(data, 0.0, -1.0, DT)
    assert car.steer_angle == pytest.approx(-car.config.steer_rate * DT)
    drive(model, data, car, 3.0, 0.0, -1.0)
    _, y, yaw = car.pose(data)
    assert yaw < -1.0 and y < -1.0
    assert car.steer_angle == pytest.approx(-car.config.max_steer)


def test_never_reverses_and_reset_places_car():
    model, data, car = build()
    drive(model, data, car, 2.0, -1.0, 0.0)
    assert abs(car.pose(data)[0]) < 0.05
    car.reset(data, 3.0, -2.0, math.pi / 2)
    assert np.allclose(car.pose(data), (3.0, -2.0, math.pi / 2), atol=1e-6)
    assert car.speed(data) == 0.0 and car.cruise_speed == 0.0


def test_discrete_actions_map_to_commands():
    assert command_from_action(DiscreteAction.ACCELERATE) == (1.0, 0.0)
    assert command_from_action(1) == (0.0, 1.0)
    assert command_from_action(np.int64(2)) == (0.0, -1.0)
    assert command_from_action([-3.0, 0.5]) == (-1.0, 0.5)
    with pytest.raises(ValueError, match="discrete action"):
        command_from_action(7)
    with pytest.raises(ValueError, match="throttle, steer"):
        command_from_action([1.0, 0.0, 0.0])


def test_missing_car_is_a_clear_error():
    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
    with pytest.raises(ValueError, match="no car body named 'ego/chassis'"):
        Car(model)


def test_physics_is_fast():
    model, data, car = build()
    car.control(data, 1.0, 0.3, DT)
    steps = 5000
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    rtf = steps * model.opt.timestep / (time.perf_counter() - t0)
    assert rtf > 20.0, f"real-time factor {rtf:.1f}"


FRONT = '<camera name="front" pos="2.25 0 0.85" xyaxes="0 -1 0 0.173648 0 0.984808" fovy="90"/>'


def test_camera_geometry_is_read_from_the_car_model():
    from garage_mj.driving.drivers.base import CameraGeometry
    from garage_mj.scene.car import car_xml_path

    assert FRONT in car_xml_path().read_text()
    # the numbers the vision driver used when they were typed in by hand, to the bit
    assert CameraGeometry() == CameraGeometry(x=2.25, z=1.18, pitch=math.radians(10.0), fovy=90.0)
    assert CameraGeometry.from_model() == CameraGeometry()
    assert CameraGeometry(fovy=60.0).x == 2.25  # a partial override keeps the model's other numbers


def test_moving_the_camera_in_the_mjcf_moves_camera_geometry(tmp_path):
    from garage_mj.driving.drivers.base import CameraGeometry
    from garage_mj.scene.car import car_xml_path

    xml = car_xml_path().read_text()
    moved = tmp_path / "car.xml"
    moved.write_text(xml.replace(FRONT, '<camera name="front" pos="2.0 0 0.95" '
                                        'xyaxes="0 -1 0 0.342020 0 0.939693" fovy="70"/>'))
    cam = CameraGeometry.from_model(path=moved)
    assert cam.x == 2.0 and cam.z == pytest.approx(0.33 + 0.95, abs=1e-12)
    assert cam.pitch == math.radians(20.0) and cam.fovy == 70.0
    aside = tmp_path / "aside.xml"
    aside.write_text(xml.replace(FRONT, FRONT.replace('pos="2.25 0 0.85"', 'pos="2.25 0.4 0.85"')))
    with pytest.raises(ValueError, match="centre line"):
        CameraGeometry.from_model(path=aside)
