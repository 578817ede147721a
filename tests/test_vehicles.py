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
    camera = env.driver_info(0)["camera"]  # where a camera driver's geometry says the van's camera is
    front = mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_CAMERA, "ego/front")
    assert camera["x"] == pytest.approx(env.model.cam_pos[front, 0]) and camera["x"] > car_geometry().front
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


# -- parked cars as real bodies ---------------------------------------------------------------------------------
def _hull_outline(model, data, geom: int) -> np.ndarray:
    """(4, 2) the floor outline of a box geom as the compiled model and data hold it."""
    rot = data.geom_xmat[geom].reshape(3, 3)
    hx, hy, _ = model.geom_size[geom]
    local = np.array([[hx, hy, 0], [-hx, hy, 0], [-hx, -hy, 0], [hx, -hy, 0]])
    return (data.geom_xpos[geom] + local @ rot.T)[:, :2]


def _same_outline(a: np.ndarray, b: np.ndarray) -> bool:
    return any(np.allclose(np.roll(a, k, axis=0), b, atol=1e-9) for k in range(4))


def test_a_mixed_jittered_fleet_is_drawn_from_the_test_seed_alone(painted_tiny):
    fleet = {"parked_fleet": "mixed", "parked_jitter": 0.5}
    env = GarageDriveEnv(painted_tiny, **fleet)
    env.reset(seed=7)
    first = dict(env.parked_bodies)
    env.reset(seed=3)
    assert env.parked_bodies != first  # another test, other cars
    env.reset(seed=7)
    assert env.parked_bodies == first and set(first) == set(env.occupied)
    assert {b.vehicle for b in first.values()} <= set(FLEET) and len({b.vehicle for b in first.values()}) > 1
    # a fresh env (another worker process) draws the same cars for the same test seed
    other = GarageDriveEnv(painted_tiny, **fleet)
    other.reset(seed=7)
    assert other.parked_bodies == first
    other.close()
    # the test's other draws are those of the default fleet: same target, parked stalls and start
    default = GarageDriveEnv(painted_tiny)
    _, info = default.reset(seed=7)
    assert (default.target, default.occupied, default.start_pose) == (env.target, env.occupied, env.start_pose)
    assert default.parked_bodies == {}  # the scene's own cars, never moved
    default.close()
    env.close()


def test_jitter_stays_in_bounds_and_out_of_the_target_stall_and_other_cars(painted_tiny):
    from garage_mj.scene.garage_scene import GarageScene
    from garage_mj.scene.parked_fleet import (
        CAR_GAP,
        JITTER_YAW,
        ParkedFleet,
        _overlap,
        draw_parked,
        fleet_rng,
        stall_inner,
    )

    stalls = GarageScene(painted_tiny).stalls.stalls
    fleet = ParkedFleet("mixed", 0.5)
    moved = 0
    for seed in range(12):
        target = (7 * seed) % len(stalls)
        bodies = draw_parked(stalls, range(len(stalls)), target, fleet, fleet_rng(seed))
        assert target not in bodies and len(bodies) == len(stalls) - 1
        inner = stall_inner(stalls[target])
        placed = list(bodies.values())
        for k, b in enumerate(placed):
            s = stalls[b.stall]
            lateral = -(b.x - s.x) * math.sin(s.yaw) + (b.y - s.y) * math.cos(s.yaw)
            turn = math.remainder(b.yaw - s.yaw, math.tau)
            assert abs(lateral) <= 0.5 + 1e-9 and abs(turn) <= JITTER_YAW * 0.5 + 1e-9
            moved += abs(lateral) > 0.25
            assert not _overlap(b.corners(), inner)  # never into the target stall's paint
            assert not any(_overlap(b.corners(), o.corners(), CAR_GAP - 1e-9) for o in placed[k + 1:])
    assert moved > 0  # some cars do stand over their line


def test_the_planner_the_cameras_and_the_collisions_see_the_same_parked_bodies(painted_tiny):
    from garage_mj.scene.parked_fleet import body_obstacles

    env = GarageDriveEnv(painted_tiny, task="park", parked_fleet="mixed", parked_jitter=0.4)
    env.reset(seed=2)
    bodies = env.parked_bodies
    assert bodies and set(bodies) == set(env.occupied)
    obstacles = body_obstacles(env.park_planner.obstacles(), env.target, bodies)
    cars = [k for k, c in enumerate(obstacles.classes) if c == "parked_car"]
    assert sorted(obstacles.stall[cars].tolist()) == sorted(bodies)  # one outline per parked car, no stall outline
    for k in cars:
        sid = int(obstacles.stall[k])
        hull = mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_GEOM, f"parkedcar_{sid}_hull")
        drawn = _hull_outline(env.model, env.data, hull)  # where MuJoCo draws and collides the car's hull
        assert _same_outline(drawn, obstacles.outlines[k]) and _same_outline(drawn, bodies[sid].corners())
        assert env.model.geom_size[hull, 0] == pytest.approx(bodies[sid].length / 2)
    # a moved car is hit where it stands: the ego car put onto a parked car's corner outside its compiled box
    sid = max(bodies, key=lambda s: abs(math.remainder(bodies[s].yaw - env.stalls[s].yaw, math.tau)))
    corner = bodies[sid].corners()[0]
    env.car.reset(env.data, float(corner[0]), float(corner[1]), bodies[sid].yaw)
    mujoco.mj_step(env.model, env.data)
    hit = {mujoco.mj_id2name(env.model, mujoco.mjtObj.mjOBJ_GEOM, int(g)) for c in env.data.contact[:env.data.ncon]
           for g in (c.geom1, c.geom2)}
    assert f"parkedcar_{sid}_hull" in hit
    env.close()


def test_the_default_fleet_plans_around_the_parked_cars_bodies(painted_tiny):
    from garage_mj.scene.clearance import nearest_obstacle
    from garage_mj.scene.park_planning import park_obstacles
    from garage_mj.scene.parked_fleet import body_obstacles, uniform_size

    env = GarageDriveEnv(painted_tiny, task="park")
    env.reset(seed=3)  # a test whose plan passes closer to a parked car than the car's stall outline allowed
    assert env.parked_bodies and set(env.parked_bodies) == set(env.occupied)
    for b in env.parked_bodies.values():  # models/parked_car, centred and square in its stall
        s = env.stalls[b.stall]
        assert (b.x, b.y, b.yaw) == (s.x, s.y, s.yaw) and (b.length, b.width, b.height) == uniform_size()
    # the plan's clearance is measured to those bodies, not to the occupied stalls' outlines
    plan, rear = env._park.plan, env._park.plan.rear_poses
    to = {name: float(nearest_obstacle(obs, env.car_geometry, rear[:, :2], rear[:, 2])[0].min()) for name, obs in (
        ("bodies", body_obstacles(env.park_planner.obstacles(), env.target, env.parked_bodies)),
        ("outlines", park_obstacles(env.park_planner.obstacles(), env.target, env.occupied)))}
    assert plan.min_clearance == pytest.approx(to["bodies"]) and to["outlines"] < to["bodies"]
    env.close()


@pytest.mark.parametrize("angle", [0.0, 45.0])
def test_parked_bodies_stand_as_the_scene_builds_its_cars_in_angled_and_parallel_stalls(painted_tiny, angle):
    from garage_mj.scene.garage_scene import GarageScene
    from garage_mj.scene.mjcf_scene import ParkedCars, build_scene
    from garage_mj.scene.parked_fleet import ParkedFleet, _overlap, draw_parked, fleet_rng, stall_inner
    from garage_mj.scene.world import world_with

    scene = GarageScene(painted_tiny, world_with({"stall_angle": angle}))
    stalls = scene.stalls.stalls
    assert {s.angle for s in stalls} == {angle}
    ids = [s.id for s in stalls]
    own = draw_parked(stalls, ids, None, ParkedFleet(), None)
    placed = {p.stall_id: p for p in scene.layout.parked_cars}
    for sid, b in own.items():  # the default fleet is the scene's own cars
        assert (b.x, b.y, b.yaw) == pytest.approx((placed[sid].x, placed[sid].y, placed[sid].yaw))
    root = build_scene(scene, fuse_static=True)
    model = mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())
    data = mujoco.MjData(model)
    mixed = draw_parked(stalls, ids, ids[0], ParkedFleet("mixed", 0.5), fleet_rng(5))
    assert not any(_overlap(b.corners(), stall_inner(stalls[ids[0]])) for b in mixed.values())
    ParkedCars(model).place(model, data, mixed)
    for sid, b in mixed.items():  # and a mixed, jittered fleet stands in MuJoCo where its bodies say
        hull = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"parkedcar_{sid}_hull")
        assert _same_outline(_hull_outline(model, data, hull), b.corners())


def test_cli_cruise_records_the_vehicles_in_run_json_and_tests_csv(painted_tiny, tmp_path):
    import csv
    import json

    from garage_mj.cli import main
    from garage_mj.driving.results import TEST_COLUMNS, VEHICLE_COLUMNS
    from garage_mj.export.pack import export_pack

    packs = tmp_path / "packs"
    export_pack(painted_tiny, packs)
    out = tmp_path / "run"
    assert main(["cruise", "--packs", str(packs), "--tests", "2", "--driver", "oracle", "--task", "park",
                 "--vehicle", "compact", "--parked-fleet", "mixed", "--parked-jitter", "0.3", "--out", str(out),
                 "--quiet"]) == 0
    with open(out / "tests.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(TEST_COLUMNS) and set(VEHICLE_COLUMNS) <= set(TEST_COLUMNS)
    assert [(r["vehicle"], r["parked_fleet"], r["parked_jitter_m"]) for r in rows] == [("compact", "mixed", "0.3")] * 2
    env = json.loads((out / "run.json").read_text())["env"]
    assert env == {"vehicle": "compact", "parked_fleet": "mixed", "parked_jitter": 0.3}
    # a default run stores none of them in run.json and writes the defaults into tests.csv
    default = tmp_path / "default"
    assert main(["cruise", "--packs", str(packs), "--tests", "1", "--driver", "oracle", "--out", str(default),
                 "--quiet"]) == 0
    assert json.loads((default / "run.json").read_text())["env"] == {}
    with open(default / "tests.csv", newline="") as f:
        (row,) = csv.DictReader(f)
    assert (row["vehicle"], row["parked_fleet"], row["parked_jitter_m"]) == ("sedan", "uniform", "0")


def test_exported_park_problems_hold_the_parked_cars_bodies(painted_tiny):
    from garage_mj.export.park_problems import park_problems
    from garage_mj.scene.garage_scene import GarageScene
    from garage_mj.scene.parked_fleet import uniform_size

    scene = GarageScene(painted_tiny)
    problems, _ = park_problems(scene, stalls={0, 1})
    length, width, _ = uniform_size()
    cars = [np.array(c) for p in problems[:4] for k, c in p.obstacles if k == "parked_car"]
    assert cars
    for c in cars:  # 4.3 x 1.9 m rectangles centred in a stall that is not the problem's
        sides = sorted(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).round(9))
        assert sides == pytest.approx([width, width, length, length])
        centre = c.mean(axis=0)
        assert any(np.allclose(centre, (s.x, s.y)) for s in scene.stalls.stalls)


def test_the_pytest_plugin_offers_the_fleet_and_hands_a_vehicle_to_the_env(garage_cruise):
    import pytest_garage_mj as plugin

    assert plugin.VEHICLES == tuple(FLEET) and plugin.DEFAULTS["vehicle"] == "sedan"
    tests = garage_cruise("oracle", tests=1, vehicle="compact")
    assert [r["vehicle"] for r in tests.rows] == ["compact"]


def test_the_cameras_draw_the_parked_cars_where_they_stand(painted_tiny):
    from garage_mj.driving.sim.sensors import Camera, CameraConfig
    from garage_mj.scene.semantics import Semantic

    env = GarageDriveEnv(painted_tiny, parked_fleet="mixed", parked_jitter=0.5)
    env.reset(seed=2)
    width, height = 800, 600
    cam = Camera(env.model, CameraConfig(camera="overview", width=width, height=height, depth=False, near=0.1,
                                         far=100.0))
    seg = cam.render(env.data)["segmentation"]
    k = mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_CAMERA, "overview")
    assert env.model.cam_projection[k] == mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC
    (cx, cy, _), scale = env.data.cam_xpos[k], height / env.model.cam_fovy[k]  # [px per m], looking down
    seen = []
    for b in env.parked_bodies.values():
        centre = np.array([b.x, b.y])
        for corner in b.corners():  # half a metre in from each corner of the body as it stands
            x, y = corner + 0.5 * (centre - corner) / np.linalg.norm(centre - corner)
            seen.append(seg[round(height / 2 - (y - cy) * scale), round(width / 2 + (x - cx) * scale)])
    cam.close()
    env.close()
    assert len(seen) > 8 and set(seen) == {Semantic.PARKED_CAR}


def test_an_openscenario_test_holds_the_parked_cars_as_they_stand(painted_tiny, tmp_path):
    from garage_mj.driving.replay import write_test_xosc
    from garage_mj.driving.sources import CruiseSettings, CruiseSource
    from garage_mj.export.pack import export_pack

    pack = export_pack(painted_tiny, tmp_path / "packs")
    source = CruiseSource.from_pack(pack)
    env_kwargs = {"parked_fleet": "mixed", "parked_jitter": 0.4}
    env = GarageDriveEnv(source.garage, action_type="continuous", **env_kwargs)
    obs, info = env.reset(seed=4)
    path = write_test_xosc(env, info, tmp_path / "t.xosc", source, 0, 4,
                           CruiseSettings("oracle", 4, "continuous", env=env_kwargs))
    text = path.read_text()
    for sid, b in env.parked_bodies.items():
        block = text[text.index(f'name="parkedcar_{sid}"'):]
        assert f'length="{b.length}"' in block[:2000] or f'length="{b.length:g}"' in block[:2000]
    env.close()


def test_cli_export_writes_park_problems_for_a_vehicle_class(painted_tiny, tmp_path):
    import json

    from garage_mj.cli import main

    garage = tmp_path / "garage.json"
    garage.write_text(painted_tiny.to_json())
    out = tmp_path / "problems"
    assert main(["export", "--garage", str(garage), "--park-problems", str(out), "--vehicle", "van", "--quiet",
                 "--stall", "0"]) == 0
    car = json.loads((out / "park_problems.json").read_text())["car"]
    van = FLEET["van"]
    assert (car["length"], car["width"], car["wheelbase"]) == pytest.approx((van.length, van.width, van.wheelbase))
    assert car["min_turning_radius"] == pytest.approx(van.min_radius)


def test_a_parked_car_in_the_way_of_the_tests_route_stands_as_the_longest_class_that_leaves_it_clear(painted_tiny):
    """A van overhanging its bay (5.14 m in a 4.5 m stall) into the lane a test's route drives stands as the longest
    class that keeps the drive planner's margin from the route (here the SUV, 0.52 m over); every other car is drawn as
    without the route, and without it the van stands."""
    from garage_mj.scene.drivable import DEFAULT_DRIVE
    from garage_mj.scene.garage_scene import GarageScene
    from garage_mj.scene.parked_fleet import ParkedFleet, RouteLane, draw_parked, fleet_rng

    stalls = GarageScene(painted_tiny).stalls.stalls
    fleet = ParkedFleet("mixed", 0.0)
    seed = next(s for s in range(200) if draw_parked(stalls, range(len(stalls)), None, fleet,
                                                     fleet_rng(s))[0].vehicle == "van")
    stall = stalls[0]
    u = np.array([math.cos(stall.car_yaw), math.sin(stall.car_yaw)])  # the bay's axis, out of its open end
    v = np.array([-u[1], u[0]])
    open_end = np.array([stall.x, stall.y]) + u * stall.length / 2
    rear = open_end + 1.85 * u + np.outer(np.arange(-6.0, 6.01, 0.1), v)  # the car's side 0.9 m past the open end
    lane = RouteLane(rear, np.full(len(rear), math.atan2(v[1], v[0])), car_geometry(), DEFAULT_DRIVE.clearance_margin)
    without = draw_parked(stalls, range(len(stalls)), None, fleet, fleet_rng(seed))
    kept = draw_parked(stalls, range(len(stalls)), None, fleet, fleet_rng(seed), lane=lane)
    assert without[0].vehicle == "van" and not lane.clear(without[0])
    assert kept[0].vehicle == "suv" and lane.clear(kept[0]) and kept[0].stall == 0
    assert {s: b for s, b in kept.items() if s != 0} == {s: b for s, b in without.items() if s != 0}
