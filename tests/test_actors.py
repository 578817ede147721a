"""Adverse events: actors drawn from the seed, judged avoidable from the scene, seen, hit, replayed."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute
from garage_mj.core.config import ConfigError
from garage_mj.driving.actors.config import ScenarioConfig, load_scenario_config
from garage_mj.driving.actors.judging import judge
from garage_mj.driving.actors.placement import draw_scenario
from garage_mj.driving.actors.scenario import Corridor, actor_poses, sample_times
from garage_mj.driving.cruise import read_tests, run_cruise
from garage_mj.driving.drivers import load_driver
from garage_mj.driving.replay import replay_xosc
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sources import CruiseSettings
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.actor_spec import ActorSpec
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.semantics import COLLIDABLE, Semantic

BUSY = {"pedestrians": 2, "moving_cars": 1, "clutter": 2}


@pytest.fixture(scope="module")
def m5():
    return paint_garage("m5_13x13_aligned", 0)


@pytest.fixture(scope="module")
def long_plan(m5):
    scene = GarageScene(m5)
    planner = drive_planner(scene)
    plan = max((p for p in planner.plans() if p.feasible), key=lambda p: p.length)
    return planner, plan


def test_config_validates_and_loads_toml(tmp_path):
    with pytest.raises(ConfigError, match="pedestrians"):
        ScenarioConfig(pedestrians=-1)
    with pytest.raises(ConfigError, match="pedestrian_behaviours"):
        ScenarioConfig(pedestrian_behaviours=("moonwalk",))
    with pytest.raises(ConfigError, match="brake_decel"):
        ScenarioConfig(brake_decel=0.0)
    f = tmp_path / "s.toml"
    f.write_text('[scenario]\npedestrians = 3\nlead = [1.0, 2.0]\nmoving_car_behaviours = ["oncoming"]\n')
    cfg = load_scenario_config(f, clutter=2)
    assert (cfg.pedestrians, cfg.clutter, cfg.lead, cfg.moving_car_behaviours) == (3, 2, (1.0, 2.0), ("oncoming",))
    f.write_text("[scenario]\nwalkers = 3\n")
    with pytest.raises(ConfigError, match="walkers"):
        load_scenario_config(f)


def test_draws_are_seeded_and_every_event_avoidable(long_plan):
    planner, plan = long_plan
    cfg = ScenarioConfig(**BUSY)
    draws = [draw_scenario(cfg, plan, planner, np.random.default_rng(s)) for s in range(12)]
    again = draw_scenario(cfg, plan, planner, np.random.default_rng(3))
    assert [a.as_dict() for a in again.actors] == [a.as_dict() for a in draws[3].actors]
    assert len({tuple(a.behaviour for a in d.actors) for d in draws}) > 1
    corr = Corridor(plan, planner.car)
    kinds = set()
    for d in draws:
        assert d.feasible, d.reason
        for a in d.actors:
            kinds.add(a.kind)
            poses = actor_poses(a, sample_times(a))
            # starts and ends clear of the car's swept path; static ones never touch it
            assert corr.clearance(a.shape, poses[:1]) >= planner.config.clearance_margin
            assert corr.clearance(a.shape, poses[-1:]) >= planner.config.clearance_margin
            assert a.static == (a.kind == "clutter")
    assert kinds == {"pedestrian", "moving_car", "clutter"}


def test_an_unavoidable_event_is_infeasible_with_a_reason(long_plan):
    planner, plan = long_plan
    corr = Corridor(plan, planner.car)
    i = corr.index_at(corr.s[corr.i0] + 20.0)
    p, h = corr.pose(i)
    right = np.array([math.sin(h), -math.cos(h)])
    a, b = p + right * 3.2, p - right * 6.0
    walk = np.array([[0.0, *a, h], [9.2 / 1.2, *b, h]])
    # triggered 1 m before the place it crosses: no driver can stop in time
    trig = corr.centre[corr.index_at(corr.s[i] - 1.0)]
    late = ActorSpec("pedestrian_0", "pedestrian", "cross", walk, (float(trig[0]), float(trig[1])), 2.0)
    ok, why = judge([late], plan, planner, ScenarioConfig())
    assert not ok and "stopping" in why
    # the same walk started 25 m ahead is avoidable
    trig = corr.centre[corr.index_at(corr.s[i] - 25.0)]
    early = ActorSpec("pedestrian_0", "pedestrian", "cross", walk, (float(trig[0]), float(trig[1])), 2.0)
    assert judge([early], plan, planner, ScenarioConfig()) == (True, "")
    # a pedestrian who stops in the lane leaves no room to pass
    stay = ActorSpec("pedestrian_0", "pedestrian", "cross", np.array([[0.0, *a, h], [3.0, *p, h]]),
                     early.trigger, 2.0)
    ok, why = judge([stay], plan, planner, ScenarioConfig())
    assert not ok and "stops in the car's path" in why
    # a cone on the lane centre line: infeasible from the scene alone
    cone = ActorSpec("clutter_0", "clutter", "cone", np.array([[0.0, *p, 0.0]]))
    assert not judge([cone], plan, planner, ScenarioConfig())[0]


def test_actors_are_seen_hit_and_counted(m5, long_plan):
    _, plan = long_plan
    env = GarageDriveEnv(m5, action_type="continuous", infeasible="report", scenario={"pedestrians": 1})
    try:
        assert {Semantic.PEDESTRIAN, Semantic.MOVING_CAR, Semantic.CLUTTER} <= COLLIDABLE
        corr = Corridor(plan, env.car_geometry)
        p, h = corr.pose(corr.i0 + 4)
        ahead = p + 6.0 * np.array([math.cos(h), math.sin(h)])
        # a pedestrian standing in the lane 6 m ahead: given (as a replay would), so judged too
        ped = {"name": "pedestrian_0", "kind": "pedestrian", "behaviour": "cross",
               "waypoints": [[0.0, ahead[0], ahead[1], 0.0]], "trigger": None}
        obs, info = env.reset(seed=0, options={"target": plan.stall, "actors": [ped]})
        assert info["outcome"] == "infeasible" and "pedestrian" in info["reason"]
        assert (obs["segmentation"] == Semantic.PEDESTRIAN).any()  # seen by the camera, its own class
        assert obs["actors"].shape == (1, 4) and obs["actors"][0, 3] == 0.0
        # a pedestrian crossing 30 m ahead, started 25 m before, dawdling 30 s across the lane:
        # avoidable (stop and wait), but the blind waypoint driver does not yield
        straight = np.abs(np.asarray(plan.curvature)) < 1e-9
        i = next(k for k in range(corr.index_at(corr.s[corr.i0] + 30.0), len(corr.s) - 40)
                 if straight[k - 40:k + 40].all())  # 10 m of straight lane either side
        p, h = corr.pose(i)
        right = np.array([math.sin(h), -math.cos(h)])
        a, b, c, d = (p + right * k for k in (3.2, 1.6, -1.6, -6.2))
        trig = corr.centre[corr.index_at(corr.s[i] - 25.0)]
        ped = {"name": "pedestrian_0", "kind": "pedestrian", "behaviour": "cross",
               "waypoints": [[0.0, *a, h], [1.3, *b, h], [31.3, *c, h], [35.0, *d, h]], "trigger": list(trig),
               "trigger_radius": 2.0}
        obs, info = env.reset(seed=0, options={"target": plan.stall, "actors": [ped]})
        assert info["feasible"] and info["actors"]["pedestrian"] == 1
        drv = load_driver("waypoint")
        drv.reset(env.driver_info(0))
        while True:
            obs, _, term, trunc, info = env.step(drv.act(obs))
            if term or trunc:
                break
        assert info["outcome"] == "collision" and info["hit"] == "pedestrian", info["reason"]
        assert obs["actors"][0, 3] > 0  # it was walking
    finally:
        env.close()


def test_oracle_yields_and_wins_with_actors(m5):
    env = GarageDriveEnv(m5, action_type="continuous", infeasible="report", scenario=BUSY)
    drv = load_driver("oracle")
    outcomes, moved = [], 0
    try:
        for seed in range(3):
            obs, info = env.reset(seed=seed)
            if info.get("outcome") == "infeasible":
                outcomes.append("infeasible")
                continue
            drv.reset(env.driver_info(seed))
            while True:
                obs, _, term, trunc, info = env.step(drv.act(obs))
                if term or trunc:
                    break
            moved += int((obs["actors"][:, 3] > 0).sum())
            outcomes.append(info["outcome"])
    finally:
        env.close()
    assert outcomes.count("success") >= 2 and set(outcomes) <= {"success", "infeasible"}, outcomes
    assert moved > 0  # events did fire


def test_cruise_actors_xosc_replay_and_workers(tmp_path):
    g = paint_garage("tiny_7x11", 2)
    env = {"scenario": {"pedestrians": 1, "moving_cars": 1, "clutter": 1}}
    one = run_cruise([g], 3, CruiseSettings("waypoint", action_type="continuous", env=env), tmp_path / "w1",
                     xosc=True, compute=Compute(workers=1, progress=False))
    two = run_cruise([g], 3, CruiseSettings("waypoint", action_type="continuous", env=env), tmp_path / "w2",
                     compute=Compute(workers=2, progress=False))
    def key(rows):
        return sorted(tuple(v for k, v in r.items() if k != "wall_s") for r in rows)

    assert key(one.rows) == key(two.rows)  # whatever the worker count
    rows = sorted(read_tests(tmp_path / "w1" / "tests.csv"), key=lambda r: int(r["test"]))
    assert sum(int(r["pedestrians"]) + int(r["moving_cars"]) + int(r["clutter"]) for r in rows) > 0
    files = sorted((tmp_path / "w1" / "xosc").glob("*.xosc"))
    assert len(files) == 3 and (tmp_path / "w1" / "packs").is_dir()
    from garage_mj.export.validate import check_xosc_batch

    for rep in check_xosc_batch(files):  # ASAM's OpenSCENARIO XML checker: every written file clean
        assert rep.ok and rep.completed >= 17 and not rep.skipped, (rep.path, rep.issues)
    for f, r in zip(files, rows, strict=True):
        again = replay_xosc(f)
        assert (again["outcome"], again["time"], again["hit"], again["path_length"]) == (
            r["outcome"], float(r["time"]), r["hit"], float(r["path_length"]))
    with open(tmp_path / "w1" / "summary.csv", newline="") as fh:
        head = next(csv.reader(fh))
    assert {"hit_pedestrian", "hit_moving_car", "hit_clutter"} <= set(head)


def test_cli_actor_flags_and_scenario_file(tmp_path, capsys):
    from garage_mj.export.pack import export_pack

    packs = tmp_path / "packs"
    export_pack(paint_garage("tiny_7x11", 1), packs)
    out = tmp_path / "run"
    assert main(["cruise", "--packs", str(packs), "--tests", "2", "--driver", "oracle", "--action-type",
                 "continuous", "--pedestrians", "1", "--clutter", "1", "--xosc", "--out", str(out), "--quiet"]) == 0
    files = sorted((out / "xosc").glob("*.xosc"))
    assert len(files) == 2
    assert main(["cruise", "--scenario-file", str(files[0]), "--out", str(tmp_path / "re")]) == 0
    said = capsys.readouterr().out
    assert "1 replayed" in said and (tmp_path / "re" / "replay.csv").is_file()
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\npedestrians = -2\n")
    assert main(["cruise", "--packs", str(packs), "--scenario", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pedestrians" in err[0]
