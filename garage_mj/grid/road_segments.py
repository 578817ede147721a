"""Road graph, tile classification and road segments (docs/spec.md section 4).

Nodes are road-like cells (ROAD, ENTRANCE, EXIT), edges join 4-adjacent road-like cells. Each
road-like cell is a tile by its degree: dead end (1), straight (2, opposite), curve (2,
perpendicular), T (3) or cross (4). Key nodes are all road-like cells except straights; a
segment is a chain of straights between two key nodes, counted with both ends.

Two ways in: :func:`analyse` recomputes everything from a grid (metrics, exporters), and
:class:`RoadTracker` keeps the same statistics up to date one painted cell at a time (the
generation env), at a cost bounded by one row or column, not the map.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from garage_mj.core.geometry import DELTAS, OPPOSITE
from garage_mj.grid.blocks import ROAD_LIKE_TABLE


class Tile(IntEnum):
    ISOLATED = 0  # road-like cell with no road-like neighbour (a gate before any road)
    DEAD_END = 1
    STRAIGHT = 2
    CURVE = 3
    T = 4
    CROSS = 5


#: Bitmask of the directions (0 W, 1 E, 2 N, 3 S) that hold road-like neighbours -> tile.
def _tile_for_mask(mask: int) -> Tile:
    n = bin(mask).count("1")
    if n == 0:
        return Tile.ISOLATED
    if n == 1:
        return Tile.DEAD_END
    if n == 2:
        return Tile.STRAIGHT if mask in (0b0011, 0b1100) else Tile.CURVE
    return Tile.T if n == 3 else Tile.CROSS


TILE_OF_MASK: tuple[Tile, ...] = tuple(_tile_for_mask(m) for m in range(16))
#: Intersection degree Y that a tile contributes (None: not counted).
Y_OF_TILE = {Tile.CURVE: 2, Tile.T: 3, Tile.CROSS: 4}
# the same tables by neighbour mask, for RoadTracker's inner loops
_STRAIGHT_MASKS = frozenset(m for m in range(16) if TILE_OF_MASK[m] == Tile.STRAIGHT)
_Y_OF_MASK: tuple[int | None, ...] = tuple(Y_OF_TILE.get(TILE_OF_MASK[m]) for m in range(16))
_DIRECTION = {delta: d for d, delta in enumerate(DELTAS)}


def road_mask(grid: np.ndarray) -> np.ndarray:
    """Boolean H x W array of road-like cells."""
    return ROAD_LIKE_TABLE[np.asarray(grid)]


def neighbour_mask(road: np.ndarray, r: int, c: int) -> int:
    """Bitmask of road-like 4-neighbours of (r, c) in boolean array ``road``."""
    h, w = road.shape
    m = 0
    for d, (dr, dc) in enumerate(DELTAS):
        rr, cc = r + dr, c + dc
        if 0 <= rr < h and 0 <= cc < w and road[rr, cc]:
            m |= 1 << d
    return m


@dataclass(frozen=True)
class Segment:
    """A chain of cells from one key node to another (both included)."""

    cells: tuple[tuple[int, int], ...]

    @property
    def length(self) -> int:
        return len(self.cells)


@dataclass(frozen=True)
class RoadAnalysis:
    """Everything the metrics and exporters need to know about a grid's roads."""

    masks: dict[tuple[int, int], int]  # road-like cell -> neighbour bitmask
    tiles: dict[tuple[int, int], Tile]
    segments: tuple[Segment, ...]

    @property
    def key_nodes(self) -> list[tuple[int, int]]:
        return [p for p, t in self.tiles.items() if t != Tile.STRAIGHT]

    def intersection_degrees(self) -> list[int]:
        """Y of every key node of degree >= 2 (curve 2, T 3, cross 4)."""
        return [Y_OF_TILE[t] for t in self.tiles.values() if t in Y_OF_TILE]

    def tile_counts(self) -> dict[str, int]:
        counts = Counter(t.name.lower() for t in self.tiles.values())
        return {t.name.lower(): counts.get(t.name.lower(), 0) for t in Tile}

    def edges(self) -> set[frozenset[tuple[int, int]]]:
        """Undirected edges of the road graph (pairs of 4-adjacent road-like cells)."""
        return {
            frozenset((p, (p[0] + dr, p[1] + dc)))
            for p, m in self.masks.items()
            for d, (dr, dc) in enumerate(DELTAS)
            if m >> d & 1
        }

    def component(self, start: tuple[int, int]) -> set[tuple[int, int]]:
        """Road-like cells reachable from ``start`` (empty if ``start`` is not road-like)."""
        if start not in self.masks:
            return set()
        seen = {start}
        queue = deque([start])
        while queue:
            r, c = queue.popleft()
            m = self.masks[(r, c)]
            for d, (dr, dc) in enumerate(DELTAS):
                if m >> d & 1:
                    q = (r + dr, c + dc)
                    if q not in seen:
                        seen.add(q)
                        queue.append(q)
        return seen

    def connected(self, a: tuple[int, int], b: tuple[int, int]) -> bool:
        return b in self.component(a)


def _walk(masks_get, start: tuple[int, int], d: int) -> list[tuple[int, int]]:
    """Cells from key node ``start`` stepping ``d`` through straights to the next key node."""
    r, c = start
    dr, dc = DELTAS[d]
    cells = [start]
    while True:
        r, c = r + dr, c + dc
        cells.append((r, c))
        if masks_get((r, c)) not in _STRAIGHT_MASKS:
            return cells  # a straight is entered and left in the same direction


def _run(masks_get, start: tuple[int, int], d: int) -> tuple[tuple[int, int], int]:
    """The key node a walk from ``start`` in direction ``d`` ends at, and the cells of the segment (both
    ends counted): :func:`_walk` without the list, whose key is ``(start, d)`` and ``(end, OPPOSITE[d])``."""
    r, c = start
    dr, dc = DELTAS[d]
    n = 1
    while True:
        r, c = r + dr, c + dc
        n += 1
        if masks_get((r, c)) not in _STRAIGHT_MASKS:
            return (r, c), n


def analyse(grid: np.ndarray) -> RoadAnalysis:
    """Tiles and segments of ``grid``, computed from scratch."""
    road = road_mask(grid)
    masks = {
        (int(r), int(c)): neighbour_mask(road, int(r), int(c)) for r, c in np.argwhere(road)
    }
    tiles = {p: TILE_OF_MASK[m] for p, m in masks.items()}
    segs: dict[tuple, Segment] = {}
    for p, t in tiles.items():
        if t == Tile.STRAIGHT:
            continue
        m = masks[p]
        for d in range(4):
            if m >> d & 1:
                cells = _walk(masks.__getitem__, p, d)
                key = _segment_key(cells)
                if key not in segs:
                    segs[key] = Segment(tuple(cells))
    return RoadAnalysis(masks, tiles, tuple(segs[k] for k in sorted(segs)))


def _direction(a: tuple[int, int], b: tuple[int, int]) -> int:
    return _DIRECTION[(b[0] - a[0], b[1] - a[1])]


def _key(a: tuple, b: tuple) -> tuple:
    """Canonical key of the segment whose two ends are ``a`` and ``b``, each (end cell, direction into the
    segment): the same whichever end it is seen from."""
    return (a, b) if a <= b else (b, a)


def _segment_key(cells: list[tuple[int, int]]) -> tuple:
    """Canonical key: the smaller of (end, first direction) seen from either end."""
    return _key((cells[0], _direction(cells[0], cells[1])), (cells[-1], _direction(cells[-1], cells[-2])))


class RoadTracker:
    """Incrementally maintained road statistics of a grid being painted road by road.

    Keeps the neighbour bitmask of every road-like cell, the histogram of segment lengths X
    (clipped to ``[x_min, x_max]``) and of intersection degrees Y. :meth:`add_road` updates them
    by looking only at the new cell, its neighbours and the segments through them.
    """

    def __init__(self, grid: np.ndarray, x_min: int = 2, x_max: int = 6) -> None:
        self.x_min, self.x_max = x_min, x_max
        a = analyse(grid)
        self.masks: dict[tuple[int, int], int] = dict(a.masks)
        self.segments: dict[tuple, int] = {}
        for s in a.segments:
            self.segments[_segment_key(list(s.cells))] = self._clip(s.length)
        self.x_hist: Counter[int] = Counter(self.segments.values())
        self.y_hist: Counter[int] = Counter(a.intersection_degrees())

    def _clip(self, n: int) -> int:
        return min(max(n, self.x_min), self.x_max)

    def _segments_at(self, p: tuple[int, int]) -> dict[tuple, int]:
        m = self.masks[p]
        get = self.masks.__getitem__
        if m in _STRAIGHT_MASKS:
            # walk to one key end, then walk the whole chain back from there
            d = (m & -m).bit_length() - 1
            a, _ = _run(get, p, d)
            back = OPPOSITE[d]
            b, n = _run(get, a, back)
            return {_key((a, back), (b, d)): self._clip(n)}
        out = {}
        for d in range(4):
            if m >> d & 1:
                b, n = _run(get, p, d)
                out[_key((p, d), (b, OPPOSITE[d]))] = self._clip(n)
        return out

    def copy(self) -> RoadTracker:
        """An independent tracker in the same state (cheaper than analysing the grid again)."""
        new = RoadTracker.__new__(RoadTracker)
        new.x_min, new.x_max = self.x_min, self.x_max
        new.masks, new.segments = dict(self.masks), dict(self.segments)
        new.x_hist, new.y_hist = Counter(self.x_hist), Counter(self.y_hist)
        return new

    def add_road(self, r: int, c: int) -> None:
        """Record that (r, c) became road-like."""
        p = (r, c)
        if p in self.masks:
            return
        touched = []
        for d, (dr, dc) in enumerate(DELTAS):
            q = (r + dr, c + dc)
            if q in self.masks:
                touched.append((q, d))
        # remove the old statistics of every touched neighbour and the segments through it
        old: dict[tuple, int] = {}
        for q, _ in touched:
            old.update(self._segments_at(q))
            y = _Y_OF_MASK[self.masks[q]]
            if y is not None:
                self.y_hist[y] -= 1
        for k, x in old.items():
            del self.segments[k]
            self.x_hist[x] -= 1
        # apply the change
        m = 0
        for q, d in touched:
            m |= 1 << d
            self.masks[q] |= 1 << OPPOSITE[d]
        self.masks[p] = m
        # add the new statistics
        new: dict[tuple, int] = {}
        for q in [p] + [q for q, _ in touched]:
            new.update(self._segments_at(q))
            y = _Y_OF_MASK[self.masks[q]]
            if y is not None:
                self.y_hist[y] += 1
        for k, x in new.items():
            self.segments[k] = x
            self.x_hist[x] += 1

    def mean_x(self) -> float:
        """E[X] over segments (x_min when there is none)."""
        n = len(self.segments)
        if n == 0:
            return float(self.x_min)
        return sum(x * k for x, k in self.x_hist.items()) / n

    def mean_y(self) -> float:
        """E[Y] over key nodes of degree >= 2 (2 when there is none)."""
        n = sum(self.y_hist.values())
        if n == 0:
            return 2.0
        return sum(y * k for y, k in self.y_hist.items()) / n

