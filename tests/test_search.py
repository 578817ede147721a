"""Search baseline: what it finds is paintable by the painter env, and its range is honest."""

from __future__ import annotations

import numpy as np

from garage_mj import evaluate
from garage_mj.generation.search import BandClimber, mutate, painter_actions, replay, road_set, search
from garage_mj.grid.painters import paint_garage


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


def test_mutate_keeps_the_painters_rules():
    rng = np.random.default_rng(0)
    garage = paint_garage("tiny_7x11", seed=0)
    made = 0
    for _ in range(50):
        child = mutate(garage, rng)
        if child is None:
            continue
        made += 1
        painted, info = replay(child)
        assert info["usable"] and np.array_equal(painted.grid, child.grid) and road_set(child) is not None
        garage = child
    assert made


def _climb(seed: int, band, n: int = 5) -> list:
    climber = BandClimber(paint_garage("tiny_7x11", seed=0), band, rng=np.random.default_rng(seed))
    for s in range(4):
        climber.add(paint_garage("tiny_7x11", seed=s))
    out = []
    while len(out) < n and climber.evaluations < 20_000:
        found = climber.step()
        if found is not None:
            out.append(found)
    return out


def test_band_climber_lands_in_the_band_with_paintable_garages():
    band = (0.6, 0.7)
    found = _climb(0, band)
    assert len(found) == 5 and len({g.canonical_hash() for g, _, _ in found}) == 5
    for g, d, cov in found:
        painted, info = replay(g)
        m = evaluate(painted)
        assert info["usable"] and np.array_equal(painted.grid, g.grid)
        assert band[0] <= d <= band[1] and abs(m.difficulty - d) < 1e-9 and abs(m.coverage - cov) < 1e-9
    assert [g.canonical_hash() for g, _, _ in _climb(0, band)] == [g.canonical_hash() for g, _, _ in found]
