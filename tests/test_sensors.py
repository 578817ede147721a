"""Camera sensor: depth and segmentation are not degenerate, classes and sides are right, errors are clear."""

from __future__ import annotations

import time

import mujoco
import numpy as np
import pytest

from garage_mj.driving.sim.sensors import Camera, CameraConfig, RenderError
from garage_mj.scene.semantics import Semantic, classify_name, geom_classes, unclassified_geoms
from tests._scenes import build

PILLAR_AHEAD = [("pillar_0", (8.0, 0.0, 1.5), (0.3, 0.3, 1.5))]


def test_pillar_ahead_is_near_and_classified():
    model, data, _ = build(PILLAR_AHEAD)
    with Camera(model, CameraConfig(rgb=True)) as cam:
        img = cam.render(data)
    depth, seg = img["depth"], img["segmentation"]
    assert img["rgb"].shape == (64, 64, 3) and depth.dtype == np.float32 and seg.dtype == np.uint8
    pillar = seg == Semantic.PILLAR
    assert pillar.sum() > 20
    cols = np.flatnonzero(pillar.any(axis=0))
    assert abs(cols.mean() - 31.5) < 3  # straight ahead
    # the pillar face is 5.45 m ahead of the camera; depth is along the (10 deg down) optical axis
    assert 4.8 < depth[pillar].min() < 5.6
    assert (seg[-8:] == Semantic.FLOOR).all()  # bottom rows: the floor, not the own bonnet
    assert depth[-1].max() < 3.0 and depth[pillar].max() < depth[seg == Semantic.BACKGROUND].min()
    assert not (seg == Semantic.EGO_CAR).any()


def test_left_is_left_and_far_is_clipped():
    model, data, _ = build([("wall_l", (6.0, 2.5, 1.5), (1.0, 0.1, 1.5))])
    with Camera(model, CameraConfig(far=20.0)) as cam:
        seg = cam.segmentation(data)
        depth = cam.depth(data)
    wall_cols = np.flatnonzero((seg == Semantic.WALL).any(axis=0))
    assert wall_cols.size and wall_cols.max() < 32  # a wall on the car's left shows in the left half
    assert depth.max() <= 20.0


def test_every_geom_of_the_test_scene_is_classified():
    model, _, car = build(PILLAR_AHEAD)
    assert unclassified_geoms(model) == []
    classes = geom_classes(model)
    assert {Semantic(classes[g]) for g in car.geoms} == {Semantic.EGO_CAR}
    assert classify_name("parkedcar_17/chassis") is Semantic.PARKED_CAR
    assert classify_name("stallmark_3_1") is Semantic.STALL_MARKING
    assert classify_name("unnamed") is None


def test_config_and_camera_errors():
    with pytest.raises(ValueError, match="near < far"):
        CameraConfig(near=2.0, far=1.0)
    with pytest.raises(ValueError, match="positive"):
        CameraConfig(width=0)
    model, _, _ = build()
    with pytest.raises(ValueError, match="no camera 'nope'"):
        Camera(model, CameraConfig(camera="nope"))


def test_missing_gl_names_the_fix(monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("eglInitialize failed")

    monkeypatch.setattr(mujoco, "MjrContext", broken)
    model, _, _ = build()
    with pytest.raises(RenderError, match=r"apt-get install libegl1 libgl1-mesa-dri.*MUJOCO_GL=osmesa") as err:
        Camera(model)
    assert "\n" not in str(err.value)
    assert "eglInitialize failed" in str(err.value)


def test_depth_and_segmentation_are_fast_enough():
    model, data, _ = build(PILLAR_AHEAD)
    with Camera(model) as cam:
        cam.render(data)
        n = 100
        t0 = time.perf_counter()
        for _ in range(n):
            cam.render(data)
        fps = n / (time.perf_counter() - t0)
    assert fps > 50, f"{fps:.0f} depth+segmentation frames/s"


def _reference(model, data, camera="ego/front", size=64):
    """Depth [m] and segmentation classes from two ``mujoco.Renderer`` passes (the slow, plain way)."""
    classes = np.append(geom_classes(model), 0)
    renderer = mujoco.Renderer(model, size, size)
    try:
        renderer.update_scene(data, camera=camera)
        renderer.enable_depth_rendering()
        depth = renderer.render()
        renderer.disable_depth_rendering()
        renderer.enable_segmentation_rendering()
        raw = renderer.render()
    finally:
        renderer.close()
    geom = raw[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
    return depth, classes[np.where(geom, raw[..., 0], model.ngeom)]


@pytest.mark.parametrize("cull", [True, False])
def test_one_pass_matches_mujoco_renderer(cull):
    boxes = PILLAR_AHEAD + [("wall_l", (6.0, 2.5, 1.5), (1.0, 0.1, 1.5)), ("obstacle_far", (30.0, -3.0, 0.5), (1, 1, 0.5)),
                            ("wall_behind", (-8.0, 0.0, 1.5), (0.1, 5.0, 1.5)), ("roadmark_0", (4.0, 0.0, 0.005), (1.5, 0.1, 0.005))]
    model, data, _ = build(boxes, pose=(0.0, 0.0, 0.1))
    with Camera(model, cull=cull) as cam:
        img = cam.render(data)
    ref_depth, ref_seg = _reference(model, data)
    far = cam.config.far
    np.testing.assert_allclose(img["depth"], np.minimum(ref_depth, far), rtol=1e-4, atol=1e-3)  # [m]: one quad per box face, not 4x4
    np.testing.assert_array_equal(img["segmentation"], ref_seg)
    assert {Semantic.PILLAR, Semantic.WALL, Semantic.OBSTACLE, Semantic.ROAD_MARKING} <= set(np.unique(ref_seg))


def test_software_gl_draws_in_the_calling_thread_unless_told_otherwise():
    import os
    import subprocess
    import sys

    code = "import os, garage_mj.driving.sim.sensors; print(os.environ['LP_NUM_THREADS'])"
    env = {k: v for k, v in os.environ.items() if k != "LP_NUM_THREADS"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "0"
    out = subprocess.run([sys.executable, "-c", code], env={**env, "LP_NUM_THREADS": "4"}, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "4"  # the user's own setting stays
