"""Verdicts before a park test's drive (docs/spec.md section 8): feasible, infeasible with its proof, unproven."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from garage_mj.driving.results import (
    PARK_SUMMARY_COLUMNS,
    park_summary,
    row_problem,
    summarize,
    write_outputs,
)
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sources import CruiseSettings, CruiseSource, cruise_seed
from garage_mj.scene.car import car_geometry
from garage_mj.scene.clearance import Obstacles
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import ParkConfig, ParkPlanner, park_obstacles

CAR = car_geometry()
#: a first attempt that cannot succeed where the analytic path does not (one BIT* iteration)
NO_FIRST = {"iterations": 1}


@pytest.fixture(scope="module")
def tiny(painted_tiny):
    scene = GarageScene(painted_tiny)
    return scene, drive_planner(scene, CAR).plan(0).goal  # stall 0 reverse-in: the analytic path does not do


def _with_boxes(planner: ParkPlanner, stall_id: int, *boxes) -> Obstacles:
    obs = park_obstacles(planner.obstacles(), stall_id)
    return Obstacles(np.vstack([obs.boxes, *boxes]), [*obs.classes, *(["wall"] * len(boxes))],
                     np.append(obs.stall, [-1] * len(boxes)))


def _pillar(x: float, y: float) -> list[float]:
    return [x - 0.3, y - 0.3, x + 0.3, y + 0.3]


def test_a_stall_pose_that_collides_is_infeasible_with_that_proof(tiny):
    scene, _ = tiny
    planner = ParkPlanner(scene, CAR)
    stall = scene.stalls.stalls[3]
    start = drive_planner(scene, CAR).plan(3).goal
    plan = planner.plan(start, 3, "reverse", obstacles=_with_boxes(planner, 3, _pillar(stall.x, stall.y)))
    assert plan.verdict == "infeasible" and not plan.found and plan.iterations == 0
    assert plan.reason.startswith("the stall pose") and "wall" in plan.reason
    assert plan.summary()["verdict"] == "infeasible"


def test_a_stall_closed_at_the_car_s_width_is_infeasible_with_that_proof(tiny):
    scene, _ = tiny
    planner = ParkPlanner(scene, CAR, ParkConfig(iterations=50, escalation=()))
    stall = scene.stalls.stalls[1]  # between two parked cars
    start = drive_planner(scene, CAR).plan(1).goal
    u = np.array([math.cos(stall.yaw), math.sin(stall.yaw)])
    v = np.array([-u[1], u[0]])
    mouth = np.array(stall.entry) + 0.8 * u  # a pillar in the stall's mouth: 0.95 m free on each side of it
    back = np.array([stall.x, stall.y]) - u * (stall.length / 2 + 0.15)
    wall = np.array([back + 0.15 * u + 6 * v, back - 0.15 * u - 6 * v])  # a wall along the back line
    open_back = planner.plan(start, 1, "reverse", obstacles=_with_boxes(planner, 1, _pillar(*mouth)))
    assert open_back.verdict == "unproven"  # the floor behind the stall is open: the pillar proves nothing
    plan = planner.plan(start, 1, "reverse", obstacles=_with_boxes(planner, 1, _pillar(*mouth),
                                                                  [*wall.min(axis=0), *wall.max(axis=0)]))
    assert plan.verdict == "infeasible" and "closed at the car's width" in plan.reason
    assert "50 iterations" in plan.reason and plan.attempt == 0  # proven after the first attempt: no escalation


def test_escalation_finds_what_the_first_budget_cannot(tiny):
    scene, start = tiny
    first = ParkPlanner(scene, CAR, ParkConfig(**NO_FIRST, escalation=())).plan(start, 0, "reverse")
    assert first.verdict == "unproven" and not first.found and "1 iterations" in first.reason
    config = ParkConfig(**NO_FIRST, escalation=(("rrtconnect", 2500, "stall"),))
    plan = ParkPlanner(scene, CAR, config).plan(start, 0, "reverse")
    assert plan.verdict == "feasible" and plan.found and plan.attempt == 1 and plan.method == "rrtconnect"
    worker = ParkPlanner(scene, CAR, config)  # another process, which planned other tests before
    worker.plan(drive_planner(scene, CAR).plan(3).goal, 3, "forward")
    again = worker.plan(start, 0, "reverse")  # seeded per plan and per stage: the same verdict and plan
    assert again.verdict == "feasible" and again.attempt == 1 and np.array_equal(plan.poses, again.poses)


def test_the_default_first_attempt_is_unchanged_by_escalation(tiny):
    scene, start = tiny
    plain = ParkPlanner(scene, CAR, ParkConfig(escalation=())).plan(start, 0, "reverse")
    plan = ParkPlanner(scene, CAR).plan(start, 0, "reverse")
    assert plan.attempt == 0 and plan.method == "bitstar" and np.array_equal(plan.poses, plain.poses)


def test_an_exhausted_escalation_without_proof_is_unproven(tiny):
    scene, start = tiny
    config = ParkConfig(**NO_FIRST, escalation=(("bitstar", 1, "out"), ("rrtconnect", 1, "stall")))
    plan = ParkPlanner(scene, CAR, config).plan(start, 0, "reverse")
    assert plan.verdict == "unproven" and not plan.found and len(plan.poses) == 0
    assert plan.reason.startswith("unproven:") and "rrtconnect 1 from the stall pose" in plan.reason
    with pytest.raises(ValueError, match="escalation"):
        ParkConfig(escalation=(("astar", 10, "out"),))
    assert ParkConfig(escalation=[["rrtconnect", 5, "stall"]]).escalation == (("rrtconnect", 5, "stall"),)


def test_an_unproven_park_test_is_never_driven_and_counted_apart(painted_tiny, tmp_path):
    tight = {**NO_FIRST, "escalation": [["rrtconnect", 1, "stall"]]}
    env = GarageDriveEnv(painted_tiny, task="park", infeasible="report", park_config=tight)
    try:
        others = [s.id for s in env.stalls if s.id != 0]
        _, info = env.reset(seed=0, options={"target": 0, "occupied": others})
        assert info["outcome"] == "unproven" and not info["feasible"] and info["reason"].startswith("unproven:")
        with pytest.raises(RuntimeError, match="episode is over"):
            env.step([0.0, 0.0, 1.0])
    finally:
        env.close()
    source = CruiseSource.from_garage(painted_tiny, "tiny")
    settings = CruiseSettings("oracle", 0, "continuous", 0.5, {}, task="park")

    def row(test: int, outcome: str) -> dict:
        return {"garage": "tiny", "garage_hash": source.hash, "test": str(test),
                "seed": str(cruise_seed(0, source.hash, test)), "driver": "oracle", "target_stall": "0",
                "feasible": "1" if outcome in ("success", "collision") else "0", "outcome": outcome, "hit": "",
                "hit_geom": "", "reason": "", "time": "", "path_length": "", "route_length": "",
                "difficulty": "0.5", "mean_road_length": "2", "mean_intersection_degree": "2", "pedestrians": "",
                "moving_cars": "", "clutter": "", "wall_s": "0.1", "task": "park", "maneuver": "reverse",
                "position_error_m": "", "heading_error_deg": "", "lateral_offset_m": "", "direction_changes": "",
                "park_time_s": "", "min_clearance_m": "", "plan_length_m": "", "plan_cusps": "", "plan_clearance_m": "",
                "park_level": "complex", "inner_margin_m": "", "outline_clearance_m": "", "stall_angle_deg": "90.0"}

    rows = [row(0, "success"), row(1, "collision"), row(2, "unproven"), row(3, "infeasible")]
    # a resumed row of an unproven test validates; one that calls it feasible, or a cruise run's, does not
    assert all(row_problem(r, settings) is None for r in rows)
    assert row_problem({**rows[2], "feasible": "1"}, settings)[0] == "feasible"
    cruise = CruiseSettings("oracle", 0, "continuous", 0.5, {})
    assert row_problem({**rows[2], "task": "cruise", "maneuver": ""}, cruise)[0] == "outcome"
    (summary,) = summarize(rows, [source])
    assert summary["tests"] == 4 and summary["infeasible"] == 1 and summary["feasible"] == 2
    assert summary["success_pct"] == 50.0  # over the feasible tests: neither unproven nor infeasible
    parking = park_summary(rows)
    assert {"unproven", "unproven_pct"} <= set(PARK_SUMMARY_COLUMNS)
    assert parking["unproven"] == 1 and parking["unproven_pct"] == 25.0 and parking["collision_pct"] == 50.0
    write_outputs(tmp_path, rows, [source], settings)
    stats = json.loads((tmp_path / "summary.json").read_text())
    assert (stats["infeasible"], stats["unproven"], stats["feasible"], stats["success_pct"]) == (1, 1, 2, 50.0)
    with open(tmp_path / "summary.csv", newline="") as f:
        (line,) = list(csv.DictReader(f))
    assert (line["infeasible"], line["unproven"], line["unproven_pct"], line["feasible"]) == ("1", "1", "25.0", "2")
