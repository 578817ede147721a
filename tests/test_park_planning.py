"""Park tests (SPEC 8): the stall pose, the success geometry and the reference planner on the tiny garage."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from garage_mj.scene.car import car_geometry
from garage_mj.scene.clearance import Obstacles, footprint, nearest_obstacle
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import (
    BACK_GAP,
    ParkConfig,
    ParkPlanner,
    centre_to_rear,
    in_stall,
    park_obstacles,
    park_pose,
    rear_to_centre,
)

CAR = car_geometry()


@pytest.fixture(scope="module")
def tiny(painted_tiny) -> tuple[GarageScene, ParkPlanner]:
    scene = GarageScene(painted_tiny)
    return scene, ParkPlanner(scene, CAR)


def _stall_frame(stall, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points in the stall's frame: along its axis (towards the aisle) and across it (to the left)."""
    u = np.array([math.cos(stall.yaw), math.sin(stall.yaw)])
    rel = points - (stall.x, stall.y)
    return rel @ u, rel @ np.array([-u[1], u[0]])


def _corners(pose) -> np.ndarray:
    rear = centre_to_rear(pose, CAR)
    return footprint(CAR, rear[None, :2], np.array([rear[2]]))[0]


@pytest.mark.parametrize("maneuver", ["reverse", "forward"])
def test_the_stall_pose_puts_the_car_0_15_m_from_the_back_line_centred_along_the_stall(tiny, maneuver):
    scene, _ = tiny
    for stall in scene.stalls.stalls[:4]:
        pose = park_pose(stall, CAR, maneuver)
        s, t = _stall_frame(stall, _corners(pose))
        assert s.min() == pytest.approx(-stall.length / 2 + BACK_GAP)  # rear (or nose) 0.15 m from the back line
        assert t.max() == pytest.approx(-t.min())  # centred between the side lines
        assert s.max() - stall.length / 2 == pytest.approx(CAR.front - CAR.rear + BACK_GAP - stall.length)  # 0.25 m out
        facing = stall.yaw if maneuver == "reverse" else stall.yaw + math.pi  # reverse-in: the nose to the aisle
        assert math.cos(pose[2] - facing) == pytest.approx(1.0)
        # the end at the back line is the rear (reverse-in) or the nose (nose-in)
        rear = centre_to_rear(pose, CAR)
        rs, _ = _stall_frame(stall, rear[None, :2])
        assert (rs[0] < 0) == (maneuver == "reverse")


def test_centre_and_rear_axle_poses_convert_both_ways():
    poses = np.array([[3.0, -2.0, 0.3], [10.0, 5.0, -2.9]])
    rear = centre_to_rear(poses, CAR)
    assert np.hypot(*(rear[:, :2] - poses[:, :2]).T) == pytest.approx([-CAR.rear_axle] * 2)
    assert rear_to_centre(rear, CAR) == pytest.approx(poses)


def test_in_stall_reports_the_success_geometry_and_the_metrics(tiny):
    scene, _ = tiny
    stall = scene.stalls.stalls[3]
    x, y, yaw = park_pose(stall, CAR, "reverse")
    u = np.array([math.cos(stall.yaw), math.sin(stall.yaw)])
    left = np.array([-u[1], u[0]])

    def at(shift_along=0.0, shift_left=0.0, turn_deg=0.0, maneuver="reverse"):
        p = np.array([x, y]) + shift_along * u + shift_left * left
        return in_stall(stall, CAR, (p[0], p[1], yaw + math.radians(turn_deg)), maneuver)

    exact = at()
    assert exact.parked and exact.position_error == pytest.approx(0) and exact.heading_error == pytest.approx(0)
    side = at(shift_left=0.2)  # 0.3 m to each side line: still inside
    assert side.parked and side.lateral_offset == pytest.approx(0.2 + exact.lateral_offset)
    assert side.position_error == pytest.approx(0.2)
    assert not at(shift_left=-0.35).inside  # across the right side line
    assert not at(shift_along=-0.2).inside  # across the back line
    assert at(shift_along=0.04).inside and not at(shift_along=0.1).inside  # the far end at most 0.3 m out
    assert at(shift_along=0.1).longitudinal_offset == pytest.approx(0.1)
    turned = at(turn_deg=12)
    assert not turned.aligned and turned.heading_error == pytest.approx(12)
    assert at(turn_deg=2).parked
    wrong_way = at(maneuver="forward")  # the reverse-in pose scored as nose-in: wrong direction
    assert wrong_way.heading_error == pytest.approx(180) and not wrong_way.parked


def _check_plan(scene, plan, start, stall_id, maneuver, occupied, margin):
    stall = scene.stalls.stalls[stall_id]
    assert plan.found, plan.reason
    assert np.array_equal(plan.poses[0][2:], start[2:])  # from the start pose (its heading exactly) ...
    assert plan.poses[0] == pytest.approx(np.array(start), abs=1e-9)
    assert plan.poses[-1] == pytest.approx(np.array(park_pose(stall, CAR, maneuver)), abs=1e-9)  # ... to the stall pose
    assert in_stall(stall, CAR, plan.poses[-1], maneuver).parked
    assert plan.rear_poses == pytest.approx(centre_to_rear(plan.poses, CAR))
    # every pose clear of every obstacle of the test by the margin (exact distances)
    obs = park_obstacles(ParkPlanner(scene, CAR).obstacles(), stall_id, occupied)
    dist, _ = nearest_obstacle(obs, CAR, plan.rear_poses[:, :2], plan.rear_poses[:, 2])
    assert dist.min() >= margin - 1e-9 and plan.min_clearance == pytest.approx(dist.min())
    steps = np.hypot(*np.diff(plan.rear_poses[:, :2], axis=0).T)
    assert steps.max() <= ParkConfig().step + 1e-6 and plan.length == pytest.approx(steps.sum())
    # the rear axle never turns tighter than the car can steer
    turn = np.abs((np.diff(plan.rear_poses[:, 2]) + math.pi) % (2 * math.pi) - math.pi)
    assert (turn <= steps * CAR.max_curvature + 1e-6).all()
    assert (turn <= steps / ParkPlanner(scene, CAR).radius * (1 + 1e-3) + 1e-9).all()  # with the curvature margin
    # gears: +1 / -1, and each step moves along the heading in its gear
    assert set(np.unique(plan.directions)) <= {-1, 1}
    heading = np.stack([np.cos(plan.rear_poses[:-1, 2]), np.sin(plan.rear_poses[:-1, 2])], axis=1)
    along = (np.diff(plan.rear_poses[:, :2], axis=0) * heading).sum(axis=1) * plan.directions[:-1]
    assert (along >= -1e-9).all()
    segments = plan.segments()
    assert len(segments) == plan.cusps + 1 and segments[0][0] == 0 and segments[-1][1] == len(plan.poses) - 1


@pytest.mark.parametrize(("stall_id", "maneuver", "method"), [(3, "reverse", "analytic"), (3, "forward", "bitstar"),
                                                               (0, "reverse", "bitstar")])
def test_a_free_stall_gets_a_clear_plan_from_the_cruise_goal_into_the_stall(tiny, stall_id, maneuver, method):
    scene, planner = tiny
    start = drive_planner(scene, CAR).plan(stall_id).goal  # where the cruise test stops
    plan = planner.plan(start, stall_id, maneuver)  # every other stall occupied
    assert plan.method == method
    _check_plan(scene, plan, start, stall_id, maneuver, None, planner.config.margin)


def test_occupancy_is_respected_and_a_free_neighbour_may_be_crossed(tiny):
    scene, planner = tiny
    start = drive_planner(scene, CAR).plan(4).goal
    plan = planner.plan(start, 4, "forward", occupied=[])  # an empty garage
    _check_plan(scene, plan, start, 4, "forward", [], planner.config.margin)
    assert plan.method == "analytic"  # nothing parked beside it: one curve does


def test_the_same_seed_gives_the_same_plan(tiny):
    scene, planner = tiny
    start = drive_planner(scene, CAR).plan(0).goal
    a, b = planner.plan(start, 0, "reverse"), ParkPlanner(scene, CAR).plan(start, 0, "reverse")
    assert a.method == "bitstar" and np.array_equal(a.poses, b.poses) and np.array_equal(a.directions, b.directions)
    other = ParkPlanner(scene, CAR, ParkConfig(seed=7)).plan(start, 0, "reverse")
    assert other.found and not np.array_equal(a.poses, other.poses)


def test_a_boxed_in_stall_is_infeasible(tiny):
    scene, planner = tiny
    stall = scene.stalls.stalls[3]
    start = drive_planner(scene, CAR).plan(3).goal
    # a pillar in the stall's mouth, 0.5 m in front of its entry line: the car cannot leave the stall
    ex, ey = np.array(stall.entry) + 0.8 * np.array([math.cos(stall.yaw), math.sin(stall.yaw)])
    obs = park_obstacles(planner.obstacles(), 3)
    boxed = Obstacles(np.vstack([obs.boxes, [ex - 0.3, ey - 0.3, ex + 0.3, ey + 0.3]]), [*obs.classes, "pillar"],
                      np.append(obs.stall, -1))
    quick = ParkPlanner(scene, CAR, ParkConfig(iterations=300))
    plan = quick.plan(start, 3, "reverse", obstacles=boxed)
    assert not plan.found and "300 iterations" in plan.reason and len(plan.poses) == 0
    # a pillar in the stall itself: the stall pose is not clear
    sx, sy = stall.x, stall.y
    inside = Obstacles(np.vstack([obs.boxes, [sx - 0.3, sy - 0.3, sx + 0.3, sy + 0.3]]), [*obs.classes, "pillar"],
                       np.append(obs.stall, -1))
    plan = quick.plan(start, 3, "forward", obstacles=inside)
    assert not plan.found and plan.reason.startswith("the stall pose") and "pillar" in plan.reason


def test_a_zero_margin_config_and_bad_settings(tiny):
    with pytest.raises(ValueError, match="unknown park planner"):
        ParkConfig(planner="astar")
    with pytest.raises(ValueError, match="step"):
        ParkConfig(step=0)
    with pytest.raises(ValueError, match="unknown park maneuver"):
        park_pose(tiny[0].stalls.stalls[0], CAR, "sideways")
    assert replace(ParkConfig(), margin=0.0).margin == 0.0


def test_planning_prints_nothing_at_exit(tmp_path):
    """OMPL's bindings report objects alive at interpreter exit on stderr; a planner run leaves none."""
    script = (
        "from garage_mj.testing.garages import tiny_garage\n"
        "from garage_mj.scene.garage_scene import GarageScene\n"
        "from garage_mj.scene.drivable import drive_planner\n"
        "from garage_mj.scene.park_planning import ParkPlanner\n"
        "scene = GarageScene(tiny_garage())\n"
        "planner = ParkPlanner(scene)\n"
        "plan = planner.plan(drive_planner(scene).plan(0).goal, 0, 'reverse')\n"
        "print(plan.found, plan.method)\n"
    )
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True bitstar"
    assert "leaked" not in done.stderr and "nanobind" not in done.stderr, done.stderr


def test_a_car_stopped_turned_in_a_bay_is_corrected_out_towards_the_aisle_and_back(tiny):
    """In a bay the correction's arc leaves towards the aisle (the maneuver's exit gear) and the straight move goes
    back in, in the maneuver's gear; it ends parked on the stall pose's heading."""
    scene, planner = tiny
    stall = scene.stalls.stalls[3]
    x, y, yaw = park_pose(stall, CAR, "reverse")
    start = (x, y, yaw + math.radians(4.0))
    assert not in_stall(stall, CAR, start, "reverse").parked
    plan = planner.correct(start, 3, "reverse", occupied=[0, 1, 2, 4])
    assert plan.found and plan.method == "correction", plan.reason
    assert [gear for *_, gear in plan.segments()] == [1, -1]  # out forward, back in reversing
    assert in_stall(stall, CAR, plan.poses[-1], "reverse").parked
    assert abs(math.remainder(plan.poses[-1][2] - yaw, 2 * math.pi)) < 1e-9
    assert not planner.correct((x, y, yaw + math.radians(30.0)), 3, "reverse").found  # too far turned: plan()'s
