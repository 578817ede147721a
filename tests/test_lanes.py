"""Lane graph: routes from the entrance reach every stall's road point and the exit, along lanes."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest

from garage_mj.grid.painters import paint_garage
from garage_mj.scene.opendrive_lanes import entrance_pose, exit_pose, lane_graph, nearest_node, route
from garage_mj.scene.opendrive_roads import build_road_model
from garage_mj.scene.road_matrix import RoadTile, road_network
from garage_mj.scene.stalls import stall_layout

STEP_TOLERANCE = 1.0  # [m] a route may stop this far from a goal on a lane centre (waypoint spacing)
CURVE_TOLERANCE = 3.3  # [m] road points beside curve tiles lie off the arc's lane (stalls assume straights)
END_ON_TOLERANCE = 2.3  # [m] a stall facing a dead end's closed end has its road point between the lanes


def _garages(painted_tiny, painted_maps, junction_garage):
    return [painted_tiny, junction_garage, paint_garage("tiny_7x11", seed=4), *painted_maps.values()]


def test_routes_reach_every_stall_and_the_exit(painted_tiny, painted_maps, junction_garage):
    for g in _garages(painted_tiny, painted_maps, junction_garage):
        graph = lane_graph(g)
        net = road_network(g)
        ex, ey, eyaw = entrance_pose(g)
        start = nearest_node(graph, ex, ey)
        assert math.isclose(graph.nodes[start]["heading"], eyaw, abs_tol=1e-9)
        to_exit = route(graph, (ex, ey), exit_pose(g)[:2])
        assert np.hypot(*(to_exit[-1] - exit_pose(g)[:2])) < 1e-9
        for st in stall_layout(g).stalls:
            path = route(graph, (ex, ey), (st.road_x, st.road_y))
            assert np.allclose(path[0], (ex, ey))
            cell = net.cells[st.road_cell]
            tol = STEP_TOLERANCE
            if cell.tile == RoadTile.CURVE:
                tol = CURVE_TOLERANCE
            elif cell.tile == RoadTile.DEAD_END and st.side in cell.openings:
                tol = END_ON_TOLERANCE
            assert np.hypot(*(path[-1] - (st.road_x, st.road_y))) < tol, (g.name, st)
            assert np.all(np.hypot(*np.diff(path, axis=0).T) < 4.0)  # no jumps: consecutive waypoints


def test_lane_graph_is_strongly_connected(painted_maps, junction_garage):
    for g in [junction_garage, *painted_maps.values()]:
        assert nx.is_strongly_connected(lane_graph(g)), g.name


def test_lanes_drive_on_the_right(junction_garage):
    """Every waypoint lies half a lane to the right of its road's reference line, heading along it."""
    m = build_road_model(junction_garage)
    graph = lane_graph(junction_garage)
    for (rid, lane, _), data in graph.nodes(data=True):
        road = m.roads[rid]
        s, t = road.project(*data["pos"])
        assert t == pytest.approx(math.copysign(m.world.lane_width / 2, lane), abs=1e-6)
        h = road.pose(s)[2] + (math.pi if lane > 0 else 0.0)
        assert abs(math.remainder(data["heading"] - h, 2 * math.pi)) < 1e-6


def test_route_follows_lane_direction(painted_tiny):
    """Going from the exit back to the entrance uses the other lane (the one driving inward is one-way)."""
    graph = lane_graph(painted_tiny)
    e, x = entrance_pose(painted_tiny), exit_pose(painted_tiny)
    forward = route(graph, e[:2], x[:2])
    kinds = [graph.edges[u, v]["kind"] for u, v in nx.utils.pairwise(_nodes(graph, forward))]
    assert "uturn" not in kinds
    back = route(graph, x[:2], e[:2])  # from the exit lane's end: needs a U-turn at the gate
    assert len(back) > 2


def _nodes(graph, path):
    return [nearest_node(graph, *p) for p in path]


def test_unreachable_goal_is_a_clear_error(painted_tiny):
    graph = lane_graph(painted_tiny)
    graph.add_node((999, -1, 0), pos=(-50.0, -50.0), heading=0.0)
    with pytest.raises(ValueError, match="no drivable route"):
        route(graph, entrance_pose(painted_tiny)[:2], (-50.0, -50.0))
