"""The painter's rules (docs/spec.md section 3): the stall rule and the 2x2 road-square rule.

Pure functions over a grid; the generation env applies them locally after each move, and the
validity check applies them to a whole grid.
"""

from __future__ import annotations

import numpy as np

from garage_mj.grid.blocks import PAINTABLE, ROAD_LIKE_TABLE, Axis, Block

_W, _E, _N, _S = 0, 1, 2, 3


def stall_code(road_sides: int, touches_obstacle: bool, axis: Axis) -> Block:
    """Block a FREE/stall cell must hold given the bitmask of its ROAD sides (0 W, 1 E, 2 N, 3 S).

    - no ROAD side: FREE
    - ROAD on both sides along the six-stall axis: STALL6
    - one ROAD side, or the only symmetric pair is on the wrong axis with two sides: (OBST_)STALL3
    - otherwise (a corner, three or four sides): (OBST_)STALL4
    """
    if road_sides == 0:
        return Block.FREE
    ew = (road_sides & 0b0011) == 0b0011
    ns = (road_sides & 0b1100) == 0b1100
    if (ns and axis == "NS") or (ew and axis == "EW"):
        return Block.STALL6
    n = bin(road_sides).count("1")
    if n == 1 or (n == 2 and (ew or ns)):
        return Block.OBST_STALL3 if touches_obstacle else Block.STALL3
    return Block.OBST_STALL4 if touches_obstacle else Block.STALL4


def expected_cell(grid: np.ndarray, r: int, c: int, axis: Axis) -> Block:
    """What the stall rule says cell (r, c) of ``grid`` must hold (it must be FREE or a stall)."""
    h, w = grid.shape
    sides = 0
    obstacle = False
    for d, (rr, cc) in enumerate(((r, c - 1), (r, c + 1), (r - 1, c), (r + 1, c))):
        if 0 <= rr < h and 0 <= cc < w:
            v = grid[rr, cc]
            if v == Block.ROAD:
                sides |= 1 << d
            elif v == Block.OBSTACLE:
                obstacle = True
    return stall_code(sides, obstacle, axis)


def road_squares(grid: np.ndarray) -> list[tuple[int, int]]:
    """Top-left corners of every 2x2 square of road-like cells in ``grid``."""
    road = ROAD_LIKE_TABLE[grid]
    sq = road[:-1, :-1] & road[1:, :-1] & road[:-1, 1:] & road[1:, 1:]
    return [(int(r), int(c)) for r, c in np.argwhere(sq)]


def _code_table(axis: Axis) -> np.ndarray:
    """:func:`stall_code` for every (road-side bitmask 0-15, touches obstacle 0/1), as a (16, 2) array."""
    return np.array([[int(stall_code(sides, bool(obst), axis)) for obst in (0, 1)] for sides in range(16)])


_CODE_TABLES = {axis: _code_table(axis) for axis in ("NS", "EW")}


def expected_cells(grid: np.ndarray, axis: Axis) -> np.ndarray:
    """:func:`expected_cell` of every cell at once (meaningful where the cell is FREE or a stall)."""
    g = np.pad(np.asarray(grid), 1, constant_values=-1)  # off-grid: neither ROAD nor OBSTACLE
    sides = np.zeros(np.shape(grid), dtype=np.int64)
    obstacle = np.zeros(np.shape(grid), dtype=np.int64)
    for d, nb in enumerate((g[1:-1, :-2], g[1:-1, 2:], g[:-2, 1:-1], g[2:, 1:-1])):  # W, E, N, S
        sides |= (nb == Block.ROAD).astype(np.int64) << d
        obstacle |= nb == Block.OBSTACLE
    return _CODE_TABLES[axis][sides, obstacle]


def stall_rule_violations(grid: np.ndarray, axis: Axis) -> list[tuple[int, int]]:
    """Cells that are FREE or a stall but not what the stall rule says (row by row)."""
    paintable = np.isin(grid, [int(b) for b in PAINTABLE])
    bad = paintable & (np.asarray(grid) != expected_cells(grid, axis))
    return [(int(r), int(c)) for r, c in np.argwhere(bad)]


def apply_stall_rule(grid: np.ndarray, axis: Axis) -> np.ndarray:
    """A copy of ``grid`` with every FREE/stall cell recoloured by the stall rule.

    Handy for garages drawn by hand: paint the ROAD cells, then derive the stalls.
    """
    out = np.array(grid, copy=True)
    paintable = np.isin(out, [int(b) for b in PAINTABLE])
    out[paintable] = expected_cells(out, axis)[paintable]  # depends on ROAD and OBSTACLE cells only
    return out
