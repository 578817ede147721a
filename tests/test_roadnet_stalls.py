"""Road network matrix and stall geometry: consistent with the grid, non-overlapping, reachable."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from garage_mj import evaluate
from garage_mj.grid.painters import paint_garage
from garage_mj.grid.road_segments import analyse
from garage_mj.scene.road_matrix import RoadTile, road_network, tile_openings, tile_rotation
from garage_mj.scene.stalls import stall_layout
from garage_mj.scene.world import DEFAULT_WORLD, WORLD_DIR, cell_center, world_to_cell

W = DEFAULT_WORLD


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), map_name=st.sampled_from(["tiny_7x11", "m5_13x13_aligned", "m6_13x13_s"]))
def test_tiles_rebuild_the_road_graph(seed, map_name):
    g = paint_garage(map_name, seed=seed)
    net = road_network(g)
    a = analyse(g.grid)
    assert set(net.cells) == set(a.masks)
    assert net.edges() == a.edges()
    for cell in net.cells.values():
        assert tile_openings(cell.tile, cell.rotation) == cell.openings
        assert (cell.x, cell.y) == cell_center(cell.row, cell.col, g.shape[0])
    assert net.cells[g.entrance].tile == RoadTile.ENTRANCE and net.cells[g.exit].tile == RoadTile.EXIT


def test_rotations_are_quarter_turns():
    assert tile_rotation(RoadTile.STRAIGHT, frozenset({2, 3})) == 90
    assert tile_rotation(RoadTile.CURVE, frozenset({2, 0})) == 90  # north + west
    assert tile_rotation(RoadTile.T, frozenset({0, 2, 3})) == 90  # closed to the east
    assert tile_rotation(RoadTile.DEAD_END, frozenset({3})) == 270
    with pytest.raises(ValueError):
        tile_rotation(RoadTile.STRAIGHT, frozenset({0, 2}))


def _box(stall):
    xs = [p[0] for p in stall.corners]
    ys = [p[1] for p in stall.corners]
    return min(xs), max(xs), min(ys), max(ys)


def _overlap(a, b, eps=1e-6):
    return a[0] < b[1] - eps and b[0] < a[1] - eps and a[2] < b[3] - eps and b[2] < a[3] - eps


@pytest.mark.parametrize("map_name", ["tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"])
@pytest.mark.parametrize("axis", ["NS", "EW"])
def test_stall_layout(map_name, axis):
    g = paint_garage(map_name, seed=5, six_stall_axis=axis)
    layout = stall_layout(g)
    assert len(layout.stalls) == evaluate(g).stalls
    assert [s.id for s in layout.stalls] == list(range(len(layout.stalls)))
    rows = g.shape[0]
    boxes = [_box(s) for s in layout.stalls]
    for i, (s, b) in enumerate(zip(layout.stalls, boxes)):
        # inside its own block
        cx, cy = cell_center(*s.block, rows)
        assert cx - W.block / 2 - 1e-6 <= b[0] and b[1] <= cx + W.block / 2 + 1e-6
        assert cy - W.block / 2 - 1e-6 <= b[2] and b[3] <= cy + W.block / 2 + 1e-6
        # no overlap with any other stall
        assert not any(_overlap(b, o) for o in boxes[i + 1 :])
        # the road point lies on the road cell it faces, on the lane nearest the stall
        assert world_to_cell(s.road_x, s.road_y, rows) == s.road_cell
        assert g.grid[s.road_cell] == 1
        rx, ry = cell_center(*s.road_cell, rows)
        ux, uy = WORLD_DIR[s.side]  # from the stall towards its road
        across = (s.road_x - rx) * ux + (s.road_y - ry) * uy
        assert across == pytest.approx(-W.lane_width / 2)  # centre of the lane next to the stall
        assert abs((s.road_x - rx) * -uy + (s.road_y - ry) * ux) <= W.block / 2
    # obstruction pillars stay out of every road cell
    for p in layout.pillars:
        r, c = world_to_cell(p.x, p.y, rows)
        assert (r, c) == p.block
