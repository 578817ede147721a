"""MJCF scene of a garage, built with ``dm_control.mjcf`` from the shared scene layout.

``build_scene(garage)`` returns an ``mjcf.RootElement``: floor slab, outer walls (gaps at the
gates), OBSTACLE blocks, pillars (``models/pillar``), lane and stall markings (visual only),
entrance/exit patches and sites, an optional ceiling, lights, a top-down orthographic camera
``overview`` and one parked car (``models/parked_car``) per stall, as a body ``parkedcar_<stall id>``.

Parked-car occupancy on a compiled model (no recompiling): every stall always has its car in
place; the car of an empty stall neither collides nor renders (its geoms get ``contype =
conaffinity = 0`` and alpha 0, which MuJoCo's scene update skips). :func:`set_parked` toggles that
on a compiled ``mujoco.MjModel``; it moves nothing. :meth:`ParkedCars.place` moves, turns and resizes
parked cars (a test's mixed fleet and jitter, :mod:`garage_mj.scene.parked_fleet`): MuJoCo keeps precomputed
bounding volumes of static geoms, and a static geom moved after compiling would be missed by collisions, so
it rewrites them too (the geoms' bounding spheres and boxes and their body's bounding-volume tree).
``build_scene(..., parked=ids)`` sets the initial occupancy in the MJCF itself, with the cars of
the other stalls :data:`HIDDEN_DEPTH` below the floor (what a reader of ``scene.xml`` expects).

``fuse_static=True`` (the drive env) compiles with MuJoCo's ``fusestatic``: the parked cars and
pillars, bodies without joints, become geoms of the world body, with the same geom names. Static
geoms of one body are never tested against each other, and the car meets the whole static scene
as one body with one bounding-volume tree: on a 13x13 garage 9 bodies instead of 121 and a
physics step about 0.6 of the time, with the same contacts. The compiled model then
has no ``parkedcar_*`` bodies; :func:`parked_car_geoms` and :func:`set_parked` work either way.

Geom groups: 0 solid geoms that draw and collide (floor, walls, obstacles, pillars, parked cars),
2 visual-only geoms (markings, gate patches; ``contype = conaffinity = 0``: outside the collision
pipeline), 4 the ceiling (hidden by default so the ``overview`` camera sees the floor; enable
``scene_option.geomgroup[4]`` to draw it).

Speed (target: XODR + MJCF < 100 ms per 13x13 garage, ``eval/bench_export.py``): ``dm_control``
costs about 60 us per element, 1 ms per ``default`` class, and as much again per array attribute
written to XML, so the scene draws all painted lines of one class as one mesh geom (``stallmark``,
``roadmark``: the top face of each line, 4 corners and 2 triangles; the 2 mm sides never cover a
pixel of the 64x64 camera, and 12 triangles a line cost a fifth of a frame under software GL),
keeps few default classes, names every element (unnamed ones are written slowly), sets attributes
in one ``add`` call, and stamps models as ``name`` + ``class`` geoms (:mod:`garage_mj.scene.templates`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf

from garage_mj.grid.garage import Garage
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.layout import CLASS_RGBA, Box, SceneLayout, build_layout
from garage_mj.scene.parked_fleet import ParkedBody, part_boxes
from garage_mj.scene.semantics import Semantic, geom_name
from garage_mj.scene.templates import (
    PARKED_CAR,
    PILLAR,
    install,
    load_template,
    resolved_geom_attributes,
    stamp,
)
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

#: Top corners (counter-clockwise seen from above) of the box [-1, 1]^3, and its top face as two triangles.
_TOP_CORNERS = np.array([[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
_TOP_FACES = np.array([[0, 1, 2], [0, 2, 3]])

_MATERIALS = {
    Semantic.FLOOR: "floor",
    Semantic.ROAD_MARKING: "roadmark",
    Semantic.STALL_MARKING: "stallmark",
    Semantic.WALL: "wall",
    Semantic.OBSTACLE: "obstacle",
    Semantic.ENTRANCE: "entrance",
    Semantic.EXIT: "exit",
}


def _tops_mesh(boxes: list[Box]) -> tuple[np.ndarray, np.ndarray]:
    """Flat ``(vertex, face)`` arrays of one mesh of the top faces of ``boxes`` (2 triangles each), each turned by
    its yaw (the painted lines of angled stalls)."""
    centers = np.array([b.center for b in boxes])
    halves = np.array([b.half for b in boxes])
    corners = halves[:, None, :] * _TOP_CORNERS[None]
    yaws = np.array([b.yaw for b in boxes])
    if yaws.any():
        c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
        x, y = corners[..., 0].copy(), corners[..., 1].copy()
        corners[..., 0], corners[..., 1] = c * x - s * y, s * x + c * y
    vertex = centers[:, None, :] + corners
    face = _TOP_FACES[None] + 4 * np.arange(len(boxes))[:, None, None]
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
    fuse_static: bool = False,
) -> mjcf.RootElement:
    """The MJCF scene of ``garage``.

    Args:
        garage: a :class:`Garage`, or a :class:`GarageScene` (its world and its layout, built once, apply).
        world: 3D conventions (docs/spec.md section 6).
        parked: stall ids with a parked car in place; ``None`` fills every stall. Cars of the
            other stalls wait below the floor (see :func:`set_parked`).
        ceiling: add the ceiling slab (geom group 4, hidden by default in renders).
        layout: the garage's :class:`SceneLayout` when already built (``ceiling`` is then its own).
        fuse_static: compile the parked cars and pillars into the world body (see the module docstring).
    """
    if isinstance(garage, GarageScene):  # its layout, derived once (the ceiling needs its own)
        if layout is None and not ceiling:
            layout = garage.layout
        garage, world = garage.garage, garage.world
    layout = layout or build_layout(garage, world, ceiling=ceiling)
    root = mjcf.RootElement(model=f"garage_{garage.name}" if garage.name else "garage")
    _setup(root, layout)
    if fuse_static:
        root.compiler.fusestatic = True
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
            turn = {"euler": (0.0, 0.0, box.yaw)} if box.yaw else {}
            wb.add("geom", name=box.name, dclass="marking", material=_MATERIALS[cls], pos=box.center,
                   size=box.half, **turn)
        else:  # a hundred stall lines as one mesh geom: one element instead of one per line
            name = geom_name(cls)
            vertex, face = _tops_mesh(boxes)
            root.asset.add("mesh", name=name, vertex=vertex, face=face, inertia="shell")  # flat: no volume
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


def write_scene(garage: Garage | GarageScene, out_dir: str | Path, *, file_name: str = SCENE_XML, **kwargs) -> Path:
    """Write ``file_name`` (and any assets it needs) into ``out_dir``; returns the XML path.

    Asset packs name the file themselves (:mod:`garage_mj.export.artefacts`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    mjcf.export_with_assets(build_scene(garage, **kwargs), str(out), out_file_name=file_name)
    return out / file_name


_PARKED_PREFIX = "parkedcar_"


def parked_car_bodies(model: mujoco.MjModel) -> dict[int, int]:
    """Stall id -> body id of its parked car, in a compiled scene ({} when built with ``fuse_static``)."""
    out = {}
    for b in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if name.startswith(_PARKED_PREFIX) and name[len(_PARKED_PREFIX):].isdigit():
            out[int(name[len(_PARKED_PREFIX):])] = b
    return out


def _car_geom_part(name: str) -> tuple[int, str] | None:
    """``(stall id, model geom name)`` of a parked car geom name such as ``parkedcar_12_hull``."""
    if not name.startswith(_PARKED_PREFIX):
        return None
    sid, _, part = name[len(_PARKED_PREFIX):].partition("_")
    return (int(sid), part) if sid.isdigit() and part else None


def parked_car_geoms(model: mujoco.MjModel) -> dict[int, np.ndarray]:
    """Stall id -> geom ids of its parked car, in a compiled scene (fused or not)."""
    out: dict[int, list[int]] = {}
    for g in range(model.ngeom):
        part = _car_geom_part(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "")
        if part is not None:
            out.setdefault(part[0], []).append(g)
    return {sid: np.array(gs) for sid, gs in sorted(out.items())}


@functools.cache
def _solid_bits() -> dict[str, tuple[int, int]]:
    """``(contype, conaffinity)`` of each geom of ``models/parked_car``, by its name: what a parked car collides as."""
    template = load_template(PARKED_CAR)
    out = {}
    for k, g in enumerate(template.geoms):
        attrs = resolved_geom_attributes(template, g)
        out[g.get("name") or str(k)] = (int(attrs.get("contype", 1)), int(attrs.get("conaffinity", 1)))
    return out


class ParkedCars:
    """What :func:`set_parked` writes, per stall, for one compiled scene: looked up once (by geom name), then
    applied to the model at every call of :meth:`apply` (a drive env resets its stalls at every test)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.geoms = parked_car_geoms(model)  # stall id -> geom ids of its car
        solid = _solid_bits()
        ids = [int(g) for geoms in self.geoms.values() for g in geoms]
        bits = [solid.get(_car_geom_part(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g))[1], (1, 1)) for g in ids]
        # every parked-car geom once, with its stall and what it collides as when its car is in place
        self._ids = np.array(ids, dtype=int)
        self._stall = np.array([sid for sid, geoms in self.geoms.items() for _ in geoms], dtype=int)
        self._contype = np.array([b[0] for b in bits], dtype=int)
        self._conaffinity = np.array([b[1] for b in bits], dtype=int)
        self.bodies = parked_car_bodies(model)  # {} when fused: nothing can lie below the floor then
        self._part = [_car_geom_part(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g))[1] for g in ids]
        self._compiled: tuple[np.ndarray, ...] | None = None  # the parked geoms as compiled, once place() moved any
        self._trees: list[_Tree] | None = None  # the bounding-volume trees holding them, once place() moved any

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData | None, occupied: Iterable[int]) -> None:
        """:func:`set_parked` on ``model``, the compiled scene this was made from."""
        want = set(occupied)
        unknown = want - self.geoms.keys()
        if unknown:
            raise ValueError(f"no stall with id {sorted(unknown)}; the scene has stalls 0..{len(self.geoms) - 1}")
        on = np.isin(self._stall, sorted(want))
        model.geom_contype[self._ids] = np.where(on, self._contype, 0)
        model.geom_conaffinity[self._ids] = np.where(on, self._conaffinity, 0)
        model.geom_rgba[self._ids, 3] = np.where(on, 1.0, 0.0)
        for sid in want & self.bodies.keys():
            model.body_pos[self.bodies[sid], 2] = 0.0
        if data is not None:
            mujoco.mj_forward(model, data)


    def place(self, model: mujoco.MjModel, data: mujoco.MjData | None, bodies: Mapping[int, ParkedBody]) -> None:
        """Stand each parked car of ``bodies`` (stall id -> :class:`~garage_mj.scene.parked_fleet.ParkedBody`) as it
        says: its geoms moved, turned and resized on ``model`` (the hull and cabin of
        :func:`~garage_mj.scene.parked_fleet.part_boxes`); every other stall's car back as compiled. Keeps what MuJoCo
        precomputed of them consistent (bounding spheres and boxes, whether a geom shares its body's frame, and the
        bounding-volume tree of the body that holds them, so a moved car is never missed by a collision and is drawn
        where it stands); occupancy stays :meth:`apply`'s. With ``data``
        the kinematics are refreshed (``mj_forward``)."""
        if self._compiled is None:  # first move: keep what the compiler made, to put back later
            ids = self._ids
            self._compiled = (model.geom_pos[ids].copy(), model.geom_quat[ids].copy(), model.geom_size[ids].copy(),
                              model.geom_rbound[ids].copy(), model.geom_aabb[ids].copy(),
                              model.geom_sameframe[ids].copy())
        pos, quat, size, rbound, aabb, same = (a.copy() for a in self._compiled)
        where = {int(g): k for k, g in enumerate(self._ids)}
        for sid, body in bodies.items():
            if sid not in self.geoms:
                raise ValueError(f"no stall with id {sid}; the scene has stalls 0..{len(self.geoms) - 1}")
            c, s = math.cos(body.yaw), math.sin(body.yaw)
            q = np.array([math.cos(body.yaw / 2), 0.0, 0.0, math.sin(body.yaw / 2)])
            parts = part_boxes(body)
            for g in self.geoms[sid]:
                k = where[int(g)]
                (px, py, pz), half = parts[self._part[k]]
                world = np.array([body.x + px * c - py * s, body.y + px * s + py * c, pz])
                pos[k], quat[k] = _in_body_frame(model, int(model.geom_bodyid[g]), world, q)
                size[k] = half
                rbound[k] = float(np.linalg.norm(half))
                aabb[k] = (0.0, 0.0, 0.0, *half)
                same[k] = mujoco.mjtSameFrame.mjSAMEFRAME_NONE  # its own pose, not its body's (which MuJoCo would copy)
        ids = self._ids
        model.geom_pos[ids], model.geom_quat[ids], model.geom_size[ids] = pos, quat, size
        model.geom_rbound[ids], model.geom_aabb[ids], model.geom_sameframe[ids] = rbound, aabb, same
        if self._trees is None:
            self._trees = [_Tree(model, int(b), ids) for b in np.unique(model.geom_bodyid[ids])]
        for tree in self._trees:
            tree.refresh(model)
        if data is not None:
            mujoco.mj_forward(model, data)


def _in_body_frame(model: mujoco.MjModel, body: int, pos: np.ndarray, quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A world pose as a pose in static ``body``'s frame (the world body's is the world's; a parked car's body hangs
    from the world body)."""
    if body == 0:
        return pos, quat
    bq = model.body_quat[body]
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, bq)
    local = rot.reshape(3, 3).T @ (pos - model.body_pos[body])
    inv, out = np.empty(4), np.empty(4)
    mujoco.mju_negQuat(inv, bq)
    mujoco.mju_mulQuat(out, inv, quat)
    return local, out


def _quat_mats(quat: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of unit quaternions (N, 4) ``(w, x, y, z)``, as ``mju_quat2Mat`` makes them."""
    w, x, y, z = quat.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)], axis=1)


class _Tree:
    """One static body's bounding-volume tree, as :meth:`ParkedCars.place` rewrites it: the leaves of the geoms
    ``geoms`` from their boxes, then every inner node, deepest first, as the union of its children. MuJoCo keeps the
    tree in the body's inertial frame; a node's child indices count from the body's first node."""

    def __init__(self, model: mujoco.MjModel, body: int, geoms: np.ndarray) -> None:
        self.adr, self.num = int(model.body_bvhadr[body]), int(model.body_bvhnum[body])
        nodeid, child = model.bvh_nodeid[self.adr:self.adr + self.num], model.bvh_child[self.adr:self.adr + self.num]
        depth = np.full(self.num, -1)
        stack = [(0, 0)] if self.num > 0 else []
        while stack:
            k, d = stack.pop()
            depth[k] = d
            stack.extend((int(j), d + 1) for j in child[k] if j >= 0)
        inner = np.flatnonzero((nodeid < 0) & (child >= 0).any(axis=1) & (depth >= 0))
        self.levels = []  # (nodes, first child, second child) per depth, deepest first
        for d in sorted(set(depth[inner].tolist()), reverse=True):
            nodes = inner[depth[inner] == d]
            c = child[nodes]
            self.levels.append((nodes, np.where(c[:, 0] >= 0, c[:, 0], c[:, 1]), np.where(c[:, 1] >= 0, c[:, 1], c[:, 0])))
        leaf = np.isin(nodeid, geoms) & (depth >= 0)
        self.leaves, self.leaf_geoms = np.flatnonzero(leaf), nodeid[leaf].astype(int)
        self.inertial = _quat_mats(model.body_iquat[body][None])[0]  # body frame <- inertial frame
        self.ipos = model.body_ipos[body].copy()

    def refresh(self, model: mujoco.MjModel) -> None:
        if not self.num:
            return
        box = model.bvh_aabb[self.adr:self.adr + self.num]  # a view: written through to the model
        g = self.leaf_geoms
        rot = np.einsum("ji,njk->nik", self.inertial, _quat_mats(model.geom_quat[g]))  # geom -> inertial frame
        centre = (model.geom_pos[g] - self.ipos) @ self.inertial + np.einsum("nij,nj->ni", rot, model.geom_aabb[g, :3])
        box[self.leaves] = np.hstack([centre, np.einsum("nij,nj->ni", np.abs(rot), model.geom_aabb[g, 3:])])
        for nodes, c0, c1 in self.levels:
            lo = np.minimum(box[c0, :3] - box[c0, 3:], box[c1, :3] - box[c1, 3:])
            hi = np.maximum(box[c0, :3] + box[c0, 3:], box[c1, :3] + box[c1, 3:])
            box[nodes] = np.hstack([(lo + hi) / 2, (hi - lo) / 2])


def set_parked(model: mujoco.MjModel, data: mujoco.MjData | None, occupied: Iterable[int]) -> None:
    """Put a parked car in exactly the stalls ``occupied`` of a compiled scene, without recompiling.

    The cars of the other stalls stay where they are but neither collide nor render (see the
    module docstring); a car built below the floor (``build_scene(parked=...)``) comes up. With
    ``data`` the kinematics are refreshed (``mj_forward``) so renders and contacts see the change at once.
    To do it often on one scene, keep a :class:`ParkedCars` of it and call its ``apply``.
    """
    ParkedCars(model).apply(model, data, occupied)


def parked_stalls(model: mujoco.MjModel) -> list[int]:
    """Stall ids whose car is in place: collidable, drawn, and not below the floor."""
    out = []
    for sid, geoms in parked_car_geoms(model).items():
        z = model.body_pos[model.geom_bodyid[geoms], 2] + model.geom_pos[geoms, 2]
        if model.geom_contype[geoms].any() and model.geom_rgba[geoms, 3].all() and (z > -HIDDEN_DEPTH / 2).all():
            out.append(sid)
    return out
