"""Block codes of the encoding matrix (paper Table "taxonomy of blocks", docs/spec.md section 1)."""

from __future__ import annotations

from enum import IntEnum
from typing import Literal

import numpy as np


class Block(IntEnum):
    """One cell of a garage grid. The integer value is the paper's code."""

    FREE = 0
    ROAD = 1
    OBSTACLE = 2
    OBST_STALL3 = 3  # three-stall block touching an obstacle block
    STALL3 = 4
    STALL4 = 5  # three stalls + one lone stall
    STALL6 = 6  # two back-to-back rows of three
    ENTRANCE = 7
    EXIT = 8
    OBST_STALL4 = 9  # four-stall block touching an obstacle block


NUM_CODES = len(Block)

#: The axis along which a cell between two roads holds six stalls (docs/spec.md section 3's stall rule).
Axis = Literal["NS", "EW"]
AXES: tuple[Axis, ...] = ("NS", "EW")

#: Stalls held by each block code.
STALLS_PER_BLOCK: dict[Block, int] = {
    Block.OBST_STALL3: 3,
    Block.STALL3: 3,
    Block.STALL4: 4,
    Block.STALL6: 6,
    Block.OBST_STALL4: 4,
}

#: Lookup table code -> stalls, for vectorised counting.
STALL_TABLE = np.zeros(NUM_CODES, dtype=np.int64)
for _b, _n in STALLS_PER_BLOCK.items():
    STALL_TABLE[_b] = _n

#: Road-like cells: the road graph and the 2x2 rule use them.
ROAD_LIKE = frozenset({Block.ROAD, Block.ENTRANCE, Block.EXIT})
ROAD_LIKE_TABLE = np.zeros(NUM_CODES, dtype=bool)
ROAD_LIKE_TABLE[[Block.ROAD, Block.ENTRANCE, Block.EXIT]] = True

#: Stall codes (including the obstructed variants).
STALL_CODES = frozenset(STALLS_PER_BLOCK)

#: Codes allowed in an initial map (docs/spec.md section 2).
INITIAL_CODES = frozenset({Block.FREE, Block.OBSTACLE, Block.ENTRANCE, Block.EXIT})

#: Codes the stall rule may (re)colour.
PAINTABLE = frozenset({Block.FREE}) | STALL_CODES


def count_stalls(grid: np.ndarray) -> int:
    """Total parking stalls in ``grid``."""
    return int(STALL_TABLE[np.asarray(grid)].sum())
