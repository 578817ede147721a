"""The oracle reference driver: every feasible test on tiny garages succeeds, deterministically."""

from __future__ import annotations

from pathlib import Path

import pytest

from garage_mj.core.backends import Compute
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.drivers import load_driver
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.grid.garage import Garage

SHAPES = Path(__file__).parent / "data" / "shapes"


def drive(env: GarageDriveEnv, seed: int):
    obs, info = env.reset(seed=seed)
    driver = load_driver("oracle")
    driver.reset(env.driver_info(seed))
    trace = []
    while True:
        obs, _, term, trunc, info = env.step(driver.act(obs))
        trace.append(tuple(round(float(v), 6) for v in info["pose"]))
        if term or trunc:
            return info, trace


def test_oracle_succeeds_on_every_feasible_tiny_test_with_default_settings(painted_tiny, tmp_path):
    res = run_cruise([painted_tiny], 8, CruiseSettings("oracle"), tmp_path,
                     compute=Compute(progress=False))  # its own action type
    outcomes = [r["outcome"] for r in res.rows]
    assert "infeasible" not in outcomes  # the painted tiny garage is wholly drivable
    assert outcomes == ["success"] * 8, [(r["outcome"], r["reason"]) for r in res.rows]
    assert res.stats["success_pct"] == 100.0 and res.stats["infeasible"] == 0
    assert (res.stats["action_type"], res.stats["action_type_from"]) == ("continuous", "driver")


@pytest.mark.parametrize("name", ["wide_15x21_s0", "small_5x9_s1", "island_9x9_s0"])
def test_oracle_drives_non_square_garages_and_islands(name):
    g = Garage.from_json((SHAPES / f"{name}.json").read_text())
    env = GarageDriveEnv(garage=g, action_type="continuous")
    try:
        for seed in (0, 1):
            info, _ = drive(env, seed)
            assert info["outcome"] == "success", info["reason"]
    finally:
        env.close()


def test_oracle_is_deterministic_and_stops_on_the_goal_pose(painted_tiny):
    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous")
    try:
        a, trace_a = drive(env, 3)
        b, trace_b = drive(env, 3)
        assert trace_a == trace_b and a["outcome"] == "success"
        gx, gy, _ = a["goal"]
        x, y, _ = a["pose"]
        assert (x - gx) ** 2 + (y - gy) ** 2 <= env.outcome_config.goal_tolerance ** 2
    finally:
        env.close()


def test_infeasible_tests_are_reported_not_driven(painted_tiny, tmp_path):
    # a car that cannot turn tighter than ~22 m: every test behind a turn is infeasible before the drive
    res = run_cruise([painted_tiny], 6,
                     CruiseSettings("oracle", action_type="continuous", env={"car": {"max_steer": 0.15}}),
                     tmp_path, compute=Compute(progress=False))
    infeasible = [r for r in res.rows if r["outcome"] == "infeasible"]
    assert infeasible and all(r["reason"] and float(r["time"]) == 0.0 and r["feasible"] == "0" for r in infeasible)
    assert all(r["feasible"] == "1" for r in res.rows if r["outcome"] != "infeasible")
    summary = res.summary[0]
    assert summary["infeasible"] == len(infeasible) and summary["feasible"] == 6 - len(infeasible)
    assert res.stats["infeasible"] == len(infeasible)
    header = (tmp_path / "summary.csv").read_text().splitlines()[0].split(",")
    assert "infeasible" in header and "feasible" in header
    assert CruiseSource.from_garage(painted_tiny).hash == res.rows[0]["garage_hash"]
