"""Draw a grid as text for terminals (the demo, ``render_mode="ansi"``, ``garage-mj show``)."""

from __future__ import annotations

import numpy as np

from garage_mj.grid.blocks import Block

SYMBOLS = {
    Block.FREE: ".",
    Block.ROAD: "=",
    Block.OBSTACLE: "#",
    Block.OBST_STALL3: "t",
    Block.STALL3: "3",
    Block.STALL4: "4",
    Block.STALL6: "6",
    Block.ENTRANCE: "E",
    Block.EXIT: "X",
    Block.OBST_STALL4: "f",
}
LEGEND = (
    ". free  = road  # obstacle  3/4/6 stall block  t/f obstructed 3/4-stall block  "
    "E entrance  X exit  @ car"
)


def draw(grid: np.ndarray, car: tuple[int, int] | None = None, legend: bool = False) -> str:
    rows = []
    for r, row in enumerate(np.asarray(grid)):
        cells = [SYMBOLS[Block(int(v))] for v in row]
        if car is not None and car[0] == r:
            cells[car[1]] = "@"
        rows.append(" ".join(cells))
    if legend:
        rows.append(LEGEND)
    return "\n".join(rows)
