"""MJCF scene: compiles, steps 1 s with zero warnings, one parked car per stall, classes render."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from garage_mj.grid.map_io import load_map
from garage_mj.grid.metrics import evaluate
from garage_mj.scene.layout import build_layout, cover_cells, merge_intervals
from garage_mj.scene.mjcf_scene import (
    HIDDEN_DEPTH,
    build_scene,
    compile_scene,
    parked_car_bodies,
    parked_stalls,
    set_parked,
    write_scene,
)
from garage_mj.scene.semantics import Semantic, geom_classes, unclassified_geoms
from garage_mj.scene.stalls import stall_layout


def _step_one_second(model: mujoco.MjModel) -> mujoco.MjData:
    data = mujoco.MjData(model)
    steps = int(round(1.0 / model.opt.timestep))
    mujoco.mj_step(model, data, steps)
    assert data.time == pytest.approx(1.0)
    warnings = {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(data.warning) if w.number}
    assert not warnings, f"MuJoCo warnings: {warnings}"
    return data


def test_every_shipped_map_scene_compiles_steps_and_counts_stalls(painted_maps):
    for name, garage in painted_maps.items():
        model = compile_scene(garage)
        _step_one_second(model)
        assert unclassified_geoms(model) == [], name
        assert len(parked_car_bodies(model)) == evaluate(garage).stalls, name


def test_unpainted_map_and_ceiling_compile():
    garage = load_map("tiny_7x11")
    model = compile_scene(garage, ceiling=True)
    _step_one_second(model)
    assert parked_car_bodies(model) == {}
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "ceiling") >= 0


def test_obstructed_blocks_get_their_pillars(painted_maps):
    for garage in painted_maps.values():
        layout = build_layout(garage)
        names = {p.name for p in layout.pillars}
        want = len(stall_layout(garage).pillars)
        assert {f"pillar_{k}" for k in range(want)} <= names


def test_set_parked_moves_cars_on_the_compiled_model(painted_tiny):
    model = compile_scene(painted_tiny)
    data = mujoco.MjData(model)
    bodies = parked_car_bodies(model)
    assert parked_stalls(model) == sorted(bodies)
    set_parked(model, data, [0, 2])
    assert parked_stalls(model) == [0, 2]
    assert data.xpos[bodies[1], 2] == pytest.approx(-HIDDEN_DEPTH)
    assert data.xpos[bodies[0], 2] == pytest.approx(0.0)
    _step_one_second(model)
    with pytest.raises(ValueError, match="no stall with id"):
        set_parked(model, None, [10_000])


def test_parked_argument_sets_initial_occupancy(painted_tiny):
    model = compile_scene(painted_tiny, parked=[1])
    assert parked_stalls(model) == [1]


def test_overview_segmentation_shows_floor_walls_and_parked_cars(painted_tiny):
    model = compile_scene(painted_tiny)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    try:
        renderer = mujoco.Renderer(model, 64, 64)
    except Exception as exc:  # no GL on this machine
        pytest.skip(f"offscreen rendering unavailable: {exc}")
    renderer.enable_segmentation_rendering()
    renderer.update_scene(data, camera="overview")
    seg = renderer.render()
    renderer.close()
    ids, kinds = seg[..., 0], seg[..., 1]
    classes = geom_classes(model)
    labels = np.where((ids >= 0) & (kinds == mujoco.mjtObj.mjOBJ_GEOM), classes[np.clip(ids, 0, None)], 0)
    seen = set(np.unique(labels).tolist())
    assert {Semantic.FLOOR, Semantic.WALL, Semantic.PARKED_CAR} <= seen, seen


def test_write_scene_loads_from_disk(painted_tiny, tmp_path):
    path = write_scene(painted_tiny, tmp_path)
    model = mujoco.MjModel.from_xml_path(str(path))
    assert len(parked_car_bodies(model)) == evaluate(painted_tiny).stalls


def test_mjcf_root_is_a_dm_control_model(painted_tiny):
    root = build_scene(painted_tiny)
    assert root.find("camera", "overview") is not None
    assert root.find("body", "parkedcar_0") is not None


def test_cover_cells_rebuilds_the_mask():
    rng = np.random.default_rng(0)
    for _ in range(50):
        mask = rng.random((6, 8)) < 0.5
        rebuilt = np.zeros_like(mask)
        for r0, c0, n, w in cover_cells(mask):
            assert not rebuilt[r0 : r0 + n, c0 : c0 + w].any()
            rebuilt[r0 : r0 + n, c0 : c0 + w] = True
        assert (rebuilt == mask).all()


def test_merge_intervals_joins_touching_segments():
    segs = [("x", 1.0, 0.0, 2.0), ("x", 1.0, 2.0, 3.0), ("x", 1.0, 5.0, 6.0), ("y", 1.0, 0.0, 1.0)]
    assert merge_intervals(segs) == [("x", 1.0, 0.0, 3.0), ("x", 1.0, 5.0, 6.0), ("y", 1.0, 0.0, 1.0)]
