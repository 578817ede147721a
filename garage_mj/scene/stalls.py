"""Stall geometry: where every parking stall of a garage lies in the world (docs/spec.md section 6).

Pure: garage in, stalls out. A block is 9 m x 9 m; a row of three 2.5 m x 4.5 m stalls sits
against the block edge that touches a ROAD cell, centred along it, each stall facing that road.

- STALL3 / OBST_STALL3: one row of three against one road side.
- STALL6: two back-to-back rows of three, one against each road of the six-stall axis pair.
- STALL4 / OBST_STALL4: a row of three against one road side plus a lone stall against a
  perpendicular road side, clear of the row.
- Obstructed blocks (codes 3 and 9) get two pillars at the front corners of the row, next to
  the road: what makes parking there harder.

Sides are chosen in the fixed order north, south, west, east, so the layout is deterministic.

The park geometry of the world (docs/spec.md section 9) shapes the rows: ``stall_width`` x ``stall_length``
(the depth) per stall; an aisle narrower than the block (``aisle_width``) leaves a strip of
``aisle_setback`` on each side of it, into which the rows move, so that a stall still opens onto the
aisle's edge (where no stall stands, the layout puts a kerb wall in the strip). Only straight stretches
of aisle are narrowed (:func:`narrowed`): junctions and turns keep the whole block. A geometry a block
cannot hold is one :class:`~garage_mj.scene.world.GeometryError` naming the block and the fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from garage_mj.core.geometry import DELTAS, EAST, NORTH, OPPOSITE, SOUTH, WEST
from garage_mj.grid.blocks import ROAD_LIKE_TABLE, STALLS_PER_BLOCK, Block
from garage_mj.grid.garage import Garage
from garage_mj.scene.world import DEFAULT_WORLD, DIR_YAW, WORLD_DIR, GeometryError, WorldConfig, cell_center

SIDE_ORDER = (NORTH, SOUTH, WEST, EAST)
LONE_GAP = 0.25  # [m] at least this between a four-stall block's lone stall and its row
_AXIS_PAIR = {"NS": (NORTH, SOUTH), "EW": (WEST, EAST)}


@dataclass(frozen=True)
class Stall:
    id: int  # index in the garage, row-major over blocks
    block: tuple[int, int]  # (row, col) of the stall block
    x: float  # [m] stall centre
    y: float  # [m]
    yaw: float  # [rad] direction the stall opens to (towards its road; an angled stall: along its axis)
    side: int  # grid direction of its road from the block (0 W, 1 E, 2 N, 3 S)
    road_cell: tuple[int, int]  # the ROAD cell it faces
    road_x: float  # [m] point on the near lane of that road, beside the stall
    road_y: float  # [m]
    obstructed: bool  # in an OBST_STALL3/OBST_STALL4 block
    length: float = DEFAULT_WORLD.stall_length  # [m] along yaw, from the world the stall was laid out in
    width: float = DEFAULT_WORLD.stall_width  # [m]
    angle: float = DEFAULT_WORLD.stall_angle  # [deg] to its aisle: 90 perpendicular, 60 or 45 angled, 0 parallel

    @property
    def corners(self) -> list[tuple[float, float]]:
        """Rectangle corners (x, y) [m], counter-clockwise."""
        return rectangle(self.x, self.y, self.yaw, self.length, self.width)

    @property
    def car_yaw(self) -> float:
        """[rad] the heading of a car parked nose out: ``yaw``, or for a parallel slot (``angle`` 0) along the
        aisle, the way the traffic of its lane drives."""
        return self.yaw - math.pi / 2 if self.angle == 0.0 else self.yaw

    @property
    def entry(self) -> tuple[float, float]:
        """Midpoint [m] of the stall's open short side, the one facing its road."""
        return (self.x + math.cos(self.yaw) * self.length / 2, self.y + math.sin(self.yaw) * self.length / 2)


@dataclass(frozen=True)
class Pillar:
    block: tuple[int, int]
    x: float  # [m] centre
    y: float  # [m]


@dataclass(frozen=True)
class StallLayout:
    stalls: tuple[Stall, ...]
    pillars: tuple[Pillar, ...]  # obstruction pillars of obstructed blocks


def rectangle(x: float, y: float, yaw: float, length: float, width: float) -> list[tuple[float, float]]:
    """Corners of a length x width rectangle centred at (x, y), its length along ``yaw``."""
    ca, sa = math.cos(yaw), math.sin(yaw)
    out = []
    for sl, sw in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        dx, dy = sl * length / 2, sw * width / 2
        out.append((x + dx * ca - dy * sa, y + dx * sa + dy * ca))
    return out


def _road_sides(grid, r: int, c: int) -> list[int]:
    h, w = grid.shape
    out = []
    for d in SIDE_ORDER:
        rr, cc = r + DELTAS[d][0], c + DELTAS[d][1]
        if 0 <= rr < h and 0 <= cc < w and grid[rr, cc] == Block.ROAD:
            out.append(d)
    return out


def _plan(code: Block, sides: list[int], axis: str) -> list[tuple[int, int]]:
    """(side, stalls) rows for a block: which road sides get a row of 3 or a lone stall."""
    if code == Block.STALL6:
        a, b = _AXIS_PAIR[axis]
        if a in sides and b in sides:
            return [(a, 3), (b, 3)]
        return []
    if code in (Block.STALL3, Block.OBST_STALL3):
        return [(sides[0], 3)] if sides else []
    # four stalls: a row against one side, a lone stall against a perpendicular side
    for main in sides:
        perp = [s for s in sides if s not in (main, OPPOSITE[main])]
        unpaired = OPPOSITE[main] not in sides
        if perp and (unpaired or len(sides) == 2):
            return [(main, 3), (perp[0], 1)]
    return []


class RowShape(NamedTuple):
    """The shape of one stall of a row in the row's frame (u: out of the block toward its road, t: along the
    block edge, counter-clockwise): the stall's rectangle is ``length`` along its axis u sin + t cos (pointing
    out of its open end) and ``width`` across; the row takes ``depth`` along u, each stall ``extent`` along t, one
    stall the next ``pitch`` along t."""

    length: float  # [m] along the stall's yaw (a parallel slot: its depth across the aisle, the stall width)
    width: float  # [m] across (a parallel slot: its length along the aisle, the slot length)
    sin: float
    cos: float
    depth: float  # [m] along u
    extent: float  # [m] along t
    pitch: float  # [m] along t


def row_shape(world: WorldConfig) -> RowShape:
    """The stalls of ``world``'s park geometry in a row's frame: perpendicular (90), angled (60, 45: the
    rectangle turned so that its axis makes the angle with the aisle), or parallel (0: a slot of ``slot_length``
    along the edge, ``stall_width`` deep, opening onto the aisle along its length)."""
    L, W = world.stall_length, world.stall_width
    if world.stall_angle == 90.0:
        return RowShape(L, W, 1.0, 0.0, L, W, W)
    if world.stall_angle == 0.0:
        return RowShape(W, world.slot_length, 1.0, 0.0, W, world.slot_length, world.slot_length)
    a = math.radians(world.stall_angle)
    sn, cs = math.sin(a), math.cos(a)
    return RowShape(L, W, sn, cs, L * sn + W * cs, L * cs + W * sn, W / sn)


def row_count(world: WorldConfig, grid_count: int, pillars: bool) -> int:
    """How many stalls of ``world``'s shape a block edge holds, at most ``grid_count`` (the grid's count), with
    room for two obstruction pillars at the row's ends when ``pillars``."""
    shape = row_shape(world)
    room = world.block - (2 * world.pillar_size if pillars else 0.0)
    n = grid_count
    while n > 0 and (n - 1) * shape.pitch + shape.extent > room + 1e-9:
        n -= 1
    return n


def stall_layout(garage: Garage, world: WorldConfig = DEFAULT_WORLD) -> StallLayout:
    """Every stall of ``garage`` with its pose and the road point beside it."""
    grid = garage.grid
    rows = grid.shape[0]
    half = world.block / 2
    margin = (world.block - world.road_width) / 2  # [m] from block edge to the road's lane edge
    shape = row_shape(world)
    flow = traffic_flow(garage) if shape.cos else {}
    stalls: list[Stall] = []
    pillars: list[Pillar] = []
    for r in range(grid.shape[0]):
        for c in range(grid.shape[1]):
            code = Block(int(grid[r, c]))
            if code not in STALLS_PER_BLOCK:
                continue
            sides = _road_sides(grid, r, c)
            plan = _plan(code, sides, garage.six_stall_axis)
            if sum(n for _, n in plan) != STALLS_PER_BLOCK[code]:
                raise ValueError(
                    f"garage {garage.name!r}, row {r}, column {c}: {code.name} does not fit its road "
                    f"sides {sorted(sides)}; the grid breaks the stall rule (check metrics.evaluate(...).valid)"
                )
            cx, cy = cell_center(r, c, rows, world)
            obstructed = code in (Block.OBST_STALL3, Block.OBST_STALL4)
            row_side = plan[0][0]
            # [m] each row moves this far into its road block, onto the edge of a narrowed aisle
            setbacks = [world.aisle_setback if narrowed(grid, r + DELTAS[d][0], c + DELTAS[d][1], d) else 0.0
                        for d, _ in plan]
            _check_fit(garage, world, (r, c), code, setbacks)
            first = len(stalls)
            counts = []
            for k, ((side, n), setback) in enumerate(zip(plan, setbacks, strict=True)):
                ux, uy = WORLD_DIR[side]
                tx, ty = -uy, ux
                depth = half - shape.depth / 2 + setback
                n = row_count(world, n, obstructed and k == 0)
                if k > 0 and _lone_gap(world, setbacks[0]) < _lone_least(world, setbacks[0]) - 1e-9:
                    n = 0  # the lone stall has no room beside this row: left out
                counts.append(n)
                if n == 1 and k > 0:  # lone stall: on the far side of the block from the row, clear of it
                    ax, ay = WORLD_DIR[row_side]
                    s = -(shape.extent / 2 + _lone_gap(world, setbacks[0]))
                    offsets = [s * (ax * tx + ay * ty)]
                else:
                    offsets = [(j - (n - 1) / 2) * shape.pitch for j in range(n)]
                if shape.cos == 0.0:
                    yaw = DIR_YAW[side]
                else:  # angled: the stall's axis leans toward where the aisle's traffic comes from
                    vx, vy = _upstream(flow.get((r + DELTAS[side][0], c + DELTAS[side][1])), side)
                    yaw = math.atan2(uy * shape.sin + vy * shape.cos, ux * shape.sin + vx * shape.cos)
                for off in offsets:
                    x = cx + ux * depth + tx * off
                    y = cy + uy * depth + ty * off
                    reach = shape.depth / 2 + margin + world.drive_lane_width / 2 - setback
                    stalls.append(
                        Stall(
                            id=len(stalls),
                            block=(r, c),
                            x=x,
                            y=y,
                            yaw=yaw,
                            side=side,
                            road_cell=(r + DELTAS[side][0], c + DELTAS[side][1]),
                            road_x=x + ux * reach,
                            road_y=y + uy * reach,
                            obstructed=obstructed,
                            length=shape.length,
                            width=shape.width,
                            angle=world.stall_angle,
                        )
                    )
            block_pillars = []
            if obstructed and counts[0]:
                ux, uy = WORLD_DIR[row_side]
                tx, ty = -uy, ux
                front = half - world.pillar_size / 2 + setbacks[0]
                along = (counts[0] - 1) / 2 * shape.pitch + shape.extent / 2 + world.pillar_size / 2
                for sgn in (-1, 1):
                    block_pillars.append(
                        Pillar((r, c), cx + ux * front + sgn * tx * along, cy + uy * front + sgn * ty * along)
                    )
            if not world.is_default_geometry:
                _check_disjoint(garage, world, (r, c), stalls[first:], block_pillars)
            pillars += block_pillars
    return StallLayout(tuple(stalls), tuple(pillars))


def traffic_flow(garage: Garage) -> dict[tuple[int, int], int]:
    """The one-way direction of every road-like cell for angled stalls (docs/spec.md section 9): the grid direction a
    car drives in when it first reaches the cell from the entrance (breadth first, neighbours in
    :data:`SIDE_ORDER`), so that every angled stall leans toward the entrance side of its aisle and is entered
    forward at a shallow turn."""
    grid = garage.grid
    h, w = grid.shape
    flow: dict[tuple[int, int], int] = {}
    seen = {garage.entrance}
    queue = [garage.entrance]
    for r, c in queue:
        for d in SIDE_ORDER:
            rr, cc = r + DELTAS[d][0], c + DELTAS[d][1]
            if 0 <= rr < h and 0 <= cc < w and (rr, cc) not in seen and ROAD_LIKE_TABLE[grid[rr, cc]]:
                seen.add((rr, cc))
                flow[(rr, cc)] = d
                queue.append((rr, cc))
    return flow


def _upstream(flow: int | None, side: int) -> tuple[float, float]:
    """Unit vector along a block edge on ``side`` toward where its road's traffic comes from: against ``flow`` when
    that runs along the edge; else (a car meets the row head-on, in a turn) the edge's counter-clockwise direction."""
    ux, uy = WORLD_DIR[side]
    if flow is not None and flow not in (side, OPPOSITE[side]):
        fx, fy = WORLD_DIR[flow]
        return -fx, -fy
    return -uy, ux


def narrowed(grid, r: int, c: int, side: int) -> bool:
    """Whether ``WorldConfig.aisle_width`` narrows road cell (r, c) on its ``side`` (a grid direction): the cell is a
    stretch of aisle (its road-like neighbours lie on one axis: a straight road, a gate, a dead end) and ``side``
    runs along it. Junctions and turns keep the whole block, so that a car can turn there, and so does a dead
    end's far end."""
    h, w = grid.shape
    dirs = {d for d in SIDE_ORDER if 0 <= r + DELTAS[d][0] < h and 0 <= c + DELTAS[d][1] < w
            and ROAD_LIKE_TABLE[grid[r + DELTAS[d][0], c + DELTAS[d][1]]]}
    across = {NORTH, SOUTH} if side in (WEST, EAST) else {WEST, EAST}
    return bool(dirs) and dirs <= across


def _lone_gap(world: WorldConfig, row_setback: float) -> float:
    """[m] from a four-stall block's centre line to the near end of its lone stall, on the far side from the row:
    :data:`LONE_GAP` past the inner end of the row (which a deep stall or a narrowed aisle moves), at least
    :data:`LONE_GAP`; less (even past the centre line, toward a shallow row) when the lone stall would leave
    the block otherwise. Clear of the row when it is at least :func:`_lone_least`."""
    shape = row_shape(world)
    return min(max(LONE_GAP, _lone_least(world, row_setback)), world.block / 2 - shape.extent)


def _lone_least(world: WorldConfig, row_setback: float) -> float:
    """[m] the smallest :func:`_lone_gap` that keeps the lone stall :data:`LONE_GAP` clear of the row's inner end."""
    return LONE_GAP - (world.block / 2 + row_setback - row_shape(world).depth)


def _check_fit(garage: Garage, world: WorldConfig, where: tuple[int, int], code: Block,
               setbacks: list[float]) -> None:
    """Refuse a geometry stall block ``where`` cannot hold with its rows moved by ``setbacks``, naming the fix."""
    half, shape = world.block / 2, row_shape(world)
    at = f"garage {garage.name or 'garage'!r}, row {where[0]}, column {where[1]}"
    if code == Block.STALL6 and 2 * shape.depth > world.block + sum(setbacks) + 1e-9:
        deepest = half + min(setbacks)
        beside = "a junction or turn" if min(setbacks) == 0 else f"{world.aisle_width:g} m aisles"
        raise GeometryError(
            f"{at}: its back-to-back rows reach {shape.depth:.2f} m deep each (stall depth {world.stall_length:g} m "
            f"at {world.stall_angle:g} degrees), at most {deepest:g} m beside {beside}; give a smaller --stall-depth "
            "or a narrower --aisle-width")


def _check_disjoint(garage: Garage, world: WorldConfig, where: tuple[int, int], stalls: list[Stall],
                    pillars: list[Pillar]) -> None:
    """Refuse a block whose stalls overlap each other or its pillars (what the checks above do not foresee)."""
    h = world.pillar_size / 2
    shapes = [s.corners for s in stalls] + [rectangle(p.x, p.y, 0.0, 2 * h, 2 * h) for p in pillars]
    for i in range(len(stalls)):
        for j in range(i + 1, len(shapes)):
            if polygons_overlap(shapes[i], shapes[j]):
                raise GeometryError(
                    f"garage {garage.name or 'garage'!r}, row {where[0]}, column {where[1]}: its stalls overlap "
                    f"{'each other' if j < len(stalls) else 'its pillars'} at stall width {world.stall_width:g} m, "
                    f"depth {world.stall_length:g} m and angle {world.stall_angle:g} degrees; give smaller stalls")


def polygons_overlap(a: list[tuple[float, float]], b: list[tuple[float, float]], tol: float = 1e-6) -> bool:
    """Whether two convex polygons overlap by more than ``tol`` (touching edges do not): separating axes."""
    for poly in (a, b):
        for k in range(len(poly)):
            (x0, y0), (x1, y1) = poly[k], poly[(k + 1) % len(poly)]
            nx, ny = y0 - y1, x1 - x0
            norm = math.hypot(nx, ny)
            if norm == 0.0:
                continue
            pa = [(x * nx + y * ny) / norm for x, y in a]
            pb = [(x * nx + y * ny) / norm for x, y in b]
            if min(pa) >= max(pb) - tol or min(pb) >= max(pa) - tol:
                return False
    return True
