"""Park geometry as a pack's parameter (docs/spec.md section 9): stall width, depth and angle, aisle width.

Each geometry builds a valid scene whose stalls overlap nothing and fit their blocks, the cruise planner still
reaches the stalls, and the geometry travels into the manifest, OpenDRIVE, park problems and the drive env.
"""

from __future__ import annotations

import json
import math

import pytest
from lxml import etree

from garage_mj.cli import main
from garage_mj.export.pack import export_pack, load_pack, manifest_world, pack_name
from garage_mj.export.xodr import to_tree
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.semantics import Semantic
from garage_mj.scene.stalls import polygons_overlap, rectangle, row_count, stall_layout
from garage_mj.scene.world import (
    DEFAULT_WORLD,
    WORLD_DIR,
    GeometryError,
    WorldConfig,
    cell_center,
    geometry,
    load_layout,
    world_with,
)

#: Geometries every test below builds: bays, depths, aisles and the three kinds of angle.
GEOMETRIES = [
    {},
    {"stall_width": 2.3, "aisle_width": 6.5},
    {"stall_width": 2.2, "stall_depth": 4.0},
    {"stall_width": 2.8},  # obstructed blocks hold two stalls (three and two pillars do not fit 9 m)
    {"stall_depth": 5.5, "aisle_width": 7.0},
    {"aisle_width": 5.5},
    {"stall_angle": 60},
    {"stall_angle": 45, "aisle_width": 6.5},
    {"stall_angle": 60, "aisle_width": 7.0},
    {"stall_angle": 0},
    {"stall_angle": 0, "slot_length": 4.5, "aisle_width": 8.0},
]
IDS = ["-".join(f"{k}={v}" for k, v in g.items()) or "default" for g in GEOMETRIES]


@pytest.fixture(scope="module")
def garages():
    """Tiny 7x11 garages and a 13x13 one with six-stall blocks (back-to-back rows)."""
    return [paint_garage("tiny_7x11", seed=s) for s in (1, 2)] + [paint_garage("m6_13x13_s", seed=1)]


# -- the geometry record --------------------------------------------------------------------------------------------
def test_the_default_slot_is_the_sedan_plus_a_metre():
    from garage_mj.scene.vehicles import DEFAULT_VEHICLE, FLEET
    from garage_mj.scene.world import DEFAULT_VEHICLE_LENGTH, SLOT_SPARE

    assert DEFAULT_VEHICLE_LENGTH == FLEET[DEFAULT_VEHICLE].length
    assert DEFAULT_WORLD.slot_length == pytest.approx(FLEET[DEFAULT_VEHICLE].length + SLOT_SPARE)


def test_defaults_are_todays_garage():
    assert geometry(DEFAULT_WORLD) == {"stall_width": 2.5, "stall_depth": 4.5, "aisle_width": 9.0, "stall_angle": 90.0,
                                       "slot_length": 5.6}
    assert DEFAULT_WORLD.is_default_geometry and DEFAULT_WORLD.aisle_setback == 0.0
    assert DEFAULT_WORLD.drive_lane_width == DEFAULT_WORLD.lane_width == 3.5


@pytest.mark.parametrize(("values", "said"), [
    ({"stall_width": 1.8}, "stall_width (--stall-width) must be a finite number in [2.2, 3]"),
    ({"stall_width": 3.2}, "stall_width (--stall-width)"),
    ({"stall_depth": 3.0}, "stall_depth (--stall-depth)"),
    ({"aisle_width": 5.0}, "aisle_width (--aisle-width)"),
    ({"aisle_width": float("nan")}, "aisle_width"),
    ({"stall_angle": 30}, "give --stall-angle 90, 60, 45 or 0"),
    ({"slot_length": 9.0}, "slot_length (--slot-length)"),
    ({"stall_width": "wide"}, "stall_width"),
    ({"bay": 2.5}, "unknown key(s) bay"),
])
def test_a_bad_geometry_is_one_line_naming_the_field_and_the_fix(values, said):
    with pytest.raises(GeometryError) as info:
        world_with(values)
    assert said in str(info.value) and "\n" not in str(info.value)


def test_the_config_itself_refuses_values_out_of_range():
    with pytest.raises(GeometryError, match="stall_width"):
        WorldConfig(stall_width=1.5)


def test_layout_file(tmp_path):
    good = tmp_path / "narrow.toml"
    good.write_text("stall_width = 2.3\naisle_width = 6.5\n")
    assert load_layout(str(good)) == {"stall_width": 2.3, "aisle_width": 6.5}
    table = tmp_path / "table.toml"
    table.write_text("[layout]\nstall_angle = 60\n")
    assert load_layout(str(table)) == {"stall_angle": 60.0}
    for text, said in (("stall_width = 2.3\nbay = 1\n", "unknown key(s) bay"), ("stall_width = 9\n", "stall_width"),
                       ("stall_width = \n", "not valid TOML")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(GeometryError, match=said.replace("(", r"\(").replace(")", r"\)")):
            load_layout(str(bad))


# -- stalls fit and overlap nothing ---------------------------------------------------------------------------------
def _fits_block(stall, world: WorldConfig, rows: int) -> bool:
    """Whether the stall lies inside its block, widened toward its road by the aisle's set-back."""
    cx, cy = cell_center(*stall.block, rows, world)
    half, k = world.block / 2, world.aisle_setback
    ux, uy = WORLD_DIR[stall.side]
    x0, x1, y0, y1 = cx - half, cx + half, cy - half, cy + half
    x1, x0 = (x1 + k, x0) if ux > 0 else (x1, x0 - k) if ux < 0 else (x1, x0)
    y1, y0 = (y1 + k, y0) if uy > 0 else (y1, y0 - k) if uy < 0 else (y1, y0)
    return all(x0 - 1e-6 <= x <= x1 + 1e-6 and y0 - 1e-6 <= y <= y1 + 1e-6 for x, y in stall.corners)


@pytest.mark.parametrize("values", GEOMETRIES, ids=IDS)
def test_every_geometry_builds_a_scene_whose_stalls_fit_and_overlap_nothing(garages, values):
    world = world_with(values)
    for garage in garages:
        try:
            scene = GarageScene(garage, world)
            stalls = scene.stalls.stalls
        except GeometryError as exc:  # only six-stall blocks may refuse: their back-to-back rows overlap
            assert "back-to-back rows" in str(exc) and garage.name.startswith("m6"), exc
            continue
        assert stalls, garage.name
        assert {s.angle for s in stalls} == {world.stall_angle}
        rows = garage.shape[0]
        assert all(_fits_block(s, world, rows) for s in stalls), garage.name
        outlines = [s.corners for s in stalls]
        for i in range(len(outlines)):
            for j in range(i + 1, len(outlines)):
                assert not polygons_overlap(outlines[i], outlines[j]), (garage.name, i, j)
        h = world.pillar_size / 2
        solids = [rectangle(p.x, p.y, 0.0, 2 * h, 2 * h) for p in scene.layout.pillars]
        solids += [rectangle(b.center[0], b.center[1], 0.0, 2 * b.half[0], 2 * b.half[1]) for b in scene.layout.boxes
                   if b.collides and b.cls in (Semantic.WALL, Semantic.OBSTACLE)]
        for s in outlines:
            assert not any(polygons_overlap(s, solid) for solid in solids), garage.name
        # every part builds: the road model with a parking space per stall, the lane graph, the layout
        assert len(scene.road_model.parking) == len(stalls)
        assert scene.lane_graph.number_of_nodes() > 0
        kerbs = [b for b in scene.layout.boxes if b.name.startswith("wall_kerb")]
        assert bool(kerbs) == (world.aisle_width < world.block)


def test_stall_width_and_depth_shape_every_stall(painted_tiny):
    world = world_with({"stall_width": 2.3, "stall_depth": 4.2})
    for s in stall_layout(painted_tiny, world).stalls:
        xs, ys = zip(*s.corners)
        assert sorted([max(xs) - min(xs), max(ys) - min(ys)]) == pytest.approx([2.3, 4.2])


def test_a_narrow_aisle_moves_the_rows_onto_its_edge_and_kerbs_the_rest(painted_tiny):
    base, narrow = stall_layout(painted_tiny), stall_layout(painted_tiny, world_with({"aisle_width": 6.5}))
    moved = [math.hypot(a.x - b.x, a.y - b.y) for a, b in zip(base.stalls, narrow.stalls, strict=True)]
    assert set(round(m, 6) for m in moved) <= {0.0, 1.25}  # 1.25 m = (9 - 6.5) / 2, beside straight aisles
    assert max(moved) == pytest.approx(1.25)


@pytest.mark.parametrize("angle", [60, 45])
def test_angled_stalls_lean_with_the_one_way_flow_from_the_entrance(painted_tiny, angle):
    world = world_with({"stall_angle": angle})
    scene = GarageScene(painted_tiny, world)
    planner = drive_planner(scene)
    shallow = 0
    for s in scene.stalls.stalls:
        side = math.atan2(WORLD_DIR[s.side][1], WORLD_DIR[s.side][0])
        assert abs(math.remainder(s.yaw - side, 2 * math.pi)) == pytest.approx(math.radians(90 - angle))
        plan = planner.plan(s.id)
        assert plan.feasible, plan.reason
        # from the goal, driving on with the flow, the stall is a forward turn of 90 - angle degrees... or, where
        # the row faces a turn, the car meets it another way
        into = (-math.cos(s.yaw), -math.sin(s.yaw))
        heading = plan.goal[2]
        shallow += math.cos(heading) * into[0] + math.sin(heading) * into[1] == pytest.approx(
            math.cos(math.radians(angle)))
    assert shallow >= 0.8 * len(scene.stalls.stalls)


def test_parallel_slots_run_along_the_block_edge(painted_tiny):
    world = world_with({"stall_angle": 0})
    layout = stall_layout(painted_tiny, world)
    assert row_count(world, 3, pillars=False) == 1 and row_count(world_with({"stall_angle": 0, "slot_length": 4.5}),
                                                                   3, pillars=False) == 2
    for s in layout.stalls:
        assert (s.length, s.width) == (2.5, 5.6)  # across the aisle along yaw, along the aisle
        assert math.cos(s.car_yaw - s.yaw) == pytest.approx(0.0, abs=1e-12)  # a parked car stands along the aisle


@pytest.mark.parametrize("values", [{"stall_width": 2.3, "aisle_width": 6.5}, {"stall_angle": 60},
                                    {"stall_angle": 45, "aisle_width": 6.5}, {"stall_angle": 0},
                                    {"aisle_width": 5.5}], ids=["bay2.3-aisle6.5", "angle60", "angle45-aisle6.5",
                                                                 "parallel", "aisle5.5"])
def test_cruise_plans_reach_the_stalls(painted_tiny, values):
    scene = GarageScene(painted_tiny, world_with(values))
    plans = drive_planner(scene).plans()
    assert plans and all(p.feasible for p in plans), [p.reason for p in plans if not p.feasible][:3]
    for p in plans:  # the goal lies in the stall's road cell
        cx, cy = cell_center(*scene.stalls.stalls[p.stall].road_cell, painted_tiny.shape[0], scene.world)
        assert max(abs(p.goal[0] - cx), abs(p.goal[1] - cy)) <= scene.world.block / 2 + 0.5, p.stall


# -- carried into every artefact ------------------------------------------------------------------------------------
def test_manifest_round_trip(painted_tiny, tmp_path):
    world = world_with({"stall_width": 2.3, "aisle_width": 6.5})
    path = export_pack(painted_tiny, tmp_path, world=world)
    assert path.name == pack_name(painted_tiny, world) and "-bay2.3x4.5-aisle6.5-angle90_" in path.name
    pack = load_pack(path)
    assert pack.manifest["geometry"] == geometry(world) and pack.world == world
    default = export_pack(painted_tiny, tmp_path)
    assert default.name == pack_name(painted_tiny) and load_pack(default).world == DEFAULT_WORLD
    manifest = json.loads((default / "manifest.json").read_text())
    del manifest["geometry"]  # a pack from before geometry was a parameter
    assert manifest_world(manifest) == DEFAULT_WORLD
    (default / "manifest.json").write_text(json.dumps(manifest))
    assert load_pack(default).world == DEFAULT_WORLD
    index = json.loads((tmp_path / "index.json").read_text()) if (tmp_path / "index.json").exists() else None
    assert index is None or all("geometry" in e for e in index["packs"])


def test_opendrive_parking_spaces_carry_width_length_and_angle(painted_tiny):
    world = world_with({"stall_width": 2.3, "stall_angle": 60, "aisle_width": 7.0})
    scene = GarageScene(painted_tiny, world)
    tree = to_tree(scene.road_model)
    spaces = tree.getroot().findall(".//object[@type='parkingSpace']")
    assert len(spaces) == len(scene.stalls.stalls)
    for obj in spaces:
        assert (float(obj.get("length")), float(obj.get("width"))) == (4.5, 2.3)
        assert obj.find("userData[@code='garage-mj:stallAngle']").get("value") == "60"
    plain = etree.tostring(to_tree(GarageScene(painted_tiny).road_model))
    assert b"userData" not in plain  # the default geometry's file is as it was


def test_park_problem_files_carry_the_geometry(painted_tiny, tmp_path):
    from garage_mj.export.park_problems import read_park_problem, write_park_problems

    world = world_with({"stall_width": 2.3, "aisle_width": 6.5})
    index = write_park_problems([GarageScene(painted_tiny, world)], tmp_path / "problems", stalls={0})
    first = json.loads(index.read_text())["problems"][0]
    problem = read_park_problem(tmp_path / "problems" / first["json"])
    assert problem.geometry == geometry(world)
    data = json.loads((tmp_path / "problems" / first["json"]).read_text())
    del data["geometry"]
    (tmp_path / "old.json").write_text(json.dumps(data))
    assert read_park_problem(tmp_path / "old.json").geometry == geometry(DEFAULT_WORLD)


def test_drive_env_builds_its_scene_in_the_geometry(painted_tiny):
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", world={"stall_angle": 60})
    try:
        assert env.scene.world.stall_angle == 60.0 and len(env.stalls) == 30
        env.reset(seed=0)
    finally:
        env.close()


def test_export_cli_writes_the_layout_files_geometry(painted_tiny, tmp_path):
    (tmp_path / "g.json").write_text(painted_tiny.to_json())
    (tmp_path / "layout.toml").write_text("stall_width = 2.3\naisle_width = 6.5\n")
    code = main(["export", "--garage", str(tmp_path / "g.json"), "--out", str(tmp_path / "packs"), "--layout",
                 str(tmp_path / "layout.toml"), "--stall-depth", "4.8", "--quiet"])
    assert code == 0
    (folder,) = [p for p in (tmp_path / "packs").iterdir() if p.is_dir()]
    assert load_pack(folder).manifest["geometry"] == {"stall_width": 2.3, "stall_depth": 4.8, "aisle_width": 6.5,
                                                      "stall_angle": 90.0, "slot_length": 5.6}


@pytest.mark.slow
@pytest.mark.parametrize("values", [{"stall_angle": 60}, {"stall_width": 2.3, "aisle_width": 6.5}],
                         ids=["angle60", "bay2.3-aisle6.5"])
def test_the_oracle_parks_in_the_geometry(painted_tiny, values):
    """A park test on the geometry drives to success: the reference planner plans in it, the env judges it."""
    from garage_mj.driving.drivers import load_driver
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", task="park", world=values)
    try:
        obs, info = env.reset(seed=0)
        driver = load_driver("oracle")
        driver.reset(env.driver_info(0))
        while "outcome" not in info:
            obs, _, _, _, info = env.step(driver.act(obs))
        assert info["outcome"] == "success", info["reason"]
    finally:
        env.close()
