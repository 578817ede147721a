"""Outcome classification: each class forced on a straight or L-shaped route, plus MuJoCo contacts."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from garage_mj.driving.sim.outcomes import (
    FAILURES,
    HIT_KINDS,
    OUTCOMES,
    PAPER_CLASS,
    PAPER_CLASSES,
    TRUNCATING,
    Contact,
    OutcomeConfig,
    OutcomeKind,
    OutcomeMonitor,
    ego_contacts,
)
from garage_mj.scene.route_line import Route, to_car_frame
from garage_mj.scene.semantics import Semantic, geom_classes

L_ROUTE = Route([(0, 0), (20, 0), (20, 20)])  # 40 m


def drive(monitor: OutcomeMonitor, path, speed=2.0, dt=0.1, contacts_at=None):
    """Feed positions along ``path`` (one per step; speed 0 where the car stands); returns the outcome or None."""
    for k, p in enumerate(path):
        contacts = contacts_at(k) if contacts_at else ()
        standing = k > 0 and np.allclose(p, path[k - 1])
        out = monitor.update(k * dt, p, 0.0 if standing else speed, contacts)
        if out is not None:
            return out
    return None


def along(route: Route, step: float, stop: int = 5):
    """Points every ``step`` metres to the end of the route, then ``stop`` steps standing there."""
    pts = [route.point_at(s) for s in np.arange(0.0, route.length, step)] + [route.goal] * (stop + 1)
    return pts


def test_route_geometry():
    assert L_ROUTE.length == pytest.approx(40.0)
    assert np.allclose(L_ROUTE.point_at(30.0), (20, 10))
    s, d = L_ROUTE.project((10, 1.5))
    assert s == pytest.approx(10.0) and d == pytest.approx(1.5)
    assert L_ROUTE.heading_at(25.0) == pytest.approx(np.pi / 2)
    assert np.allclose(to_car_frame((1, 1), 0, 0, np.pi / 2), (1, -1))
    with pytest.raises(ValueError):
        Route([(0, 0), (0, 0)])


def test_success_at_goal():
    out = drive(OutcomeMonitor(L_ROUTE), along(L_ROUTE, 0.2))
    assert out.kind is OutcomeKind.SUCCESS and out.success
    assert out.time == pytest.approx(0.1 * (round(L_ROUTE.length / 0.2) + 1))  # the first step standing at the goal


def test_success_needs_low_speed_and_the_goal_heading():
    cfg = OutcomeConfig()
    mon = OutcomeMonitor(L_ROUTE, cfg)
    mon.progress = 30.0
    beyond = [(20.0, 10.0 + s) for s in np.arange(0.0, 18.0, 0.3)]  # on through the goal at (20, 20)
    fast = drive(mon, beyond, speed=3.0)
    assert fast.kind is OutcomeKind.DEADLOCK and "overshot the goal" in fast.reason  # drove through it
    mon = OutcomeMonitor(L_ROUTE, cfg)
    mon.progress = 39.0
    assert mon.update(0.0, (20.0, 19.8), 0.0, yaw=0.0) is None  # at the goal, but facing east
    assert mon.update(0.1, (20.0, 19.8), 0.0, yaw=np.pi / 2).kind is OutcomeKind.SUCCESS


def test_collision_records_what_was_hit():
    hit = Contact(Semantic.PILLAR, "pillar_2_4/column")
    floor = Contact(Semantic.FLOOR, "floor")
    out = drive(OutcomeMonitor(L_ROUTE), along(L_ROUTE, 0.2),
                contacts_at=lambda k: [floor, hit] if k == 30 else [floor])
    assert out.kind is OutcomeKind.COLLISION
    assert (out.hit_class, out.hit_geom) == ("pillar", "pillar_2_4/column")
    assert out.time == pytest.approx(3.0)
    assert out.as_dict()["kind"] == "collision"


def test_floor_and_markings_are_not_collisions():
    touches = [Contact(Semantic.FLOOR, "floor"), Contact(Semantic.STALL_MARKING, "stallmark_1")]
    out = drive(OutcomeMonitor(L_ROUTE), along(L_ROUTE, 0.2), contacts_at=lambda k: touches)
    assert out.kind is OutcomeKind.SUCCESS


def test_timeout_from_route_length():
    cfg = OutcomeConfig(min_mean_speed=1.0, time_slack=5.0, stuck_time=1000.0)
    mon = OutcomeMonitor(L_ROUTE, cfg)
    assert mon.time_limit == pytest.approx(45.0)
    out = drive(mon, along(L_ROUTE, 0.05))  # 0.5 m/s: too slow
    assert out.kind is OutcomeKind.TIMEOUT and out.time == pytest.approx(45.0)


def test_deadlock_when_stuck():
    cfg = OutcomeConfig(stuck_time=5.0)
    path = along(Route([(0, 0), (6, 0)]), 0.2) + [np.array([6.0, 0.0])] * 200
    out = drive(OutcomeMonitor(L_ROUTE, cfg), path)
    assert out.kind is OutcomeKind.DEADLOCK and "no progress" in out.reason
    assert "goal" not in out.reason  # stuck 24 m from the goal: not a missed goal
    assert 5.0 <= out.time - 3.0 <= 5.2  # stopped at t = 3 s


def stop_short(monitor: OutcomeMonitor, short: float, yaw: float, steps: int = 200):
    """Drive the L route to ``short`` metres before its end, then stand there facing ``yaw``; the outcome."""
    stop = L_ROUTE.length - short
    path = [L_ROUTE.point_at(s) for s in np.arange(0.0, stop, 0.2)] + [L_ROUTE.point_at(stop)] * steps
    for k, p in enumerate(path):
        moving = k + 1 < len(path) and not np.allclose(p, path[k + 1])
        out = monitor.update(k * 0.1, p, 2.0 if moving else 0.0, yaw=yaw)
        if out is not None:
            return out
    return None


def test_a_car_stopped_near_the_goal_missed_it():
    # 1.5 m short of the goal, 0.4 rad off its heading (the goal faces +y): outside both tolerances
    out = stop_short(OutcomeMonitor(L_ROUTE), 1.5, np.pi / 2 - 0.4)
    assert out.kind is OutcomeKind.MISSED_GOAL and not out.success
    assert out.reason.startswith("stopped 1.50 m and 0.40 rad from the goal pose (tolerance 1 m, 0.35 rad)")
    assert "no progress for 8.0 s" in out.reason
    # within the position tolerance but 0.5 rad off the heading: missed too, with both numbers
    out = stop_short(OutcomeMonitor(L_ROUTE), 0.5, np.pi / 2 + 0.5)
    assert out.kind is OutcomeKind.MISSED_GOAL and "stopped 0.50 m and 0.50 rad" in out.reason


def test_missed_goal_radius_separates_a_missed_goal_from_a_deadlock():
    assert OutcomeConfig().missed_goal_radius == 2 * OutcomeConfig().max_deviation  # the criterion deadlocks had
    assert stop_short(OutcomeMonitor(L_ROUTE), 6.5, np.pi / 2).kind is OutcomeKind.MISSED_GOAL
    stuck = stop_short(OutcomeMonitor(L_ROUTE), 7.5, np.pi / 2)
    assert stuck.kind is OutcomeKind.DEADLOCK and stuck.reason == "no progress for 8.0 s"
    tight = OutcomeMonitor(L_ROUTE, OutcomeConfig(missed_goal_radius=1.0))
    assert stop_short(tight, 1.5, np.pi / 2).kind is OutcomeKind.DEADLOCK


def test_missed_goal_is_a_failure_and_a_deadlock_in_the_papers_classes():
    assert OutcomeKind.MISSED_GOAL in FAILURES and OutcomeKind.MISSED_GOAL.value == "missed_goal"
    assert PAPER_CLASS == {"collision": "collision", "timeout": "timeout", "deadlock": "deadlock",
                           "missed_goal": "deadlock", "outside_stall": "deadlock", "driver_crash": "deadlock",
                           "driver_timeout": "timeout"}
    assert set(PAPER_CLASS) == {k.value for k in FAILURES}


def test_every_table_of_outcomes_follows_the_declared_one():
    """OUTCOMES is the one declaration: the enum, the failure kinds, the paper classes and every column of
    counts (summary.csv, failures.csv, a driver's test table, the demo's table) are read off it."""
    from dataclasses import asdict

    from garage_mj.driving.hunt import FAILURE_COLUMNS
    from garage_mj.driving.results import (
        COUNT_COLUMNS,
        FAILURE_KINDS,
        SUMMARY_COLUMNS,
        driven_tests,
        failed_tests,
        failure_counts,
    )
    from garage_mj.reporting.demo import _failure_cells
    from garage_mj.testing.driver_tests import TABLE_COLUMNS

    kinds = [s.kind for s in OUTCOMES]
    assert len(set(kinds)) == len(kinds) and len({s.column for s in OUTCOMES}) == len(OUTCOMES)
    assert [k.value for k in OutcomeKind] == kinds
    failures = [s for s in OUTCOMES if s.failure]
    assert [k.value for k in FAILURES] == list(FAILURE_KINDS) == [s.kind for s in failures]
    assert PAPER_CLASSES == ("collision", "timeout", "deadlock")  # the paper's three, in its order
    assert all(s.paper_class in PAPER_CLASSES for s in failures)
    assert all(s.paper_class is None for s in OUTCOMES if not s.failure)
    assert PAPER_CLASS == {s.kind: s.paper_class for s in failures}
    assert (OutcomeKind.SUCCESS, OutcomeKind.INFEASIBLE) == (OutcomeKind(kinds[0]), OutcomeKind(kinds[-1]))
    assert set(HIT_KINDS) | set(TRUNCATING) <= set(FAILURES)
    values = asdict(OutcomeConfig())
    assert all(s.note.format(**values) for s in OUTCOMES if s.note)  # its slots are OutcomeConfig fields
    assert COUNT_COLUMNS == {s.kind: s.column for s in failures}
    counts = list(COUNT_COLUMNS.values())
    at = SUMMARY_COLUMNS.index("successes") + 1
    assert list(SUMMARY_COLUMNS[at:at + len(counts)]) == counts and SUMMARY_COLUMNS[at + len(counts)] == "success_pct"
    at = TABLE_COLUMNS.index("successes") + 1
    assert list(TABLE_COLUMNS[at:at + len(counts) + 1]) == [*counts, "success_pct"]
    at = FAILURE_COLUMNS.index("failure_pct") + 1
    assert list(FAILURE_COLUMNS[at:at + len(counts)]) == sorted(counts)
    cells = _failure_cells(COUNT_COLUMNS, "hit")
    assert [c for c in cells if c != "hit"] == counts and cells.count("hit") == len(HIT_KINDS)
    rows = [{"outcome": k, "test": str(i)} for i, k in enumerate(kinds * 2)]
    assert failed_tests(rows) == [r for r in driven_tests(rows) if r["outcome"] != "success"]
    assert failure_counts(rows) == {s.kind: 2 for s in failures}


def test_deadlock_when_off_route():
    path = [np.array([x, 0.0]) for x in np.arange(0, 10, 0.2)] + [np.array([10.0, -y]) for y in np.arange(0, 6, 0.2)]
    out = drive(OutcomeMonitor(L_ROUTE, OutcomeConfig(max_deviation=3.0)), path)
    assert out.kind is OutcomeKind.DEADLOCK and "off the route" in out.reason


def test_progress_tracks_the_route_not_a_nearby_later_leg():
    loop = Route([(0, 0), (10, 0), (10, 2), (0, 2)])  # the return leg passes 2 m away
    mon = OutcomeMonitor(loop, OutcomeConfig(goal_tolerance=0.5))
    for k, x in enumerate(np.arange(0, 5, 0.2)):
        mon.update(k * 0.1, (x, 1.1), 2.0)
    assert mon.progress < 6.0


def test_outcome_is_sticky():
    mon = OutcomeMonitor(L_ROUTE)
    first = mon.update(0.0, (0, 0), 0.0, [Contact(Semantic.WALL, "wall_n")])
    assert mon.update(0.1, (20, 20), 0.0) is first


def test_ego_contacts_from_mujoco():
    xml = """<mujoco><worldbody>
      <geom name="floor" type="plane" size="5 5 1"/>
      <geom name="wall_e" type="box" size="0.1 2 1" pos="0.55 0 1"/>
      <body name="ego/chassis" pos="0 0 0.5"><freejoint/><geom name="ego/body" type="box" size="0.5 0.3 0.5"/></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    ego = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "ego/body")}
    found = {(c.semantic, c.geom) for c in ego_contacts(m, d, ego, geom_classes(m))}
    assert found == {(Semantic.WALL, "wall_e")}  # the floor touches the car too, but is not collidable
