"""Garage metrics (docs/spec.md section 4): coverage, difficulty, stalls and road statistics.

``difficulty(E[Y], E[X])`` is the paper's lambda with the weights of its table of 16 garages;
``evaluate(garage)`` computes every metric the library stores and the reports show, from the grid
alone (fast). The route-aware difficulty needs the 3D scene and its planner: the public facade
``garage_mj.evaluate(garage, route=True)`` fills :attr:`GarageMetrics.route_difficulty` with it
(:mod:`garage_mj.scene.route_difficulty`); this module only holds the number.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from garage_mj.grid.blocks import Block, count_stalls
from garage_mj.grid.garage import Garage
from garage_mj.grid.reward import RewardConfig
from garage_mj.grid.road_segments import analyse
from garage_mj.grid.rules import road_squares, stall_rule_violations


@dataclass(frozen=True)
class DifficultyConfig:
    """Difficulty lambda (docs/spec.md section 4) and the ranges of X and Y.

    The intersection term carries 0.33 and road length 0.67, as the paper's table of 16 garages
    requires (its text says the opposite; docs/spec.md follows the table).
    """

    w_intersection: float = 0.33
    w_road_length: float = 0.67
    road_length_min: int = 2  # [cells]
    road_length_max: int = 6  # [cells]
    intersection_min: int = 2  # [roads meeting at a key node]
    intersection_max: int = 4


DEFAULT_DIFFICULTY = DifficultyConfig()


def difficulty(
    mean_intersection_degree: float,
    mean_road_length: float,
    config: DifficultyConfig = DEFAULT_DIFFICULTY,
) -> float:
    """lambda = w_Y (1 - n_Y) + w_X (1 - n_X), clipped to [0, 1].

    n_Y = (E[Y] - 2) / 2 and n_X = (E[X] - 2) / 4 with the default ranges. Short roads and
    few-way intersections are harder.
    """
    n_y = (mean_intersection_degree - config.intersection_min) / (
        config.intersection_max - config.intersection_min
    )
    n_x = (mean_road_length - config.road_length_min) / (
        config.road_length_max - config.road_length_min
    )
    lam = config.w_intersection * (1.0 - n_y) + config.w_road_length * (1.0 - n_x)
    return float(min(1.0, max(0.0, lam)))


def coverage(grid: np.ndarray, initial: np.ndarray) -> float:
    """delta = 1 - #FREE(grid) / #FREE(initial)."""
    free0 = int(np.count_nonzero(initial == Block.FREE))
    if free0 == 0:
        return 0.0
    return 1.0 - int(np.count_nonzero(grid == Block.FREE)) / free0


def utility_values(
    stalls: int, free0: int, x_hist: dict[int, int], y_hist: dict[int, int], reward: RewardConfig
) -> tuple[float, float, float]:
    """Performance values (P_s, P_r, P_c) of the utility rules (docs/spec.md section 4).

    P_s = stalls per initial FREE cell; P_r = sum_x P(X=x) w_x[x]; P_c = sum_y P(Y=y) w_y[y].
    """
    p_s = stalls / free0 if free0 else 0.0
    nx = sum(x_hist.values())
    p_r = sum(k * reward.w_x.get(x, 0.0) for x, k in x_hist.items()) / nx if nx else 0.0
    ny = sum(y_hist.values())
    p_c = sum(k * reward.w_y.get(y, 0.0) for y, k in y_hist.items()) / ny if ny else 0.0
    return p_s, p_r, p_c


@dataclass(frozen=True)
class GarageMetrics:
    coverage: float  # delta, share of initial FREE cells painted
    difficulty: float  # lambda in [0, 1]
    stalls: int
    mean_road_length: float  # E[X], cells per segment clipped to [2, 6]
    mean_intersection_degree: float  # E[Y], 2 when there is no key node of degree >= 2
    connected: bool  # entrance and exit joined by road-like cells
    valid: bool  # no 2x2 road square and the stall rule holds everywhere
    usable: bool  # connected and valid
    segments: int
    road_cells: int
    tiles: dict[str, int]
    # the route difficulty (expected failure rate of a cruise test, garage_mj.scene.route_difficulty): None when
    # not computed (this module's evaluate never does; garage_mj.evaluate(garage, route=True) does), NaN when the
    # garage has no feasible stall
    route_difficulty: float | None = None

    def to_dict(self) -> dict:
        """The metrics as a dict; ``route_difficulty`` only when computed (so files written without it stay as they were)."""
        d = asdict(self)
        if d["route_difficulty"] is None:
            del d["route_difficulty"]
        return d


def evaluate(garage: Garage, config: DifficultyConfig = DEFAULT_DIFFICULTY) -> GarageMetrics:
    """Every metric of ``garage``, recomputed from its grid."""
    grid = garage.grid
    a = analyse(grid)
    lo, hi = config.road_length_min, config.road_length_max
    xs = [min(max(s.length, lo), hi) for s in a.segments]
    ys = a.intersection_degrees()
    ex = float(np.mean(xs)) if xs else float(lo)
    ey = float(np.mean(ys)) if ys else float(config.intersection_min)
    connected = a.connected(garage.entrance, garage.exit)
    valid = not road_squares(grid) and not stall_rule_violations(grid, garage.six_stall_axis)
    return GarageMetrics(
        coverage=coverage(grid, garage.initial),
        difficulty=difficulty(ey, ex, config),
        stalls=count_stalls(grid),
        mean_road_length=ex,
        mean_intersection_degree=ey,
        connected=connected,
        valid=valid,
        usable=connected and valid,
        segments=len(a.segments),
        road_cells=len(a.masks),
        tiles=a.tile_counts(),
    )
