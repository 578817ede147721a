"""Grid directions shared by the generation env, the road graph and the exporters.

Row 0 is north and column 0 is west (docs/spec.md section 2). Directions are indexed like the
generation env's actions: 0 west, 1 east, 2 north, 3 south.
"""

from __future__ import annotations

WEST, EAST, NORTH, SOUTH = 0, 1, 2, 3
DIRECTION_NAMES = ("west", "east", "north", "south")
#: (d_row, d_col) per direction.
DELTAS: tuple[tuple[int, int], ...] = ((0, -1), (0, 1), (-1, 0), (1, 0))
OPPOSITE = (EAST, WEST, SOUTH, NORTH)


def neighbours(r: int, c: int, h: int, w: int):
    """Yield ``(direction, row, col)`` of the in-grid 4-neighbours of (r, c)."""
    for d, (dr, dc) in enumerate(DELTAS):
        rr, cc = r + dr, c + dc
        if 0 <= rr < h and 0 <= cc < w:
            yield d, rr, cc
