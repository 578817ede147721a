"""Search baseline: what it finds is paintable by the painter env, and its range is honest."""

from __future__ import annotations

import numpy as np

from garage_mj import evaluate
from garage_mj.painter import paint_garage
from garage_mj.search import painter_actions, replay, search


def test_painter_actions_repaint_a_painted_garage():
    for seed in range(3):
        garage = paint_garage("tiny_7x11", seed=seed)
        painted, info = replay(garage)
        assert info["usable"] and info["errors"] == 0
        assert np.array_equal(painted.grid, garage.grid)
        assert len(painter_actions(garage)) <= 4 * garage.grid.size


def test_search_range_ends_are_usable_garages_of_that_difficulty():
    result = search("tiny_7x11", evaluations=300, seed=0)
    lo, hi = result.range
    assert 0.0 <= lo <= hi <= 1.0
    for d, garage in (result.lowest, result.highest):
        m = evaluate(garage)
        assert m.usable and abs(m.difficulty - d) < 1e-9
    found = [d for d, _ in result.bins.values()]
    assert lo <= min(found) and max(found) <= hi
    assert result.bins_reached()
