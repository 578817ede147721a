"""Scene layout: a garage as named, classified boxes plus model placements (pure, no MuJoCo).

The MJCF builder and the mesh writer both draw this one layout, so the 3D scene, the GLB and the
OBJ always hold the same geometry. Positions come only from the shared road network
(:mod:`garage_mj.scene.road_matrix`), the stall geometry (:mod:`garage_mj.scene.stalls`) and the world
conventions (:mod:`garage_mj.scene.world`).

What it holds (z up, floor top at z = 0):
- one floor slab under the whole grid;
- outer walls around the grid, merged into one box per run, with gaps at the entrance and exit;
- OBSTACLE blocks as solid boxes, merged into rectangles (rows, then equal runs stacked);
- pillars: structural ones at grid corners whose four blocks are all non-road (never next to a
  lane) and include a stall block, plus the obstruction pillars of codes 3 and 9 from ``stall_layout``;
- lane centre lines and stall outlines as thin boxes, collinear pieces merged;
- entrance and exit floor patches; an optional ceiling; one parked-car placement per stall;
- kerb walls where the aisle is narrower than its road block (``WorldConfig.aisle_width`` < block): along
  each side of a stretch of aisle (:func:`~garage_mj.scene.stalls.narrowed`), a wall ``aisle_setback`` deep,
  except where stalls stand in that strip (their rows moved onto the aisle's edge, :mod:`garage_mj.scene.stalls`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from garage_mj.core.geometry import OPPOSITE
from garage_mj.grid.blocks import ROAD_LIKE_TABLE, STALL_TABLE, Block
from garage_mj.grid.garage import Garage
from garage_mj.scene.road_matrix import RoadNetwork, RoadTile, road_network
from garage_mj.scene.semantics import Semantic, geom_name
from garage_mj.scene.stalls import StallLayout, narrowed, stall_layout
from garage_mj.scene.world import DEFAULT_WORLD, WORLD_DIR, WorldConfig

FLOOR_THICKNESS = 0.1  # [m] floor slab, top face at z = 0
CEILING_THICKNESS = 0.2  # [m]
MARKING_HEIGHT = 0.002  # [m] painted lines: top face just above the floor
GATE_PATCH_HEIGHT = 0.001  # [m] entrance/exit floor patches, under the lines

#: Colours (RGBA, 0-1) per class, shared by the MJCF materials and the GLB/OBJ materials.
CLASS_RGBA: dict[Semantic, tuple[float, float, float, float]] = {
    Semantic.FLOOR: (0.36, 0.37, 0.39, 1.0),
    Semantic.ROAD_MARKING: (0.95, 0.95, 0.95, 1.0),
    Semantic.STALL_MARKING: (0.98, 0.82, 0.15, 1.0),
    Semantic.WALL: (0.62, 0.58, 0.52, 1.0),
    Semantic.PILLAR: (0.62, 0.64, 0.66, 1.0),
    Semantic.OBSTACLE: (0.48, 0.40, 0.36, 1.0),
    Semantic.PARKED_CAR: (0.15, 0.45, 0.70, 1.0),
    Semantic.ENTRANCE: (0.10, 0.70, 0.85, 1.0),
    Semantic.EXIT: (0.95, 0.55, 0.10, 1.0),
    Semantic.PEDESTRIAN: (0.85, 0.25, 0.55, 1.0),
    Semantic.MOVING_CAR: (0.55, 0.20, 0.85, 1.0),
    Semantic.CLUTTER: (0.98, 0.45, 0.10, 1.0),
}


@dataclass(frozen=True)
class Box:
    """A box: ``center`` and ``half`` sizes [m], turned by ``yaw`` about z (0: axis-aligned; only the painted
    lines of angled stalls are turned), carrying its class in ``name``."""

    name: str
    cls: Semantic
    center: tuple[float, float, float]
    half: tuple[float, float, float]
    collides: bool  # solid (walls, obstacles, floor) or visual only (markings, gate patches)
    yaw: float = 0.0  # [rad] counter-clockwise about z


@dataclass(frozen=True)
class Placement:
    """Where a reusable model (parked car, pillar) is instanced: name, (x, y) [m], yaw [rad]."""

    name: str
    x: float
    y: float
    yaw: float
    stall_id: int | None = None


@dataclass(frozen=True)
class SceneLayout:
    rows: int
    cols: int
    world: WorldConfig
    boxes: tuple[Box, ...]
    pillars: tuple[Placement, ...]
    parked_cars: tuple[Placement, ...]  # one per stall, ``stall_id`` = Stall.id

    @property
    def size(self) -> tuple[float, float]:
        """Grid extent (x, y) [m]."""
        return self.cols * self.world.block, self.rows * self.world.block


def merge_intervals(segments: list[tuple[str, float, float, float]]) -> list[tuple[str, float, float, float]]:
    """Merge collinear axis-aligned segments ``(axis, line, lo, hi)`` that touch or overlap.

    ``axis`` is ``"x"`` (the segment runs along x at y = line) or ``"y"``.
    """
    groups: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for axis, line, lo, hi in segments:
        groups.setdefault((axis, round(line, 4)), []).append((min(lo, hi), max(lo, hi)))
    out = []
    for (axis, line), spans in sorted(groups.items()):
        spans.sort()
        cur_lo, cur_hi = spans[0]
        for lo, hi in spans[1:]:
            if lo <= cur_hi + 1e-6:
                cur_hi = max(cur_hi, hi)
            else:
                out.append((axis, line, cur_lo, cur_hi))
                cur_lo, cur_hi = lo, hi
        out.append((axis, line, cur_lo, cur_hi))
    return out


def cover_cells(mask: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Cover the True cells of ``mask`` with disjoint rectangles ``(row0, col0, rows, cols)``.

    Horizontal runs per row; a run identical to the one just above extends that rectangle.
    """
    open_: dict[tuple[int, int], list[int]] = {}  # (col0, cols) -> [row0, rows]
    out: list[tuple[int, int, int, int]] = []
    for r in range(mask.shape[0]):
        runs, c = [], 0
        while c < mask.shape[1]:
            if mask[r, c]:
                c0 = c
                while c < mask.shape[1] and mask[r, c]:
                    c += 1
                runs.append((c0, c - c0))
            c += 1
        nxt: dict[tuple[int, int], list[int]] = {}
        for run in runs:
            rect = open_.pop(run, None)
            if rect is not None and rect[0] + rect[1] == r:
                rect[1] += 1
                nxt[run] = rect
            else:
                nxt[run] = [r, 1]
        out.extend((r0, c0, n, w) for (c0, w), (r0, n) in open_.items())
        open_ = nxt
    out.extend((r0, c0, n, w) for (c0, w), (r0, n) in open_.items())
    return sorted(out)


def _line_boxes(segs, cls: Semantic, width: float) -> list[Box]:
    out = []
    for k, (axis, line, lo, hi) in enumerate(merge_intervals(segs)):
        mid, half_len = (lo + hi) / 2, (hi - lo) / 2
        center = (mid, line) if axis == "x" else (line, mid)
        half = (half_len, width / 2) if axis == "x" else (width / 2, half_len)
        z = MARKING_HEIGHT / 2
        out.append(Box(geom_name(cls, k), cls, (*center, z), (*half, MARKING_HEIGHT / 2), False))
    return out


def _segment(x0: float, y0: float, x1: float, y1: float) -> tuple[str, float, float, float]:
    if abs(y0 - y1) < 1e-9:
        return ("x", y0, x0, x1)
    return ("y", x0, y0, y1)


def build_layout(garage: Garage, world: WorldConfig = DEFAULT_WORLD, ceiling: bool = False, *,
                 network: RoadNetwork | None = None, stalls: StallLayout | None = None) -> SceneLayout:
    """The scene layout of ``garage`` (see the module docstring); ``network``/``stalls`` are derived if not given."""
    rows, cols = garage.grid.shape
    net = network or road_network(garage, world)
    stalls = stalls or stall_layout(garage, world)
    boxes = [_floor_box(rows, cols, world), *_wall_boxes(garage, world), *_obstacle_boxes(garage.grid, world)]
    if ceiling:
        boxes.append(_ceiling_box(rows, cols, world))
    boxes += _lane_marking_boxes(net, world)
    boxes += _stall_marking_boxes(stalls, world)
    boxes += _gate_patch_boxes(garage, net, world)
    if world.aisle_setback > 0:
        boxes += _kerb_boxes(garage.grid, net, stalls, world)
    parked = [Placement(f"parkedcar_{s.id}", s.x, s.y, s.car_yaw, s.id) for s in stalls.stalls]
    return SceneLayout(rows, cols, world, tuple(boxes), tuple(_pillar_placements(garage.grid, stalls, world)),
                       tuple(parked))


def _floor_box(rows: int, cols: int, world: WorldConfig) -> Box:
    """One slab under the whole grid, its top face at z = 0."""
    sx, sy = cols * world.block, rows * world.block
    return Box("floor", Semantic.FLOOR, (sx / 2, sy / 2, -FLOOR_THICKNESS / 2),
               (sx / 2, sy / 2, FLOOR_THICKNESS / 2), True)


def _ceiling_box(rows: int, cols: int, world: WorldConfig) -> Box:
    """One slab over the whole grid, its bottom face at the ceiling height."""
    sx, sy = cols * world.block, rows * world.block
    h = world.ceiling_height
    return Box("ceiling", Semantic.WALL, (sx / 2, sy / 2, h + CEILING_THICKNESS / 2),
               (sx / 2, sy / 2, CEILING_THICKNESS / 2), True)


def _wall_segments(garage: Garage, world: WorldConfig) -> list[tuple[str, float, float, float]]:
    """One wall segment per border block, just outside the grid, none at the entrance and exit;
    the end blocks reach over the corners by the wall thickness so the walls close there."""
    rows, cols = garage.grid.shape
    b, t = world.block, world.wall_thickness
    sx, sy = cols * b, rows * b
    gates = {garage.entrance, garage.exit}
    wall_segs = []
    for side, cells, fixed in (
        ("n", [(0, c) for c in range(cols)], sy + t / 2),
        ("s", [(rows - 1, c) for c in range(cols)], -t / 2),
        ("w", [(r, 0) for r in range(rows)], -t / 2),
        ("e", [(r, cols - 1) for r in range(rows)], sx + t / 2),
    ):
        along = "x" if side in "ns" else "y"
        for r, c in cells:
            if (r, c) in gates:
                continue
            if along == "x":
                lo = c * b - (t if c == 0 else 0)
                hi = (c + 1) * b + (t if c == cols - 1 else 0)
            else:
                lo = (rows - 1 - r) * b - (t if r == rows - 1 else 0)
                hi = (rows - r) * b + (t if r == 0 else 0)
            wall_segs.append((along, fixed, lo, hi))
    return wall_segs


def _wall_boxes(garage: Garage, world: WorldConfig) -> list[Box]:
    """The outer walls, merged into one box per straight run, split at the gates."""
    h, t = world.ceiling_height, world.wall_thickness
    boxes = []
    for k, (axis, line, lo, hi) in enumerate(merge_intervals(_wall_segments(garage, world))):
        mid, hl = (lo + hi) / 2, (hi - lo) / 2
        center = (mid, line, h / 2) if axis == "x" else (line, mid, h / 2)
        half = (hl, t / 2, h / 2) if axis == "x" else (t / 2, hl, h / 2)
        boxes.append(Box(geom_name(Semantic.WALL, k), Semantic.WALL, center, half, True))
    return boxes


def _obstacle_boxes(grid: np.ndarray, world: WorldConfig) -> list[Box]:
    """OBSTACLE blocks as solid boxes up to the ceiling, merged into rectangles."""
    rows = grid.shape[0]
    b, h = world.block, world.ceiling_height
    boxes = []
    for k, (r0, c0, n, w) in enumerate(cover_cells(grid == Block.OBSTACLE)):
        x0, x1 = c0 * b, (c0 + w) * b
        y0, y1 = (rows - r0 - n) * b, (rows - r0) * b
        boxes.append(
            Box(
                geom_name(Semantic.OBSTACLE, k),
                Semantic.OBSTACLE,
                ((x0 + x1) / 2, (y0 + y1) / 2, h / 2),
                ((x1 - x0) / 2, (y1 - y0) / 2, h / 2),
                True,
            )
        )
    return boxes


def _lane_marking_boxes(net: RoadNetwork, world: WorldConfig) -> list[Box]:
    """Lane centre lines: junction interiors stay clear, gates run across their whole cell."""
    b, half_road = world.block, world.road_width / 2
    lane_segs = []
    for cell in net.cells.values():
        dirs = set(cell.openings)
        if cell.tile in (RoadTile.ENTRANCE, RoadTile.EXIT):
            dirs |= {OPPOSITE[d] for d in cell.openings}
        start = half_road if cell.tile in (RoadTile.T, RoadTile.CROSS) else 0.0
        for d in dirs:
            ux, uy = WORLD_DIR[d]
            lane_segs.append(
                _segment(cell.x + ux * start, cell.y + uy * start, cell.x + ux * b / 2, cell.y + uy * b / 2)
            )
    return _line_boxes(lane_segs, Semantic.ROAD_MARKING, world.marking_width)


def _stall_marking_boxes(stalls: StallLayout, world: WorldConfig) -> list[Box]:
    """Stall outlines: two sides and the back line, open towards the road (angled stalls: turned lines, one box each)."""
    stall_segs = []
    mw = world.marking_width
    turned: list[Box] = []
    for s in stalls.stalls:
        L, W = s.length, s.width
        if s.angle not in (90.0, 0.0):
            turned += _turned_marking_boxes(s, mw, len(turned))
            continue
        ux, uy = WORLD_DIR[s.side]
        tx, ty = -uy, ux
        for sgn in (-1, 1):
            px, py = s.x + tx * sgn * W / 2, s.y + ty * sgn * W / 2
            stall_segs.append(_segment(px - ux * L / 2, py - uy * L / 2, px + ux * L / 2, py + uy * L / 2))
        bx, by = s.x - ux * L / 2, s.y - uy * L / 2
        e = W / 2 + mw / 2
        stall_segs.append(_segment(bx - tx * e, by - ty * e, bx + tx * e, by + ty * e))
    return _line_boxes(stall_segs, Semantic.STALL_MARKING, mw) + turned


def _turned_marking_boxes(s, mw: float, first: int) -> list[Box]:
    """The two sides and the back line of angled stall ``s``, each a box turned by the stall's yaw."""
    ca, sa = math.cos(s.yaw), math.sin(s.yaw)
    z = MARKING_HEIGHT / 2
    lines = [((0.0, sgn * s.width / 2), (s.length / 2, mw / 2)) for sgn in (-1, 1)]
    lines.append(((-s.length / 2, 0.0), (mw / 2, s.width / 2 + mw / 2)))
    out = []
    for k, ((du, dv), half) in enumerate(lines):
        center = (s.x + du * ca - dv * sa, s.y + du * sa + dv * ca, z)
        out.append(Box(geom_name(Semantic.STALL_MARKING, "turned", first + k), Semantic.STALL_MARKING, center,
                       (*half, MARKING_HEIGHT / 2), False, s.yaw))
    return out


def _gate_patch_boxes(garage: Garage, net: RoadNetwork, world: WorldConfig) -> list[Box]:
    """Entrance and exit floor patches: the road width, across the whole gate cell."""
    b, half_road = world.block, world.road_width / 2
    boxes = []
    for cls, pos in ((Semantic.ENTRANCE, garage.entrance), (Semantic.EXIT, garage.exit)):
        cell = net.cells[pos]
        along_x = any(WORLD_DIR[d][0] != 0 for d in cell.openings)
        half = (b / 2, half_road, GATE_PATCH_HEIGHT / 2) if along_x else (half_road, b / 2, GATE_PATCH_HEIGHT / 2)
        boxes.append(Box(geom_name(cls, "floor"), cls, (cell.x, cell.y, GATE_PATCH_HEIGHT / 2), half, False))
    return boxes


def _kerb_boxes(grid: np.ndarray, net: RoadNetwork, stalls: StallLayout, world: WorldConfig) -> list[Box]:
    """Kerb walls: the strip of ``aisle_setback`` along each side of a stretch of aisle that runs along it
    (:func:`~garage_mj.scene.stalls.narrowed`), less the spans of the stalls that stand in it."""
    k, b, h = world.aisle_setback, world.block, world.ceiling_height
    facing: dict[tuple[int, int], list[tuple[float, float, float, float]]] = {}
    for st in stalls.stalls:
        xs, ys = zip(*st.corners)
        facing.setdefault(st.road_cell, []).append((min(xs), min(ys), max(xs), max(ys)))
    boxes: list[Box] = []
    for pos in sorted(net.cells):
        cell = net.cells[pos]
        for d in sorted(d for d in WORLD_DIR if narrowed(grid, *pos, d)):  # junctions and turns keep the block
            ux, uy = WORLD_DIR[d]
            if ux:  # a strip along y at the east or west edge
                x0 = cell.x + ux * (b / 2 - k / 2) - k / 2
                rect = (x0, cell.y - b / 2, x0 + k, cell.y + b / 2)
            else:
                y0 = cell.y + uy * (b / 2 - k / 2) - k / 2
                rect = (cell.x - b / 2, y0, cell.x + b / 2, y0 + k)
            axis = 1 if ux else 0  # the strip's long axis: y for east/west, x for north/south
            spans = [(lo, hi) for lo, hi in _free_spans(rect, axis, facing.get(pos, [])) if hi - lo > 1e-6]
            for lo, hi in spans:
                x0, y0, x1, y1 = rect
                if axis == 0:
                    x0, x1 = lo, hi
                else:
                    y0, y1 = lo, hi
                boxes.append(Box(geom_name(Semantic.WALL, "kerb", len(boxes)), Semantic.WALL,
                                 ((x0 + x1) / 2, (y0 + y1) / 2, h / 2), ((x1 - x0) / 2, (y1 - y0) / 2, h / 2), True))
    return boxes


def _free_spans(rect: tuple[float, float, float, float], axis: int,
                stalls: list[tuple[float, float, float, float]]) -> list[tuple[float, float]]:
    """The spans of ``rect`` along ``axis`` (0 x, 1 y) that no stall rectangle (x0, y0, x1, y1) overlaps."""
    eps = 1e-9
    lo, hi = rect[axis], rect[axis + 2]
    cuts = sorted((s[axis], s[axis + 2]) for s in stalls
                  if s[0] < rect[2] - eps and s[2] > rect[0] + eps and s[1] < rect[3] - eps and s[3] > rect[1] + eps)
    out, at = [], lo
    for a, z in cuts:
        if a > at:
            out.append((at, min(a, hi)))
        at = max(at, z)
    if at < hi:
        out.append((at, hi))
    return out


def _pillar_placements(grid: np.ndarray, stalls: StallLayout, world: WorldConfig) -> list[Placement]:
    """The obstruction pillars of the stall layout first, then the structural ones, numbered in that order."""
    pillars = [Placement(f"pillar_{k}", p.x, p.y, 0.0) for k, p in enumerate(stalls.pillars)]
    for x, y in structural_pillars(grid, world):
        pillars.append(Placement(f"pillar_{len(pillars)}", x, y, 0.0))
    return pillars


def structural_pillars(grid: np.ndarray, world: WorldConfig = DEFAULT_WORLD) -> list[tuple[float, float]]:
    """(x, y) [m] of structural pillars: interior grid corners whose four blocks are not road-like
    (so no lane passes within a block of them) and include a stall block (pillars stand between
    parking bays, not in unbuilt FREE space)."""
    rows, cols = grid.shape
    road = ROAD_LIKE_TABLE[grid]
    stall = STALL_TABLE[grid] > 0
    out = []
    for i in range(1, rows):
        for j in range(1, cols):
            quad = (slice(i - 1, i + 1), slice(j - 1, j + 1))
            if not road[quad].any() and stall[quad].any():
                out.append((j * world.block, (rows - i) * world.block))
    return out
