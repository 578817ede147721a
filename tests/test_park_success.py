"""Hard parking, honestly judged (docs/spec.md section 9): the stricter success, its metrics, and the levels."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from garage_mj.driving.cases import case_settings, case_summary
from garage_mj.driving.results import (
    BREAKDOWNS,
    TEST_COLUMNS,
    breakdown_lines,
    check_rows,
    park_breakdown,
    parse_tests,
    row_problem,
)
from garage_mj.driving.sim.outcomes import OutcomeKind
from garage_mj.driving.sim.park_outcomes import ParkMonitor, ParkOutcomeConfig, park_time_limit
from garage_mj.driving.sources import CruiseError, CruiseSettings, CruiseSource, cruise_seed
from garage_mj.scene.body_outlines import BodyOutlines, body_clearance, segment_crosses
from garage_mj.scene.car import car_geometry
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_levels import FAR, NARROW_AISLE, NARROW_BAY, PARALLEL_EXTREME, VERY_FAR, park_level
from garage_mj.scene.park_planning import centre_to_rear, far_end_allowance, in_stall, park_pose
from garage_mj.scene.route_line import Route
from garage_mj.scene.stalls import Stall
from garage_mj.scene.vehicles import FLEET
from garage_mj.scene.world import DEFAULT_WORLD

CAR = car_geometry()
LENGTH, WIDTH = CAR.front - CAR.rear, 2 * CAR.half_width  # [m] the default car, 4.6 x 1.9


@pytest.fixture(scope="module")
def stall3(painted_tiny) -> Stall:
    return GarageScene(painted_tiny).stalls.stalls[3]


def _shifted(stall: Stall, along: float = 0.0, left: float = 0.0, turn_deg: float = 0.0):
    """The reverse-in stall pose moved ``along`` the stall axis (towards the aisle) and ``left`` across it."""
    x, y, yaw = park_pose(stall, CAR, "reverse")
    u = np.array([math.cos(stall.yaw), math.sin(stall.yaw)])
    p = np.array([x, y]) + along * u + left * np.array([-u[1], u[0]])
    return float(p[0]), float(p[1]), yaw + math.radians(turn_deg)


# -- the footprint inside the paint's inner edges ----------------------------------------------------------------
def test_over_an_inner_edge_fails_where_the_centre_line_rule_passed(stall3):
    half_mark = DEFAULT_WORLD.marking_width / 2
    side_room = stall3.width / 2 - CAR.half_width  # [m] from the car's side to the side line's centre at the pose
    for left, line in ((side_room - half_mark / 2, "left side line"), (-(side_room - half_mark / 2), "right side line")):
        pose = _shifted(stall3, left=left)
        assert in_stall(stall3, CAR, pose, marking=0.0).inside  # the centre line (section 8): inside
        fit = in_stall(stall3, CAR, pose)  # section 9: over the paint's inner edge
        assert not fit.inside and not fit.parked and fit.line == line
        assert fit.margin == pytest.approx(-half_mark / 2) and fit.overhang == pytest.approx(half_mark / 2)
    back = _shifted(stall3, along=-0.1)  # the rear 0.05 m from the back line's centre, so 0.025 m over its inner edge
    assert in_stall(stall3, CAR, back, marking=0.0).inside
    fit = in_stall(stall3, CAR, back)
    assert not fit.inside and fit.line == "back line" and fit.margin == pytest.approx(-0.025)


def test_the_inner_margin_is_the_smallest_distance_inside_and_negative_over_a_line(stall3):
    exact = in_stall(stall3, CAR, park_pose(stall3, CAR, "reverse"))
    assert exact.parked and exact.margin > 0 and exact.overhang == 0
    side = stall3.width / 2 - DEFAULT_WORLD.marking_width / 2 - CAR.half_width  # [m] to each side line's inner edge
    assert exact.margin <= side + 1e-9
    for left in (0.1, 0.2, 0.3):  # moving left uses up the left margin, then crosses the line
        fit = in_stall(stall3, CAR, _shifted(stall3, left=left))
        if left < side - 1e-9:
            assert fit.inside and fit.margin >= 0
        else:
            assert not fit.inside and fit.margin < 0 and fit.line == "left side line"
            assert fit.margin == pytest.approx(side - left)


def test_the_far_end_may_overhang_only_what_the_stall_pose_needs(stall3):
    assert far_end_allowance(stall3, CAR) == pytest.approx(0.3)  # section 8's figure for the default car
    compact = FLEET["compact"].geometry()
    assert far_end_allowance(stall3, compact) == 0.0  # fits the stall: its nose may not stand past the open end
    for cls in FLEET.values():  # every class's own stall pose is a success pose
        car = cls.geometry()
        assert in_stall(stall3, car, park_pose(stall3, car, "reverse")).parked, cls.name
        assert in_stall(stall3, car, park_pose(stall3, car, "forward"), "forward").parked, cls.name
    out = in_stall(stall3, CAR, _shifted(stall3, along=0.1))
    assert not out.inside and out.line == "aisle-side limit"


# -- at rest for the dwell --------------------------------------------------------------------------------------
def _monitor(stall: Stall, pose, config: ParkOutcomeConfig | None = None) -> ParkMonitor:
    goal = park_pose(stall, CAR, "reverse")
    monitor = ParkMonitor(Route([(pose[0] + 3.0, pose[1]), goal[:2]]), stall, CAR, "reverse", 100.0, config)
    monitor.start(pose)
    return monitor


def test_a_car_that_stops_for_less_than_the_dwell_is_not_a_success(stall3):
    pose = park_pose(stall3, CAR, "reverse")
    monitor = _monitor(stall3, pose)
    t = 0.0
    for _ in range(9):  # 0.9 s at rest in the stall: not yet
        t += 0.1
        assert monitor.update(t, pose[:2], 0.0, yaw=pose[2]) is None
    t += 0.1
    assert monitor.update(t, pose[:2], 0.2, yaw=pose[2]) is None  # moves off: the dwell starts again
    start = t + 0.1
    out = None
    while out is None:
        t += 0.1
        out = monitor.update(t, pose[:2], 0.0, yaw=pose[2])
        assert out is None or t - start >= 1.0 - 1e-9
    assert out.kind is OutcomeKind.SUCCESS and "at rest 1.0 s" in out.reason
    assert t == pytest.approx(start + 1.0)
    quick = _monitor(stall3, pose, ParkOutcomeConfig(dwell=0.0))  # dwell 0: section 8's first parked step
    assert quick.update(0.1, pose[:2], 0.0, yaw=pose[2]).kind is OutcomeKind.SUCCESS


def test_the_dwell_is_validated_and_in_the_time_limit():
    for bad in (-0.5, math.nan, math.inf):
        with pytest.raises(ValueError, match="dwell"):
            ParkOutcomeConfig(dwell=bad)
    assert park_time_limit(ParkOutcomeConfig(dwell=2.5), 3.0, 1) == pytest.approx(
        park_time_limit(ParkOutcomeConfig(dwell=0.0), 3.0, 1) + 2.5)


def test_outside_stall_names_the_line_crossed(stall3):
    pose = _shifted(stall3, left=0.3)
    monitor = _monitor(stall3, pose)
    out, t = None, 0.0
    while out is None:
        t += 0.5
        out = monitor.update(t, pose[:2], 0.0, yaw=pose[2])
    assert out.kind is OutcomeKind.OUTSIDE_STALL and "over the left side line" in out.reason


# -- clearance to the solid bodies ------------------------------------------------------------------------------
def test_body_clearance_and_the_straight_way_on_turned_bodies():
    rear = centre_to_rear(np.array([0.0, 0.0, 0.0]), CAR)  # the car centred at the origin, heading +x
    r = 0.5 * math.sqrt(2)  # [m] centre to corner of a 1 m box turned 45 deg
    diamond = np.array([[3.5 + r, 0.0], [3.5, r], [3.5 - r, 0.0], [3.5, -r]])
    bodies = BodyOutlines(diamond[None], ("pillar",), ("pillar_0",))
    dist, k = body_clearance(bodies, CAR, rear[None, :2], rear[None, 2])
    assert k[0] == 0 and dist[0] == pytest.approx(3.5 - r - CAR.front)  # to its near corner, not its bounding box
    touching = BodyOutlines(diamond[None] - [0.6, 0.0], ("pillar",), ("p",))
    assert body_clearance(touching, CAR, rear[None, :2], rear[None, 2])[0][0] == 0.0
    assert segment_crosses(bodies, (0.0, 0.0), (6.0, 0.0)) == [0]
    assert segment_crosses(bodies, (0.0, 0.8), (6.0, 0.8)) == []  # passes beside its top corner (y 0.71)
    assert segment_crosses(bodies, (3.0, 0.65), (3.0, 3.0)) == []  # beside its edge, inside its bounding box


def test_an_oracle_success_keeps_clear_of_the_bodies_and_inside_the_lines(painted_tiny):
    from garage_mj.driving.drivers import load_driver
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    env = GarageDriveEnv(painted_tiny, task="park", action_type="continuous", infeasible="report")
    try:
        others = [s.id for s in env.stalls if s.id != 3]
        obs, info = env.reset(seed=0, options={"target": 3, "occupied": others})
        assert info["park_level"] == "complex" and "bay 2.50 m" in info["park_level_reason"]  # 2.5 m < 1.9 + 0.85 m
        parked = [k for k, c in enumerate(env._bodies.classes) if c == "parked_car"]
        assert parked  # the parked cars' bodies, not their stall outlines: a 4.3 x 1.9 m hull
        sides = sorted(np.ptp(env._bodies.corners[parked[0]], axis=0))
        assert sides == pytest.approx([1.9, 4.3])
        driver = load_driver("oracle")
        driver.reset(env.driver_info(0))
        while "outcome" not in info:
            obs, _, _, _, info = env.step(driver.act(obs))
    finally:
        env.close()
    assert info["outcome"] == "success", info["reason"]
    assert info["min_clearance"] > 0 and info["inner_margin"] >= 0 and math.isfinite(info["outline_clearance"])
    assert "at rest 1.0 s" in info["reason"] and "inside the" in info["reason"]


def test_the_solid_bodies_are_those_in_place_never_an_empty_stall_s_car(painted_tiny):
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    env = GarageDriveEnv(painted_tiny, task="park", action_type="continuous", infeasible="report")
    try:
        env.reset(seed=0, options={"target": 3, "occupied": [0, 4]})
        named = {n.split("_")[1] for n, c in zip(env._bodies.names, env._bodies.classes) if c == "parked_car"}
        assert named == {"0", "4"} and {"wall", "parked_car"} <= set(env._bodies.classes)
        env.reset(seed=0, options={"target": 3, "occupied": []})
        assert "parked_car" not in env._bodies.classes
    finally:
        env.close()


# -- levels ----------------------------------------------------------------------------------------------------
def _stall(width: float = 2.5, length: float = 4.5, angle: float = 90.0) -> Stall:
    return Stall(id=0, block=(0, 0), x=0.0, y=0.0, yaw=math.pi / 2, side=2, road_cell=(0, 1), road_x=0.0,
                 road_y=5.0, obstructed=False, length=length, width=width, angle=angle)


def test_each_level_rule_at_its_boundary():
    wide = WIDTH + NARROW_BAY  # [m] the narrowest bay that is not narrow

    def level(stall, aisle=9.0, start=(0.0, 5.0), bodies=None):
        return park_level(stall, LENGTH, WIDTH, aisle, start, bodies).level

    assert level(_stall(width=wide)) == "normal"
    assert level(_stall(width=wide - 0.01)) == "complex"
    assert level(_stall(width=wide - 0.01), start=(0.0, VERY_FAR)) == "complex"  # exactly 30 m: not more
    assert level(_stall(width=wide - 0.01), start=(0.0, VERY_FAR + 0.01)) == "extreme"
    assert level(_stall(width=wide), start=(0.0, VERY_FAR + 0.01)) == "complex"  # far, but a wide bay
    assert level(_stall(width=wide), aisle=NARROW_AISLE) == "complex"
    assert level(_stall(width=wide), aisle=NARROW_AISLE + 0.01) == "normal"
    assert level(_stall(width=wide), start=(0.0, FAR)) == "normal"
    assert level(_stall(width=wide), start=(0.0, FAR + 0.01)) == "complex"
    slot = LENGTH + PARALLEL_EXTREME
    # a parallel slot: its length along the aisle is Stall.width (Stall.length its depth); the bay rule is not its
    assert level(_stall(width=slot, length=2.2, angle=0.0)) == "normal"
    assert level(_stall(width=slot - 0.01, length=2.2, angle=0.0)) == "extreme"
    assert level(_stall(width=slot - 0.01, length=9.0, angle=0.0)) == "extreme"  # a deep slot is no longer
    pillar = BodyOutlines.from_boxes([[-0.3, 2.0, 0.3, 2.6]], ["pillar"])
    beside = BodyOutlines.from_boxes([[1.0, 2.0, 1.6, 2.6]], ["pillar"])
    blocked = park_level(_stall(width=wide), LENGTH, WIDTH, 9.0, (0.0, 5.0), pillar)
    assert blocked.level == "complex" and "crosses a pillar" in blocked.reason
    assert level(_stall(width=wide), bodies=beside) == "normal"
    assert park_level(_stall(width=wide - 0.01), LENGTH, WIDTH, 6.0, (0.0, 20.0)).reasons == (
        f"bay 2.74 m < vehicle width + 0.85 m ({wide:.2f} m)", "aisle 6.00 m <= 6.5 m", "start 20.0 m > 15 m away")


# -- tests.csv rows --------------------------------------------------------------------------------------------
def _row(source: CruiseSource, test: int, outcome: str, level: str = "complex", **cells) -> dict[str, str]:
    row = dict.fromkeys(TEST_COLUMNS, "")
    row.update(garage="tiny", garage_hash=source.hash, test=str(test), seed=str(cruise_seed(0, source.hash, test)),
               driver="oracle", target_stall="3", feasible="0" if outcome in ("infeasible", "unproven") else "1",
               outcome=outcome, difficulty="0.5", mean_road_length="2", mean_intersection_degree="2", wall_s="0.1",
               task="park", maneuver="reverse", park_level=level, stall_angle_deg="90.0")
    if row["feasible"] == "1":
        row.update(position_error_m="0.02", heading_error_deg="0.1", lateral_offset_m="0.01", direction_changes="1",
                   park_time_s="15.0", min_clearance_m="0.3", inner_margin_m="0.03", outline_clearance_m="0.24")
    row.update(cells)
    return row


def test_resumed_rows_with_the_new_columns_validate(painted_tiny, tmp_path):
    source = CruiseSource.from_garage(painted_tiny, "tiny")
    settings = CruiseSettings("oracle", 0, "continuous", 0.5, {}, task="park")
    rows = [_row(source, 0, "success"), _row(source, 1, "outside_stall", "normal", inner_margin_m="-0.04"),
            _row(source, 2, "unproven", "extreme"), _row(source, 3, "success", "normal")]
    assert [row_problem(r, settings) for r in rows] == [None] * 4
    assert row_problem({**rows[0], "park_level": ""}, settings)[0] == "park_level"
    assert row_problem({**rows[0], "park_level": "hard"}, settings)[0] == "park_level"
    assert row_problem({**rows[0], "inner_margin_m": "-0.01"}, settings)[0] == "inner_margin_m"
    assert row_problem({**rows[0], "min_clearance_m": "-0.01"}, settings)[0] == "min_clearance_m"
    assert row_problem({**rows[0], "min_clearance_m": "0.0"}, settings) is None  # under half a mm, rounded
    assert row_problem({**rows[0], "outline_clearance_m": "x"}, settings)[0] == "outline_clearance_m"
    path = tmp_path / "tests.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=TEST_COLUMNS)
        w.writeheader()
        w.writerows(rows)
    parsed = parse_tests(path)
    assert not parsed.repair and parsed.rows == rows
    check_rows(path, parsed, settings)  # nothing to refuse
    old = [c for c in TEST_COLUMNS if c not in ("park_level", "inner_margin_m", "outline_clearance_m",
                                                 "stall_angle_deg")]
    with open(path, "w", newline="") as f:  # a park run from before section 9: judged by section 8's rule
        w = csv.DictWriter(f, fieldnames=old, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    parsed = parse_tests(path)
    assert parsed.repair and all(r["park_level"] == "" for r in parsed.rows)
    with pytest.raises(CruiseError, match="line 2: park_level '' is empty.*section 8"):
        check_rows(path, parsed, settings)


def test_success_breaks_down_by_level_maneuver_and_stall_angle(painted_tiny):
    source = CruiseSource.from_garage(painted_tiny, "tiny")
    rows = [_row(source, 0, "success"), _row(source, 1, "collision", "complex", maneuver="forward"),
            _row(source, 2, "unproven", "extreme"), _row(source, 3, "success", "normal", stall_angle_deg="60.0"),
            _row(source, 4, "infeasible", "normal")]
    out = park_breakdown(rows)
    assert set(out) == set(BREAKDOWNS)
    assert list(out["by_level"]) == ["normal", "complex", "extreme"]
    assert out["by_level"]["complex"] == {"tests": 2, "infeasible": 0, "unproven": 0, "feasible": 2, "successes": 1,
                                          "success_pct": 50.0}
    assert out["by_level"]["extreme"]["success_pct"] is None and out["by_level"]["extreme"]["unproven"] == 1
    assert out["by_level"]["normal"]["feasible"] == 1 and out["by_level"]["normal"]["infeasible"] == 1
    assert list(out["by_maneuver"]) == ["reverse", "forward"] and out["by_maneuver"]["forward"]["successes"] == 0
    assert list(out["by_stall_angle"]) == ["60", "90"]
    assert case_summary(rows, case_settings("oracle", 0, "continuous"), "--action-type")["by_level"] == out["by_level"]
    lines = breakdown_lines(out)
    assert lines[0] == "success by level: normal 1/1 (100.0%); complex 1/2 (50.0%); extreme 0/0, 1 unproven"
    assert lines[2] == "success by stall angle [deg]: 60 1/1 (100.0%); 90 1/2 (50.0%), 1 unproven"


def test_success_by_park_difficulty_band_leaves_out_tests_without_one():
    from garage_mj.driving.results import breakdown_lines, park_breakdown

    def row(outcome, difficulty):
        return {"outcome": outcome, "park_level": "normal", "maneuver": "reverse", "stall_angle_deg": "90",
                "park_difficulty": difficulty}

    rows = [row("success", "0.05"), row("success", "0.19"), row("collision", "0.2"), row("success", "0.55"),
            row("timeout", "1.0"), row("unproven", "0.9"), row("success", "")]
    bands = park_breakdown(rows)["by_park_difficulty"]
    assert list(bands) == ["0.0-0.2", "0.2-0.4", "0.4-0.6", "0.8-1.0"]  # a band per 0.2, 1 in the top one
    assert (bands["0.0-0.2"]["successes"], bands["0.0-0.2"]["feasible"]) == (2, 2)
    assert bands["0.8-1.0"] == {"tests": 2, "infeasible": 0, "unproven": 1, "feasible": 1, "successes": 0,
                                "success_pct": 0.0}
    assert sum(b["tests"] for b in bands.values()) == 6  # the test without a park difficulty is in no band
    line = breakdown_lines({"by_park_difficulty": bands})[0]
    assert line.startswith("success by park difficulty: 0.0-0.2 2/2 (100.0%); 0.2-0.4 0/1 (0.0%)")
    assert park_breakdown([row("success", "")])["by_park_difficulty"] == {}
