"""Metrics: the paper's difficulty table, coverage, road statistics on hand-made grids."""

from __future__ import annotations

import numpy as np
import pytest

from garage_mj import Block, Garage, difficulty, evaluate
from garage_mj.grid.road_segments import Tile, analyse
from garage_mj.grid.rules import apply_stall_rule

# docs/spec.md section 5: (E[Y], E[X], difficulty, success %) of the paper's 16 tested garages.
PAPER_ROWS = [
    (3.8, 6, 0.033, 86), (3.25, 6, 0.124, 80), (3.6, 5.4, 0.167, 86), (3.167, 4.833, 0.333, 90),
    (3.667, 5.75, 0.097, 84), (3.2, 4.833, 0.328, 86), (3.333, 5, 0.278, 98), (2.8, 4.833, 0.394, 96),
    (4, 5, 0.168, 92), (3, 4.6, 0.4, 86), (2.667, 3.714, 0.603, 78), (3.5, 4.333, 0.362, 98),
    (2.4, 3.667, 0.655, 78), (2.167, 3.429, 0.733, 0), (2.2, 3.333, 0.744, 68), (2.222, 2.8, 0.829, 42),
]


@pytest.mark.parametrize("ey, ex, lam, _success", PAPER_ROWS)
def test_difficulty_reproduces_the_paper_table(ey, ex, lam, _success):
    assert difficulty(ey, ex) == pytest.approx(lam, abs=0.002)


def test_difficulty_is_clipped_and_monotone():
    assert difficulty(2, 2) == pytest.approx(1.0)
    assert difficulty(4, 6) == pytest.approx(0.0)
    assert 0.0 <= difficulty(5, 9) <= difficulty(4, 6) + 1e-12
    assert difficulty(3, 3) > difficulty(3, 5) > difficulty(4, 5)


O, F, R, E, X = Block.OBSTACLE, Block.FREE, Block.ROAD, Block.ENTRANCE, Block.EXIT  # noqa: E741
S3, S4, S6, T3, T4 = Block.STALL3, Block.STALL4, Block.STALL6, Block.OBST_STALL3, Block.OBST_STALL4


def garage(grid, initial, axis="NS") -> Garage:
    return Garage(np.array(grid), np.array(initial), six_stall_axis=axis)


# A 6x7 garage: the road enters from the south, runs north, turns east along row 1, exits east.
INITIAL = [
    [O, O, O, O, O, O, O],
    [O, F, F, F, F, F, X],
    [O, F, F, F, F, F, O],
    [O, F, F, F, F, F, O],
    [O, F, F, F, F, F, O],
    [O, O, E, O, O, O, O],
]
L_ROAD = [
    [O, O, O, O, O, O, O],
    [O, T3, R, R, R, R, X],
    [O, T3, R, S4, S3, T3, O],
    [O, T3, R, S3, F, F, O],
    [O, T3, R, T3, F, F, O],
    [O, O, E, O, O, O, O],
]


def test_metrics_on_a_hand_made_l_shaped_road():
    g = garage(L_ROAD, INITIAL)
    m = evaluate(g)
    # key nodes: entrance (dead end), curve at (1, 2), exit (dead end); segments:
    # entrance->curve = 5 cells (clipped to 5), curve->exit = 5 cells
    assert m.connected and m.valid and m.usable
    assert m.mean_intersection_degree == pytest.approx(2.0)
    assert m.mean_road_length == pytest.approx(5.0)
    assert m.difficulty == pytest.approx(difficulty(2.0, 5.0))
    assert m.stalls == 4 * 3 + 4 + 3 + 3 + 3 + 3
    free0 = 20
    assert m.coverage == pytest.approx(1 - 4 / free0)
    assert m.tiles["curve"] == 1 and m.tiles["dead_end"] == 2 and m.tiles["straight"] == 6


def test_apply_stall_rule_derives_the_stalls_of_a_hand_drawn_road():
    roads_only = np.where(np.isin(L_ROAD, [R, E, X, O]), L_ROAD, F)
    assert np.array_equal(apply_stall_rule(roads_only, "NS"), np.array(L_ROAD))
    # on the EW axis the same road gives the same stalls here: no cell has W and E roads
    assert np.array_equal(apply_stall_rule(roads_only, "EW"), np.array(L_ROAD))


def test_t_junction_and_clipping():
    # a straight north-south road with a branch west at row 2: T at (2, 2)
    grid = [
        [O, O, X, O, O],
        [O, S4, R, S3, O],
        [R, R, R, S3, O],
        [O, S4, R, S3, O],
        [O, O, E, O, O],
    ]
    a = analyse(np.array(grid))
    assert a.tiles[(2, 2)] == Tile.T
    assert sorted(a.intersection_degrees()) == [3]
    assert sorted(s.length for s in a.segments) == [3, 3, 3]


def test_unusable_when_disconnected_or_invalid():
    g = garage(L_ROAD, INITIAL)
    broken = g.grid.copy()
    broken[1, 4] = Block.STALL3  # cut the road to the exit
    assert not evaluate(Garage(broken, g.initial)).connected
    square = g.grid.copy()
    square[2, 3] = Block.ROAD  # (1,2),(1,3),(2,2),(2,3) become a 2x2 road square
    m = evaluate(Garage(square, g.initial))
    assert not m.valid and not m.usable


def test_stall_rule_violation_is_invalid():
    g = garage(L_ROAD, INITIAL)
    bad = g.grid.copy()
    bad[3, 4] = Block.STALL6  # no road beside it
    assert not evaluate(Garage(bad, g.initial)).valid


def test_coverage_of_blank_and_painted(painted_tiny):
    from garage_mj import load_map

    assert evaluate(load_map("tiny_7x11")).coverage == 0.0
    m = evaluate(painted_tiny)
    free0 = int((painted_tiny.initial == Block.FREE).sum())
    free = int((painted_tiny.grid == Block.FREE).sum())
    assert m.coverage == pytest.approx(1 - free / free0)


def test_long_straight_road_is_clipped_to_six():
    from garage_mj import load_map
    from garage_mj.grid.rules import apply_stall_rule

    g = load_map("m5_13x13_aligned")
    grid = g.grid.copy()
    grid[1:12, 6] = Block.ROAD  # entrance (12, 6) straight up to the exit (0, 6): 13 cells
    m = evaluate(Garage(apply_stall_rule(grid, "NS"), g.initial))
    assert m.usable and m.segments == 1
    assert m.mean_road_length == 6.0 and m.mean_intersection_degree == 2.0
    assert m.difficulty == pytest.approx(0.33)
    assert m.stalls == 2 * 11 * 3  # a row of STALL3 blocks on either side
