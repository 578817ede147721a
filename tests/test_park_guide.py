"""The park guide: a park test's route stretch by stretch, as the observation's ``park_guide`` entry, and what a
learned parking driver reads of it."""

from __future__ import annotations

import numpy as np
import pytest

from garage_mj.driving.sim.park_guide import GUIDE_KEYS
from garage_mj.driving.sources import painted_sources


@pytest.fixture(scope="module")
def env():
    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.driving.sim.park_sensors import ALL_SENSORS

    (source,) = painted_sources("tiny_7x11", 1, seed=0)
    e = GarageDriveEnv(garage=source.garage, action_type="continuous", task="park", maneuver="reverse",
                       sensors=ALL_SENSORS)
    yield e
    e.close()


def test_the_guide_shows_the_stretch_the_oracle_drives_until_the_car_is_parked(env):
    """Driven by the oracle, the guide is on the stretch the oracle's tracker is on at every step, in its gear; it
    moves on at rest at the end of a stretch; the stretches after it count down to 0 and the last stretch's left reads
    about 0 once the car is parked."""
    from garage_mj.driving.drivers.oracle import OracleDriver

    oracle = OracleDriver()
    obs, info = env.reset(seed=2)
    oracle.reset(env.driver_info(2))
    first = dict(zip(GUIDE_KEYS, obs["park_guide"].tolist()))
    stretches = len(oracle.tracker.segments)
    assert stretches >= 2 and first["stretches_after"] == stretches - 1
    assert first["gear"] == oracle.tracker.segments[0].gear.sign and first["stretch_left"] > 0.5
    seen, done, speeds = [], False, []
    while not done:
        action = oracle.act(obs)
        assert env.park_guide.stretch == oracle.tracker.k  # the same rule, the same stretch
        assert obs["park_guide"][0] == oracle.tracker.segment.gear.sign
        obs, _, term, trunc, info = env.step(action)
        seen.append(env.park_guide.stretch)
        speeds.append(abs(float(obs["speed"][0])))
        done = term or trunc
    assert info["outcome"] == "success", info.get("reason")
    assert seen == sorted(seen) and seen[-1] == stretches - 1  # forward through every stretch, none skipped
    for k in range(1, stretches):  # a stretch is taken only at rest
        assert speeds[seen.index(k)] < 0.08
    last = dict(zip(GUIDE_KEYS, obs["park_guide"].tolist()))
    assert last["stretches_after"] == 0 and abs(last["stretch_left"]) < 0.3
    assert abs(last["lateral"]) < 0.1 and abs(last["heading"]) < 0.05
    assert env.observation_space["park_guide"].contains(obs["park_guide"])


def test_a_learned_parking_driver_reads_the_guide_after_the_rest_and_only_when_trained_with_it(env):
    from garage_mj.driving.learning.observation import (
        PARK_GUIDE_KEYS,
        PARK_ROUTE_KEYS,
        PARK_VECTOR_KEYS,
        park_observation,
        park_space,
        park_vector_size,
    )

    obs, _ = env.reset(seed=2)
    plain = park_observation(obs, route=True)
    guided = park_observation(obs, route=True, guide=True)
    assert park_vector_size(True, True) == len(PARK_VECTOR_KEYS) + len(PARK_ROUTE_KEYS) + len(PARK_GUIDE_KEYS)
    assert park_space(64, 64, True, True).contains(guided) and not park_space(64, 64, True).contains(guided)
    np.testing.assert_array_equal(guided["vector"][: len(plain["vector"])], plain["vector"])
    read = dict(zip(PARK_GUIDE_KEYS, guided["vector"][len(plain["vector"]):].tolist()))
    raw = dict(zip(GUIDE_KEYS, obs["park_guide"].tolist()))
    assert read["guide_gear"] == raw["gear"] and read["guide_after"] == min(raw["stretches_after"] / 2, 1)
    assert read["guide_left"] == pytest.approx(min(raw["stretch_left"] / 5.0, 1.0))
    # a different guide, the same rest: the guide is read only when asked for
    moved = dict(obs, park_guide=obs["park_guide"] + np.float32(0.5))
    np.testing.assert_array_equal(park_observation(moved, route=True)["vector"], plain["vector"])
    assert not np.array_equal(park_observation(moved, route=True, guide=True)["vector"], guided["vector"])
    with pytest.raises(ValueError, match="park_guide"):
        park_observation({k: v for k, v in obs.items() if k != "park_guide"}, guide=True)


def test_a_parking_config_takes_the_guide_or_a_replanning_expert_not_both():
    from garage_mj.driving.learning.train import DriverTrainConfig

    with pytest.raises(ValueError, match="park_guide, replan"):
        DriverTrainConfig(task="park", park_guide=True, replan=True)
    with pytest.raises(ValueError, match="a parking driver's"):
        DriverTrainConfig(park_guide=True)
    assert DriverTrainConfig(task="park", park_route=True, park_guide=True).fleet_options() == {
        "park_route": True, "replan": False, "park_guide": True, "actor_foresight": "trajectory"}
    with pytest.raises(ValueError, match="a parking driver's"):
        DriverTrainConfig(expert_foresight="present")


def test_the_learners_expert_takes_a_cusp_within_a_tenth_and_creeps_on_when_it_stopped_short():
    """The guide's rule (GUIDE_TRACKING), which the trainer's expert keeps too: at rest 5 cm short of a cusp the cusp
    is reached (the oracle's own rule creeps the 5 cm first); at rest 30 cm short of the stall after the stop began,
    it creeps on (the oracle's own rule holds there: a learner that braked early was told to stay)."""
    from garage_mj.driving.drivers.park_tracking import ParkTrackConfig, ParkTracker
    from garage_mj.driving.sim.park_guide import GUIDE_TRACKING
    from garage_mj.driving.sim.vehicle import Gear
    from tests.test_park_oracle import CAR, synthetic_plan

    poses, gears = synthetic_plan([(1, 3.0, 0.0), (-1, 3.0, 0.0)])  # 3 m forward, cusp, 3 m back
    for config, reached in ((GUIDE_TRACKING, True), (ParkTrackConfig(), False)):
        tracker = ParkTracker(poses, gears, CAR, config)
        short = (poses[0][0] + 2.95, poses[0][1], poses[0][2])  # at rest 5 cm before the cusp
        tracker.command(short, 0.0, Gear.D, 0.0)
        assert (tracker.k == 1) is reached, config
    for config, creeps in ((GUIDE_TRACKING, True), (ParkTrackConfig(), False)):
        tracker = ParkTracker(poses, gears, CAR, config)
        tracker.k, tracker.stopping = 1, True  # the stop at the stall began (the car braked early) ...
        end = poses[-1]
        pedal, _, gear = tracker.command((end[0] + 0.3, end[1], end[2]), 0.0, Gear.R, 0.0)  # ... 30 cm short, at rest
        assert gear is Gear.R and (pedal > 0) is creeps, config


def test_in_an_avp_test_the_guide_waits_for_the_car_at_the_plans_start(painted_tiny):
    """An AVP test starts at the entrance, at rest, far from the park plan: the guide reads zeros and stays on the plan's
    first stretch until the car has come near its start (at rest there, it would otherwise have taken the next
    stretch)."""
    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.driving.sim.park_guide import START_RADIUS

    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", task="avp", maneuver="reverse")
    obs, info = env.reset(seed=0)
    guide = env.park_guide
    start = info["park_plan"]["poses"][0]
    far = env.car.pose(env.data)
    assert np.hypot(far[0] - start[0], far[1] - start[1]) > START_RADIUS
    for _ in range(5):  # at rest at the entrance
        obs, *_ = env.step(np.array([-1.0, 0.0, 1.0], np.float32))
    assert not guide.started and guide.stretch == 0
    assert not obs["park_guide"].any()  # and reads zeros: no gear yet (the AVP driver hands over when it begins)
    guide.update(tuple(start), 0.0)  # the car at the plan's start: the guide follows it from there
    assert guide.started and guide.read(tuple(start))[0] == guide.tracker.segments[0].gear.sign  # its first stretch
    env.close()


def test_the_guide_plans_again_for_a_car_at_rest_off_its_plan_and_the_oracle_parks_on_the_new_plan():
    """A car held at rest on the plan's start for REPLAN_STUCK is shown a new plan from where it stands (the judge's
    reference stays the test's); the oracle driving that plan parks. With ``guide_replans=0`` the guide keeps the
    test's plan."""
    from garage_mj.driving.drivers.oracle import OracleDriver
    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.driving.sim.park_guide import REPLAN_STUCK
    from garage_mj.driving.sim.park_sensors import ALL_SENSORS

    (source,) = painted_sources("tiny_7x11", 1, seed=0)
    for replans in (3, 0):
        env = GarageDriveEnv(garage=source.garage, action_type="continuous", task="park", maneuver="reverse",
                             sensors=ALL_SENSORS, guide_replans=replans)
        try:
            obs, info = env.reset(seed=2)
            first, reference = env.park_guide.poses, env.route
            brake = np.array([-1.0, 0.0, 1.0], dtype=np.float32)
            steps = int(round(REPLAN_STUCK / env.dt)) + 2
            for _ in range(steps):
                obs, _, term, trunc, info = env.step(brake)
                assert not (term or trunc)
            guide = env.park_guide
            assert env.route is reference
            if not replans:
                assert guide.replans == 0 and guide.poses is first
                continue
            assert guide.replans == 1 and guide.poses is not first
            x, y, yaw = info["pose"]
            assert np.hypot(*(guide.poses[0, :2] - (x, y))) < 0.05  # the new plan starts where the car stands
            assert obs["park_guide"][GUIDE_KEYS.index("stretches_after")] == len(guide.tracker.segments) - 1
            oracle = OracleDriver()
            oracle.reset(env.driver_info(2))
            oracle.follow(guide.poses, guide.directions)
            done = False
            while not done:
                obs, _, term, trunc, info = env.step(oracle.act(obs))
                done = term or trunc
            assert info["outcome"] == "success", info.get("reason")
        finally:
            env.close()
    with pytest.raises(ValueError, match="guide_replans"):
        GarageDriveEnv(garage=source.garage, task="park", guide_replans=11)


def test_when_the_guide_wants_a_new_plan():
    """At rest where the last stretch ends (the guide stopping the car there) after REPLAN_AT_END, anywhere else after
    REPLAN_STUCK; never before the plan has begun, nor after ``max_replans`` tries."""
    from garage_mj.driving.sim.park_guide import REPLAN_AT_END, REPLAN_STUCK, ParkGuide
    from tests.test_park_oracle import CAR, synthetic_plan

    poses, gears = synthetic_plan([(1, 3.0, 0.0), (-1, 3.0, 0.0)])
    guide = ParkGuide(poses, gears, CAR, max_replans=1)
    assert not guide.wants_plan(100.0)  # the plan has not begun (an AVP test's cruise)
    guide.update(poses[0], 0.0)
    assert guide.started and not guide.wants_plan(REPLAN_AT_END) and guide.wants_plan(REPLAN_STUCK)
    guide.tracker.k, guide.tracker.stopping = 1, True  # stopped where the last stretch ends
    assert guide.wants_plan(REPLAN_AT_END) and not guide.wants_plan(REPLAN_AT_END - 0.2)
    guide.tracker.stopping, guide.left = False, 0.05  # at rest 5 cm short of the end, the stop not begun: at its end
    assert guide.wants_plan(REPLAN_AT_END)
    guide.left = 0.5  # half a metre short: stuck on the stretch
    assert not guide.wants_plan(REPLAN_AT_END) and guide.wants_plan(REPLAN_STUCK)
    guide.replace(poses[::-1], gears[::-1])
    assert guide.replans == 1 and guide.stretch == 0 and not guide.wants_plan(100.0)


def test_cruise_guide_replans_reaches_the_env_and_the_default_leaves_run_json_as_it_was():
    from garage_mj.cli import build_parser
    from garage_mj.cli.cruise import guide_env

    parser = build_parser()
    base = ["cruise", "--library", "lib.sqlite", "--task", "park", "--driver", "learned:park", "--out", "o"]
    assert guide_env(parser.parse_args(base)) == {}  # the default: no key, so a default run's run.json is unchanged
    assert guide_env(parser.parse_args([*base, "--guide-replans", "0"])) == {"guide_replans": 0}


def test_a_plans_first_stretch_of_a_few_centimetres_is_shown_as_driven():
    """A plan (the test's or a new one) that begins with a stretch shorter than SHORT_FIRST shows the car, at rest
    where it starts, the second stretch; a longer first stretch, and every later short one, is shown; with
    ``guide_replans`` 0 the test's plan is shown as it is."""
    from garage_mj.driving.sim.park_guide import SHORT_FIRST, ParkGuide
    from tests.test_park_oracle import CAR, synthetic_plan

    short, short_gears = synthetic_plan([(1, 0.1, 0.0), (-1, 3.0, 0.0), (1, 0.1, 0.0), (-1, 1.0, 0.0)])
    assert 0.1 < SHORT_FIRST
    guide = ParkGuide(short, short_gears, CAR)
    assert guide.stretch == 1 and guide.read(short[0])[0] == -1  # reverse: the 0.1 m forward nudge is not shown
    assert len(guide.tracker.segments) == 4  # the 0.1 m shuffle later in the plan stays
    longer, gears = synthetic_plan([(1, 0.3, 0.0), (-1, 3.0, 0.0)])
    guide.replace(longer, gears)
    assert guide.stretch == 0 and guide.read(longer[0])[0] == 1
    guide.replace(short, short_gears)
    assert guide.stretch == 1
    assert ParkGuide(short, short_gears, CAR, max_replans=0).stretch == 0  # guide_replans 0: the plan as it is


def test_a_car_stopped_a_little_short_of_a_cusp_is_shown_the_next_stretch():
    """A car at rest up to STUCK_CUSP_WITHIN short of a cusp, due a new plan and given none, is shown the next
    stretch; one farther short, or on the last stretch, is not."""
    from garage_mj.driving.sim.park_guide import STUCK_CUSP_WITHIN, ParkGuide
    from tests.test_park_oracle import CAR, synthetic_plan

    poses, gears = synthetic_plan([(1, 3.0, 0.0), (-1, 3.0, 0.0)])
    guide = ParkGuide(poses, gears, CAR)
    guide.update(poses[0], 0.0)
    guide.left = STUCK_CUSP_WITHIN + 0.05  # farther short: a new plan, not the next stretch
    assert not guide.skip_to_next() and guide.stretch == 0
    guide.left = 0.15  # over CUSP_WITHIN (so the cusp was not taken), within STUCK_CUSP_WITHIN
    assert guide.skip_to_next() and guide.stretch == 1 and guide.skips == 1
    assert guide.read(poses[30])[0] == -1  # the reverse stretch is shown
    guide.left = 0.1
    assert not guide.skip_to_next() and guide.stretch == 1  # the last stretch: nothing after it


def test_the_env_shows_a_correction_to_a_car_stopped_turned_in_its_stall_and_a_plan_to_one_farther_off():
    """``GarageDriveEnv.plan_from``, which the guide's new plans come from: a car a few degrees off the stall pose
    gets a correction ending parked; a car at the test's start gets the planner's plan into the stall."""
    import math

    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.scene.park_planning import in_stall

    (source,) = painted_sources("tiny_7x11", 1, seed=0)
    env = GarageDriveEnv(garage=source.garage, action_type="continuous", task="park", maneuver="reverse")
    try:
        env.reset(seed=2)
        x, y, yaw = env._park.stall_pose
        near = env.plan_from((x, y, yaw + math.radians(4.0)))
        stall = env.park_planner.scene.stalls.stalls[env._park.stall]
        assert near.found and near.method == "correction", near.reason
        assert in_stall(stall, env.park_planner.car, near.poses[-1], "reverse").parked
        far = env.plan_from(env._park.start)
        assert far.found and far.method != "correction" and np.allclose(far.poses[-1], (x, y, yaw))
    finally:
        env.close()


def test_at_a_cusp_a_car_turned_so_the_next_stretch_would_hit_something_is_shown_a_new_plan():
    """``ParkGuide.stretch_from`` is the stretch moved rigidly onto the car's rear axle (itself for a car on it); at a
    cusp the env shows a new plan from the car's pose when that would hit something (its own budget, not the new plans
    of a car at rest), and keeps the plan for a car on it; with ``guide_replans`` 0 no cusp is checked."""
    import math

    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.driving.sim.park_guide import ParkGuide
    from garage_mj.scene.clearance import nearest_obstacle

    (source,) = painted_sources("tiny_7x11", 1, seed=0)
    env = GarageDriveEnv(garage=source.garage, action_type="continuous", task="park", maneuver="reverse")
    try:
        env.reset(seed=2)
        guide = env.park_guide
        tracker = guide.tracker
        seg = tracker.segments[1]  # the reverse stretch into the stall, after the plan's one cusp
        b = tracker.car.rear_axle

        def at_cusp(turn_deg: float) -> tuple[float, float, float]:
            yaw = float(seg.yaw[0]) + math.radians(turn_deg)
            return seg.points[0, 0] - b * math.cos(yaw), seg.points[0, 1] - b * math.sin(yaw), yaw

        tracker.k, tracker.index = 1, 0  # the cusp taken
        rear, heading = guide.stretch_from(at_cusp(0.0))
        np.testing.assert_allclose(rear, seg.points, atol=1e-9)
        np.testing.assert_allclose(heading, seg.yaw, atol=1e-12)
        rear, heading = guide.stretch_from(at_cusp(-40.0))
        np.testing.assert_allclose(heading, seg.yaw - math.radians(40.0), atol=1e-12)
        turned = np.hypot(*(rear[-1] - seg.points[0])), np.hypot(*(seg.points[-1] - seg.points[0]))
        assert turned[0] == pytest.approx(turned[1])  # the same shape, turned about the rear axle
        clearance, _ = nearest_obstacle(env._park_obstacles(), env.car_geometry, rear, heading)
        assert clearance.min() <= 0.0  # driven from there, the stretch hits something
        env._check_cusp(at_cusp(0.0))
        assert guide.tracker is tracker and guide.cusp_plans == 0 and guide.replans == 0
        env._check_cusp(at_cusp(-40.0))
        assert guide.tracker is not tracker and guide.cusp_plans == 1
        assert guide.replans == 1 and guide.tries == 0  # shown, and the car at rest keeps its own new plans
        assert np.hypot(*(guide.poses[0, :2] - at_cusp(-40.0)[:2])) < 0.05  # from where the car stands
        assert guide.wants_cusp_check() and not ParkGuide(guide.poses, guide.directions, tracker.car,
                                                          max_replans=0).wants_cusp_check()
    finally:
        env.close()


def test_the_env_checks_each_cusp_the_guide_takes_and_an_oracle_on_its_plan_needs_no_new_one(env):
    """Driving a plan, the env checks the next stretch once at each cusp the guide takes, never elsewhere; the oracle,
    on its plan, is shown no new plan there."""
    from garage_mj.driving.drivers.oracle import OracleDriver

    checked: list[int] = []
    check = env._check_cusp
    env._check_cusp = lambda pose: (checked.append(env.park_guide.stretch), check(pose))
    try:
        oracle = OracleDriver()
        obs, info = env.reset(seed=2)
        oracle.reset(env.driver_info(2))
        stretches = len(env.park_guide.tracker.segments)
        done = False
        while not done:
            obs, _, term, trunc, info = env.step(oracle.act(obs))
            done = term or trunc
        assert info["outcome"] == "success", info.get("reason")
        assert checked == list(range(1, stretches)) and env.park_guide.cusp_plans == 0
    finally:
        del env._check_cusp
