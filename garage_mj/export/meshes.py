"""Meshes of a garage (``garage.glb``, ``garage.obj`` + ``.mtl``) with trimesh, for other engines.

Same geometry as the MJCF scene (both draw :func:`garage_mj.scene.layout.build_layout`): floor,
walls, obstacles, pillars, markings, gate patches and the parked cars' visual boxes. One mesh per
semantic class, each with its own material named after the class (``floor``, ``wall``,
``parkedcar``, ...) and coloured by :data:`~garage_mj.scene.layout.CLASS_RGBA`, so Blender, Unity,
Unreal or CARLA users can re-material a class at once.

Axes: the files follow glTF, Y up: file (x, y, z) = world (x east, z up, -y north), metres. The
glTF importers of Blender and Unity and the OBJ importers with "Y up" convert this for you.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import trimesh
from trimesh.visual.material import PBRMaterial

from garage_mj.grid.garage import Garage
from garage_mj.scene.garage_scene import GarageScene, as_scene
from garage_mj.scene.layout import CLASS_RGBA, SceneLayout, build_layout
from garage_mj.scene.semantics import PREFIXES, Semantic
from garage_mj.scene.templates import PARKED_CAR, PILLAR, Template, load_template
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

#: World (z up) -> file (glTF, y up).
Z_UP_TO_Y_UP = trimesh.transformations.rotation_matrix(-math.pi / 2, [1, 0, 0])
#: Material and node name per class: the semantic prefix (``parkedcar``, ``roadmark``, ...).
CLASS_NAMES = {cls: next(p for p, c in PREFIXES.items() if c == cls) for cls in CLASS_RGBA}
_COLLISION_ONLY_GROUP = 3


_UNIT = trimesh.creation.box(extents=(2.0, 2.0, 2.0))  # half sizes 1: scaled per box


def _box(center, half, yaw: float = 0.0) -> np.ndarray:
    """Vertices (8, 3) of a box: the unit box's corners scaled, rotated about z and moved."""
    v = _UNIT.vertices * np.asarray(half, dtype=float)
    if yaw:
        ca, sa = math.cos(yaw), math.sin(yaw)
        v = v @ np.array([[ca, sa, 0.0], [-sa, ca, 0.0], [0.0, 0.0, 1.0]])
    return v + np.asarray(center, dtype=float)


def _boxes_mesh(boxes: list[np.ndarray]) -> trimesh.Trimesh:
    """One mesh of many boxes (vectorised: no per-box Trimesh objects)."""
    n, nv = len(boxes), len(_UNIT.vertices)
    vertices = np.concatenate(boxes)
    faces = (_UNIT.faces[None, :, :] + nv * np.arange(n)[:, None, None]).reshape(-1, 3)
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


def _template_boxes(template: Template, x: float, y: float, yaw: float, z_scale: float = 1.0):
    """World boxes of a stamped model's drawn geoms (collision-only geoms left out)."""
    ca, sa = math.cos(yaw), math.sin(yaw)
    drawn_classes = {d for d, _, attrs in template.defaults if attrs.get("group") != _COLLISION_ONLY_GROUP}
    drawn_classes |= {None}
    for g in template.geoms:
        if g.get("dclass") not in drawn_classes:
            continue
        px, py, pz = (list(g.get("pos", (0.0, 0.0, 0.0))) + [0.0] * 3)[:3]
        hx, hy, hz = g["size"]
        center = (x + px * ca - py * sa, y + px * sa + py * ca, pz * z_scale)
        yield _box(center, (hx, hy, hz * z_scale), yaw)


def _material(cls: Semantic) -> PBRMaterial:
    rgba = [int(round(255 * c)) for c in CLASS_RGBA[cls]]
    return PBRMaterial(name=CLASS_NAMES[cls], baseColorFactor=rgba, metallicFactor=0.0, roughnessFactor=0.8)


def layout_meshes(layout: SceneLayout, parked: Iterable[int] | None = None) -> trimesh.Scene:
    """A trimesh scene of ``layout``: one mesh and one material per class."""
    parts: dict[Semantic, list[np.ndarray]] = {}
    for box in layout.boxes:
        parts.setdefault(box.cls, []).append(_box(box.center, box.half, box.yaw))
    pillar = load_template(PILLAR)
    z_scale = layout.world.ceiling_height / 3.0
    for p in layout.pillars:
        parts.setdefault(Semantic.PILLAR, []).extend(_template_boxes(pillar, p.x, p.y, p.yaw, z_scale))
    car = load_template(PARKED_CAR)
    occupied = None if parked is None else set(parked)
    for p in layout.parked_cars:
        if occupied is None or p.stall_id in occupied:
            parts.setdefault(Semantic.PARKED_CAR, []).extend(_template_boxes(car, p.x, p.y, p.yaw))
    scene = trimesh.Scene()
    for cls in sorted(parts):
        mesh = _boxes_mesh(parts[cls])
        mesh.visual = trimesh.visual.TextureVisuals(material=_material(cls))
        name = CLASS_NAMES[cls]
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    scene.apply_transform(Z_UP_TO_Y_UP)
    return scene


def garage_meshes(
    garage: Garage | GarageScene, *, world: WorldConfig = DEFAULT_WORLD, parked: Iterable[int] | None = None,
    ceiling: bool = False,
) -> trimesh.Scene:
    """The garage as a trimesh scene (see the module docstring); ``parked=None`` fills every stall."""
    scene = as_scene(garage, world)
    layout = build_layout(scene.garage, scene.world, ceiling=True, network=scene.network,
                          stalls=scene.stalls) if ceiling else scene.layout
    return layout_meshes(layout, parked)


def write_glb(scene: trimesh.Scene, path: str | Path) -> Path:
    """Write ``scene`` as binary glTF."""
    path = Path(path)
    path.write_bytes(scene.export(file_type="glb"))
    return path


def write_obj(scene: trimesh.Scene, path: str | Path) -> Path:
    """Write ``scene`` as OBJ plus its material library (``<stem>.mtl`` beside it)."""
    path = Path(path)
    mtl = f"{path.stem}.mtl"
    text, files = trimesh.exchange.obj.export_obj(
        scene, include_texture=True, return_texture=True, mtl_name=mtl, include_normals=True
    )
    path.write_text(text)
    for name, data in files.items():
        (path.parent / name).write_bytes(data)
    return path
