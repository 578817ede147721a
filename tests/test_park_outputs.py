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


# -- a park run's outputs name its task and show what parking is judged by ----------------------------------------
def test_a_park_run_reads_as_a_park_run(tiny_garage, tmp_path, capsys):
    """The progress bar, the closing lines, the figure and the report say park, and nothing cites the paper's cruise
    regression; --pictures all draws the successes too, listed apart in the report."""
    from garage_mj.cli import main
    from garage_mj.export.pack import export_pack
    from garage_mj.reporting.cruise import cruise_figure
    from garage_mj.reporting.park import PICTURES
    from garage_mj.reporting.park_figure import PARK_FIGURE

    export_pack(tiny_garage, tmp_path / "packs")
    out = tmp_path / "park"
    assert main(["cruise", "--packs", str(tmp_path / "packs"), "--tests", "2", "--driver", "oracle", "--task", "park",
                 "--out", str(out), "--report", "--pictures", "all"]) == 0
    printed = capsys.readouterr()
    assert "park: 100%" in printed.err and "cruise:" not in printed.err  # the progress bar
    lines = printed.out.splitlines()
    assert lines[0].startswith("2 park tests (reverse) on 1 garage (2 new): ") and "success 100.0% of 2" in lines[0]
    assert "Pearson" not in printed.out and "-0.638" not in printed.out and "paper" not in printed.out
    assert f"park success by level and maneuver: {out / PARK_FIGURE}" in printed.out
    assert (out / PARK_FIGURE).stat().st_size > 1000
    assert not (out / "regression.png").exists() and not (out / "regression_route.png").exists()
    assert cruise_figure(out) is None and not (out / "regression.png").exists()
    import json

    assert "paper_r" not in json.loads((out / "summary.json").read_text())
    html = (out / "report.html").read_text()
    assert "<title>garage-mj park tests: oracle</title>" in html and "2 park tests (reverse) on 1 garage" in html
    assert f'src="{PARK_FIGURE}"' in html and "regression" not in html and "-0.638" not in html
    pictures = sorted((out / PICTURES).glob("*_success.png"))
    assert len(pictures) == 2 and "id=parked-table" in html
    assert all(f"{PICTURES}/{p.name}" in html for p in pictures)


def test_the_park_figure_draws_each_level_and_maneuver_with_its_counts(tmp_path):
    import json

    from garage_mj.reporting.park_figure import PARK_FIGURE, group_label, park_figure

    group = {"tests": 3, "infeasible": 0, "unproven": 1, "feasible": 2, "successes": 1, "success_pct": 50.0}
    none = {"tests": 1, "infeasible": 0, "unproven": 1, "feasible": 0, "successes": 0, "success_pct": None}
    assert group_label(group) == "1/2, 1 unproven" and group_label(none) == "0 feasible, 1 unproven"
    stats = {"task": "avp", "driver": "mine", "tests": 4, "feasible": 2,
             "by_level": {"complex": group, "extreme": none}, "by_maneuver": {"reverse": group, "forward": none}}
    (tmp_path / "summary.json").write_text(json.dumps(stats))
    assert park_figure(tmp_path) == tmp_path / PARK_FIGURE and (tmp_path / PARK_FIGURE).stat().st_size > 1000
    (tmp_path / "summary.json").write_text(json.dumps({"driver": "mine", "tests": 4, "feasible": 2}))  # a cruise run's
    assert park_figure(tmp_path / ".") is None


def test_pictures_are_refused_for_a_cruise_run(tiny_garage, tmp_path, capsys):
    from garage_mj.cli import main

    assert main(["cruise", "--packs", str(tmp_path), "--tests", "1", "--pictures", "all", "--out",
                 str(tmp_path / "out")]) != 0
    err = capsys.readouterr().err
    assert "--pictures draws park and AVP tests" in err and "--videos" in err and not (tmp_path / "out").exists()


# -- the pictures ---------------------------------------------------------------------------------------------------
class ShortParker:
    """The oracle, braking for good once the car centre comes within 0.7 m of the stall pose: it stops short, over
    the stall's aisle-side limit (an ``outside_stall``)."""

    action_type = "continuous"
    tasks = ("park", "avp")

    def __init__(self) -> None:
        from garage_mj.driving.drivers.oracle import OracleDriver

        self.oracle = OracleDriver()

    def reset(self, info) -> None:
        self.oracle.reset(info)

    def act(self, obs):
        if float(np.hypot(*obs["stall"][:2])) < 0.7:
            return np.array([-1.0, 0.0, float(obs["gear"][0])])
        return self.oracle.act(obs)


def _settings(driver: str, **kwargs):
    from garage_mj.driving.sources import CruiseSettings

    return CruiseSettings(driver, 0, "continuous", task="park", **kwargs)


def test_an_outside_stall_picture_draws_the_line_its_reason_names(tiny_garage, tmp_path):
    from garage_mj.driving.sources import CruiseSource
    from garage_mj.reporting.park import drive_park_test, park_axes, park_picture
    from garage_mj.scene.park_planning import STALL_LINES

    settings = _settings("tests.test_park_outputs:ShortParker")
    source = CruiseSource.from_garage(tiny_garage)
    drive = drive_park_test(source, settings, 0)
    assert "outside stall" in drive.title and drive.limit is not None
    name, segment, label = drive.limit
    assert name in STALL_LINES and label.startswith(f"{name}: ") and label.endswith(" m over") and segment.shape == (2, 2)
    ax = park_axes(drive)
    try:
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert label in labels and "parked car" in labels
        drawn = [line for line in ax.get_lines() if line.get_label() == label]
        assert len(drawn) == 1 and np.allclose(drawn[0].get_xydata(), segment)
    finally:
        import matplotlib.pyplot as plt

        plt.close(ax.figure)
    assert park_picture(source, tmp_path / "p.png", settings, 0).stat().st_size > 1000


def test_a_collision_picture_marks_where_the_car_touched(tiny_garage):
    """park_assist's third test of seed 0 (nose-in, drawn per test) hits the parked car beside the stall; the mark is
    on the final footprint's edge, on the parked car's outline."""
    from matplotlib.path import Path as Outline

    from garage_mj.driving.sources import CruiseSource
    from garage_mj.reporting.park import _body, drive_park_test, park_axes

    drive = drive_park_test(CruiseSource.from_garage(tiny_garage), _settings("park_assist", maneuver="any"), 2)
    assert "collision (parked_car)" in drive.title and drive.hit == "parked_car" and drive.contact is not None
    body = _body(drive.car, drive.driven[-1])
    assert Outline(body).contains_point(drive.contact, radius=0.1) or Outline(body).contains_point(
        drive.contact, radius=-0.1)
    cars = [o for o, c in zip(drive.obstacles.outlines, drive.obstacles.classes, strict=True) if c == "parked_car"]
    assert min(np.abs(np.linalg.norm(o - drive.contact, axis=1)).min() for o in cars) < 2.5
    assert any(Outline(o).contains_point(drive.contact, radius=0.1) or Outline(o).contains_point(drive.contact,
                                                                                                   radius=-0.1)
               for o in cars)
    ax = park_axes(drive)
    try:
        assert "collision point (parked_car)" in [t.get_text() for t in ax.get_legend().get_texts()]
    finally:
        import matplotlib.pyplot as plt

        plt.close(ax.figure)


def test_obstacles_are_drawn_as_their_outlines_with_a_legend():
    """A turned obstacle is its polygon, not its bounding box; every class drawn is in the legend once."""
    import math

    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    from garage_mj.reporting.park import OBSTACLE_STYLES, ParkDrive, park_axes
    from garage_mj.scene.car import car_geometry
    from garage_mj.scene.clearance import Obstacles
    from garage_mj.scene.stalls import Stall

    turned = np.array([[3.0 + math.cos(a), 3.0 + math.sin(a)] for a in np.arange(4) * math.pi / 2 + math.pi / 4])
    square = np.array([[8.0, 0.0], [9.0, 0.0], [9.0, 1.0], [8.0, 1.0]])
    obstacles = Obstacles.from_polygons([turned, square, square + 2.0], ["pillar", "wall", "wall"])
    stall = Stall(id=0, block=(0, 0), x=5.0, y=5.0, yaw=0.0, side=1, road_cell=(0, 1), road_x=9.0, road_y=5.0,
                  obstructed=False)
    plan = {"poses": np.zeros((0, 3)), "directions": np.zeros(0), "stall_pose": (5.0, 5.0, 0.0)}
    drive = ParkDrive("t", stall, obstacles, [np.array(stall.corners)], plan, np.array([[5.0, 2.0, 0.0]] * 2),
                      car_geometry())
    ax = park_axes(drive)
    try:
        patches = [p for p in ax.patches if isinstance(p, Polygon)]
        assert any(np.allclose(p.get_xy()[:4], turned) for p in patches)
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert labels.count(OBSTACLE_STYLES["wall"][1]) == 1 and OBSTACLE_STYLES["pillar"][1] in labels
    finally:
        plt.close(ax.figure)


@pytest.mark.parametrize("angle", [90, 60])
@pytest.mark.parametrize("offset", [(0.3, 0.0), (-0.4, 0.0), (0.0, 0.3), (0.0, -0.3), (0.2, 0.25)])
def test_the_stall_limits_are_the_lines_in_stall_measures(tiny_garage, offset, angle):
    """The footprint's signed distance inside the segment of the limit ``in_stall`` names is its margin, in a
    perpendicular and an angled stall."""
    from garage_mj.scene.car import car_geometry
    from garage_mj.scene.clearance import footprint
    from garage_mj.scene.garage_scene import GarageScene
    from garage_mj.scene.park_planning import centre_to_rear, in_stall, park_pose, stall_limits
    from garage_mj.scene.world import world_with

    car = car_geometry()
    world = world_with({"stall_angle": angle})
    stall = GarageScene(tiny_garage, world).stalls.stalls[0]
    x, y, yaw = park_pose(stall, car, "reverse")
    pose = (x + offset[0], y + offset[1], yaw)
    fit = in_stall(stall, car, pose, "reverse", world.marking_width)
    a, b = stall_limits(stall, car, world.marking_width)[fit.line]
    normal = np.array([a[1] - b[1], b[0] - a[0]]) / np.linalg.norm(b - a)
    normal *= np.sign((np.array([stall.x, stall.y]) - a) @ normal)  # towards the stall's centre
    rear = centre_to_rear(pose, car)
    corners = footprint(car, rear[None, :2], np.array([yaw]))[0]
    assert float(((corners - a) @ normal).min()) == pytest.approx(fit.margin, abs=1e-9)


def test_a_park_hunt_names_its_task_in_its_closing_line(tmp_path):
    from garage_mj.cli.hunt import failure_summary
    from garage_mj.driving.hunt import HuntResult

    res = HuntResult(tmp_path, 2, 1, [], {}, action_label="x")
    assert failure_summary(res, task="avp") == "2 AVP tests on 0 garages in 1 generation (x); 0 garages with a failure"
    assert failure_summary(res).startswith("2 tests on 0 garages")  # a cruise hunt's, as it was
