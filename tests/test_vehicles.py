"""Vehicle classes (docs/spec.md section 9): the car under test is a real class of the fleet, in MuJoCo and
everywhere that plans or judges; parked cars come from the fleet, seeded, and stand where the planner sees them."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from garage_mj.driving.drivers import load_driver
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.vehicle import Car, attach_car, compile_mjcf
from garage_mj.scene.car import WHEEL_RADIUS, car_body, car_geometry, car_model
from garage_mj.scene.vehicles import FLEET, TPCAP_VEHICLE
from tests._scenes import arena

CLASSES = [*FLEET.values(), TPCAP_VEHICLE]
DT = 0.1  # [s] control period


def _compiled(vehicle) -> mujoco.MjModel:
    root = car_model(vehicle)
    return mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())


@pytest.mark.parametrize("vehicle", CLASSES, ids=lambda v: v.name)
def test_each_class_compiles_to_the_outline_axles_and_height_of_its_table_row(vehicle):
    model = _compiled(vehicle)
    body, want = car_body(model), vehicle.geometry()
    for key, value in body.items():
        assert value == pytest.approx(getattr(want, key), abs=1e-9), key
    cabin = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "cabin_col")
    roof = WHEEL_RADIUS + model.geom_pos[cabin, 2] + model.geom_size[cabin, 2]
    assert roof == pytest.approx(vehicle.height, abs=1e-9)
    front = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "front")
    assert 0 < want.front - model.cam_pos[front, 0] < 0.1  # the camera sits just behind this class's bumper
    # the steering joints reach the inner wheel's angle at the class's full lock
    car = Car(model, vehicle.car_config(), prefix="")
    tan_d = math.tan(vehicle.max_steer)
    inner = math.atan(car.wheelbase * tan_d / (car.wheelbase - car.track / 2 * tan_d))
    steer = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "steer_fl")
    assert model.jnt_range[steer, 1] > inner


def test_sedan_is_models_car_exactly():
    assert car_model(FLEET["sedan"]).to_xml_string() == car_model(None).to_xml_string()
    assert FLEET["sedan"].geometry() == car_geometry()


@pytest.mark.parametrize("vehicle", CLASSES, ids=lambda v: v.name)
def test_the_car_turns_at_its_full_lock_radius_in_mujoco(vehicle):
    root = arena()
    attach_car(root, 0.0, 0.0, 0.0, vehicle=vehicle)
    model = compile_mjcf(root)
    data = mujoco.MjData(model)
    car = Car(model, vehicle.car_config())
    car.reset(data, 0.0, 0.0, 0.0)
    rear_axle = vehicle.geometry().rear_axle
    n = round(DT / model.opt.timestep)
    points = []
    for k in range(120):  # at about 1.5 m/s, full lock left: the steering settles within the first 3 s
        car.control(data, 1.0 if car.speed(data) < 1.5 else 0.0, 1.0, DT)
        for _ in range(n):
            mujoco.mj_step(model, data)
        x, y, yaw = car.pose(data)
        if k >= 40:
            points.append((x + rear_axle * math.cos(yaw), y + rear_axle * math.sin(yaw)))
    p = np.array(points)
    (cx, cy, c), *_ = np.linalg.lstsq(np.c_[2 * p, np.ones(len(p))], (p ** 2).sum(axis=1), rcond=None)
    radius = math.sqrt(c + cx ** 2 + cy ** 2)  # the rear axle's circle, fitted
    assert radius == pytest.approx(vehicle.min_radius, rel=0.02)


def test_the_env_plans_judges_and_observes_with_the_class(painted_tiny):
    van = FLEET["van"]
    env = GarageDriveEnv(painted_tiny, action_type="continuous", task="park", vehicle="van")
    assert env.car_geometry == van.geometry() and env.car_config.max_steer == van.max_steer
    assert env.planner.car is env.car_geometry and env.park_planner.car is env.car_geometry
    for key, value in car_body(env.model, "ego/").items():  # the MuJoCo car is the van
        assert value == pytest.approx(getattr(van.geometry(), key), abs=1e-9), key
    obs, info = env.reset(seed=0)
    assert env.monitor.car is env.car_geometry and env.driver_info(0)["car"] is env.car_geometry
    env.close()
    # the default env is models/car with the car config's full lock, as before classes existed
    default = GarageDriveEnv(painted_tiny, car={"max_steer": 0.5})
    assert default.vehicle is None and default.car_geometry == car_geometry(default.car_config)
    assert default.car_geometry.max_steer == 0.5
    default.close()


def test_a_vehicle_outside_the_fleet_or_a_second_full_lock_is_refused(painted_tiny):
    with pytest.raises(ValueError, match="vehicle 'truck' is not in the fleet; choose one of compact, sedan, suv, van"):
        GarageDriveEnv(painted_tiny, vehicle="truck")
    with pytest.raises(ValueError, match="vehicle 'suv' steers to 0.6 rad at full lock"):
        GarageDriveEnv(painted_tiny, vehicle="suv", car={"max_steer": 0.5})


@pytest.mark.parametrize("name", list(FLEET))
def test_the_oracle_parks_every_class_on_the_tiny_garage(painted_tiny, name):
    env = GarageDriveEnv(painted_tiny, action_type="continuous", task="park", vehicle=name)
    obs, info = env.reset(seed=1)
    assert info["feasible"], info
    driver = load_driver("oracle")
    driver.reset(env.driver_info(1))
    while True:
        obs, _, term, trunc, info = env.step(driver.act(obs))
        if term or trunc:
            break
    env.close()
    assert info["outcome"] == "success", info["reason"]
