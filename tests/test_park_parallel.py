"""Park and AVP tests on parallel slots (docs/spec.md section 9: stall angle 0).

The stall pose lies along the slot, inside its lines, for every class of the fleet that fits; a slot too short for
the car is infeasible by proof, and extreme; the reference planner's plans are collision-free pose by pose and enter
the slot in the maneuver's gear; the oracle parks one end to end; mixed, jittered parked cars stand along their slots.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from garage_mj.driving.drivers import load_driver
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.scene.clearance import footprint, nearest_obstacle
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_levels import PARALLEL_EXTREME, park_level
from garage_mj.scene.park_planning import (
    BACK_GAP,
    MANEUVERS,
    centre_to_rear,
    in_stall,
    park_obstacles,
    park_planner,
    park_pose,
)
from garage_mj.scene.parked_fleet import (
    CAR_GAP,
    END_GAP,
    JITTER_YAW,
    ParkedFleet,
    _overlap,
    body_obstacles,
    draw_parked,
    fleet_rng,
    stall_inner,
)
from garage_mj.scene.stalls import Stall
from garage_mj.scene.vehicles import FLEET
from garage_mj.scene.world import DEFAULT_WORLD, world_with

MARK = DEFAULT_WORLD.marking_width


def _slot(length: float, depth: float = 2.5, yaw: float = 0.3) -> Stall:
    """A parallel slot ``length`` along its aisle and ``depth`` across, opening toward ``yaw``."""
    return Stall(id=0, block=(0, 0), x=3.0, y=-2.0, yaw=yaw, side=0, road_cell=(0, 1), road_x=3.0 + 4 * math.cos(yaw),
                 road_y=-2.0 + 4 * math.sin(yaw), obstructed=False, length=depth, width=length, angle=0.0)


def _local(stall: Stall, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points in the slot's frame: across it toward the aisle, and along it (to the left looking out)."""
    ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)
    rel = np.asarray(pts) - (stall.x, stall.y)
    return rel @ (ux, uy), rel @ (-uy, ux)


@pytest.mark.parametrize("slot_length", [4.5, 5.6, 6.5])
@pytest.mark.parametrize("name", sorted(FLEET))
def test_the_slot_pose_lies_inside_the_slot_for_every_class_that_fits(name, slot_length):
    car = FLEET[name].geometry()
    stall = _slot(slot_length)
    length = car.front - car.rear
    for m in MANEUVERS:
        pose = park_pose(stall, car, m)
        fit = in_stall(stall, car, pose, m)
        assert math.cos(pose[2] - stall.car_yaw) == pytest.approx(1.0)  # along the slot, the lane's traffic direction
        if length > slot_length - MARK:  # longer than the room between the end lines' inner edges: never inside
            assert not fit.inside and fit.line in ("left side line", "right side line")
            continue
        assert fit.parked and fit.position_error < 1e-9 and fit.margin > 0
        corners = _corners(car, pose)
        across, along = _local(stall, corners)
        assert across.min() == pytest.approx(-stall.length / 2 + BACK_GAP)  # the right side 0.15 m from the kerb line
        assert across.max() < stall.length / 2  # the left side short of the open, aisle-side edge
        assert along.max() == pytest.approx(-along.min())  # centred along the slot
        # the far-end allowance of a bay does not apply: a pose moved toward the aisle past the open edge is outside
        over = (pose[0] + 0.7 * math.cos(stall.yaw), pose[1] + 0.7 * math.sin(stall.yaw), pose[2])
        assert not in_stall(stall, car, over, m).inside


def _corners(car, pose) -> np.ndarray:
    rear = centre_to_rear(pose, car)
    return footprint(car, rear[None, :2], np.array([rear[2]]))[0]


@pytest.fixture(scope="module")
def parallel_scene(painted_tiny) -> GarageScene:
    return GarageScene(painted_tiny, world_with({"stall_angle": 0}))


@pytest.mark.parametrize("maneuver", ["reverse", "forward"])
def test_a_parallel_park_plan_is_collision_free_pose_by_pose_and_enters_in_the_maneuvers_gear(parallel_scene,
                                                                                               maneuver):
    scene = parallel_scene
    planner = park_planner(scene)
    cruise = {p.stall: p for p in drive_planner(scene).plans()}
    stalls = scene.stalls.stalls
    rng = np.random.default_rng(5)
    checked = 0
    for stall in stalls[::3]:
        occupied = [s.id for s in stalls if s.id != stall.id and rng.random() < 0.5]
        plan = planner.plan(cruise[stall.id].goal, stall.id, maneuver, occupied=occupied)
        assert plan.verdict == "feasible", plan.reason
        obs = park_obstacles(planner.obstacles(), stall.id, occupied)
        dist, _ = nearest_obstacle(obs, planner.car, plan.rear_poses[:, :2], plan.rear_poses[:, 2])
        assert dist.min() >= planner.config.margin - 1e-6  # every pose of the plan keeps the margin
        assert np.allclose(plan.poses[-1], park_pose(stall, planner.car, maneuver))
        assert in_stall(stall, planner.car, plan.poses[-1], maneuver).parked
        # the move that takes the car's centre into the slot is in the maneuver's gear (reverse: it backs in)
        centre = plan.rear_poses[:, :2] + ((planner.car.front + planner.car.rear) / 2 - planner.car.rear_axle) * \
            np.column_stack([np.cos(plan.rear_poses[:, 2]), np.sin(plan.rear_poses[:, 2])])
        across, _ = _local(stall, centre)
        k = int(np.flatnonzero(across > stall.length / 2)[-1])  # the last pose with the centre out of the slot
        assert plan.directions[k] == (-1 if maneuver == "reverse" else 1)
        checked += 1
    assert checked >= 4


def test_a_slot_shorter_than_the_car_is_infeasible_by_proof_and_extreme(painted_tiny):
    scene = GarageScene(painted_tiny, world_with({"stall_angle": 0, "slot_length": 4.5}))
    sedan, compact = FLEET["sedan"].geometry(), FLEET["compact"].geometry()
    cruise = {p.stall: p for p in drive_planner(scene).plans()}
    stall = scene.stalls.stalls[0]
    assert stall.width == 4.5
    plan = park_planner(scene, sedan).plan(cruise[0].goal, 0, "reverse", occupied=[])
    assert plan.verdict == "infeasible" and "too short for the car" in plan.reason
    level = park_level(stall, 4.6, 1.9, 9.0, cruise[0].goal[:2])
    assert level.level == "extreme" and f"vehicle length + {PARALLEL_EXTREME:g} m" in level.reason
    # the compact fits between the lines: extreme, never proven impossible by the slot's length
    assert in_stall(stall, compact, park_pose(stall, compact)).parked
    assert park_level(stall, compact.front - compact.rear, 2 * compact.half_width, 9.0, cruise[0].goal[:2]).level == \
        "extreme"
    # the default slot (the sedan + 1 m) is long enough: not extreme for the sedan
    default = GarageScene(painted_tiny, world_with({"stall_angle": 0})).stalls.stalls[0]
    assert park_level(default, 4.6, 1.9, 9.0, cruise[0].goal[:2]).level == "normal"


@pytest.mark.parametrize("slot_length", [4.5, 5.6])
def test_a_mixed_jittered_fleet_stands_along_its_slots(painted_tiny, slot_length):
    scene = GarageScene(painted_tiny, world_with({"stall_angle": 0, "slot_length": slot_length}))
    stalls = list(scene.stalls.stalls)
    fleet = ParkedFleet("mixed", 0.5)
    moved = 0
    for seed in range(6):
        target = seed % len(stalls)
        bodies = draw_parked(stalls, [s.id for s in stalls], target, fleet, fleet_rng(seed))
        assert set(bodies) == {s.id for s in stalls} - {target}
        keep_out = stall_inner(stalls[target])
        for sid, b in bodies.items():
            stall = stalls[sid]
            assert b.length + 2 * END_GAP <= stall.width  # a class that fits its slot (a compact in a 4.5 m one)
            assert abs(math.remainder(b.yaw - stall.car_yaw, math.tau)) <= JITTER_YAW * 0.5 + 1e-9  # along the slot
            across, along = _local(stall, [(b.x, b.y)])
            assert abs(across[0]) <= 0.5 + 1e-9 and abs(along[0]) <= 0.5 + 1e-9
            moved += abs(along[0]) > 1e-6
            assert not _overlap(b.corners(), keep_out)  # never into the target slot's paint
            for other in bodies.values():
                if other.stall != sid:
                    assert not _overlap(b.corners(), other.corners(), CAR_GAP - 1e-9)
    assert moved  # the jitter moves cars along their slots too
    if slot_length == 4.5:
        assert {b.vehicle for b in bodies.values()} == {"compact"}


def test_the_oracle_parks_a_parallel_slot_end_to_end(painted_tiny):
    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", task="park", maneuver="reverse",
                         occupancy=0.5, infeasible="report", world=world_with({"stall_angle": 0}),
                         parked_fleet="mixed", parked_jitter=0.15)
    try:
        obs, info = env.reset(seed=3)
        assert info["feasible"] and info["stall_angle"] == 0.0, info.get("reason")
        driver = load_driver("oracle")
        driver.reset(env.driver_info(3))
        while "outcome" not in info:
            obs, _, _, _, info = env.step(driver.act(obs))
        assert info["outcome"] == "success", info["reason"]
        assert info["position_error"] < 0.15 and info["heading_error"] < 3.0
    finally:
        env.close()


def test_the_planner_plans_among_the_mixed_fleets_bodies(parallel_scene):
    """The plan of a park test among real parked cars (the drive env's obstacles) keeps its margin to their bodies."""
    scene = parallel_scene
    planner = park_planner(scene)
    stalls = list(scene.stalls.stalls)
    cruise = {p.stall: p for p in drive_planner(scene).plans()}
    target = 7
    bodies = draw_parked(stalls, [s.id for s in stalls], target, ParkedFleet("mixed", 0.3), fleet_rng(11))
    obs = body_obstacles(planner.obstacles(), target, bodies)
    plan = planner.plan(cruise[target].goal, target, "reverse", obstacles=obs)
    assert plan.verdict == "feasible", plan.reason
    dist, _ = nearest_obstacle(obs, planner.car, plan.rear_poses[:, :2], plan.rear_poses[:, 2])
    assert dist.min() >= planner.config.margin - 1e-6


def test_a_car_stopped_a_little_off_the_slot_pose_is_shown_a_correction_that_ends_parked(parallel_scene):
    """A car at rest in its slot a few centimetres and degrees off the stall pose, not parked (a corner over the
    kerb-side line), gets a correction: an arc onto the stall pose's heading and straight back, each stretch long
    enough to drive, clear of the parked cars by the margin, ending parked; a car far from the pose gets none."""
    from garage_mj.scene.park_planning import CORRECTION_MIN_STRETCH

    scene = parallel_scene
    planner = park_planner(scene)
    stalls = list(scene.stalls.stalls)
    target = 7
    bodies = draw_parked(stalls, [s.id for s in stalls], target, ParkedFleet("mixed", 0.3), fleet_rng(11))
    obs = body_obstacles(planner.obstacles(), target, bodies)
    stall, car = stalls[target], planner.car
    x, y, yaw = park_pose(stall, car, "reverse")
    for turn in (math.radians(3.0), math.radians(-3.0)):
        # 3 degrees turned either way, 2 cm nearer the kerb
        start = (x - 0.02 * math.cos(stall.yaw), y - 0.02 * math.sin(stall.yaw), yaw + turn)
        assert not in_stall(stall, car, start, "reverse").parked
        plan = planner.correct(start, target, "reverse", obstacles=obs)
        assert plan.found and plan.method == "correction", plan.reason
        assert np.allclose(plan.poses[0, :2], start[:2]) and abs(math.remainder(plan.poses[0, 2] - start[2], 2 * math.pi)) < 1e-9
        assert in_stall(stall, car, plan.poses[-1], "reverse").parked
        assert abs(math.remainder(plan.poses[-1][2] - yaw, 2 * math.pi)) < 1e-9  # on the stall pose's heading
        dist, _ = nearest_obstacle(obs, car, plan.rear_poses[:, :2], plan.rear_poses[:, 2])
        assert dist.min() >= planner.config.margin - 1e-6
        for first, last, _ in plan.segments():
            steps = np.linalg.norm(np.diff(plan.rear_poses[first:last + 1, :2], axis=0), axis=1)
            assert steps.sum() >= CORRECTION_MIN_STRETCH - 1e-9
    far = planner.correct((x + 3.0, y, yaw), target, "reverse", obstacles=obs)
    assert not far.found and "not within" in far.reason and far.verdict == "unproven"
