"""Park and AVP tests in GarageDrive-v0 (docs/spec.md section 8): reset, plan, outcomes, metrics; cruise untouched."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import garage_mj  # noqa: F401  (registers the ids)
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.observations import ObservationSetup, observation_spaces
from garage_mj.driving.sim.outcomes import OUTCOMES, PAPER_CLASS, OutcomeKind
from garage_mj.driving.sim.park_outcomes import ParkMonitor, ParkOutcomeConfig
from garage_mj.driving.sim.vehicle import Gear
from garage_mj.scene.park_planning import in_stall, park_pose
from garage_mj.scene.route_line import Route

CRUISE_KEYS = ["depth", "goal", "pose", "remaining", "segmentation", "speed", "steer", "waypoint"]


@pytest.fixture(scope="module")
def park_env(painted_tiny):
    env = GarageDriveEnv(painted_tiny, action_type="continuous", task="park")
    yield env
    env.close()


def test_a_park_reset_starts_at_rest_on_the_cruise_goal_with_a_plan(park_env):
    obs, info = park_env.reset(seed=0)
    assert info["task"] == "park" and info["maneuver"] == "reverse" and info["feasible"] and "outcome" not in info
    goal = park_env.test_plan.goal  # the cruise goal beside the stall: the start, within the start noise
    x, y, yaw = info["pose"]
    assert math.hypot(x - goal[0], y - goal[1]) <= park_env.start_noise[0] + 1e-3
    assert abs(math.remainder(yaw - goal[2], math.tau)) <= park_env.start_noise[1] + 1e-3
    assert abs(obs["speed"][0]) < 0.05 and obs["gear"][0] == 1.0 and park_env.car.gear is Gear.D
    plan = info["park_plan"]
    assert plan["poses"].shape[1] == 3 and len(plan["directions"]) == len(plan["poses"]) > 2
    assert set(np.unique(plan["directions"])) <= {-1, 1}
    stall = park_env.stalls[info["target_stall"]]
    assert plan["stall_pose"] == pytest.approx(park_pose(stall, park_env.car_geometry, "reverse"))
    assert np.allclose(plan["poses"][0], info["pose"], atol=1e-6)  # planned from where the car stands
    assert info["plan_length"] > 0 and info["plan_cusps"] >= 0 and info["plan_clearance"] >= 0.1 - 1e-9
    assert park_env.observation_space.contains(obs) and set(obs) == {*CRUISE_KEYS, "stall", "gear", "park_guide"}
    assert obs["stall"][0] ** 2 + obs["stall"][1] ** 2 > 1.0  # the stall lies beside the car, not under it
    assert park_env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    assert park_env.driver_info(0)["park_plan"]["poses"] is plan["poses"]


def test_maneuver_any_is_drawn_from_the_seed_and_stall_fixes_the_target(painted_tiny):
    env = GarageDriveEnv(painted_tiny, task="park", maneuver="any", stall=3)
    drawn = [env.reset(seed=s)[1] for s in range(6)]
    assert {i["target_stall"] for i in drawn} == {3}
    assert {i["maneuver"] for i in drawn} == {"reverse", "forward"}
    assert env.reset(seed=2)[1]["maneuver"] == drawn[2]["maneuver"]
    assert env.action_space.n == 6
    env.close()
    with pytest.raises(ValueError, match=r"stall 999 does not exist; garage .* has stalls 0\.\.\d+"):
        GarageDriveEnv(painted_tiny, task="park", stall=999)
    with pytest.raises(ValueError, match="task must be one of"):
        GarageDriveEnv(painted_tiny, task="valet")
    with pytest.raises(ValueError, match="maneuver must be one of"):
        GarageDriveEnv(painted_tiny, task="park", maneuver="sideways")


def test_a_handover_start_stands_off_the_plans_start_and_keeps_its_plan(painted_tiny):
    plain = GarageDriveEnv(painted_tiny, action_type="continuous", task="park", maneuver="any")
    off = GarageDriveEnv(painted_tiny, action_type="continuous", task="park", maneuver="any", handover_start=1.5)
    moved = []
    for seed in range(6):
        _, a = plain.reset(seed=seed)
        _, b = off.reset(seed=seed)
        # the same test (stall, parked cars, maneuver, plan from the noised cruise goal); only the car stands elsewhere
        assert (a["target_stall"], a["maneuver"]) == (b["target_stall"], b["maneuver"])
        np.testing.assert_allclose(a["park_plan"]["poses"], b["park_plan"]["poses"])
        start = b["park_plan"]["poses"][0]
        d = math.hypot(b["pose"][0] - start[0], b["pose"][1] - start[1])
        assert d <= 1.5 + off.start_noise[0] + 1e-3  # within the handover's reach (the start noise on the route)
        moved.append(d)
        assert abs(off.car.speed(off.data)) < 0.05
    assert max(moved) > 0.3  # it does stand off the start (the plain env: on it)
    _, again = off.reset(seed=3)
    _, first = GarageDriveEnv(painted_tiny, action_type="continuous", task="park", maneuver="any",
                              handover_start=1.5).reset(seed=3)
    assert again["pose"] == pytest.approx(first["pose"])  # drawn from the test's seed
    plain.close()
    off.close()
    with pytest.raises(ValueError, match="handover_start must be in"):
        GarageDriveEnv(painted_tiny, task="park", handover_start=9.0)
    with pytest.raises(ValueError, match="handover_start is for park tests"):
        GarageDriveEnv(painted_tiny, task="avp", handover_start=1.0)


def test_stopping_short_of_the_stall_is_outside_stall(park_env):
    park_env.reset(seed=0)
    for k in range(400):
        _, _, term, trunc, info = park_env.step([0.3 if k < 10 else -1.0, 0.0, 1.0])
        if term or trunc:
            break
    assert term and not trunc and info["outcome"] == "outside_stall", info["reason"]
    assert "from the stall pose" in info["reason"] and "no progress" in info["reason"]
    assert info["position_error"] > 1.0 and info["direction_changes"] == 0 and info["park_time"] == info["time"]
    assert 0 < info["min_clearance"] < 10


def test_a_car_at_rest_on_the_stall_pose_is_parked(park_env):
    _, info = park_env.reset(seed=0)
    pose = info["park_plan"]["stall_pose"]
    park_env.car.reset(park_env.data, *pose)  # placed in the stall, at rest
    for _ in range(round(2 * park_env.park_outcome_config.dwell / park_env.dt) + 1):
        _, reward, term, _, info = park_env.step([-1.0, 0.0, 1.0])
        if term:
            break
        assert "outcome" not in info  # not before the dwell at rest (docs/spec.md section 9)
    assert term and info["outcome"] == "success", info["reason"]
    assert info["time"] >= park_env.park_outcome_config.dwell
    assert info["position_error"] < 0.1 and info["heading_error"] < 1.0 and abs(info["lateral_offset"]) < 0.1
    assert reward >= 10.0


def test_a_boxed_in_stall_is_infeasible_or_skipped(painted_tiny):
    # a margin no stall pose can keep: no plan for any stall
    tight = {"margin": 3.0}
    env = GarageDriveEnv(painted_tiny, task="park", infeasible="report", park_config=tight)
    obs, info = env.reset(seed=0)
    assert info["outcome"] == "infeasible" and not info["feasible"] and "not clear" in info["reason"]
    assert len(info["park_plan"]["poses"]) == 0 and env.observation_space.contains(obs)
    with pytest.raises(RuntimeError, match="episode is over"):
        env.step([0.0, 0.0, 1.0])
    env.close()
    env = GarageDriveEnv(painted_tiny, task="park", infeasible="skip", park_config=tight)
    _, info = env.reset(seed=0)  # every stall tried in turn: the last one is reported
    assert info["outcome"] == "infeasible"
    env.close()


def test_avp_starts_at_the_entrance_and_plans_the_route_then_the_stall(painted_tiny):
    cruise = GarageDriveEnv(painted_tiny)
    _, c_info = cruise.reset(seed=1)
    cruise.close()
    env = GarageDriveEnv(painted_tiny, task="avp")
    obs, info = env.reset(seed=1)
    assert info["task"] == "avp" and info["target_stall"] == c_info["target_stall"]
    assert info["pose"] == pytest.approx(c_info["pose"])  # the cruise test's start, the same draws
    assert info["route_length"] > c_info["route_length"] > 0  # the cruise route, then the park plan
    assert np.allclose(info["park_plan"]["poses"][0], env.test_plan.goal, atol=1e-6)  # planned from the cruise goal
    assert info["time_limit"] > c_info["time_limit"]
    assert set(obs) == {*CRUISE_KEYS, "stall", "gear", "park_guide"}
    env.close()


def test_a_cruise_driver_action_is_taken_in_a_park_test_and_keeps_the_gear(park_env):
    park_env.reset(seed=0)
    park_env.step(np.array([1.0, 0.0], np.float32))
    park_env.step(0)  # a cruise discrete action is a park action too
    assert park_env.car.gear is Gear.D and park_env.car.speed(park_env.data) > 0
    with pytest.raises(ValueError, match="not finite"):
        park_env.step([math.nan, 0.0, 1.0])


def test_cruise_spaces_and_observation_keys_are_unchanged(painted_tiny):
    for action_type, space in (("discrete", gym.spaces.Discrete(4)),
                               ("continuous", gym.spaces.Box(-1.0, 1.0, (2,), np.float32))):
        env = GarageDriveEnv(painted_tiny, action_type=action_type)
        obs, info = env.reset(seed=0)
        assert env.action_space == space and sorted(obs) == CRUISE_KEYS
        assert "task" not in info and "park_plan" not in info and "park_plan" not in env.driver_info(0)
        env.close()
    assert set(observation_spaces(ObservationSetup())) == set(CRUISE_KEYS)


def test_outside_stall_is_a_declared_failure_in_the_deadlock_class():
    spec = next(s for s in OUTCOMES if s.kind == "outside_stall")
    assert spec.failure and spec.column == "outside_stalls" and PAPER_CLASS["outside_stall"] == "deadlock"


def _monitor_east_of_stall_3(garage, dx: float):
    """A reverse-in ParkMonitor of stall 3, started ``dx`` metres east of its stall pose: (stall, car, start, monitor)."""
    from garage_mj.scene.car import car_geometry
    from garage_mj.scene.garage_scene import GarageScene

    stall, car = GarageScene(garage).stalls.stalls[3], car_geometry()
    goal = park_pose(stall, car, "reverse")
    start = (goal[0] + dx, goal[1], goal[2])
    monitor = ParkMonitor(Route([start[:2], goal[:2]]), stall, car, "reverse", 100.0, ParkOutcomeConfig())
    monitor.start(start)
    return stall, car, start, monitor


def test_the_park_monitor_counts_direction_changes_and_deadlocks_far_away(painted_tiny):
    stall, car, far, monitor = _monitor_east_of_stall_3(painted_tiny, 30.0)
    for t, v in enumerate([1.0, 1.0, 0.0, -1.0, -1.0, 0.05, 1.0]):
        assert monitor.update(0.1 * (t + 1), far[:2], v, yaw=far[2]) is None
    assert monitor.direction_changes == 2
    out = monitor.update(9.0, far[:2], 0.0, yaw=far[2])
    assert out.kind is OutcomeKind.DEADLOCK and "from the stall pose" in out.reason
    assert not in_stall(stall, car, far, "reverse").parked


@pytest.mark.parametrize("task", ["park", "avp"])
def test_check_env_and_seeded_resets_of_the_registered_id(painted_tiny, task):
    from gymnasium.utils.env_checker import check_env

    env = gym.make("garage_mj/GarageDrive-v0", garage=painted_tiny, task=task, maneuver="any").unwrapped
    check_env(env, skip_render_check=True)
    a, b = (env.reset(seed=5)[1] for _ in range(2))
    assert (a["target_stall"], a["maneuver"], a["pose"]) == (b["target_stall"], b["maneuver"], b["pose"])
    assert np.array_equal(a["park_plan"]["poses"], b["park_plan"]["poses"])
    env.close()


def test_stall_fixes_a_cruise_tests_target_too(painted_tiny):
    env = GarageDriveEnv(painted_tiny, stall=3, infeasible="report")
    assert {env.reset(seed=s)[1]["target_stall"] for s in range(3)} == {3}
    assert env.action_space.n == 4  # still a cruise test
    env.close()


def test_a_multi_point_turn_of_short_shuffles_is_progress_until_it_stops(painted_tiny):
    """Each cusp driven restarts the no-progress clock (wheels turned at rest between short shuffles);
    the car stopping for good near the stall is then outside_stall."""
    _, _, near, monitor = _monitor_east_of_stall_3(painted_tiny, 2.0)
    t, sign = 0.0, 1.0
    for _ in range(12):  # 12 shuffles, 3 s each: 36 s without 0.3 m of progress, far past stuck_time
        for v in (0.0, 0.0, 0.0, 0.0, 0.2 * sign, 0.0):  # 2.5 s at rest turning the wheels, then a short move
            t += 0.5
            assert monitor.update(t, near[:2], v, yaw=near[2]) is None, t
        sign = -sign
    assert monitor.direction_changes == 11
    out = None
    while out is None:
        t += 0.5
        out = monitor.update(t, near[:2], 0.0, yaw=near[2])
    assert out.kind is OutcomeKind.OUTSIDE_STALL and "no progress for 8.0 s" in out.reason


def test_driving_a_new_plan_out_of_the_stall_area_is_progress_until_it_stops(painted_tiny):
    """Once the car is shown a new plan (the park guide's, from where it stood), driving along it counts as progress
    even away from the stall; without one the same drive is no progress, and a stop on it is outside_stall."""
    _, _, near, with_plan = _monitor_east_of_stall_3(painted_tiny, 0.5)
    _, _, _, without = _monitor_east_of_stall_3(painted_tiny, 0.5)
    away = Route([near[:2], (near[0] + 8.0, near[1])])  # the new plan: 8 m straight away from the stall
    with_plan.follow(away)
    for t in range(1, 101):  # 10 s at 0.5 m/s along it, away from the stall
        pose = (near[0] + 0.05 * t, near[1])
        assert with_plan.update(0.1 * t, pose, 0.5, yaw=near[2]) is None, t
        out = without.update(0.1 * t, pose, 0.5, yaw=near[2])
        if out is not None:
            break
    assert out is not None and out.kind is OutcomeKind.OUTSIDE_STALL and t * 0.1 >= 8.0
    stop, t = (near[0] + 5.0, near[1]), 10.0
    out = None
    while out is None:  # it stops on the new plan: after stuck_time of no progress, outside_stall
        t += 0.5
        out = with_plan.update(t, stop, 0.0, yaw=near[2])
    assert out.kind is OutcomeKind.OUTSIDE_STALL and 18.0 <= t <= 18.6
