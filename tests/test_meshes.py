"""GLB/OBJ meshes and the preview: same geometry as the scene, one material per class."""

from __future__ import annotations

import numpy as np
import trimesh

from garage_mj.export.meshes import CLASS_NAMES, garage_meshes, write_glb, write_obj
from garage_mj.export.preview import render_preview, write_preview
from garage_mj.scene.layout import build_layout
from garage_mj.scene.semantics import Semantic

EXPECTED = {"floor", "wall", "obstacle", "parkedcar", "stallmark", "roadmark", "entrance", "exit", "pillar"}


def _materials(scene: trimesh.Scene) -> dict[str, str]:
    return {name: g.visual.material.name for name, g in scene.geometry.items()}


def test_glb_round_trip_has_per_class_materials_and_the_grid_extent(painted_tiny, tmp_path):
    scene = garage_meshes(painted_tiny)
    path = write_glb(scene, tmp_path / "garage.glb")
    back = trimesh.load(path)
    mats = _materials(back)
    assert EXPECTED <= set(mats.values()), mats
    colours = {g.visual.material.name: tuple(g.visual.material.baseColorFactor) for g in back.geometry.values()}
    assert colours["floor"] != colours["parkedcar"]
    sx, sy = build_layout(painted_tiny).size
    lo, hi = back.bounds
    # Y up: file x = east, file z = -north; walls stand just outside the grid
    assert hi[0] - lo[0] > sx and hi[2] - lo[2] > sy
    assert np.isclose(hi[1], 3.0, atol=0.01)  # ceiling height (walls), metres


def test_obj_with_mtl_round_trip(painted_tiny, tmp_path):
    path = write_obj(garage_meshes(painted_tiny), tmp_path / "garage.obj")
    mtl = (tmp_path / "garage.mtl").read_text()
    for name in EXPECTED:
        assert f"newmtl {name}" in mtl
    back = trimesh.load(path, group_material=True)
    assert EXPECTED <= {g.visual.material.name for g in back.geometry.values()}


def test_parked_subset_and_every_class_named_after_its_prefix(painted_tiny):
    full = garage_meshes(painted_tiny)
    one = garage_meshes(painted_tiny, parked=[0])
    assert len(one.geometry["parkedcar"].faces) < len(full.geometry["parkedcar"].faces)
    assert CLASS_NAMES[Semantic.PARKED_CAR] == "parkedcar"


def test_preview_png(painted_tiny, tmp_path):
    img = render_preview(painted_tiny)
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= 6  # blocks, roads, stalls, cars, pillars...
    path = write_preview(painted_tiny, tmp_path / "preview.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_preview_has_a_legend_naming_the_entrance_and_the_exit(painted_tiny):
    from garage_mj.export.preview import _bgr, legend_entries
    from garage_mj.scene.semantics import Semantic

    bare, img = render_preview(painted_tiny, legend=False), render_preview(painted_tiny)
    assert img.shape[1] == bare.shape[1] and img.shape[0] > bare.shape[0]
    assert np.array_equal(img[: bare.shape[0]], bare)  # the garage keeps its pixels; the legend is a strip under it
    labels = [label for label, _ in legend_entries()]
    assert labels[:2] == ["entrance", "exit"]
    strip = {tuple(c) for c in img[bare.shape[0]:].reshape(-1, 3)}
    for cls in (Semantic.ENTRANCE, Semantic.EXIT):  # each colour's square is in the strip (RGB)
        assert tuple(reversed(_bgr(cls))) in strip
    narrow = render_preview(painted_tiny, pixels_per_metre=2.0)  # a small picture wraps the legend into more rows
    assert narrow.shape[0] - render_preview(painted_tiny, pixels_per_metre=2.0, legend=False).shape[0] > \
        img.shape[0] - bare.shape[0]
