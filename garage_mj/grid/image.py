"""RGB pictures of an encoding matrix with the painter car, in numpy only (no matplotlib).

``grid_image(grid, car, heading)`` is what ``GarageGenEnv(render_mode="rgb_array")`` returns: one
``cell_px`` square per cell in the block colours of ``garage-mj show`` (:data:`garage_mj.reporting.plots.BLOCK_COLOURS`),
thin white lines between cells, and the car as a yellow square with a black nose on the side it heads to.
Cheap enough for every frame of a ``RecordVideo`` (under a millisecond for a 7x11 grid).
"""

from __future__ import annotations

import numpy as np

from garage_mj.core.geometry import DELTAS
from garage_mj.grid.blocks import NUM_CODES, Block

CELL_PX = 16  # [pixels] side of one grid cell
#: Colour of each block code, shared with :mod:`garage_mj.reporting.plots` (one table for every picture of a grid).
BLOCK_COLOURS = {
    Block.FREE: "#f2f2f2",
    Block.ROAD: "#5b5b5b",
    Block.OBSTACLE: "#1e1e1e",
    Block.OBST_STALL3: "#f4a582",
    Block.STALL3: "#92c5de",
    Block.STALL4: "#4393c3",
    Block.STALL6: "#2166ac",
    Block.ENTRANCE: "#1a9850",
    Block.EXIT: "#d73027",
    Block.OBST_STALL4: "#d6604d",
}
#: (NUM_CODES, 3) uint8 colour per block code.
BLOCK_RGB = np.array([[int(BLOCK_COLOURS[Block(i)][k : k + 2], 16) for k in (1, 3, 5)] for i in range(NUM_CODES)],
                     dtype=np.uint8)
CAR_RGB = np.array([255, 215, 0], dtype=np.uint8)
NOSE_RGB = np.array([0, 0, 0], dtype=np.uint8)
LINE_RGB = np.array([255, 255, 255], dtype=np.uint8)


def grid_image(grid: np.ndarray, car: tuple[int, int] | None = None, heading: int | None = None,
               cell_px: int = CELL_PX) -> np.ndarray:
    """An (H * cell_px, W * cell_px, 3) uint8 picture of ``grid`` (row 0 north at the top).

    ``car`` is the (row, col) of the painter car and ``heading`` its direction (0 west, 1 east,
    2 north, 3 south, as the env's actions); either may be None.
    """
    if cell_px < 4:
        raise ValueError(f"cell_px must be >= 4, got {cell_px}")
    g = np.asarray(grid)
    img = np.repeat(np.repeat(BLOCK_RGB[g], cell_px, axis=0), cell_px, axis=1)
    img[::cell_px, :] = LINE_RGB
    img[:, ::cell_px] = LINE_RGB
    if car is not None:
        r, c = car
        q = cell_px // 4
        y0, x0 = r * cell_px, c * cell_px
        img[y0 + q : y0 + cell_px - q + 1, x0 + q : x0 + cell_px - q + 1] = CAR_RGB
        if heading is not None:
            dr, dc = DELTAS[heading]
            cy, cx = y0 + cell_px // 2, x0 + cell_px // 2
            ny, nx = cy + dr * (cell_px // 2 - q), cx + dc * (cell_px // 2 - q)
            h = max(q // 2, 1)
            img[ny - h : ny + h + 1, nx - h : nx + h + 1] = NOSE_RGB
    return img
