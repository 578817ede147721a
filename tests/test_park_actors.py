"""Actors in park and AVP tests: placed around the target stall and the park plan from the test's seed, judged on the
plan's swept path, yielded to by the oracle, hit as collisions, exported and replayed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from garage_mj.core.backends import Compute
from garage_mj.driving.actors.config import SCENARIOS, load_scenario_config
from garage_mj.driving.actors.park_placement import park_corridor
from garage_mj.driving.actors.scenario import actor_poses, sample_times
from garage_mj.driving.cruise import read_tests, run_cruise
from garage_mj.driving.drivers import load_driver
from garage_mj.driving.replay import replay_xosc
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sources import CruiseSettings
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.actor_spec import PARK_BEHAVIOURS


@pytest.fixture(scope="module")
def tiny():
    return paint_garage("tiny_7x11", seed=1)


def _drive(env, obs, seed: int, blind: bool = False):
    """The oracle to the end of the test; ``blind``: it is not told of the actors. Returns the last info and how
    many steps it stood still while an actor moved."""
    drv = load_driver("oracle")
    info = env.driver_info(seed)
    if blind:
        info["actors"] = []
    drv.reset(info)
    held = 0
    while True:
        obs, _, term, trunc, info = env.step(drv.act(obs))
        moving = [0.0 <= t < a.duration for t, a in zip(env._actor_tau, env.scenario.actors, strict=True)
                  if not a.static and t is not None]
        held += abs(float(obs["speed"][0])) < 0.02 and any(moving)
        if term or trunc:
            return info, held


def test_named_scenarios_load_and_a_cruise_test_draws_none_of_their_behaviours():
    cfg = load_scenario_config("park_mixed")
    assert (cfg.pedestrians, cfg.moving_cars, cfg.clutter) == (1, 1, 1)
    assert set(cfg.pedestrian_behaviours) == set(PARK_BEHAVIOURS["pedestrian"])
    assert load_scenario_config("park_car_pulling_out").moving_car_behaviours == ("pull_out",)
    assert all(name.startswith("park_") for name in SCENARIOS)
    # a cruise test asked only for park behaviours places nothing, and says so
    env = GarageDriveEnv(paint_garage("tiny_7x11", seed=1), scenario="park_pedestrian_behind")
    try:
        _, info = env.reset(seed=0)
        assert info["actors"]["pedestrian"] == 0 and info["actors_missing"] == {"pedestrian": 1}
    finally:
        env.close()


def test_placement_is_seeded_and_leaves_the_other_draws_alone(tiny):
    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_mixed")
    bare = GarageDriveEnv(tiny, action_type="continuous", task="park")
    try:
        for seed in (1, 4):
            _, info = env.reset(seed=seed)
            first = [a.as_dict() for a in env.scenario.actors]
            assert first and info["feasible"]
            _, again = env.reset(seed=seed)
            assert [a.as_dict() for a in env.scenario.actors] == first
            _, plain = bare.reset(seed=seed)
            # the same stall, start, plan and parked cars (less the stall a pulling-out car takes) as without actors
            assert (env.target, env.start_pose) == (bare.target, bare.start_pose)
            assert np.array_equal(env._park.plan.poses, bare._park.plan.poses)
            assert sorted(env.occupied) == sorted(set(bare.occupied) - env.scenario.free_stalls)
    finally:
        env.close()
        bare.close()


def test_a_scene_seed_keeps_one_tests_scene_and_places_its_actors_anew(tiny):
    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_mixed", parked_fleet="mixed")
    kept = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_mixed", parked_fleet="mixed",
                          scene_seed=4)
    try:
        env.reset(seed=4)
        scene = (env.target, env.start_pose, env._park.plan.poses, env._park.maneuver)
        actors = [a.as_dict() for a in env.scenario.actors]
        kept.reset(seed=4)  # its own seed: the very test
        assert [a.as_dict() for a in kept.scenario.actors] == actors
        placed = set()
        for seed in (5, 6, 7):
            kept.reset(seed=seed)
            # the scene of seed 4: stall, start, maneuver, plan and parked cars (but those the actors' take)
            assert (kept.target, kept.start_pose, kept._park.maneuver) == (scene[0], scene[1], scene[3])
            assert np.array_equal(kept._park.plan.poses, scene[2])
            taken = kept.scenario.free_stalls | env.scenario.free_stalls
            assert sorted(set(kept.occupied) - taken) == sorted(set(env.occupied) - taken)
            assert {k: b for k, b in kept.parked_bodies.items() if k not in taken} == \
                {k: b for k, b in env.parked_bodies.items() if k not in taken}  # the mixed fleet's cars too
            placed.add(repr([a.as_dict() for a in kept.scenario.actors]))
        assert len(placed) == 3 and repr(actors) not in placed
    finally:
        env.close()
        kept.close()
    with pytest.raises(ValueError, match="scene_seed is for park and AVP tests"):
        GarageDriveEnv(tiny, scene_seed=4)
    with pytest.raises(ValueError, match="scene_seed must be a test seed"):
        GarageDriveEnv(tiny, task="park", scene_seed=-1)


def test_the_pedestrian_behind_crosses_the_reverse_path(tiny):
    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_pedestrian_behind")
    try:
        crossed = 0
        for seed in range(4):
            _, info = env.reset(seed=seed)
            (ped,) = env.scenario.actors
            plan = env._park.plan
            rev = np.flatnonzero(np.asarray(plan.directions) < 0)
            assert ped.behaviour == "behind_stall" and len(rev)
            # it starts as the car reaches the first reverse stretch
            assert np.allclose(ped.trigger, plan.poses[rev[0], :2])
            corr = park_corridor(plan.poses[rev[0]:], env.car_geometry)
            hit = corr.conflicts(ped.shape, actor_poses(ped, sample_times(ped)), 0.0)
            assert not hit[0].any() and not hit[-1].any()  # it waits and ends clear of the path
            crossed += bool(hit.any())
        assert crossed == 4
    finally:
        env.close()


def test_the_pulling_out_car_starts_in_an_occupied_neighbour_stall(tiny):
    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_car_pulling_out")
    bare = GarageDriveEnv(tiny, action_type="continuous", task="park")
    try:
        seen = 0
        for seed in range(1, 5):
            env.reset(seed=seed)
            bare.reset(seed=seed)
            if not env.scenario.actors:
                continue
            (car,) = env.scenario.actors
            st, target = env.stalls[car.stall], env.stalls[env.target]
            assert car.behaviour == "pull_out" and car.stall in bare.occupied and car.stall not in env.occupied
            assert np.allclose(car.waypoints[0, 1:3], (st.x, st.y))  # where its parked car stood
            assert abs(math.remainder(st.yaw - target.yaw, math.tau)) < 0.1  # the target's row
            assert math.hypot(st.x - target.x, st.y - target.y) <= 3.6 * target.width
            out = np.array([math.cos(st.yaw), math.sin(st.yaw)])
            assert float((car.waypoints[-1, 1:3] - np.array(st.entry)) @ out) > 2.0  # it ends in the aisle
            seen += 1
        assert seen >= 3
    finally:
        env.close()
        bare.close()


def test_the_oracle_parks_and_waits_for_the_actors(tiny):
    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_mixed")
    try:
        outcomes, held = [], 0
        for seed in range(3):
            obs, info = env.reset(seed=seed)
            assert info["feasible"] and sum(info["actors"].values()) >= 2
            info, h = _drive(env, obs, seed)
            outcomes.append(info["outcome"])
            assert info["min_clearance"] > 0  # measured to what stands still, not to where a walker started
            held += h
        assert outcomes == ["success"] * 3
        assert held > 0  # it stood while an actor crossed its way
    finally:
        env.close()


def test_contact_with_an_actor_is_a_collision(tiny):
    """A pedestrian that stops behind the reversing car for 15 s: avoidable, so the oracle waits and parks; told
    nothing of it, the oracle reverses into it (a collision with a pedestrian)."""
    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_pedestrian_behind")
    try:
        obs, info = env.reset(seed=2)
        (ped,) = env.scenario.actors
        plan = env._park.plan
        rev = int(np.flatnonzero(np.asarray(plan.directions) < 0)[0])
        corr = park_corridor(plan.poses[rev:], env.car_geometry)
        times = sample_times(ped)
        k = int(np.flatnonzero(corr.conflicts(ped.shape, actor_poses(ped, times), 0.0).any(axis=1))[0])
        stop = ped.pose_at(float(times[k]) + 0.5)  # well inside the reverse path
        w = ped.waypoints
        d = ped.as_dict()
        d["waypoints"] = [w[0].tolist(), [times[k] + 0.5, *stop], [times[k] + 15.5, *stop],
                          [w[-1, 0] + 15.0, *w[-1, 1:]]]
        opts = {"target": env.target, "occupied": env.occupied, "start": env.start_pose, "actors": [d]}
        obs, info = env.reset(seed=2, options=opts)
        assert info["feasible"], info.get("reason")
        info, held = _drive(env, obs, 2)
        assert info["outcome"] == "success" and held * env.dt > 5.0
        obs, info = env.reset(seed=2, options=opts)
        info, _ = _drive(env, obs, 2, blind=True)
        assert info["outcome"] == "collision" and info["hit"] == "pedestrian", info["reason"]
    finally:
        env.close()


@pytest.mark.slow
def test_park_actors_export_replay_and_any_worker_count(tmp_path, tiny):
    settings = CruiseSettings("oracle", action_type="continuous", task="park", env={"scenario": "park_mixed"})
    one = run_cruise([tiny], 3, settings, tmp_path / "w1", xosc=True, compute=Compute(workers=1, progress=False))
    two = run_cruise([tiny], 3, settings, tmp_path / "w2", compute=Compute(workers=2, progress=False))

    def key(rows):
        return sorted(tuple(v for k, v in r.items() if k != "wall_s") for r in rows)

    assert key(one.rows) == key(two.rows)  # the same actors and outcomes whatever the worker count
    rows = sorted(read_tests(tmp_path / "w1" / "tests.csv"), key=lambda r: int(r["test"]))
    assert all(int(r["pedestrians"]) + int(r["moving_cars"]) + int(r["clutter"]) >= 2 for r in rows)
    # the pedestrians by behaviour, the hazard a park difficulty would weigh
    assert all(int(r["pedestrians_behind"]) + int(r["pedestrians_beside"]) == int(r["pedestrians"]) for r in rows)
    assert any(int(r["moving_cars"]) for r in rows)  # a pulling-out car's stall is freed in the replay too
    files = sorted((tmp_path / "w1" / "xosc").glob("*.xosc"))
    assert len(files) == 3
    from garage_mj.export.validate import check_xosc_batch

    for rep in check_xosc_batch(files):  # ASAM's OpenSCENARIO XML checker: park files with actors are clean too
        assert rep.ok and rep.completed >= 17 and not rep.skipped, (rep.path, rep.issues)
    for f, r in zip(files, rows, strict=True):
        again = replay_xosc(f)
        assert (again["outcome"], again["time"], again["hit"], again["path_length"]) == (
            r["outcome"], float(r["time"]), r["hit"], float(r["path_length"]))


def test_cli_park_scenarios_are_named_and_refused_in_cruise_tests(tmp_path, capsys, tiny):
    from garage_mj.cli import main
    from garage_mj.export.pack import export_pack

    export_pack(tiny, tmp_path)
    assert main(["cruise", "--packs", str(tmp_path), "--scenario", "park_mixed", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--task park" in err[0]
    assert main(["cruise", "--packs", str(tmp_path), "--task", "park", "--scenario", "park_nosuch",
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "park_car_pulling_out" in err[0]


def test_a_present_foresight_tracker_yields_only_to_where_an_actor_is_now(tiny):
    """The privileged tracker stops for a pedestrian that will cross its path; with ``actor_foresight`` "present"
    (the expert a camera-driven learner imitates) only once the pedestrian is on it, and both go on when it has
    passed."""
    from garage_mj.driving.drivers.park_tracking import ACTOR_FORESIGHT, ParkTrackConfig, ParkTracker

    env = GarageDriveEnv(tiny, action_type="continuous", task="park", scenario="park_pedestrian_behind")
    try:
        env.reset(seed=2)
        (ped,) = env.scenario.actors
        plan = env._park.plan
        trackers = {f: ParkTracker(plan.poses, plan.directions, env.car_geometry, ParkTrackConfig(actor_foresight=f))
                    for f in ACTOR_FORESIGHT}
        for tracker in trackers.values():
            tracker.watch([ped], 0.4, 0.5, 2.0)
        tracker = trackers["trajectory"]
        k = next(i for i, b in enumerate(tracker.blocks) if b)  # the stretch the pedestrian crosses
        (_, times, _), = tracker.blocks[k]
        on_path = trackers["present"].blocks[k][0][2].any(axis=1)  # per moment: on the path now
        assert on_path.any() and not on_path[0]
        first = int(np.flatnonzero(on_path)[0])
        gone = int(np.flatnonzero(on_path)[-1]) + 1

        def stop(foresight, t):
            tr = trackers[foresight]
            tr.k, tr.index = k, 0
            return tr._actor_stop(np.array([[0.0, 0.0, 0.0, times[t] + 0.2]]))

        assert stop("trajectory", 0) < math.inf and stop("present", 0) == math.inf  # coming: only foresight stops
        assert stop("trajectory", first) < math.inf and stop("present", first) < math.inf  # on the path: both
        if gone < len(times):
            assert stop("present", gone) == math.inf  # passed
        with pytest.raises(ValueError, match="actor_foresight"):
            ParkTrackConfig(actor_foresight="psychic")
    finally:
        env.close()


def test_a_rows_pedestrians_by_behaviour_are_the_tests_own(tiny):
    """``pedestrians_behind`` and ``pedestrians_beside`` count the test's pedestrians by what they do; a cruise row
    leaves both empty."""
    from garage_mj.driving.cruise import run_test
    from garage_mj.driving.sources import CruiseSource

    source = CruiseSource.from_garage(tiny, "tiny")
    for scenario, behaviour in (("park_pedestrian_behind", "behind_stall"), ("park_pedestrian_beside", "beside_stall")):
        settings = CruiseSettings("oracle", action_type="continuous", task="park", env={"scenario": scenario})
        row = run_test(source, 0, settings)
        env = GarageDriveEnv(garage=tiny, task="park", scenario=scenario)
        env.reset(seed=int(row["seed"]))
        drawn = [a.behaviour for a in env.scenario.actors if a.kind == "pedestrian"]
        env.close()
        assert drawn == [behaviour] and int(row["pedestrians"]) == 1, (scenario, drawn, row["pedestrians"])
        cells = (int(row["pedestrians_behind"]), int(row["pedestrians_beside"]))
        assert cells == ((1, 0) if behaviour == "behind_stall" else (0, 1)), (scenario, cells)
    cruise = run_test(source, 0, CruiseSettings("oracle", action_type="continuous"))
    assert cruise["pedestrians_behind"] == cruise["pedestrians_beside"] == ""
