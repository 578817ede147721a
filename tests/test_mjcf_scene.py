"""MJCF scene: compiles, steps 1 s with zero warnings, one parked car per stall, classes render; empty
stalls' cars cannot be hit or seen, markings cannot be hit, the fused scene keeps every geom."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from garage_mj.grid.map_io import load_map
from garage_mj.grid.metrics import evaluate
from garage_mj.scene.layout import MARKING_HEIGHT, build_layout, cover_cells, merge_intervals
from garage_mj.scene.mjcf_scene import (
    ParkedCars,
    build_scene,
    compile_scene,
    parked_car_bodies,
    parked_car_geoms,
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


def _probe_lands_at(garage, stall: int, occupied: list[int], fuse_static: bool) -> float:
    """Height [m] of a 0.2 m box dropped from 2.5 m onto stall ``stall``, 1 s later."""
    root = build_scene(garage, fuse_static=fuse_static)
    (place,) = [p for p in build_layout(garage).parked_cars if p.stall_id == stall]
    probe = root.worldbody.add("body", name="probe", pos=[place.x, place.y, 2.5])
    probe.add("freejoint", name="probe")
    probe.add("geom", name="probe", type="box", size=[0.1, 0.1, 0.1], mass=1.0)
    model = mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())
    set_parked(model, None, occupied)
    data = _step_one_second(model)
    return float(data.xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "probe"), 2])


@pytest.mark.parametrize("fuse_static", [False, True])
def test_set_parked_hides_and_shows_cars_on_the_compiled_model(painted_tiny, fuse_static):
    model = compile_scene(painted_tiny, fuse_static=fuse_static)
    cars = parked_car_geoms(model)
    assert parked_stalls(model) == sorted(cars) and len(cars) == evaluate(painted_tiny).stalls
    set_parked(model, mujoco.MjData(model), [0, 2])
    assert parked_stalls(model) == [0, 2]
    set_parked(model, None, [1])
    assert parked_stalls(model) == [1]
    with pytest.raises(ValueError, match="no stall with id"):
        set_parked(model, None, [10_000])
    # what a user relies on: a parked car is solid, the car of an empty stall is not there
    assert _probe_lands_at(painted_tiny, 1, [1], fuse_static) > 1.4  # on the car's roof (1.49 m)
    assert _probe_lands_at(painted_tiny, 1, [0, 2], fuse_static) == pytest.approx(0.1, abs=0.01)  # on the floor


@pytest.mark.parametrize("fuse_static", [False, True])
def test_parked_cars_kept_for_a_scene_set_what_set_parked_sets(painted_tiny, fuse_static):
    """A drive env keeps one ParkedCars per scene and applies it at every reset: whatever stalls it had before,
    the model ends up as set_parked on a freshly compiled scene leaves it."""
    model = compile_scene(painted_tiny, fuse_static=fuse_static)
    cars = ParkedCars(model)
    rng = np.random.default_rng(0)
    for _ in range(6):
        occupied = [s for s in cars.geoms if rng.random() < 0.5]
        cars.apply(model, None, occupied)
        fresh = compile_scene(painted_tiny, fuse_static=fuse_static)
        set_parked(fresh, None, occupied)
        for field in ("geom_contype", "geom_conaffinity", "geom_rgba", "body_pos"):
            assert np.array_equal(getattr(model, field), getattr(fresh, field)), field
        assert parked_stalls(model) == sorted(occupied)


def test_fused_scene_keeps_every_geom_as_a_world_geom(painted_maps):
    garage = painted_maps["m5_13x13_aligned"]
    plain, fused = compile_scene(garage), compile_scene(garage, fuse_static=True)

    def names(model):
        return sorted(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(model.ngeom))

    assert names(fused) == names(plain)
    assert fused.nbody == 1 and plain.nbody > 100  # parked cars and pillars were bodies
    assert np.array_equal(np.bincount(geom_classes(fused)), np.bincount(geom_classes(plain)))
    assert parked_car_geoms(fused).keys() == parked_car_bodies(plain).keys() and parked_car_bodies(fused) == {}
    _step_one_second(fused)


def test_markings_are_flat_and_cannot_be_hit(painted_tiny):
    model = compile_scene(painted_tiny, fuse_static=True)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    classes = geom_classes(model)
    painted = np.isin(classes, [Semantic.ROAD_MARKING, Semantic.STALL_MARKING, Semantic.ENTRANCE, Semantic.EXIT])
    assert painted.sum() >= 4
    assert not model.geom_contype[painted].any() and not model.geom_conaffinity[painted].any()
    for g in np.flatnonzero(painted & (model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)):
        m = model.geom_dataid[g]
        vert = model.mesh_vert[model.mesh_vertadr[m] : model.mesh_vertadr[m] + model.mesh_vertnum[m]]
        world = data.geom_xpos[g] + vert @ data.geom_xmat[g].reshape(3, 3).T
        np.testing.assert_allclose(world[:, 2], MARKING_HEIGHT, atol=1e-9)  # the top faces only
        assert model.mesh_facenum[m] == model.mesh_vertnum[m] // 2  # 2 triangles per 4 corners


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
    ids, kinds = seg[..., 0], seg[..., 1]
    classes = geom_classes(model)
    labels = np.where((ids >= 0) & (kinds == mujoco.mjtObj.mjOBJ_GEOM), classes[np.clip(ids, 0, None)], 0)
    seen = set(np.unique(labels).tolist())
    assert {Semantic.FLOOR, Semantic.WALL, Semantic.PARKED_CAR} <= seen, seen
    set_parked(model, data, [])  # empty stalls: their cars are not drawn
    renderer.update_scene(data, camera="overview")
    seg = renderer.render()
    renderer.close()
    drawn = seg[..., 0][(seg[..., 0] >= 0) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)]
    assert Semantic.PARKED_CAR not in set(classes[drawn].tolist())


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
