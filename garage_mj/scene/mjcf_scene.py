"""MJCF scene of a garage, built with ``dm_control.mjcf`` from the shared scene layout.

``build_scene(garage)`` returns an ``mjcf.RootElement``: floor slab, outer walls (gaps at the
gates), OBSTACLE blocks, pillars (``models/pillar``), lane and stall markings (visual only),
entrance/exit patches and sites, an optional ceiling, lights, a top-down orthographic camera
``overview`` and one parked car (``models/parked_car``) per stall, as a body ``parkedcar_<stall id>``.

Parked-car occupancy on a compiled model (no recompiling): every stall always has its car body;
an empty stall's car sits :data:`HIDDEN_DEPTH` below the floor, out of sight and out of reach.
:func:`set_parked` moves the cars of a compiled ``mujoco.MjModel`` up or down; ``build_scene(...,
parked=ids)`` sets the initial occupancy in the MJCF itself.

Geom groups: 0 solid geoms that draw and collide (floor, walls, obstacles, pillars, parked cars),
2 visual-only geoms (markings, gate patches), 4 the ceiling (hidden by default so the ``overview``
camera sees the floor; enable ``scene_option.geomgroup[4]`` to draw it).

Speed (issue 4: XODR + MJCF < 100 ms per 13x13 garage, ``eval/bench_export.py``): ``dm_control``
costs about 60 us per element, 1 ms per ``default`` class, and as much again per array attribute
written to XML, so the scene draws all painted lines of one class as one mesh geom (``stallmark``,
``roadmark``: a box per line, 8 corners and 12 triangles each), keeps few default classes, names
every element (unnamed ones are written slowly), sets attributes in one ``add`` call, and stamps
models as ``name`` + ``class`` geoms (:mod:`garage_mj.scene.templates`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf

from garage_mj.grid.garage import Garage
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.layout import CLASS_RGBA, Box, SceneLayout, build_layout
from garage_mj.scene.semantics import Semantic, geom_name
from garage_mj.scene.templates import PARKED_CAR, PILLAR, install, load_template, stamp
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

TIMESTEP = 0.005  # [s] physics step; the static scene needs little, the ego car's model may override
HIDDEN_DEPTH = 10.0  # [m] below the floor: where the car of an empty stall waits
CAMERA_HEIGHT = 40.0  # [m] above the floor, overview camera
CAMERA_MARGIN = 1.05  # overview camera frame = grid extent x this
MAX_ORTHO_FOVY = 179.0  # [m] MuJoCo rejects fovy >= 180, also as an orthographic view height
WIDE_FOVY = 45.0  # [deg] perspective overview of garages too large for the orthographic one
OFFSCREEN = (1280, 960)  # [px] largest offscreen render the scene allows
CEILING_GROUP = 4
VISUAL_GROUP = 2
SCENE_XML = "scene.xml"

#: Corners and outward triangles (counter-clockwise seen from outside) of the box [-1, 1]^3.
_UNIT_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
_UNIT_FACES = np.array([
    [0, 1, 3], [0, 3, 2],  # x = -1
    [4, 6, 7], [4, 7, 5],  # x = +1
    [0, 4, 5], [0, 5, 1],  # y = -1
    [2, 3, 7], [2, 7, 6],  # y = +1
    [0, 2, 6], [0, 6, 4],  # z = -1
    [1, 5, 7], [1, 7, 3],  # z = +1
])

_MATERIALS = {
    Semantic.FLOOR: "floor",
    Semantic.ROAD_MARKING: "roadmark",
    Semantic.STALL_MARKING: "stallmark",
    Semantic.WALL: "wall",
    Semantic.OBSTACLE: "obstacle",
    Semantic.ENTRANCE: "entrance",
    Semantic.EXIT: "exit",
}


def _boxes_mesh(boxes: list[Box]) -> tuple[np.ndarray, np.ndarray]:
    """Flat ``(vertex, face)`` arrays of one mesh of axis-aligned ``boxes`` (8 corners, 12 triangles each)."""
    centers = np.array([b.center for b in boxes])
    halves = np.array([b.half for b in boxes])
    vertex = centers[:, None, :] + halves[:, None, :] * _UNIT_CORNERS[None]
    face = _UNIT_FACES[None] + 8 * np.arange(len(boxes))[:, None, None]
    return vertex.ravel(), face.ravel()


def _setup(root: mjcf.RootElement, layout: SceneLayout) -> None:
    root.compiler.angle = "radian"
    root.option.timestep = TIMESTEP
    root.option.integrator = "implicitfast"
    vis = root.visual
    glob = getattr(vis, "global")  # "global" is a Python keyword
    glob.offwidth, glob.offheight = OFFSCREEN
    vis.headlight.ambient = [0.35, 0.35, 0.35]
    vis.headlight.diffuse = [0.45, 0.45, 0.45]
    vis.headlight.specular = [0.05, 0.05, 0.05]
    vis.quality.shadowsize = 0  # no shadow maps: fast small offscreen renders
    vis.map.znear = 0.002  # relative to the extent: about 0.1 m, fine for a camera in a car
    structure = root.default.add("default", dclass="structure")
    structure.geom.set_attributes(type="box", contype=1, conaffinity=1, group=0, friction=[0.9, 0.005, 0.0001])
    marking = root.default.add("default", dclass="marking")
    marking.geom.set_attributes(type="box", contype=0, conaffinity=0, group=VISUAL_GROUP, mass=0)
    for cls, name in _MATERIALS.items():
        root.asset.add("material", name=name, rgba=list(CLASS_RGBA[cls]), specular=0.1)
    sx, sy = layout.size
    light_z = layout.world.ceiling_height * 0.9
    root.worldbody.add("light", name="sun", type="directional", pos=[sx / 2, sy / 2, 30], dir=[0.2, 0.3, -1],
                       diffuse=[0.5, 0.5, 0.5], castshadow=False)
    root.worldbody.add("light", name="fill", pos=[sx / 2, sy / 2, light_z], dir=[0, 0, -1],
                       diffuse=[0.25, 0.25, 0.25], castshadow=False, attenuation=[1, 0, 0], cutoff=80)
    extent = max(sx, sy) * CAMERA_MARGIN  # [m] the view's height
    if extent < MAX_ORTHO_FOVY:
        root.worldbody.add("camera", name="overview", pos=[sx / 2, sy / 2, CAMERA_HEIGHT], projection="orthographic",
                           fovy=extent)
    else:  # MuJoCo caps fovy below 180 even for orthographic cameras: look down from high enough instead
        height = extent / 2 / math.tan(math.radians(WIDE_FOVY) / 2)
        root.worldbody.add("camera", name="overview", pos=[sx / 2, sy / 2, height], fovy=WIDE_FOVY)


def build_scene(
    garage: Garage | GarageScene,
    *,
    world: WorldConfig = DEFAULT_WORLD,
    parked: Iterable[int] | None = None,
    ceiling: bool = False,
    layout: SceneLayout | None = None,
) -> mjcf.RootElement:
    """The MJCF scene of ``garage``.

    Args:
        garage: a :class:`Garage`, or a :class:`GarageScene` (its world and its layout, built once, apply).
        world: 3D conventions (SPEC section 6).
        parked: stall ids with a parked car in place; ``None`` fills every stall. Cars of the
            other stalls wait below the floor (see :func:`set_parked`).
        ceiling: add the ceiling slab (geom group 4, hidden by default in renders).
        layout: the garage's :class:`SceneLayout` when already built (``ceiling`` is then its own).
    """
    if isinstance(garage, GarageScene):  # its layout, derived once (the ceiling needs its own)
        if layout is None and not ceiling:
            layout = garage.layout
        garage, world = garage.garage, garage.world
    layout = layout or build_layout(garage, world, ceiling=ceiling)
    root = mjcf.RootElement(model=f"garage_{garage.name}" if garage.name else "garage")
    _setup(root, layout)
    wb = root.worldbody
    painted: dict[Semantic, list[Box]] = {}
    for box in layout.boxes:
        if not box.collides:
            painted.setdefault(box.cls, []).append(box)
            continue
        # one add() with every attribute: each later assignment costs dm_control a validation pass
        extra = {"group": CEILING_GROUP} if box.name == "ceiling" else {}
        wb.add("geom", name=box.name, dclass="structure", material=_MATERIALS[box.cls], pos=box.center,
               size=box.half, **extra)
    for cls, boxes in painted.items():
        if len(boxes) == 1:
            (box,) = boxes
            wb.add("geom", name=box.name, dclass="marking", material=_MATERIALS[cls], pos=box.center,
                   size=box.half)
        else:  # a hundred stall lines as one mesh geom: one element instead of one per line
            name = geom_name(cls)
            vertex, face = _boxes_mesh(boxes)
            root.asset.add("mesh", name=name, vertex=vertex, face=face)
            wb.add("geom", name=name, dclass="marking", type="mesh", mesh=name, material=_MATERIALS[cls])
    for cls, pos in ((Semantic.ENTRANCE, garage.entrance), (Semantic.EXIT, garage.exit)):
        x, y = layout_cell(layout, pos)
        wb.add("site", name=cls.name.lower(), pos=[x, y, 0.05], size=[0.2], group=VISUAL_GROUP,
               rgba=list(CLASS_RGBA[cls]))

    pillar = load_template(PILLAR)
    install(root, pillar, z_scale=world.ceiling_height / 3.0)  # the pillar model is 3.0 m high
    for p in layout.pillars:
        stamp(wb, pillar, p.name, (p.x, p.y, 0.0), p.yaw)

    car = load_template(PARKED_CAR)
    install(root, car)
    occupied = None if parked is None else set(parked)
    for p in layout.parked_cars:
        z = 0.0 if occupied is None or p.stall_id in occupied else -HIDDEN_DEPTH
        stamp(wb, car, p.name, (p.x, p.y, z), p.yaw)
    return root


def layout_cell(layout: SceneLayout, pos: tuple[int, int]) -> tuple[float, float]:
    b = layout.world.block
    r, c = pos
    return b * c + b / 2, b * (layout.rows - 1 - r) + b / 2


def scene_xml(garage: Garage, **kwargs) -> tuple[str, dict[str, bytes]]:
    """``(xml_string, assets)`` of :func:`build_scene`, ready for ``MjModel.from_xml_string``."""
    root = build_scene(garage, **kwargs)
    return root.to_xml_string(), root.get_assets()


def compile_scene(garage: Garage, **kwargs) -> mujoco.MjModel:
    """Build and compile the scene of ``garage``."""
    xml, assets = scene_xml(garage, **kwargs)
    return mujoco.MjModel.from_xml_string(xml, assets)


def write_scene(garage: Garage | GarageScene, out_dir: str | Path, **kwargs) -> Path:
    """Write ``scene.xml`` (and any assets it needs) into ``out_dir``; returns the XML path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    mjcf.export_with_assets(build_scene(garage, **kwargs), str(out), out_file_name=SCENE_XML)
    return out / SCENE_XML


def parked_car_bodies(model: mujoco.MjModel) -> dict[int, int]:
    """Stall id -> body id of its parked car, in a compiled scene."""
    out = {}
    prefix = "parkedcar_"
    for b in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if name.startswith(prefix) and name[len(prefix):].isdigit():
            out[int(name[len(prefix):])] = b
    return out


def set_parked(model: mujoco.MjModel, data: mujoco.MjData | None, occupied: Iterable[int]) -> None:
    """Put a parked car in exactly the stalls ``occupied`` of a compiled scene, without recompiling.

    Cars of the other stalls move :data:`HIDDEN_DEPTH` below the floor. With ``data`` the
    kinematics are refreshed (``mj_forward``) so renders and contacts see the change at once.
    """
    bodies = parked_car_bodies(model)
    want = set(occupied)
    unknown = want - bodies.keys()
    if unknown:
        raise ValueError(f"no stall with id {sorted(unknown)}; the scene has stalls 0..{len(bodies) - 1}")
    for sid, b in bodies.items():
        model.body_pos[b, 2] = 0.0 if sid in want else -HIDDEN_DEPTH
    if data is not None:
        mujoco.mj_forward(model, data)


def parked_stalls(model: mujoco.MjModel) -> list[int]:
    """Stall ids whose car is in place (not hidden below the floor)."""
    return sorted(sid for sid, b in parked_car_bodies(model).items() if model.body_pos[b, 2] > -HIDDEN_DEPTH / 2)
