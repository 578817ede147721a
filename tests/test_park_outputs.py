"""Park and AVP runs read as park runs: the park-driver contract of docs/own-driver.md checked against the code,
the outputs that name their task, the park success figure, and the failure pictures (docs/cruise.md)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from garage_mj.driving.sim.drive_env import COLLISION_PENALTY, SUCCESS_REWARD
from garage_mj.driving.sim.park_outcomes import ParkOutcomeConfig
from garage_mj.driving.sim.vehicle import (
    PARK_CONTINUOUS_SIZE,
    PARK_DISCRETE_COMMANDS,
    Gear,
    ParkAction,
    park_action_space,
)
from garage_mj.scene.car import CarConfig
from garage_mj.scene.park_planning import FAR_END_SLACK, HEADING_TOLERANCE
from garage_mj.scene.world import DEFAULT_WORLD

ROOT = Path(__file__).resolve().parents[1]
OWN_DRIVER = ROOT / "docs" / "own-driver.md"


@pytest.fixture(scope="module")
def tiny_garage():
    from garage_mj.grid.painters import paint_garage

    return paint_garage("tiny_7x11", seed=1)


def _section(text: str, heading: str) -> str:
    """The text of the ``## heading`` section of a page (up to the next ``## ``)."""
    start = text.index(f"## {heading}\n")
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end]


def _table(text: str, first_header: str) -> list[list[str]]:
    """The body rows of the markdown table whose header row starts with ``| first_header |``, as cells."""
    lines = text.splitlines()
    at = next(k for k, line in enumerate(lines) if line.startswith(f"| {first_header} |"))
    rows = []
    for line in lines[at + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


def _number(cell: str) -> float:
    return float(cell.replace("+", ""))


# -- the park-driver contract (docs/own-driver.md) ------------------------------------------------------------
def test_the_documented_discrete_park_actions_are_the_env_s():
    """Every ParkAction, in order, with the pedal, steer and gear request the env turns it into; the speeds each
    gear reaches are the car's."""
    rows = _table(_section(OWN_DRIVER.read_text(), "Park and AVP drivers"), "action")
    assert park_action_space("discrete").n == len(ParkAction) == len(rows)
    cfg = CarConfig()
    for row, action in zip(rows, ParkAction, strict=True):
        number, name, pedal, steer, gear, in_d, in_r = row
        pedal_code, steer_code, request = PARK_DISCRETE_COMMANDS[action]
        assert (int(number), name) == (int(action), f"`{action.name}`")
        assert (_number(pedal), _number(steer)) == (pedal_code, steer_code), row
        assert gear == ("keep" if request is None else request.name), row
        if pedal_code > 0:
            assert f"forward (up to {cfg.max_speed:g} m/s)" in in_d and f"backward (up to {cfg.max_reverse_speed:g} m/s)" in in_r
        if request is not None:  # a selection brakes; the gear it asks for engages at rest, the other is BRAKE
            engaging, already = (in_d, in_r) if request is Gear.R else (in_r, in_d)
            assert f"engages {request.name}" in engaging and "as `BRAKE`" in already, row


def test_the_documented_continuous_park_action_is_the_env_s():
    text = _section(OWN_DRIVER.read_text(), "Park and AVP drivers")
    rows = _table(text, "index")
    space = park_action_space("continuous")
    assert space.shape == (PARK_CONTINUOUS_SIZE,) == (len(rows),)
    assert (space.low == -1).all() and (space.high == 1).all() and "Box(-1, 1, (3,))" in text
    assert [(int(r[0]), r[1]) for r in rows] == [(0, "`pedal`"), (1, "`steer`"), (2, "`gear`")]
    from garage_mj.driving.sim.vehicle import park_command_from_action

    assert park_command_from_action([0.0, 0.0, -0.01])[2] is Gear.R and park_command_from_action([0.0, 0.0, 0.0])[2] is Gear.D
    assert "below 0 reverse (R), 0 or above drive (D)" in rows[2][2]
    cfg = CarConfig()
    assert f"{cfg.max_accel:g} m/s^2" in rows[0][2] and f"{cfg.max_decel:g} m/s^2" in rows[0][2]
    assert f"{cfg.steer_rate:g} rad/s" in rows[1][2]
    assert f"slower than {cfg.gear_change_speed:g} m/s" in text


def test_the_documented_reward_end_and_success_are_the_env_s():
    text = _section(OWN_DRIVER.read_text(), "Park and AVP drivers")
    cfg = ParkOutcomeConfig()
    assert f"plus {SUCCESS_REWARD:g} on success or {COLLISION_PENALTY:g} on a collision" in text
    assert f"{cfg.dwell:g} s on end" in text and f"below {cfg.rest_speed:g} m/s" in text
    assert f"within {HEADING_TOLERANCE:g} degrees" in text and f"{DEFAULT_WORLD.marking_width:g} m wide" in text
    assert f"plus {FAR_END_SLACK:g} m" in text
    assert f"no progress for {cfg.stuck_time:g} s" in text and f"by {cfg.stuck_progress:g} m" in text
    assert f"within {cfg.outside_radius:g} m of the stall pose" in text
    assert (f"plan length / {cfg.min_mean_speed:g} m/s + {cfg.time_slack:g} s + {cfg.cusp_time:g} s per cusp"
            in text)


def test_the_documented_info_and_reset_entries_are_the_env_s(tiny_garage):
    """The info table's keys are what a park test's info holds at reset, at each step and at its end; every entry
    of the driver's reset info is named on the page."""
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    text = _section(OWN_DRIVER.read_text(), "Park and AVP drivers")
    rows = _table(text, "info key")
    when = {}
    for key, moment, _ in rows:
        when.setdefault(moment, set()).add(key.strip("`"))
    env = GarageDriveEnv(garage=tiny_garage, task="park", action_type="continuous", stall=0,
                         park_outcome={"stuck_time": 0.3})
    try:
        obs, info = env.reset(seed=0)
        assert info["feasible"]
        assert set(info) == when["every step"] | when["at reset"]
        for entry in env.driver_info(0):
            assert f"`{entry}`" in text, entry
        assert {"stall", "gear"} <= set(obs) and all(f"`{k}`" in text for k in ("stall", "gear"))
        step = None
        while True:
            obs, _, term, trunc, info = env.step(np.array([-1.0, 0.0, 1.0]))
            step = step or set(info)
            if term or trunc:
                break
        assert step == when["every step"]
        assert set(info) == when["every step"] | when["at the end"] | when["at the end of a driven test"]
    finally:
        env.close()


def test_every_built_in_driver_is_named_in_the_guide_and_the_help():
    from garage_mj.cli.cruise import built_in_drivers
    from garage_mj.driving.drivers import DRIVERS, tasks_of

    built_in = _section(OWN_DRIVER.read_text(), "The built-in drivers")
    for name in DRIVERS:
        assert f"`{name}`" in built_in and name in built_in_drivers()
        if "cruise" not in tasks_of(name):
            assert f"{name} ({' and '.join(tasks_of(name))} tests only)" in built_in_drivers()
    assert re.search(r"`tasks`", _section(OWN_DRIVER.read_text(), "Park and AVP drivers"))
