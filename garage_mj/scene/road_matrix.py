"""The road network matrix (paper Sec. "3D Maps Generation"): one entry per road-like cell.

Each entry holds the tile (dead end, straight, curve, T, cross, entrance, exit), the rotation
of the tile's canonical model (0/90/180/270 degrees counter-clockwise about z) and the world
position of the cell centre. Pure: grid in, records out. Every exporter (OpenDRIVE, MJCF,
meshes) and the drive env read roads from here and nowhere else.

Canonical orientations (rotation 0), with E = +x and N = +y:
- dead end, entrance, exit: open to the east
- straight: east-west
- curve: open to east and north
- T: open to west, east and north (closed to the south)
- cross: open on all four sides
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from garage_mj.core.geometry import DELTAS, EAST, NORTH, SOUTH, WEST
from garage_mj.core.words import a_noun
from garage_mj.grid.blocks import Block
from garage_mj.grid.garage import Garage
from garage_mj.grid.road_segments import Tile, analyse
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig, cell_center


class RoadTile(Enum):
    DEAD_END = "dead_end"
    STRAIGHT = "straight"
    CURVE = "curve"
    T = "t_junction"
    CROSS = "cross"
    ENTRANCE = "entrance"
    EXIT = "exit"


#: Counter-clockwise order of directions: rotating by 90 degrees maps E->N->W->S->E.
_CCW = (EAST, NORTH, WEST, SOUTH)


def _rotate_set(dirs: frozenset[int], quarter_turns: int) -> frozenset[int]:
    return frozenset(_CCW[(_CCW.index(d) + quarter_turns) % 4] for d in dirs)


_CANONICAL = {
    RoadTile.DEAD_END: frozenset({EAST}),
    RoadTile.STRAIGHT: frozenset({WEST, EAST}),
    RoadTile.CURVE: frozenset({EAST, NORTH}),
    RoadTile.T: frozenset({WEST, EAST, NORTH}),
    RoadTile.CROSS: frozenset({WEST, EAST, NORTH, SOUTH}),
}
_CANONICAL[RoadTile.ENTRANCE] = _CANONICAL[RoadTile.DEAD_END]
_CANONICAL[RoadTile.EXIT] = _CANONICAL[RoadTile.DEAD_END]

_TILE_OF = {
    Tile.DEAD_END: RoadTile.DEAD_END,
    Tile.STRAIGHT: RoadTile.STRAIGHT,
    Tile.CURVE: RoadTile.CURVE,
    Tile.T: RoadTile.T,
    Tile.CROSS: RoadTile.CROSS,
}


def tile_rotation(tile: RoadTile, openings: frozenset[int]) -> int:
    """Rotation in degrees (0/90/180/270, smallest that fits) mapping the canonical tile onto ``openings``."""
    for k in range(4):
        if _rotate_set(_CANONICAL[tile], k) == openings:
            return 90 * k
    raise ValueError(f"openings {sorted(openings)} do not fit {a_noun(tile.value)} tile")


def tile_openings(tile: RoadTile, rotation: int) -> frozenset[int]:
    """Directions (0 W, 1 E, 2 N, 3 S) a tile with ``rotation`` opens to (inverse of tile_rotation)."""
    return _rotate_set(_CANONICAL[tile], (rotation // 90) % 4)


@dataclass(frozen=True)
class RoadCell:
    row: int
    col: int
    tile: RoadTile
    rotation: int  # [deg] counter-clockwise, 0/90/180/270
    x: float  # [m] world position of the cell centre
    y: float  # [m]
    openings: frozenset[int]  # directions with a road-like neighbour (0 W, 1 E, 2 N, 3 S)

    @property
    def position(self) -> tuple[int, int]:
        return (self.row, self.col)


@dataclass(frozen=True)
class RoadNetwork:
    """The road network matrix of one garage."""

    rows: int
    cols: int
    cells: dict[tuple[int, int], RoadCell]
    entrance: tuple[int, int]
    exit: tuple[int, int]
    world: WorldConfig

    def neighbours(self, cell: tuple[int, int]) -> list[tuple[int, int]]:
        """Road-like cells joined to ``cell``."""
        rc = self.cells[cell]
        return [(rc.row + DELTAS[d][0], rc.col + DELTAS[d][1]) for d in sorted(rc.openings)]

    def edges(self) -> set[frozenset[tuple[int, int]]]:
        """Undirected connections between road-like cells, from the tiles' openings."""
        return {frozenset((p, q)) for p in self.cells for q in self.neighbours(p)}

    def tile_counts(self) -> dict[str, int]:
        out = {t.value: 0 for t in RoadTile}
        for c in self.cells.values():
            out[c.tile.value] += 1
        return out


def road_network(garage: Garage, world: WorldConfig = DEFAULT_WORLD) -> RoadNetwork:
    """Build the road network matrix of ``garage``."""
    a = analyse(garage.grid)
    rows, cols = garage.shape
    cells: dict[tuple[int, int], RoadCell] = {}
    for (r, c), mask in a.masks.items():
        openings = frozenset(d for d in range(4) if mask >> d & 1)
        code = garage.grid[r, c]
        if code in (Block.ENTRANCE, Block.EXIT):
            tile = RoadTile.ENTRANCE if code == Block.ENTRANCE else RoadTile.EXIT
            if len(openings) != 1:  # a gate not (yet) joined to a road: face inward
                openings = frozenset({_gate_inward(garage, r, c)})
        elif a.tiles[(r, c)] == Tile.ISOLATED:
            raise ValueError(f"road cell ({r}, {c}) touches no other road-like cell")
        else:
            tile = _TILE_OF[a.tiles[(r, c)]]
        x, y = cell_center(r, c, rows, world)
        cells[(r, c)] = RoadCell(r, c, tile, tile_rotation(tile, openings), x, y, openings)
    return RoadNetwork(rows, cols, cells, garage.entrance, garage.exit, world)


def _gate_inward(garage: Garage, r: int, c: int) -> int:
    h, w = garage.shape
    for d, (dr, dc) in enumerate(DELTAS):
        rr, cc = r + dr, c + dc
        if 0 <= rr < h and 0 <= cc < w and garage.initial[rr, cc] != Block.OBSTACLE:
            return d
    raise ValueError(f"gate ({r}, {c}) has no open neighbour")  # Garage validation prevents this
