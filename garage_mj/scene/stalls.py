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
    yaw: float  # [rad] direction the stall opens to (towards its road)
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


def stall_layout(garage: Garage, world: WorldConfig = DEFAULT_WORLD) -> StallLayout:
    """Every stall of ``garage`` with its pose and the road point beside it."""
    if world.stall_angle != 90.0:
        raise GeometryError(f"stall angle {world.stall_angle:g} degrees: angled and parallel stalls are not built yet; "
                            "give --stall-angle 90 (perpendicular)")
    grid = garage.grid
    rows = grid.shape[0]
    half = world.block / 2
    margin = (world.block - world.road_width) / 2  # [m] from block edge to the road's lane edge
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
            setbacks = [world.aisle_setback if narrowed(grid, r + DELTAS[d][0], c + DELTAS[d][1]) else 0.0
                        for d, _ in plan]
            _check_fit(garage, world, (r, c), code, setbacks)
            for (side, n), setback in zip(plan, setbacks, strict=True):
                ux, uy = WORLD_DIR[side]
                tx, ty = -uy, ux
                depth = half - world.stall_length / 2 + setback
                if n == 3:
                    offsets = [(k - 1) * world.stall_width for k in range(3)]
                else:  # lone stall: on the far side of the block from the row, clear of it
                    ax, ay = WORLD_DIR[row_side]
                    s = -(world.stall_width / 2 + _lone_gap(world, setbacks[0]))
                    offsets = [s * (ax * tx + ay * ty)]
                for off in offsets:
                    x = cx + ux * depth + tx * off
                    y = cy + uy * depth + ty * off
                    reach = world.stall_length / 2 + margin + world.drive_lane_width / 2 - setback
                    stalls.append(
                        Stall(
                            id=len(stalls),
                            block=(r, c),
                            x=x,
                            y=y,
                            yaw=DIR_YAW[side],
                            side=side,
                            road_cell=(r + DELTAS[side][0], c + DELTAS[side][1]),
                            road_x=x + ux * reach,
                            road_y=y + uy * reach,
                            obstructed=obstructed,
                            length=world.stall_length,
                            width=world.stall_width,
                        )
                    )
            if obstructed:
                ux, uy = WORLD_DIR[row_side]
                tx, ty = -uy, ux
                front = half - world.pillar_size / 2 + setbacks[0]
                along = 1.5 * world.stall_width + world.pillar_size / 2
                for sgn in (-1, 1):
                    pillars.append(
                        Pillar((r, c), cx + ux * front + sgn * tx * along, cy + uy * front + sgn * ty * along)
                    )
    return StallLayout(tuple(stalls), tuple(pillars))


def narrowed(grid, r: int, c: int) -> bool:
    """Whether road cell (r, c) is a stretch of aisle that ``WorldConfig.aisle_width`` narrows: its road-like
    neighbours lie on one axis (a straight road, a gate, a dead end). Junctions and turns keep the whole block,
    so that a car can turn there."""
    h, w = grid.shape
    dirs = {d for d in SIDE_ORDER if 0 <= r + DELTAS[d][0] < h and 0 <= c + DELTAS[d][1] < w
            and ROAD_LIKE_TABLE[grid[r + DELTAS[d][0], c + DELTAS[d][1]]]}
    return dirs <= {NORTH, SOUTH} or dirs <= {WEST, EAST}


def _lone_gap(world: WorldConfig, row_setback: float) -> float:
    """[m] from a four-stall block's centre line to its lone stall: :data:`LONE_GAP` past the inner end of
    the row (which a deep stall or a narrowed aisle moves), at least :data:`LONE_GAP`."""
    return max(LONE_GAP, world.stall_length - world.block / 2 - row_setback + LONE_GAP)


def _check_fit(garage: Garage, world: WorldConfig, where: tuple[int, int], code: Block,
               setbacks: list[float]) -> None:
    """Refuse a geometry stall block ``where`` cannot hold with its rows moved by ``setbacks``, naming the fix."""
    half, pillar, L, W = world.block / 2, world.pillar_size, world.stall_length, world.stall_width
    at = f"garage {garage.name or 'garage'!r}, row {where[0]}, column {where[1]}"
    if code == Block.STALL6 and 2 * L > world.block + sum(setbacks) + 1e-9:
        deepest = half + min(setbacks)
        raise GeometryError(
            f"{at}: stall depth {L:g} m does not fit the back-to-back rows of a six-stall block (at most "
            f"{deepest:g} m beside {'a junction or turn' if min(setbacks) == 0 else f'{world.aisle_width:g} m aisles'})"
            f"; give --stall-depth {math.floor(deepest * 100) / 100:g} or less")
    if code in (Block.STALL4, Block.OBST_STALL4) and W + _lone_gap(world, setbacks[0]) > half + 1e-9:
        raise GeometryError(
            f"{at}: a four-stall block's lone stall does not fit beside its row at stall width {W:g} m and depth "
            f"{L:g} m; give a smaller --stall-depth or --stall-width")
    if code in (Block.OBST_STALL3, Block.OBST_STALL4) and 3 * W + 2 * pillar > world.block + 1e-9:
        widest = (world.block - 2 * pillar) / 3
        raise GeometryError(
            f"{at}: an obstructed stall block (codes 3 and 9) holds three stalls and two {pillar:g} m pillars in "
            f"{world.block:g} m; give --stall-width {math.floor(widest * 100) / 100:g} or less")
