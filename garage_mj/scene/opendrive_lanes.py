"""Lane graph and routing: the OpenDRIVE road network, reachable from Python without XML.

Built from the same :class:`~garage_mj.scene.opendrive_roads.RoadModel` the ``garage.xodr`` writer
spells, so a route here is a route in CARLA. Nodes are waypoints on lane centre lines, in
driving direction (right-hand traffic): ``(road id, lane id, index)`` with attributes
``pos=(x, y)`` [m] and ``heading`` [rad]. Edges follow the lanes, the lane links across
junctions, and a U-turn at every lane end without a successor (dead ends and gates), so every
stall's near lane is reachable from the entrance; edges carry ``length`` [m] and ``kind``
(``"lane"``, ``"link"`` or ``"uturn"``).
"""

from __future__ import annotations

import math

import networkx as nx
import numpy as np

from garage_mj.grid.garage import Garage
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

from .opendrive_roads import Road, RoadModel, build_road_model
from .planview import sample

WAYPOINT_STEP = 1.0  # [m] target spacing of lane waypoints
UTURN_PENALTY = 20.0  # [m] added to a U-turn's length so routes avoid them when they can

Node = tuple[int, int, int]  # (road id, lane id, index along the driving direction)


def _lane_nodes(road: Road, lane: int, world: WorldConfig) -> list[tuple[float, float, float]]:
    """Waypoints (x, y, heading) of ``lane`` of ``road`` in its driving direction."""
    t = math.copysign(world.drive_lane_width / 2, lane)
    poses = sample(road.segments, t, WAYPOINT_STEP)
    if lane > 0:  # left lanes drive towards s = 0
        poses = [(x, y, h + math.pi) for x, y, h in reversed(poses)]
    return poses


def _ends(model: RoadModel, road: Road, lane: int) -> tuple[object, object]:
    """(link at the lane's start, link at its end) in driving direction."""
    if lane < 0:
        return road.predecessor, road.successor
    return road.successor, road.predecessor


def lane_graph_of(model: RoadModel) -> nx.DiGraph:
    """The lane graph of a road model (see the module docstring)."""
    g = nx.DiGraph()
    world = model.world
    count: dict[tuple[int, int], int] = {}
    for road in model.roads.values():
        for lane in road.lanes:
            poses = _lane_nodes(road, lane, world)
            count[(road.id, lane)] = len(poses)
            for i, (x, y, h) in enumerate(poses):
                g.add_node((road.id, lane, i), pos=(x, y), heading=math.atan2(math.sin(h), math.cos(h)))
            for i in range(len(poses) - 1):
                a, b = poses[i], poses[i + 1]
                g.add_edge(
                    (road.id, lane, i), (road.id, lane, i + 1), length=math.dist(a[:2], b[:2]), kind="lane"
                )
    # junction lane links: incoming lane end -> connecting lane start -> outgoing lane start
    for road in model.roads.values():
        if road.kind != "connecting":
            continue
        last = (road.id, -1, count[(road.id, -1)] - 1)
        _link(g, (road.predecessor.id, road.lane_predecessor[-1]), count, (road.id, -1, 0), end=True)
        _link(g, (road.successor.id, road.lane_successor[-1]), count, last, end=False)
    # roads linked directly (loops without junctions) and dead ends
    for road in model.roads.values():
        if road.kind == "connecting":
            continue
        for lane in road.lanes:
            _, end_link = _ends(model, road, lane)
            last = (road.id, lane, count[(road.id, lane)] - 1)
            if end_link is not None and end_link.element == "road":
                nxt = road.lane_successor[lane] if lane < 0 else road.lane_predecessor[lane]
                g.add_edge(last, (end_link.id, nxt, 0), length=0.0, kind="link")
            elif end_link is None:
                other = (road.id, -lane, 0)
                length = math.pi * world.drive_lane_width / 2 + UTURN_PENALTY
                g.add_edge(last, other, length=length, kind="uturn")
    return g


def _link(g: nx.DiGraph, lane: tuple[int, int], count: dict, node: Node, end: bool) -> None:
    """Join ``node`` to the end (``end=True``: lane -> node) or start (node -> lane) of ``lane``."""
    if end:
        a, b = (*lane, count[lane] - 1), node
    else:
        a, b = node, (*lane, 0)
    g.add_edge(a, b, length=math.dist(g.nodes[a]["pos"], g.nodes[b]["pos"]), kind="link")


def lane_graph(garage: Garage, world: WorldConfig = DEFAULT_WORLD, model: RoadModel | None = None) -> nx.DiGraph:
    """Directed graph of right-hand lane waypoints of ``garage`` (see the module docstring)."""
    g = lane_graph_of(model or build_road_model(garage, world))
    g.graph["name"] = garage.name
    return g


def entrance_pose(
    garage: Garage | RoadModel, world: WorldConfig = DEFAULT_WORLD
) -> tuple[float, float, float]:
    """(x [m], y [m], yaw [rad]) at the start of the entrance lane, at the grid edge, heading inward."""
    model = garage if isinstance(garage, RoadModel) else build_road_model(garage, world)
    road = model.roads[model.entrance_road]
    return _clean(_lane_nodes(road, model.entrance_lane, model.world)[0])


def exit_pose(garage: Garage | RoadModel, world: WorldConfig = DEFAULT_WORLD) -> tuple[float, float, float]:
    """(x [m], y [m], yaw [rad]) at the end of the exit lane, at the grid edge, heading out."""
    model = garage if isinstance(garage, RoadModel) else build_road_model(garage, world)
    road = model.roads[model.exit_road]
    return _clean(_lane_nodes(road, model.exit_lane, model.world)[-1])


def _clean(pose: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, h = (round(v, 9) + 0.0 for v in pose)
    return x, y, h


def nearest_node(graph: nx.DiGraph, x: float, y: float) -> Node:
    """The lane waypoint nearest (x, y)."""
    nodes, pts = _index(graph)
    return nodes[int(np.argmin(((pts - (x, y)) ** 2).sum(axis=1)))]


def _index(graph: nx.DiGraph) -> tuple[list[Node], np.ndarray]:
    cache = graph.graph.get("_index")
    if cache is None or len(cache[0]) != graph.number_of_nodes():
        nodes = list(graph.nodes)
        pts = np.array([graph.nodes[n]["pos"] for n in nodes], dtype=float)
        cache = graph.graph["_index"] = (nodes, pts)
    return cache


def route(
    graph_or_garage: nx.DiGraph | Garage,
    start: tuple[float, float],
    goal: tuple[float, float],
) -> np.ndarray:
    """Shortest drive (N, 2) [m] from the lane waypoint nearest ``start`` to the one nearest ``goal``.

    Follows lane directions and junction lane links; U-turns only where a lane ends with no
    successor. Raises ``ValueError`` naming both points when the goal cannot be reached.
    """
    g = graph_or_garage if isinstance(graph_or_garage, nx.DiGraph) else lane_graph(graph_or_garage)
    a = nearest_node(g, *start[:2])
    b = nearest_node(g, *goal[:2])
    try:
        path = nx.shortest_path(g, a, b, weight="length")
    except nx.NetworkXNoPath:
        raise ValueError(
            f"no drivable route from ({start[0]:.2f}, {start[1]:.2f}) to ({goal[0]:.2f}, {goal[1]:.2f}) "
            f"in garage {g.graph.get('name', '?')!r}: the goal's road is not connected to the start's"
        ) from None
    return np.array([g.nodes[n]["pos"] for n in path], dtype=float)
