"""Search baseline: which difficulties a map admits under the painter's rules.

A painted garage is fixed by its set of ROAD cells: the stall rule colours the rest, and difficulty
depends on the roads alone. The painter (``GarageGenEnv``) can make exactly the road sets R that
  * lie on the map's FREE cells and contain the cell the entrance opens onto,
  * are 4-connected (the car paints a cell next to where it stands, and drives over road freely),
  * contain the cell the exit opens onto (the car enters the exit last), and
  * hold no 2x2 square of road-like cells (painting the fourth cell is refused).
Every such R is painted error-free by a depth-first walk (:func:`painter_actions`), and
:func:`replay` checks it by running the env.

:func:`search` is MAP-Elites over difficulty bins: start from garages of the scripted
:class:`~garage_mj.grid.painters.ExitSeekingPainter`, mutate a random elite or, half of the time, the lowest or highest garage so far (grow a straight road or a
staircase from a road cell, or cut one and keep what stays joined to the entrance), and keep the first garage of
each bin plus the lowest and highest difficulty seen. The range it returns is what search reached:
a lower bound on the map's true range, with each end replayed through the env.

:class:`BandClimber` uses the same mutation (:func:`mutate`) the other way round: from given
garages it hill-climbs road sets toward a difficulty (and coverage) band, then walks inside the
band, and hands out every new road set that lands there (``garage-mj generate``'s second stage).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from garage_mj.core.geometry import DELTAS
from garage_mj.grid.blocks import AXES, Axis, Block
from garage_mj.grid.garage import Garage
from garage_mj.grid.map_io import load_map
from garage_mj.grid.metrics import DEFAULT_DIFFICULTY, difficulty
from garage_mj.grid.road_segments import analyse
from garage_mj.grid.rules import apply_stall_rule

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
    """One random mutation of ``roads`` (see :func:`mutate`)."""
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


def road_set(garage: Garage) -> np.ndarray | None:
    """``garage``'s ROAD cells as a road set the painter can make, or None (not joined to both gates, or a square)."""
    return _Map(garage).repair(garage.grid == Block.ROAD)


def mutate(garage: Garage, rng: np.random.Generator) -> Garage | None:
    """One random mutation of ``garage``'s road set under the painter's rules, or None if it broke them.

    Grows a straight road or a staircase of up to :data:`MAX_GROW` steps from a road cell, or cuts
    up to that many cells of a straight and keeps what stays joined to the entrance; the result must
    still reach the exit and hold no 2x2 square. The six-stall axis is kept.
    """
    m = _Map(garage)
    roads = m.repair(garage.grid == Block.ROAD)
    child = None if roads is None else _mutate(m, roads, rng)
    return None if child is None else m.garage_of(child, garage.six_stall_axis)


def _free_left(m: _Map, roads: np.ndarray) -> int:
    """FREE cells left once ``roads`` are painted: FREE cells with no ROAD 4-neighbour (the stall rule)."""
    near = roads.copy()
    near[1:, :] |= roads[:-1, :]
    near[:-1, :] |= roads[1:, :]
    near[:, 1:] |= roads[:, :-1]
    near[:, :-1] |= roads[:, 1:]
    return int(np.count_nonzero(m.free & ~near))


def _outside(x: float, band: tuple[float, float]) -> float:
    return max(band[0] - x, 0.0, x - band[1])


CLIMBERS = 8  # road sets the climb keeps outside the band (the nearest to it)
MAX_CHAIN = 3  # mutations chained into one step of the climb (a wider neighbourhood than one)
STALL_STEPS = 2_000  # steps without progress (a new road set in the band, or a climber nearer than ever) before a restart
WALK_SHARE = 0.5  # share of mutations spent walking inside the band once it holds a road set


class BandClimber:
    """Hill-climb road sets of a map toward a difficulty (and coverage) band and walk inside it.

    Seed it with garages (:meth:`add`); each :meth:`step` mutates one road set (:func:`mutate`'s
    operators): with probability :data:`WALK_SHARE`, once the band holds road sets, a random one of
    them, kept only if the child stays in the band (a walk that spreads inside the band); otherwise
    one of the :data:`CLIMBERS` road sets nearest to the band (the nearest half of the time),
    replaced by its child when the child is no farther (neutral moves let it cross plateaus).
    A step chains one to :data:`MAX_CHAIN` mutations. After :data:`STALL_STEPS` steps without
    progress the climbers restart from the next seeds (all seeds outside the band, nearest first,
    cycling). Distance = how far difficulty lies outside its band plus how far coverage lies outside its.
    :meth:`step` returns ``(garage, difficulty, coverage)`` when the child is a road set in the
    band not seen before (the garage built by the stall rule, not yet replayed through the env),
    else None. Deterministic for the ``rng`` given.
    """

    def __init__(self, base: Garage, difficulty: tuple[float, float], coverage: tuple[float, float] | None = None,
                 rng: np.random.Generator | None = None, metric: Callable[[Garage], float] | None = None) -> None:
        self.m = _Map(base)
        self.metric = metric  # None: the paper's difficulty of the road set; else metric(garage) climbs that
        self._metric_cache: dict[bytes, float] = {}
        self.band = (float(difficulty[0]), float(difficulty[1]))
        self.cov_band = (0.0, 1.0) if coverage is None else (float(coverage[0]), float(coverage[1]))
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.free0 = int(np.count_nonzero(self.m.free))
        self.climbers: list[tuple[float, np.ndarray, Axis]] = []  # (distance, roads, axis), nearest first
        self.reserve: list[tuple[float, np.ndarray, Axis]] = []  # every seed outside the band, in the order added
        self.next_seed = 0
        self.best = float("inf")
        self.stalled = 0
        self.restarts = 0
        self.inside: list[tuple[np.ndarray, Axis]] = []
        self.seen: set[bytes] = set()
        self.evaluations = 0

    def _key(self, roads: np.ndarray, axis: Axis) -> bytes:
        return axis.encode() + np.packbits(roads).tobytes()

    def measure(self, roads: np.ndarray, axis: Axis = "NS") -> tuple[float, float, float]:
        """(difficulty, coverage, distance to the bands) of a road set (``axis``: its six-stall axis, which
        only a ``metric`` reads; NaN, a garage the metric cannot rate, lies outside every band)."""
        if self.metric is None:
            d = self.m.difficulty(roads)
        else:
            key = self._key(roads, axis)
            if key not in self._metric_cache:
                self._metric_cache[key] = float(self.metric(self.m.garage_of(roads, axis)))
            d = self._metric_cache[key]
            if d != d:  # NaN
                return d, 0.0, float("inf")
        cov = 1.0 - _free_left(self.m, roads) / self.free0 if self.free0 else 0.0
        return d, cov, _outside(d, self.band) + _outside(cov, self.cov_band)

    def add(self, garage: Garage) -> float | None:
        """Seed with ``garage``'s road set; returns its distance to the bands (None if the painter can't make it).

        A seed inside the bands counts as seen (the caller has it already) and seeds the walk.
        """
        roads = self.m.repair(garage.grid == Block.ROAD)
        if roads is None:
            return None
        _, _, dist = self.measure(roads, garage.six_stall_axis)
        if dist == float("inf"):
            return None
        key = self._key(roads, garage.six_stall_axis)
        if dist == 0.0:
            if key not in self.seen:
                self.seen.add(key)
                self.inside.append((roads, garage.six_stall_axis))
        else:
            self.reserve.append((dist, roads, garage.six_stall_axis))
            self.climbers.append((dist, roads, garage.six_stall_axis))
            self.climbers.sort(key=lambda e: e[0])  # stable: ties keep the order they came in
            del self.climbers[CLIMBERS:]
            self.best = min(self.best, dist)
        return dist

    def _restart(self) -> None:
        order = sorted(range(len(self.reserve)), key=lambda k: self.reserve[k][0])
        picked = [self.reserve[order[(self.next_seed + k) % len(order)]] for k in range(min(CLIMBERS, len(order)))]
        self.next_seed += len(picked)
        self.climbers = sorted(picked, key=lambda e: e[0])
        self.best = self.climbers[0][0]
        self.restarts += 1

    def step(self) -> tuple[Garage, float, float] | None:
        if not self.climbers and not self.inside:
            raise ValueError("BandClimber: add a garage first")
        self.evaluations += 1
        self.stalled += 1
        if self.stalled >= STALL_STEPS and self.reserve:
            self._restart()
            self.stalled = 0
        rng = self.rng
        walk = bool(self.inside) and (not self.climbers or rng.random() < WALK_SHARE)
        if walk:
            roads, axis = self.inside[int(rng.integers(len(self.inside)))]
            i = -1
        else:
            i = 0 if rng.random() < 0.5 else int(rng.integers(len(self.climbers)))
            dist0, roads, axis = self.climbers[i]
        child = roads
        for _ in range(1 + int(rng.integers(MAX_CHAIN))):  # a chain of one to MAX_CHAIN mutations
            child = _mutate(self.m, child, rng)
            if child is None:
                return None
        d, cov, dist = self.measure(child, axis)
        if i >= 0 and 0.0 < dist <= dist0 and not any(np.array_equal(child, r) for _, r, _ in self.climbers):
            self.climbers[i] = (dist, child, axis)  # (no two climbers alike: they would climb the same way)
            self.climbers.sort(key=lambda e: e[0])
            if dist < self.best:
                self.best, self.stalled = dist, 0
        if dist > 0.0:
            return None
        key = self._key(child, axis)
        if key in self.seen:
            return None
        self.seen.add(key)
        self.inside.append((child, axis))
        self.stalled = 0
        return self.m.garage_of(child, axis), d, cov


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
    from garage_mj.generation.gen_env import GarageGenEnv

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
    from garage_mj.grid.painters import paint_garage

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


__all__ = ["BandClimber", "SearchResult", "mutate", "painter_actions", "replay", "road_set", "search"]
