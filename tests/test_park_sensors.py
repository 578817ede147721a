"""A parking car's sensors (garage_mj.driving.sim.park_sensors): the rear camera, the bumper rangefinders and the slot
detector, on every vehicle class, opt-in so that an env without them observes exactly what it did."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from garage_mj.driving.drivers.oracle import OracleDriver
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.observations import ObservationSetup, observation_spaces
from garage_mj.driving.sim.park_sensors import (
    ULTRASONIC_MAX,
    ULTRASONIC_MIN,
    SensorConfig,
    Ultrasonic,
    sensor_config,
    slot_pose,
)
from garage_mj.driving.sim.sensors import Camera, CameraConfig
from garage_mj.driving.sim.vehicle import Car, attach_car, compile_mjcf
from garage_mj.scene.car import (
    CAMERA_SETBACK,
    REAR_CAMERA,
    ULTRASONIC_SENSORS,
    WHEEL_RADIUS,
    car_camera,
    car_model,
    ultrasonic_positions,
)
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.mjcf_scene import build_scene
from garage_mj.scene.semantics import Semantic
from garage_mj.scene.vehicles import FLEET
from tests._scenes import arena


class SensorCheckingOracle(OracleDriver):
    """The oracle, failing where an observation lacks a parking sensor (a driver the pytest plugin runs by name)."""

    def act(self, obs):
        missing = [k for k in ("rear_depth", "rear_segmentation", "ultrasonic", "slot") if k not in obs]
        if missing:
            raise AssertionError(f"no {', '.join(missing)} in the observation")
        return super().act(obs)


CLASSES = list(FLEET.values())
BUMPER_HEIGHT = 0.5  # [m] above the ground: where the ultrasonic sensors sit
SENSOR_KEYS = ("rear_depth", "rear_segmentation", "ultrasonic", "slot")


def _scene(vehicle, boxes=(), hidden=()):
    """(model, data, car) of ``vehicle`` at the origin facing +x, among ``boxes`` (tests._scenes.arena's); the boxes
    named in ``hidden`` are transparent, as an empty stall's parked car is."""
    root = arena(boxes)
    for name in hidden:
        root.find("geom", name).rgba = [0.3, 0.4, 0.8, 0.0]
    attach_car(root, 0.0, 0.0, 0.0, vehicle=vehicle, ultrasonic=True)
    model = compile_mjcf(root)
    data = mujoco.MjData(model)
    car = Car(model)
    car.reset(data, 0.0, 0.0, 0.0)
    return model, data, car


def _index(name: str) -> int:
    return ULTRASONIC_SENSORS.index(name)


# -- the car model ------------------------------------------------------------------------------------
@pytest.mark.parametrize("vehicle", CLASSES, ids=lambda v: v.name)
def test_every_class_carries_a_rear_camera_and_bumper_sensors(vehicle):
    root = car_model(vehicle)
    model = mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    half, hw = vehicle.length / 2, vehicle.width / 2
    front, rear = car_camera(vehicle=vehicle), car_camera(REAR_CAMERA, vehicle=vehicle)
    assert rear["x"] == pytest.approx(-(half - CAMERA_SETBACK)) and front["x"] == pytest.approx(half - CAMERA_SETBACK)
    assert {k: rear[k] for k in ("z", "pitch", "fovy")} == {k: front[k] for k in ("z", "pitch", "fovy")}
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, REAR_CAMERA)
    look = -data.cam_xmat[cam].reshape(3, 3)[:, 2]  # a camera looks along its -z axis
    assert look[0] < -0.98 and look[2] < 0  # backwards, tilted down
    positions = ultrasonic_positions(vehicle.length, vehicle.width)
    for n in ULTRASONIC_SENSORS:
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, n)
        sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, n)
        assert site >= 0 and model.sensor_type[sensor] == mujoco.mjtSensor.mjSENS_RANGEFINDER
        assert model.sensor_objid[sensor] == site
        x, y, z = data.site_xpos[site] - data.xpos[model.site_bodyid[site]] + [0, 0, WHEEL_RADIUS]
        assert (x, y) == pytest.approx(positions[n]) and z == pytest.approx(BUMPER_HEIGHT)
        ray = data.site_xmat[site].reshape(3, 3)[:, 2]  # a rangefinder looks along its site's z axis
        assert ray[2] == pytest.approx(0.0, abs=1e-9)  # level
        end = 1 if "_f_" in n else -1
        if "side" in n:  # on the body side, looking straight out of it, ahead of the wheels
            assert abs(y) == pytest.approx(hw) and ray[1] * y == pytest.approx(abs(y))
            assert end * x > vehicle.length / 2 - vehicle.front_overhang if end > 0 else -x > half - vehicle.rear_overhang
        else:  # on the bumper, within the body's width, looking out of it
            assert x == pytest.approx(end * half) and abs(y) < hw and ray[0] * end > 0.8
            if "outer" in n:
                assert ray[1] * y > 0  # a corner sensor turns outward


def test_sedan_model_is_the_model_file():
    assert car_model(FLEET["sedan"]).to_xml_string() == car_model(None).to_xml_string()


# -- ultrasonic ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("vehicle", CLASSES, ids=lambda v: v.name)
def test_rangefinders_read_walls_at_known_distances_and_nothing_else(vehicle):
    half, hw = vehicle.length / 2, vehicle.width / 2
    front_gap, rear_gap, side_gap = 1.5, 2.75, 0.8  # [m] bumper or body side to the wall
    boxes = [("wall_front", (half + front_gap + 0.1, 0.0, 1.0), (0.1, 0.6, 1.0)),  # only the inner pair sees it
             ("pillar_rear", (-half - rear_gap - 0.1, 0.0, 1.0), (0.1, 6.0, 1.0)),
             ("wall_left", (half - 0.4, hw + side_gap + 0.1, 1.0), (0.2, 0.1, 1.0))]
    model, data, _ = _scene(vehicle, boxes)
    got = Ultrasonic(model).read(data)
    want = np.full(len(ULTRASONIC_SENSORS), ULTRASONIC_MAX)  # the floor and the car itself: no echo
    want[[_index("us_f_inner_l"), _index("us_f_inner_r")]] = front_gap
    want[[_index("us_r_inner_l"), _index("us_r_inner_r")]] = rear_gap
    want[[_index("us_r_outer_l"), _index("us_r_outer_r")]] = rear_gap / math.cos(math.radians(30))
    want[_index("us_f_side_l")] = side_gap
    assert got == pytest.approx(want, abs=0.05)
    assert got.dtype == np.float32


def test_rangefinders_see_parked_cars_and_kerbs_not_hidden_ones_and_clip_to_their_range():
    sedan = FLEET["sedan"]
    boxes = [("parkedcar_3_hull", (2.3 + 1.0 + 2.15, 0.0, 0.5), (2.15, 0.95, 0.45)),  # a parked car 1 m ahead
             ("parkedcar_4_hull", (-2.3 - 0.5 - 2.15, 0.0, 0.5), (2.15, 0.95, 0.45)),  # an empty stall's, hidden
             ("wall_kerb_0", (-2.3 - 2.0, 0.0, 1.0), (0.05, 4.0, 1.0)),  # a kerb wall 2 m behind the hidden car's front
             ("pillar_1", (1.9, -0.95 - 0.1 - 0.3, 1.0), (0.3, 0.3, 1.0)),  # a pillar 0.1 m off the right side
             ("wall_far", (1.9, 0.95 + 6.0, 1.0), (1.0, 0.1, 1.0))]  # a wall 5.9 m off the left side: out of range
    model, data, _ = _scene(sedan, boxes, hidden=["parkedcar_4_hull"])
    got = Ultrasonic(model).read(data)
    assert got[_index("us_f_inner_l")] == pytest.approx(1.0, abs=0.05)
    assert got[_index("us_r_inner_r")] == pytest.approx(1.95, abs=0.05)  # the kerb, through the hidden car
    assert got[_index("us_f_side_r")] == ULTRASONIC_MIN  # 0.1 m reads the minimum
    assert got[_index("us_f_side_l")] == ULTRASONIC_MAX  # beyond reach reads the maximum
    assert ((got >= ULTRASONIC_MIN) & (got <= ULTRASONIC_MAX)).all()


def test_rangefinders_see_actors_while_they_are_in_the_scene():
    from garage_mj.driving.actors.config import ScenarioConfig
    from garage_mj.scene.actor_bodies import ActorBodies, add_actor_bodies

    cfg = ScenarioConfig(pedestrians=1, moving_cars=1)
    root = arena()
    add_actor_bodies(root, cfg)
    attach_car(root, 0.0, 0.0, 0.0, ultrasonic=True)
    model = compile_mjcf(root)
    data = mujoco.MjData(model)
    Car(model).reset(data, 0.0, 0.0, 0.0)
    bodies, sonar = ActorBodies(model, cfg), Ultrasonic(model)
    for name in bodies.mocap:  # in the scene (a placed actor is opaque; an unused slot transparent)
        model.geom_rgba[bodies.geoms[name], 3] = 1.0
    ActorBodies.set_pose(data, bodies.mocap["pedestrian_0"], (2.3 + 1.5, 0.0, 0.0))  # 1.5 m ahead of the bumper
    ActorBodies.set_pose(data, bodies.mocap["movingcar_0"], (-2.3 - 2.0 - 2.5, 0.0, 0.0))  # about 2 m behind
    mujoco.mj_forward(model, data)
    got = sonar.read(data)
    assert 1.0 < min(got[_index("us_f_inner_l")], got[_index("us_f_inner_r")]) < 1.55
    assert 1.0 < min(got[_index("us_r_inner_l")], got[_index("us_r_inner_r")]) < 2.6
    for name in bodies.mocap:  # unused slots: transparent, never seen
        model.geom_rgba[bodies.geoms[name], 3] = 0.0
    assert (sonar.read(data) == ULTRASONIC_MAX).all()


def test_the_rays_cast_per_observation_are_mujocos_rangefinders(painted_tiny):
    scene = GarageScene(painted_tiny)
    root = build_scene(scene, fuse_static=True)
    attach_car(root, *scene.entrance_pose, ultrasonic=True)  # the car with its MuJoCo rangefinder sensors
    model = compile_mjcf(root)
    data = mujoco.MjData(model)
    car, sonar = Car(model), Ultrasonic(model)
    adr = [model.sensor_adr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, "ego/" + n)] for n in ULTRASONIC_SENSORS]
    rng = np.random.default_rng(0)
    echoes = 0
    for stall in scene.stalls.stalls:  # the car on its cruise goal beside each stall, turned every which way
        car.reset(data, stall.road_x, stall.road_y, float(rng.uniform(-math.pi, math.pi)))  # runs mj_forward
        assert np.array_equal(sonar.raw(data), data.sensordata[adr])
        echoes += int((sonar.raw(data) >= 0).sum())
    assert echoes > 0


# -- rear camera --------------------------------------------------------------------------------------
def test_rear_camera_sees_a_parked_car_behind_and_shares_the_front_context():
    boxes = [("parkedcar_2_hull", (-2.3 - 2.0 - 2.15, 0.0, 0.5), (2.15, 0.95, 0.45))]  # 2 m behind the bumper
    model, data, _ = _scene(None, boxes)
    front = Camera(model, CameraConfig())
    rear = Camera(model, CameraConfig(camera="ego/rear"), share=front)
    alone = Camera(model, CameraConfig(camera="ego/rear"))
    try:
        seen = rear.render(data)
        seg = seen["segmentation"]
        assert (seg[30:42, 24:40] == Semantic.PARKED_CAR).all()  # the car fills the middle of the image
        assert (seg[34:] != Semantic.BACKGROUND).all()  # the floor everywhere below: no rangefinder rays drawn
        assert not (front.render(data)["segmentation"] == Semantic.PARKED_CAR).any()  # and is not ahead
        mid = seen["depth"][32, 28:36]
        assert 1.9 < mid.min() and mid.max() < 2.4  # its back about 2 m behind (along the tilted axis)
        own = alone.render(data)
        assert all(np.array_equal(seen[k], own[k]) for k in seen)  # a borrowed context renders the same images
    finally:
        rear.close(), alone.close(), front.close()


# -- the drive env ------------------------------------------------------------------------------------
def test_default_observations_unchanged(painted_tiny):
    plain = GarageDriveEnv(painted_tiny, task="park")
    fitted = GarageDriveEnv(painted_tiny, task="park", sensors="all")
    assert set(plain.observation_space.spaces) == set(observation_spaces(ObservationSetup(task="park")))
    assert not set(SENSOR_KEYS) & set(plain.observation_space.spaces)
    assert set(fitted.observation_space.spaces) == set(plain.observation_space.spaces) | set(SENSOR_KEYS)
    assert fitted.model.nsensor == plain.model.nsensor  # the rays are cast per observation, not per physics step
    a, _ = plain.reset(seed=3)
    b, _ = fitted.reset(seed=3)
    for _ in range(5):
        assert list(a) == [k for k in b if k not in SENSOR_KEYS]
        for k in a:
            assert a[k].shape == b[k].shape and np.array_equal(a[k], b[k]), k
        assert fitted.observation_space.contains(b)
        a, *_ = plain.step(1)
        b, *_ = fitted.step(1)
    plain.close(), fitted.close()


def test_slot_detector_reports_the_stall_in_the_car_frame(painted_tiny):
    env = GarageDriveEnv(painted_tiny, task="park", sensors={"slot": True})
    obs, info = env.reset(seed=1)
    stall = env.stalls[env.target]
    x, y, yaw = info["pose"]
    dx, dy = stall.x - x, stall.y - y
    want = [math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy,
            math.remainder(stall.yaw - yaw, math.tau), stall.width, stall.length]
    assert obs["slot"] == pytest.approx(want, abs=1e-5)
    obs, _, _, _, info = env.step(1)  # and still after the car moved
    assert obs["slot"] == pytest.approx(slot_pose(stall, *info["pose"]), abs=1e-6)
    env.close()


def test_slot_detector_noise_is_seeded_and_leaves_other_draws_alone(painted_tiny):
    noisy = {"slot": True, "slot_position_sigma": 0.3, "slot_yaw_sigma": 0.05}
    exact = GarageDriveEnv(painted_tiny, task="park", sensors={"slot": True})
    env = GarageDriveEnv(painted_tiny, task="park", sensors=noisy)
    twin = GarageDriveEnv(painted_tiny, sensors=noisy, task="park")
    errors = []
    for seed in range(4):
        a, ia = exact.reset(seed=seed)
        b, ib = env.reset(seed=seed)
        c, _ = twin.reset(seed=seed)
        assert ia["target_stall"] == ib["target_stall"] and ia["pose"] == ib["pose"]  # the test's draws unchanged
        assert all(np.array_equal(a[k], b[k]) for k in a if k != "slot")
        assert np.array_equal(b["slot"], c["slot"])  # the same seed, the same noise
        assert np.array_equal(b["slot"][3:], a["slot"][3:])  # the size is exact
        errors.append(b["slot"][:3] - a["slot"][:3])
        b2, *_ = env.step(0)
        a2, *_ = exact.step(0)
        errors.append(b2["slot"][:3] - a2["slot"][:3])  # a fresh draw per observation
    errors = np.array(errors)
    assert (np.abs(errors) > 0).all() and len({tuple(e) for e in errors.round(6)}) == len(errors)
    assert np.abs(errors[:, :2]).max() < 5 * 0.3 and np.abs(errors[:, 2]).max() < 5 * 0.05
    for e in (exact, env, twin):
        e.close()


def test_sensor_config_is_checked():
    assert sensor_config("rear_camera, ultrasonic") == SensorConfig(rear_camera=True, ultrasonic=True)
    assert sensor_config("all").any and not sensor_config(None).any
    with pytest.raises(ValueError, match="unknown sensor 'lidar'"):
        sensor_config("lidar")
    with pytest.raises(ValueError, match="slot_yaw_sigma"):
        SensorConfig(slot=True, slot_yaw_sigma=-0.1)
    with pytest.raises(ValueError):
        sensor_config({"sonar": True})  # unknown keys are an error


def test_cruise_env_observes_the_rear_camera_and_ranges(painted_tiny):
    env = GarageDriveEnv(painted_tiny, sensors=["rear_camera", "ultrasonic"], image_obs=True)
    obs, _ = env.reset(seed=0)
    assert obs["rear_depth"].shape == (64, 64, 1) and obs["rear_segmentation"].dtype == np.uint8
    assert obs["ultrasonic"].shape == (12,) and "slot" not in obs
    assert env.observation_space.contains(obs)
    env.close()


def test_cruise_cli_observes_the_sensors_it_is_given(painted_tiny, tmp_path, capsys):
    import json

    from garage_mj.cli import main
    from garage_mj.export.pack import export_pack

    packs = tmp_path / "packs"
    export_pack(painted_tiny, packs)
    out = tmp_path / "run"
    assert main(["cruise", "--packs", str(packs), "--tests", "1", "--driver", "oracle", "--task", "park",
                 "--sensors", "rear_camera,ultrasonic,slot", "--slot-noise", "0.1", "0.02", "--out", str(out),
                 "--quiet"]) == 0
    assert json.loads((out / "run.json").read_text())["env"] == {"sensors": {
        "rear_camera": True, "ultrasonic": True, "slot": True, "slot_position_sigma": 0.1, "slot_yaw_sigma": 0.02}}
    capsys.readouterr()
    assert main(["cruise", "--packs", str(packs), "--tests", "1", "--sensors", "ultrasonic", "--slot-noise", "0.1",
                 "0", "--out", str(tmp_path / "refused"), "--quiet"]) != 0
    assert "add slot to --sensors" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["cruise", "--packs", str(packs), "--sensors", "lidar", "--out", str(tmp_path / "bad")])
    assert "unknown sensor 'lidar'" in capsys.readouterr().err


def test_the_pytest_plugin_hands_sensors_to_the_env(garage_cruise):
    import pytest_garage_mj as plugin

    assert set(plugin.SENSORS) == {f.name for f in dataclasses.fields(SensorConfig) if f.type in (bool, "bool")}
    tests = garage_cruise(SensorCheckingOracle, tests=1, task="park", sensors="all")
    assert [r["outcome"] for r in tests.rows] == ["success"]
