"""The drive env's observation table: the env, the learned driver's view and the docs all follow it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces

import garage_mj.driving.sim.observations as table
from garage_mj.driving.learning import observation as learned
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.observations import (
    OBSERVATIONS,
    ObservationEntry,
    ObservationSetup,
    observation_spaces,
    observations_markdown,
)
from garage_mj.driving.sim.park_sensors import ALL_SENSORS
from garage_mj.driving.sim.sensors import CameraConfig

DOCS = Path(__file__).resolve().parents[1] / "docs" / "observations.md"
SENSORS = {"rear_depth", "rear_segmentation", "ultrasonic", "slot"}  # opt-in: GarageDriveEnv(sensors=...)


def test_docs_observations_md_is_rendered_from_the_table():
    assert DOCS.read_text() == observations_markdown(), (
        "docs/observations.md is stale: python -m garage_mj.driving.sim.observations > docs/observations.md")
    for e in OBSERVATIONS:
        assert f"| `{e.name}` |" in DOCS.read_text()


def test_table_entries_are_unique_and_documented():
    names = [e.name for e in OBSERVATIONS]
    assert len(set(names)) == len(names)
    assert all(e.description and "\n" not in e.description for e in OBSERVATIONS)
    assert {e.name for e in OBSERVATIONS if e.privileged} == {"pose", "actors"}


@pytest.mark.parametrize("setup, present", [
    (ObservationSetup(CameraConfig()), {"depth", "segmentation", "waypoint", "speed", "goal", "remaining",
                                        "steer", "pose"}),
    (ObservationSetup(CameraConfig(rgb=True), image_obs=True, actors=3),
     {e.name for e in OBSERVATIONS} - {"stall", "gear", "park_guide"} - SENSORS),  # a cruise test's: none of a park test's
    (ObservationSetup(CameraConfig(rgb=True), image_obs=True, actors=3, task="park"),
     {e.name for e in OBSERVATIONS} - SENSORS),
    (ObservationSetup(CameraConfig(rgb=True), image_obs=True, actors=3, task="park", sensors=ALL_SENSORS),
     {e.name for e in OBSERVATIONS}),
])
def test_options_pick_the_entries(setup, present):
    got = observation_spaces(setup)
    assert set(got) == present
    if setup.actors:
        assert got["actors"].shape == (3, 4) and got["depth"].shape == (64, 64, 1)


def test_env_space_and_observation_follow_the_table(painted_tiny):
    env = GarageDriveEnv(painted_tiny, rgb=True, scenario={"clutter": 1})
    setup = ObservationSetup(env.camera_config, actors=1)
    assert env.observation_space == spaces.Dict(observation_spaces(setup))
    obs, _ = env.reset(seed=0)
    assert list(obs) == [e.name for e in OBSERVATIONS if e.name not in {"stall", "gear", "park_guide"} | SENSORS]  # in order
    assert env.observation_space.contains(obs)
    env.close()


def test_a_new_sensor_is_one_entry(painted_tiny, monkeypatch):
    odometer = ObservationEntry("odometer", lambda setup: spaces.Box(0.0, np.inf, (1,), np.float32), False,
                                "path driven [m]", lambda s: np.array([s.env.path_length], np.float32))
    monkeypatch.setattr(table, "OBSERVATIONS", (*OBSERVATIONS, odometer))
    env = GarageDriveEnv(painted_tiny)
    obs, _ = env.reset(seed=0)
    obs, *_ = env.step(0)
    assert "odometer" in env.observation_space.spaces and obs["odometer"][0] > 0
    assert "| `odometer` |" in table.observations_markdown()
    env.close()


def test_the_learned_view_reads_only_the_unprivileged_entries(monkeypatch):
    assert learned.UNPRIVILEGED == tuple(e.name for e in OBSERVATIONS if not e.privileged)
    rng = np.random.default_rng(0)
    obs = {"depth": rng.uniform(0, 60, (8, 8)).astype(np.float32),
           "segmentation": rng.integers(0, 14, (8, 8)).astype(np.uint8),
           "waypoint": np.array([4.0, -1.0], np.float32), "speed": np.array([2.0], np.float32),
           "remaining": np.array([25.0], np.float32), "steer": np.array([0.5], np.float32),
           "goal": np.array([3.0, 3.0], np.float32)}
    learned.learned_observation(obs)
    # an entry the table marked privileged is out of the learned driver's reach, present or not
    monkeypatch.setattr(learned, "UNPRIVILEGED", tuple(k for k in learned.UNPRIVILEGED if k != "goal"))
    with pytest.raises(KeyError, match="goal"):
        learned.learned_observation(obs)
