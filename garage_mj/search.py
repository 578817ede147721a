"""Search baseline: which difficulties a map admits under the painter's rules (issue 11, item 2).

A painted garage is fixed by its set of ROAD cells: the stall rule colours the rest, and difficulty
depends on the roads alone. The painter (``GarageGenEnv``) can make exactly the road sets R that
  * lie on the map's FREE cells and contain the cell the entrance opens onto,
  * are 4-connected (the car paints a cell next to where it stands, and drives over road freely),
  * contain the cell the exit opens onto (the car enters the exit last), and
  * hold no 2x2 square of road-like cells (painting the fourth cell is refused).
Every such R is painted error-free by a depth-first walk (:func:`painter_actions`), and
:func:`replay` checks it by running the env.

:func:`search` is MAP-Elites over difficulty bins: start from garages of the scripted
:class:`~garage_mj.painter.ExitSeekingPainter`, mutate a random elite or, half of the time, the lowest or highest garage so far (grow a straight road or a
staircase from a road cell, or cut one and keep what stays joined to the entrance), and keep the first garage of
each bin plus the lowest and highest difficulty seen. The range it returns is what search reached:
a lower bound on the map's true range, with each end replayed through the env.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from garage_mj.blocks import Block
from garage_mj.garage import AXES, Axis, Garage
from garage_mj.geometry import DELTAS
from garage_mj.map_io import load_map
from garage_mj.metrics import DEFAULT_DIFFICULTY, difficulty
from garage_mj.roadgraph import analyse
from garage_mj.rules import apply_stall_rule

BIN_WIDTH = 0.1  # difficulty bin of the report
MAX_GROW = 4  # [cells] longest straight added by one mutation
SEED_GARAGES = 8  # painter garages the search starts from (per six-stall axis)
EXTREME_PARENT = 0.5  # share of mutations applied to the lowest or highest garage so far


@dataclass
class SearchResult:
    """What :func:`search` found on one map."""

    map: str
    evaluations: int
    lowest: tuple[float, Garage]  # (difficulty, garage), replayed through the env
    highest: tuple[float, Garage]
    bins: dict[int, tuple[float, Garage]] = field(default_factory=dict)  # bin index -> first garage found

    @property
    def range(self) -> tuple[float, float]:
        return self.lowest[0], self.highest[0]

    def bins_reached(self, width: float = BIN_WIDTH) -> list[int]:
        """Indices of the ``width``-wide difficulty bins (0 = [0, width)) holding a found garage."""
        return sorted({min(int(d / width), int(round(1 / width)) - 1) for d, _ in self.bins.values()})


class _Map:
    """The fixed facts of a map the search needs."""

    def __init__(self, garage: Garage) -> None:
        self.garage = garage
        self.initial = garage.initial
        self.free = self.initial == Block.FREE
        self.h, self.w = self.initial.shape
        self.start = _gate_neighbour(self.initial, garage.entrance)
        self.goal = _gate_neighbour(self.initial, garage.exit)
        self.gates = np.zeros_like(self.free)
        self.gates[garage.entrance] = self.gates[garage.exit] = True

    def grid(self, roads: np.ndarray) -> np.ndarray:
        """The initial map with ``roads`` painted ROAD (no stalls)."""
        g = self.initial.copy()
        g[roads] = Block.ROAD
        return g

    def garage_of(self, roads: np.ndarray, axis: Axis) -> Garage:
        return Garage(apply_stall_rule(self.grid(roads), axis), self.initial, six_stall_axis=axis,
                      name=self.garage.name)

    def repair(self, roads: np.ndarray) -> np.ndarray | None:
        """``roads`` cut to the part joined to the entrance; None if that misses the exit or has a square."""
        if not roads[self.start]:
            return None
        keep = np.zeros_like(roads)
        keep[self.start] = True
        queue = deque([self.start])
        while queue:
            r, c = queue.popleft()
            for dr, dc in DELTAS:
                q = (r + dr, c + dc)
                if 0 <= q[0] < self.h and 0 <= q[1] < self.w and roads[q] and not keep[q]:
                    keep[q] = True
                    queue.append(q)
        if not keep[self.goal]:
            return None
        like = keep | self.gates
        if (like[:-1, :-1] & like[1:, :-1] & like[:-1, 1:] & like[1:, 1:]).any():
            return None
        return keep

    def difficulty(self, roads: np.ndarray) -> float:
        a = analyse(self.grid(roads))
        cfg = DEFAULT_DIFFICULTY
        xs = [min(max(s.length, cfg.road_length_min), cfg.road_length_max) for s in a.segments]
        ys = a.intersection_degrees()
        ex = float(np.mean(xs)) if xs else float(cfg.road_length_min)
        ey = float(np.mean(ys)) if ys else float(cfg.intersection_min)
        return difficulty(ey, ex, cfg)


def _gate_neighbour(initial: np.ndarray, gate: tuple[int, int]) -> tuple[int, int]:
    h, w = initial.shape
    for dr, dc in DELTAS:
        r, c = gate[0] + dr, gate[1] + dc
        if 0 <= r < h and 0 <= c < w and initial[r, c] == Block.FREE:
            return r, c
    raise ValueError(f"gate {gate} opens onto no FREE cell")


def _mutate(m: _Map, roads: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
    new = roads.copy()
    cells = np.argwhere(roads)
    r, c = (int(x) for x in cells[rng.integers(len(cells))])
    d = int(rng.integers(4))
    dr, dc = DELTAS[d]
    n = int(rng.integers(1, MAX_GROW + 1))
    u = rng.random()
    if u < 0.6:  # grow a straight road from (r, c), or a staircase (alternating d and a turn)
        turn = DELTAS[(2 + int(rng.integers(2))) if d < 2 else int(rng.integers(2))]
        stairs = u < 0.2
        for i in range(2 * n if stairs else n):
            sr, sc = turn if stairs and i % 2 else (dr, dc)
            r, c = r + sr, c + sc
            if not (0 <= r < m.h and 0 <= c < m.w and m.free[r, c]):
                break
            new[r, c] = True
    else:  # cut up to n cells of a straight starting at (r, c)
        for _ in range(n):
            if not (0 <= r < m.h and 0 <= c < m.w and new[r, c]):
                break
            new[r, c] = False
            r, c = r + dr, c + dc
    return m.repair(new)


def painter_actions(garage: Garage) -> list[int]:
    """Actions (0 west, 1 east, 2 north, 3 south) that paint ``garage``'s roads error-free.

    A depth-first walk over the road cells from the cell the entrance opens onto that paints
    each cell on first entry, then the shortest road path to the exit's cell and into the exit.
    """
    m = _Map(garage)
    roads = garage.grid == Block.ROAD
    inward = next(d for d, (dr, dc) in enumerate(DELTAS) if (garage.entrance[0] + dr, garage.entrance[1] + dc) == m.start)
    actions = [inward]
    seen = {m.start}
    stack = [(m.start, 0)]
    while stack:  # iterative DFS with explicit backtracking moves
        (r, c), k = stack.pop()
        for d in range(k, 4):
            dr, dc = DELTAS[d]
            q = (r + dr, c + dc)
            if 0 <= q[0] < m.h and 0 <= q[1] < m.w and roads[q] and q not in seen:
                seen.add(q)
                actions.append(d)
                stack.append(((r, c), d + 1))
                stack.append((q, 0))
                break
        else:
            if stack:  # back to the parent
                parent = stack[-1][0]
                actions.append(next(d for d, (dr, dc) in enumerate(DELTAS) if (r + dr, c + dc) == parent))
    # the walk ends back at the start cell: go to the exit's cell along roads, then into the exit
    prev = {m.start: None}
    queue = deque([m.start])
    while queue:
        p = queue.popleft()
        for d, (dr, dc) in enumerate(DELTAS):
            q = (p[0] + dr, p[1] + dc)
            if 0 <= q[0] < m.h and 0 <= q[1] < m.w and roads[q] and q not in prev:
                prev[q] = (p, d)
                queue.append(q)
    path = []
    p = m.goal
    while prev[p] is not None:
        p, d = prev[p]
        path.append(d)
    actions.extend(reversed(path))
    actions.append(next(d for d, (dr, dc) in enumerate(DELTAS) if (m.goal[0] + dr, m.goal[1] + dc) == garage.exit))
    return actions


def replay(garage: Garage, max_errors: int = 10) -> tuple[Garage, dict]:
    """Paint ``garage`` with :func:`painter_actions` in ``GarageGenEnv``; the env's garage and last info."""
    from garage_mj.envs.gen_env import GarageGenEnv

    actions = painter_actions(garage)
    env = GarageGenEnv(map=garage, six_stall_axis=garage.six_stall_axis, max_errors=max_errors,
                       max_steps=max(4 * garage.grid.size, len(actions)))
    env.reset(seed=0)
    info: dict = {}
    for a in actions:
        _, _, term, trunc, info = env.step(a)
        if term or trunc:
            break
    return env.garage(), info


def search(map: str | Garage, evaluations: int = 5_000, seed: int = 0, bin_width: float = BIN_WIDTH / 2) -> SearchResult:
    """MAP-Elites over difficulty bins of ``bin_width`` on ``map`` for ``evaluations`` mutations.

    Raises RuntimeError if an end of the range does not replay to a usable garage of the same
    difficulty (the search's model of the painter would be wrong).
    """
    from garage_mj.painter import paint_garage

    base = map if isinstance(map, Garage) else load_map(map)
    m = _Map(base)
    rng = np.random.default_rng(seed)
    n_bins = int(round(1 / bin_width))
    elites: dict[int, tuple[float, np.ndarray, Axis]] = {}
    lowest = highest = None

    def consider(roads: np.ndarray, axis: Axis) -> None:
        nonlocal lowest, highest
        d = m.difficulty(roads)
        b = min(int(d / bin_width), n_bins - 1)
        if b not in elites or rng.random() < 0.3:  # occasional replacement keeps the bins drifting
            elites[b] = (d, roads, axis)
        if lowest is None or d < lowest[0]:
            lowest = (d, roads, axis)
        if highest is None or d > highest[0]:
            highest = (d, roads, axis)

    for i in range(SEED_GARAGES):
        for axis in AXES:
            g = paint_garage(base, seed=seed * 1000 + i, six_stall_axis=axis)
            roads = m.repair(g.grid == Block.ROAD)
            if roads is not None:
                consider(roads, axis)
    for _ in range(evaluations):
        u = rng.random()
        if u < EXTREME_PARENT:  # push the ends of the range
            _, roads, axis = lowest if u < EXTREME_PARENT / 2 else highest
        else:
            keys = list(elites)
            _, roads, axis = elites[keys[rng.integers(len(keys))]]
        child = _mutate(m, roads, rng)
        if child is not None:
            consider(child, axis)

    def checked(entry: tuple[float, np.ndarray, Axis]) -> tuple[float, Garage]:
        d, roads, axis = entry
        garage = m.garage_of(roads, axis)
        painted, info = replay(garage)
        if not info.get("usable") or not np.array_equal(painted.grid, garage.grid) or abs(info["difficulty"] - d) > 1e-9:
            raise RuntimeError(f"{base.name}: a searched garage (difficulty {d:.3f}) did not replay through the env")
        return d, painted

    return SearchResult(
        map=base.name, evaluations=evaluations, lowest=checked(lowest), highest=checked(highest),
        bins={b: (d, m.garage_of(r, a)) for b, (d, r, a) in elites.items()},
    )


__all__ = ["SearchResult", "painter_actions", "replay", "search"]
