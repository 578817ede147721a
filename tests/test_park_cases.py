"""Park cases from elsewhere (docs/spec.md section 9): ``garage-mj cruise --cases`` runs TPCAP case files and this
project's exported park problems as park tests, one each, end to end; the MuJoCo scene holds the case's polygons.

TPCAP's published cases are read only where ``GARAGE_MJ_TPCAP_CASES`` names a folder holding them (a clone of
github.com/libai1943/TPCAP_benchmarks); the tests here write their own small cases.
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import mujoco
import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.driving.cases import case_files, read_case, read_cases
from garage_mj.driving.sim.vehicle import compile_mjcf
from garage_mj.export.park_problems import ParkProblemError, write_park_problems
from garage_mj.scene.case_scene import (
    HEIGHTS,
    CaseObstacle,
    CaseScene,
    ParkCase,
    build_case_scene,
    convex_pieces,
    is_convex,
    signed_area,
    tpcap_class,
)
from garage_mj.scene.park_planning import in_stall, park_pose, rear_to_centre
from garage_mj.scene.vehicles import TPCAP_VEHICLE

TPCAP_CASES = os.environ.get("GARAGE_MJ_TPCAP_CASES")


def _rect(cx: float, cy: float, length: float, width: float, yaw: float = 0.0) -> list[tuple[float, float]]:
    c, s = math.cos(yaw), math.sin(yaw)
    return [(cx + c * dx - s * dy, cy + s * dx + c * dy)
            for dx, dy in ((length / 2, width / 2), (-length / 2, width / 2), (-length / 2, -width / 2),
                           (length / 2, -width / 2))]


def _tpcap_text(start, goal, polygons) -> str:
    """A case as TPCAP publishes them: one comma-separated line, CRLF."""
    v = [*start, *goal, len(polygons), *(len(p) for p in polygons), *(c for p in polygons for xy in p for c in xy)]
    return ",".join(repr(float(x)) if not float(x).is_integer() or i < 6 else str(int(x)) for i, x in enumerate(v)) + "\r\n"


#: A parallel slot 7.5 m long between two parked cars along a kerb wall, far from the origin (as TPCAP's cases 13 to
#: 15 are): the car starts beside the front car on the lane and ends in the slot, both headed +x (rear axles).
FAR = (4.0e9, -3.5e8)
SLOT_CARS = [_rect(FAR[0] - 6.0, FAR[1], 4.5, 1.9), _rect(FAR[0] + 6.0, FAR[1], 4.5, 1.9)]
KERB = [(FAR[0] - 15.0, FAR[1] - 2.0), (FAR[0] + 15.0, FAR[1] - 2.0), (FAR[0] + 15.0, FAR[1] - 1.2),
        (FAR[0] - 15.0, FAR[1] - 1.2)]
SLOT_START = (FAR[0] + 5.0, FAR[1] + 2.6, 0.0)
SLOT_GOAL = (FAR[0] - 1.9, FAR[1] + 0.05, 0.0)


@pytest.fixture
def slot_case(tmp_path) -> Path:
    path = tmp_path / "slot.csv"
    path.write_text(_tpcap_text(SLOT_START, SLOT_GOAL, [*SLOT_CARS, KERB]), newline="")
    return path


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "tests.csv").open(newline="") as f:
        return list(csv.DictReader(f))


# -- polygons ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("poly", [
    [(0, 0), (4, 0), (4, 1), (1, 1), (1, 3), (0, 3)],  # an L
    [(0, 0), (6, 0), (6, 4), (5, 4), (5, 1), (1, 1), (1, 4), (0, 4)],  # a U (TPCAP's cases 16 to 18 are such)
    [(0, 0), (2, 0), (4, 0), (4, 2), (2, 1), (0, 2)][::-1],  # clockwise, a collinear vertex, a notch
    [(math.cos(a) * (2 + (k % 2)), math.sin(a) * (2 + (k % 2))) for k, a in enumerate(np.linspace(0, 2 * np.pi, 14)[:-1])],
])
def test_convex_pieces_are_convex_and_cover_the_polygon_exactly(poly):
    pieces = convex_pieces(poly)
    assert all(is_convex(p) and signed_area(p) > 0 for p in pieces)
    assert sum(signed_area(p) for p in pieces) == pytest.approx(abs(signed_area(poly)), rel=1e-12)
    corners = {tuple(np.round(v, 9)) for v in np.asarray(poly, dtype=float)}
    assert all(tuple(np.round(v, 9)) in corners for p in pieces for v in p)  # cut along diagonals only
    if is_convex(np.asarray(poly[::-1] if signed_area(poly) < 0 else poly, dtype=float)):
        assert len(pieces) == 1


def test_a_polygon_that_crosses_itself_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "bow.csv"
    path.write_text(_tpcap_text((0, 0, 0), (10, 0, 0), [[(3, 3), (7, 6), (7, 3), (3, 5)]]))
    with pytest.raises(ParkProblemError, match=r"bow\.csv.*obstacle 1 is no simple polygon"):
        read_case(path)


def test_tpcap_polygons_of_a_car_s_size_are_parked_cars():
    assert tpcap_class(_rect(0, 0, 4.5, 1.9, 0.3)) == "parked_car"
    assert tpcap_class(_rect(0, 0, 20.0, 1.0)) == "wall"
    assert tpcap_class([(0, 0), (4, 0), (4, 1), (1, 1), (1, 3), (0, 3)]) == "wall"
    assert tpcap_class([(0, 0), (1.2, 0.1), (0.9, 1.0)]) == "obstacle"


# -- the scene ---------------------------------------------------------------------------------------------------
def _floor_outline(model, data, g: int) -> np.ndarray:
    """Geom ``g``'s corners on the floor (its vertices' x, y in the world), from the compiled model."""
    if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
        half = model.geom_size[g]
        local = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]) * half
    else:
        mesh = model.geom_dataid[g]
        a, n = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        local = model.mesh_vert[a:a + n]
    world = data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T
    return world


def test_the_mujoco_scene_holds_exactly_the_case_s_polygons():
    l_wall = [(-8, -6), (8, -6), (8, -5), (-7, -5), (-7, 6), (-8, 6)]
    car = _rect(3.0, 2.0, 4.5, 1.9, 0.4)
    case = ParkCase("t", "t", "0" * 64, "tpcap", (0.0, 0.0), TPCAP_VEHICLE, (0.0, 0.0, 0.0), (-3.0, 0.0, 0.0),
                    (CaseObstacle("wall", tuple(l_wall)), CaseObstacle("parked_car", tuple(car))))
    scene = CaseScene(case)
    model = compile_mjcf(build_case_scene(scene))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for k, o in enumerate(case.obstacles):
        prefix = "wall" if o.cls == "wall" else "parkedcar"
        geoms = [g for g in range(model.ngeom)
                 if (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "").startswith(f"{prefix}_{k}_")]
        assert geoms
        outlines = [_floor_outline(model, data, g) for g in geoms]
        area = 0.0
        for pts in outlines:
            assert pts[:, 2].min() == pytest.approx(0.0, abs=1e-6)
            assert pts[:, 2].max() == pytest.approx(HEIGHTS[o.cls], abs=1e-6)
            flat = np.unique(np.round(pts[:, :2], 6), axis=0)
            centre = flat.mean(axis=0)
            ring = flat[np.argsort(np.arctan2(flat[:, 1] - centre[1], flat[:, 0] - centre[0]))]
            area += signed_area(ring)
            corners = {tuple(np.round(v, 6)) for v in np.asarray(o.vertices, dtype=float)}
            assert all(tuple(v) in corners for v in np.round(flat, 6)), "a geom corner that is no polygon corner"
        assert area == pytest.approx(abs(signed_area(o.vertices)), rel=1e-6)
    # and the planner's obstacles are the same pieces
    assert len(scene.obstacles.boxes) == sum(len(convex_pieces(o.vertices)) for o in case.obstacles)


def test_the_stall_pose_of_a_tpcap_case_is_its_goal(slot_case):
    scene = CaseScene(read_case(slot_case))
    goal = rear_to_centre(scene.case.goal, scene.car)
    assert np.allclose(park_pose(scene.stall, scene.car, scene.maneuver), goal, atol=1e-9)
    assert in_stall(scene.stall, scene.car, goal, scene.maneuver).parked
    assert scene.case.origin == (SLOT_START[0], SLOT_START[1])  # subtracted: the scene lies near the origin
    assert max(abs(v) for v in scene.extent) < 100


# -- end to end, through the CLI -----------------------------------------------------------------------------------
def test_a_hand_made_tpcap_parallel_slot_is_parked_by_the_oracle(slot_case, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["cruise", "--cases", str(slot_case), "--driver", "oracle", "--out", str(out), "--quiet"]) == 0
    (row,) = _rows(out)
    assert row["garage"] == str(slot_case) and row["task"] == "park" and row["feasible"] == "1"
    assert row["vehicle"] == "tpcap"
    assert row["outcome"] == "success", row["reason"]
    assert float(row["position_error_m"]) < 0.3 and float(row["heading_error_deg"]) < 10
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cases"] == 1 and summary["success_pct"] == 100.0
    # a case is a park test: its park difficulty under the default park model (the oracle has none of its own)
    assert 0 < float(row["park_difficulty"]) < 1 and summary["park_model_name"] == "park_assist"
    assert float(row["bay_margin_m"]) != 0 and float(row["start_distance_m"]) > 0
    assert "1 cases (1 new)" in capsys.readouterr().out
    # resumed: nothing runs again
    assert main(["cruise", "--cases", str(slot_case), "--driver", "oracle", "--out", str(out), "--quiet"]) == 0
    assert "1 cases (0 new)" in capsys.readouterr().out
    assert len(_rows(out)) == 1


def test_a_blocked_goal_is_infeasible_by_proof_and_never_driven(tmp_path):
    path = tmp_path / "blocked.csv"
    path.write_text(_tpcap_text((0, 0, 0), (10, 0, 0), [_rect(11.5, 0, 3.0, 3.0)]))
    out = tmp_path / "run"
    assert main(["cruise", "--cases", str(path), "--driver", "oracle", "--out", str(out), "--quiet"]) == 0
    (row,) = _rows(out)
    assert row["outcome"] == "infeasible" and row["feasible"] == "0" and "stall pose" in row["reason"]


def test_an_exported_park_problem_runs_end_to_end(painted_tiny, tmp_path):
    write_park_problems([painted_tiny], tmp_path / "park", stalls={0}, maneuvers=("reverse",))
    problem = sorted((tmp_path / "park").rglob("stall*_reverse.json"))[0]
    case = read_case(problem)
    data = json.loads(problem.read_text())
    assert case.kind == "garage-mj" and case.maneuver == "reverse" and case.vehicle.name == "sedan"
    assert [o.cls for o in case.obstacles] == [o["class"] for o in data["obstacles"]]
    x0, y0 = data["start"][:2]
    assert case.obstacles[0].vertices == tuple((x - x0, y - y0) for x, y in data["obstacles"][0]["vertices"])
    out = tmp_path / "run"
    assert main(["cruise", "--cases", str(problem), "--driver", "oracle", "--out", str(out), "--quiet"]) == 0
    (row,) = _rows(out)
    assert row["garage"] == str(problem) and row["maneuver"] == "reverse" and row["vehicle"] == "sedan"
    assert row["outcome"] == "success", row["reason"]


def test_a_folder_of_an_export_stands_for_its_json_problems(painted_tiny, tmp_path):
    write_park_problems([painted_tiny], tmp_path / "park", stalls={0, 1})
    files = case_files([tmp_path / "park"])
    assert len(files) == 4 and all(f.suffix == ".json" and f.name != "park_problems.json" for f in files)
    csv_only = tmp_path / "csv"
    csv_only.mkdir()
    (csv_only / "a.csv").write_bytes(files[0].with_suffix(".csv").read_bytes())
    assert case_files([csv_only]) == [csv_only / "a.csv"]
    with pytest.raises(ParkProblemError, match="same case"):
        read_cases([csv_only / "a.csv", csv_only / "a.csv"])


@pytest.mark.skipif(not TPCAP_CASES, reason="GARAGE_MJ_TPCAP_CASES names no folder of TPCAP's Case1.csv ... "
                                            "Case20.csv (a clone of github.com/libai1943/TPCAP_benchmarks)")
def test_tpcap_s_published_cases_build_scenes_and_case_2_is_feasible():
    for k in range(1, 21):
        scene = CaseScene(read_case(Path(TPCAP_CASES) / f"Case{k}.csv"))
        model = compile_mjcf(build_case_scene(scene))
        assert model.ngeom >= len(scene.obstacles.boxes)
        assert max(abs(v) for v in scene.extent) < 200, k  # subtracted: near the origin, cases 13 to 15 too
    plan = CaseScene(read_case(Path(TPCAP_CASES) / "Case2.csv")).planner().plan_case()
    assert plan.verdict == "feasible", plan.reason


def test_a_mesh_obstacle_s_body_outline_holds_its_polygon_tightly():
    """The solid body outline that min_clearance_m is measured to (driving/sim/solid_bodies.py): a case's triangle,
    extruded to a mesh geom, within the box of its vertices, not a square of its bounding sphere."""
    from garage_mj.driving.sim.solid_bodies import solid_bodies
    from garage_mj.scene.semantics import geom_classes

    tri = ((4.0, -6.0), (12.0, -5.0), (6.0, -2.0))
    case = ParkCase("t", "t", "0" * 64, "tpcap", (0.0, 0.0), TPCAP_VEHICLE, (0.0, 0.0, 0.0), (-3.0, 0.0, 0.0),
                    (CaseObstacle("wall", tri),))
    model = compile_mjcf(build_case_scene(CaseScene(case)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = solid_bodies(model, data, np.zeros(model.ngeom, dtype=bool), geom_classes(model))
    (outline,) = [c for c, n in zip(bodies.corners, bodies.names, strict=True) if n.startswith("wall_0")]
    area = abs(signed_area(outline))
    assert abs(signed_area(tri)) <= area <= 2.0 * abs(signed_area(tri)) + 1e-6
    turn = np.sign(signed_area(outline))
    for q in np.asarray(tri):  # every corner of the triangle inside the (convex) outline
        for i in range(4):
            (ex, ey), (qx, qy) = outline[(i + 1) % 4] - outline[i], q - outline[i]
            assert (ex * qy - ey * qx) * turn >= -1e-6
