"""Cruise, park and AVP tests as OpenSCENARIO: the ASAM checker finds zero issues, read gives back what was
written, a replayed park test ends as the test did.

Like the OpenDRIVE tests, the real ASAM checker (``qc_openscenario`` in ``.venv-qc``, from
``make install``) runs once per session on one batch of files; if it is missing the tests fail
with the install hint, never skip.
"""

from __future__ import annotations

import math
import shutil
import warnings

import numpy as np
import pytest
from lxml import etree
from scenariogeneration.xosc import ParseOpenScenario

from garage_mj.core.backends import Compute
from garage_mj.core.errors import GarageMJError
from garage_mj.driving.actors.config import ScenarioConfig
from garage_mj.driving.actors.placement import draw_scenario
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.drivers import ActionTypeWarning
from garage_mj.driving.replay import replay_xosc
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sources import CruiseSettings
from garage_mj.export.pack import export_pack
from garage_mj.export.validate import ToolMissing, check_xosc_batch, qc_xosc_executable
from garage_mj.export.xosc import XoscError, write_xosc
from garage_mj.export.xosc_read import read_xosc
from garage_mj.scene.actor_spec import ActorSpec
from garage_mj.scene.drivable import START_OFFSET, drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.testing.garages import cruise_sources

META = {"seed": 123456, "driver": "pure_pursuit", "action_type": "continuous", "test": 3, "speed": 2.5,
        "strict": True, "tags": ["a", "b"], "note": None}
QUIET = Compute(progress=False)
#: tests.csv cells a replay must give back as the test had them (the wall times aside)
SAME = ("outcome", "reason", "hit", "time", "path_length", "task", "maneuver", "position_error_m",
        "heading_error_deg", "lateral_offset_m", "direction_changes", "park_time_s", "min_clearance_m")


def _start(plan) -> tuple[float, float, float]:
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(plan.centre, axis=0), axis=1))])
    i0 = int(np.searchsorted(s, START_OFFSET))
    return float(plan.centre[i0, 0]), float(plan.centre[i0, 1]), float(plan.heading[i0])


def _hand_actors(plan, free_stall: int) -> list[ActorSpec]:
    """Two actors of each kind near the middle of the route (placement only, not feasibility)."""
    c = plan.centre[len(plan.centre) // 2]
    t1, t2 = (tuple(float(v) for v in plan.centre[k]) for k in (len(plan.centre) // 4, len(plan.centre) // 3))
    x, y = float(c[0]), float(c[1])
    return [
        ActorSpec("pedestrian_0", "pedestrian", "cross",
                  np.array([[0.0, x + 3.0, y + 3.1, -1.2], [3.3, x - 3.0, y + 3.1, -1.2]]), t1, 2.0),
        ActorSpec("pedestrian_1", "pedestrian", "along",
                  np.array([[0.0, x + 1.0 / 3, y - 2.0, math.pi], [1.7, x + 0.123456789, y - 2.5, 3.0],
                            [5.25, x - 4.0, y - 2.5, 3.0]]), t2, 1.5),
        ActorSpec("movingcar_0", "moving_car", "reverse_out",
                  np.array([[0.0, x + 6.0, y + 6.0, 0.1], [2.0, x + 6.0, y + 3.0, 1.6], [4.5, x + 6.0, y + 3.0, 1.6],
                            [9.0, x - 10.0, y + 3.0, 1.6]]), t1, 3.25, free_stall),
        ActorSpec("movingcar_1", "moving_car", "oncoming",
                  np.array([[0.0, x + 15.0, y, math.pi], [6.0, x + 1.0, y, math.pi]]), t2, 2.0),
        ActorSpec("clutter_0", "clutter", "cone", np.array([[0.0, x + 1.0, y - 1.75, 0.7]])),
        ActorSpec("clutter_1", "clutter", "trolley", np.array([[0.0, x - 2.0, y - 1.75, -2.0]])),
    ]


@pytest.fixture(scope="module")
def case(painted_tiny, tmp_path_factory):
    """A pack, one feasible plan of it, and the write_xosc arguments of a test with hand-made actors."""
    root = tmp_path_factory.mktemp("xosc")
    pack = export_pack(painted_tiny, root / "packs")
    scene = GarageScene(painted_tiny)
    plan = next(p for p in drive_planner(scene).plans() if p.feasible)
    stalls = [pc.stall_id for pc in scene.layout.parked_cars if pc.stall_id != plan.stall]
    free = stalls[0]
    occupied = stalls[1:]
    kwargs = dict(pack_dir=pack, target_stall=plan.stall, occupied=occupied, start=_start(plan), route=plan.centre,
                  goal=plan.goal, actors=_hand_actors(plan, free), parked_poses=scene.layout.parked_cars, meta=META)
    return {"root": root, "pack": pack, "scene": scene, "plan": plan, "kwargs": kwargs}


@pytest.fixture(scope="module")
def files(case):
    """name -> .xosc path: the hand-made test as 1.2 and 1.1, a drawn scenario, and a broken copy."""
    root, kw = case["root"], case["kwargs"]
    out = {"hand_1_2": write_xosc(root / "scenarios" / "hand.xosc", **kw),
           "hand_1_1": write_xosc(root / "scenarios" / "hand_1_1.xosc", osc_minor=1, **kw)}
    scene, plan = case["scene"], case["plan"]
    drawn = None
    for seed in range(20):
        sc = draw_scenario(ScenarioConfig(pedestrians=1, moving_cars=1, clutter=1), plan, drive_planner(scene),
                           np.random.default_rng(seed))
        if len({a.kind for a in sc.actors}) >= 2:
            drawn = sc
            break
    assert drawn is not None, "draw_scenario placed no actors on the tiny garage"
    case["drawn"] = drawn.actors
    occ = [s for s in kw["occupied"] if s not in drawn.free_stalls]
    out["drawn"] = write_xosc(root / "drawn.xosc", **{**kw, "occupied": occ, "actors": drawn.actors})
    # broken: a required attribute removed and an invalid value
    tree = etree.parse(str(out["hand_1_2"]))
    del tree.find("Entities/ScenarioObject/Vehicle").attrib["vehicleCategory"]
    tree.find(".//Dimensions").set("width", "wide")
    broken = root / "scenarios" / "broken.xosc"
    tree.write(str(broken), xml_declaration=True, encoding="UTF-8")
    out["broken"] = broken
    return out


@pytest.fixture(scope="module")
def park(case):
    """Park and AVP runs of the oracle (which parks) and of waypoint (which cannot reverse), each test written
    with xosc=True: run name -> (tests.csv rows, their .xosc files in test order)."""
    srcs = cruise_sources([case["pack"]])
    runs = {"park_oracle": CruiseSettings("oracle", task="park", maneuver="any"),
            "park_waypoint": CruiseSettings("waypoint", task="park"),
            "avp_oracle": CruiseSettings("oracle", task="avp", maneuver="forward")}
    out = {}
    for name, settings in runs.items():
        run_dir = case["root"] / name
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ActionTypeWarning)
            res = run_cruise(srcs, 2 if name == "park_oracle" else 1, settings, run_dir, compute=QUIET, xosc=True)
        out[name] = (res.rows, sorted((run_dir / "xosc").glob("*.xosc")))
    return out


@pytest.fixture(scope="module")
def reports(files, park):
    names = [*files, "park", "avp"]
    paths = [*files.values(), park["park_oracle"][1][0], park["avp_oracle"][1][0]]
    return dict(zip(names, check_xosc_batch(paths)))


def test_asam_checker_finds_zero_issues(files, reports):
    for name in ("hand_1_2", "hand_1_1", "drawn", "park", "avp"):
        rep = reports[name]
        assert rep.issues == [] and rep.errored == 0, f"{name}: {rep.issues[:5]}"
    for name in ("hand_1_2", "drawn", "park", "avp"):  # 1.2: every checker of the bundle applies
        assert reports[name].completed >= 17 and reports[name].skipped == 0, reports[name]
    # 1.1: the XML and schema checks run; the bundle's rule checks are defined from 1.2 on
    assert reports["hand_1_1"].completed >= 5


def test_asam_checker_catches_a_broken_file(reports):
    issues = reports["broken"].issues
    assert issues and all(i.level == 1 for i in issues)
    assert any("schema" in i.description for i in issues)
    assert any("vehicleCategory" in i.location or "wide" in i.location for i in issues), issues


def _same_actors(got, want):
    assert [a.name for a in got] == [a.name for a in want]
    for a, b in zip(got, want):
        assert (a.kind, a.behaviour, a.stall) == (b.kind, b.behaviour, b.stall), a.name
        np.testing.assert_allclose(a.waypoints, b.waypoints, rtol=0, atol=1e-6)
        assert (a.trigger is None) == (b.trigger is None), a.name
        if b.trigger is not None:
            np.testing.assert_allclose(a.trigger, b.trigger, rtol=0, atol=1e-6)
            assert a.trigger_radius == pytest.approx(b.trigger_radius, abs=1e-6)


@pytest.mark.parametrize("name", ["hand_1_2", "hand_1_1"])
def test_round_trip(case, files, name):
    kw = case["kwargs"]
    t = read_xosc(files[name])
    assert t.pack_dir == case["pack"].resolve() and t.xodr_path == (case["pack"] / "garage.xodr").resolve()
    assert t.garage_hash == case["scene"].garage.canonical_hash()
    assert t.target_stall == kw["target_stall"] and t.occupied == sorted(kw["occupied"])
    np.testing.assert_allclose(t.start, kw["start"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(t.goal, kw["goal"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(t.route, kw["route"], rtol=0, atol=1e-6)
    _same_actors(t.actors, kw["actors"])
    placed = {pc.stall_id: (pc.x, pc.y, pc.yaw) for pc in case["scene"].layout.parked_cars}
    assert sorted(t.parked) == t.occupied
    for s, pose in t.parked.items():
        np.testing.assert_allclose(pose, placed[s], rtol=0, atol=1e-6)
    assert (t.seed, t.driver, t.action_type) == (123456, "pure_pursuit", "continuous")
    assert t.meta == {k: v for k, v in META.items() if k not in ("seed", "driver", "action_type")}
    assert t.pack().manifest["garage_hash"] == t.garage_hash
    root = etree.parse(str(files[name])).getroot()
    assert root.find("FileHeader").get("revMinor") == name[-1]
    logic = root.find("RoadNetwork/LogicFile").get("filepath")
    assert not logic.startswith("/") and logic.endswith("garage.xodr")  # relative to the .xosc
    cond = "DistanceCondition" if name == "hand_1_2" else "ReachPositionCondition"
    assert len(root.findall(f".//{cond}")) == 1 + sum(not a.static for a in kw["actors"])  # goal + triggers
    kinds = {so.get("name"): so[0].tag for so in root.findall("Entities/ScenarioObject")}
    assert kinds["pedestrian_0"] == "Pedestrian" and kinds["movingcar_0"] == "Vehicle"
    assert kinds["clutter_0"] == "MiscObject" and root.find(".//MiscObject").get("miscObjectCategory") == "obstacle"
    assert {n for n in kinds if n.startswith("parkedcar_")} == {f"parkedcar_{s}" for s in kw["occupied"]}
    parsed = ParseOpenScenario(str(files[name]))  # scenariogeneration's own reader accepts the file too
    assert len(parsed.entities.scenario_objects) == len(kinds)


def test_round_trip_of_drawn_actors(case, files):
    t = read_xosc(files["drawn"])
    _same_actors(t.actors, case["drawn"])


def _tampered(files, tmp_path, edit, name="tampered.xosc"):
    src = files["hand_1_2"]
    dst = src.parent / name  # beside the original, so the relative road network path still resolves
    tree = etree.parse(str(src))
    edit(tree.getroot())
    tree.write(str(dst), xml_declaration=True, encoding="UTF-8")
    return dst


def _set(xpath, attr, value):
    def edit(root):
        root.xpath(xpath)[0].set(attr, value)
    return edit


def _drop(xpath):
    def edit(root):
        el = root.xpath(xpath)[0]
        el.getparent().remove(el)
    return edit


def _retag(xpath, tag):
    def edit(root):
        root.xpath(xpath)[0].tag = tag
    return edit


TAMPERS = {
    "target_missing": (_drop("ParameterDeclarations/ParameterDeclaration[@name='gmj_target_stall']"),
                       "parameter gmj_target_stall is missing"),
    "seed_not_int": (_set("ParameterDeclarations/ParameterDeclaration[@name='gmj_seed']", "value", "12x"),
                     "gmj_seed: '12x' is not a valid int"),
    "vertex_not_number": (_set("(//Vertex/Position/WorldPosition)[3]", "x", "east"), "'east' is not a number"),
    "no_road_network": (_set("RoadNetwork/LogicFile", "filepath", "../nowhere/garage.xodr"), "does not exist"),
    "actor_wrong_entity": (_retag("Entities/ScenarioObject[@name='clutter_0']/MiscObject", "Pedestrian"),
                           "clutter_0 (clutter) is a Pedestrian"),
    "parked_car_removed": (_drop("Entities/ScenarioObject[starts-with(@name, 'parkedcar_')]"),
                           "Init acts on unknown entity 'parkedcar_"),
    "occupied_changed": (_set("ParameterDeclarations/ParameterDeclaration[@name='gmj_occupied']", "value", "0"),
                         "does not match the parked cars"),
    "trigger_on_other_entity": (_set("(//StartTrigger//TriggeringEntities/EntityRef)[2]", "entityRef",
                                     "pedestrian_1"), "not the ego"),
    "negative_radius": (_set("(//Event//DistanceCondition)[1]", "value", "-2"), "negative"),
    "goal_missing": (_drop("Storyboard/StopTrigger"), "no StopTrigger"),
    "unknown_behaviour": (_set("ParameterDeclarations/ParameterDeclaration[@name='gmj_actor_pedestrian_0_behaviour']",
                               "value", "moonwalk"), "unknown kind/behaviour"),
}


@pytest.mark.parametrize("name", sorted(TAMPERS))
def test_tampered_file_gives_one_clear_line(files, tmp_path, name):
    edit, words = TAMPERS[name]
    path = _tampered(files, tmp_path, edit, f"tampered_{name}.xosc")
    with pytest.raises(XoscError) as info:
        read_xosc(path)
    msg = str(info.value)
    assert isinstance(info.value, GarageMJError)
    assert "\n" not in msg and str(path) in msg and words in msg, msg


def test_unreadable_files_give_one_clear_line(files, tmp_path):
    bad = tmp_path / "garbage.xosc"
    bad.write_bytes(files["hand_1_2"].read_bytes()[:500])
    for path, words in ((bad, "not well-formed XML"), (tmp_path / "missing.xosc", "no such file")):
        with pytest.raises(XoscError, match=words) as info:
            read_xosc(path)
        assert "\n" not in str(info.value) and str(path) in str(info.value)
    other = tmp_path / "other.xml"
    other.write_text("<OpenDRIVE><header/></OpenDRIVE>")
    with pytest.raises(XoscError, match="not <OpenSCENARIO>"):
        read_xosc(other)


def test_copied_pack_with_another_garage_is_refused(case, files, tmp_path):
    t = read_xosc(files["hand_1_2"])
    t.garage_hash = "0" * 64
    with pytest.raises(XoscError, match="is not the garage of pack"):
        t.pack()


def test_write_refuses_what_it_cannot_carry(case, tmp_path):
    kw = case["kwargs"]
    a = kw["actors"][0]
    bad = [
        ([ActorSpec(a.name, a.kind, a.behaviour, a.waypoints)], "needs one"),  # moving without a trigger
        ([a, a], "unique"),
        ([ActorSpec("ego", "clutter", "cone", a.waypoints[:1])], "identifier other than"),
    ]
    for actors, words in bad:
        with pytest.raises(XoscError, match=words):
            write_xosc(tmp_path / "x.xosc", **{**kw, "actors": actors})
    with pytest.raises(XoscError, match="no parked-car pose"):
        write_xosc(tmp_path / "x.xosc", **{**kw, "parked_poses": {}})
    with pytest.raises(XoscError, match="meta key"):
        write_xosc(tmp_path / "x.xosc", **{**kw, "meta": {"target_stall": 3}})
    assert not (tmp_path / "x.xosc").exists()


def test_xosc_moves_with_its_pack(case, files, tmp_path):
    """The road network path is relative: a folder holding both the pack and the .xosc can move."""
    moved = tmp_path / "moved"
    shutil.copytree(case["root"], moved)
    t = read_xosc(moved / "scenarios" / "hand.xosc")
    assert t.pack_dir == (moved / "packs" / case["pack"].name).resolve()


def test_missing_checker_names_the_fix(monkeypatch, tmp_path):
    import garage_mj.export.validate as v

    monkeypatch.setattr(v, "_REPO", tmp_path)
    monkeypatch.delenv(v.QC_XOSC_ENV, raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ToolMissing, match="make install"):
        qc_xosc_executable()


def test_a_replayed_park_or_avp_test_ends_as_the_test_did(park):
    seen = set()
    for name, (rows, paths) in park.items():
        assert len(rows) == len(paths) >= 1, name
        for row, path in zip(rows, paths, strict=True):
            again = replay_xosc(path)
            assert {k: str(again[k]) for k in SAME} == {k: str(row[k]) for k in SAME}, (name, path)
            seen.add(row["outcome"])
    assert "success" in seen and seen - {"success"}, seen  # the oracle parks, waypoint does not


def test_a_park_file_holds_the_start_the_stall_pose_and_the_plan_with_its_reverse_steps(park, painted_tiny):
    rows, paths = park["park_oracle"]
    for row, path in zip(rows, paths, strict=True):
        t = read_xosc(path)
        assert (t.task, t.meta["maneuver"], t.meta["plan_start"]) == ("park", row["maneuver"], 0)
        env = GarageDriveEnv(painted_tiny, task="park", maneuver=row["maneuver"], infeasible="report")
        try:
            _, info = env.reset(seed=t.seed, options={"target": t.target_stall, "occupied": t.occupied,
                                                      "start": t.start})
        finally:
            env.close()
        want, got = info["park_plan"], t.park_plan()
        np.testing.assert_allclose(got["poses"], want["poses"], atol=1e-9)
        assert list(got["directions"][:-1]) == list(want["directions"][:-1]) and -1 in got["directions"]
        np.testing.assert_allclose(t.goal, want["stall_pose"], atol=1e-9)
        np.testing.assert_allclose(t.start, env.start_pose, atol=1e-9)
    avp = read_xosc(park["avp_oracle"][1][0])
    assert avp.task == "avp" and 0 < avp.meta["plan_start"] < len(avp.route) - 1
    assert avp.park_plan()["poses"].shape[1] == 3 and read_xosc(park["park_waypoint"][1][0]).task == "park"


PARK_TAMPERS = {
    "task": ("gmj_task", "valet", "gmj_task: 'valet' is not a park or AVP test"),
    "maneuver": ("gmj_maneuver", "sideways", "gmj_maneuver: 'sideways' is not one of reverse, forward"),
    "plan_start": ("gmj_plan_start", "100000", "gmj_plan_start: 100000 is not a vertex"),
}


@pytest.mark.parametrize("name", sorted(PARK_TAMPERS))
def test_a_malformed_park_file_gives_one_clear_line(park, name):
    param, value, words = PARK_TAMPERS[name]
    src = park["park_oracle"][1][0]
    dst = src.parent / f"tampered_{name}.xosc"
    tree = etree.parse(str(src))
    tree.getroot().xpath(f"ParameterDeclarations/ParameterDeclaration[@name='{param}']")[0].set("value", value)
    tree.write(str(dst), xml_declaration=True, encoding="UTF-8")
    with pytest.raises(XoscError) as info:
        replay_xosc(dst)
    msg = str(info.value)
    assert "\n" not in msg and str(dst) in msg and words in msg, msg
