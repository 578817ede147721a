"""Road model: the garage's roads as OpenDRIVE sees them, before any XML.

Built from the road network matrix (:mod:`garage_mj.scene.road_matrix`) and the stall geometry
(:mod:`garage_mj.scene.stalls`) only. Both the OpenDRIVE writer (:mod:`garage_mj.export.xodr`)
and the lane graph (:mod:`garage_mj.scene.opendrive_lanes`) read this one model.

- Runs of dead-end, straight, curve and gate tiles merge into one road each (lines, and a
  quarter circle of radius B/2 per curve tile). Dead ends and gates end their road at the far
  edge of their cell; the entrance road starts at the entrance's outer edge, driving inward.
- T and cross tiles become junctions: one one-lane connecting road per ordered pair of arms
  (lane -1, right-hand traffic), so both travel directions are linked.
- Two adjacent junctions get an implicit road of ``IMPLICIT_ROAD`` metres across their shared
  edge (paper Sec. "3D Maps Generation"); their arms on that side retreat by half of it.
- Ordinary and implicit roads carry lane 1 (left, driving towards s = 0) and lane -1 (right,
  driving towards increasing s), each ``lane_width`` wide.
- Every stall becomes a parking space on the road it faces, at (s, t) of its centre; a stall
  facing a dead end's closed end lies past the road, so its origin is the road end and its
  offset (du, dv) to the true centre goes with it (the writer spells it as an outline).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from garage_mj.core.geometry import DELTAS, OPPOSITE
from garage_mj.grid.garage import Garage
from garage_mj.scene.road_matrix import RoadNetwork, RoadTile, road_network
from garage_mj.scene.stalls import Stall, StallLayout, stall_layout
from garage_mj.scene.world import DEFAULT_WORLD, DIR_YAW, WORLD_DIR, WorldConfig

from .planview import Pose, Segment, connect, merge_lines, pose_at, wrap

IMPLICIT_ROAD = 1.0  # [m] length of the road joining two adjacent junctions
JUNCTION_TILES = (RoadTile.T, RoadTile.CROSS)

Cell = tuple[int, int]


@dataclass(frozen=True)
class Link:
    """A road's predecessor or successor: a junction, or a road with its contact point."""

    element: str  # "road" | "junction"
    id: int
    contact: str | None = None  # "start" | "end" for roads


@dataclass
class Road:
    id: int
    kind: str  # "road" | "implicit" | "connecting"
    segments: list[Segment]
    junction: int = -1  # junction id of a connecting road
    predecessor: Link | None = None
    successor: Link | None = None
    lanes: tuple[int, ...] = (1, -1)
    lane_predecessor: dict[int, int] = field(default_factory=dict)  # lane id -> lane id
    lane_successor: dict[int, int] = field(default_factory=dict)
    spans: dict[Cell, tuple[float, float]] = field(default_factory=dict)  # cell -> (s0, s1) [m]

    @property
    def length(self) -> float:
        last = self.segments[-1]
        return last.s + last.length

    def pose(self, s: float) -> Pose:
        return pose_at(self.segments, s)

    def project(self, x: float, y: float, s0: float = 0.0, s1: float = math.inf) -> tuple[float, float]:
        """(s, t) of (x, y) on the reference line between ``s0`` and ``s1``; t > 0 on the left."""
        best = None
        for seg in self.segments:
            if seg.s + seg.length < s0 - 1e-9 or seg.s > s1 + 1e-9:
                continue
            ds, t = seg.project(x, y)
            px, py, _ = seg.pose(ds)
            err = math.hypot(x - px, y - py)
            if best is None or err < best[0] - 1e-9:
                best = (err, seg.s + ds, t)
        if best is None:
            raise ValueError(f"road {self.id} has no geometry between s={s0} and s={s1}")
        return best[1], best[2]


@dataclass(frozen=True)
class Connection:
    id: int
    incoming: int  # road id
    connecting: int  # road id
    contact: str  # contact point on the connecting road ("start")
    lane_links: tuple[tuple[int, int], ...]  # (from lane of incoming, to lane of connecting)


@dataclass
class Junction:
    id: int
    cell: Cell
    connections: list[Connection] = field(default_factory=list)


@dataclass(frozen=True)
class ParkingSpace:
    stall: Stall
    road: int
    s: float  # [m]
    t: float  # [m], > 0 left of the reference line
    hdg: float  # [rad] stall yaw relative to the road heading at s
    du: float = 0.0  # [m] stall centre from the (s, t) origin, along the stall's yaw
    dv: float = 0.0  # [m] and to its left; non-zero only where the stall lies past a road's end


@dataclass
class RoadModel:
    """Roads, junctions and parking spaces of one garage, in world metres."""

    name: str
    rows: int
    cols: int
    world: WorldConfig
    roads: dict[int, Road]
    junctions: dict[int, Junction]
    parking: list[ParkingSpace]
    entrance_road: int
    entrance_lane: int  # lane of the entrance road driving inward
    exit_road: int
    exit_lane: int  # lane of the exit road driving out of the garage


class _Builder:
    def __init__(self, garage: Garage, world: WorldConfig, network: RoadNetwork | None = None,
                 stalls: StallLayout | None = None) -> None:
        self.garage = garage
        self.world = world
        self.net: RoadNetwork = network or road_network(garage, world)
        self.stalls: StallLayout = stalls or stall_layout(garage, world)
        self.jcells = sorted(p for p, c in self.net.cells.items() if c.tile in JUNCTION_TILES)
        self.jid = {p: 1000 + i for i, p in enumerate(self.jcells)}
        self.roads: dict[int, Road] = {}
        self.road_of: dict[Cell, int] = {}
        self.arms: dict[tuple[Cell, int], tuple[int, str]] = {}  # (junction cell, dir) -> (road, contact)

    # -- poses at cell edges -------------------------------------------------------------------
    def port(self, p: Cell, d: int) -> tuple[float, float]:
        """Midpoint of cell ``p``'s edge towards ``d``; a junction's arm retreats before a junction."""
        c = self.net.cells[p]
        ux, uy = WORLD_DIR[d]
        reach = self.world.block / 2
        q = (p[0] + DELTAS[d][0], p[1] + DELTAS[d][1])
        if p in self.jid and q in self.jid:
            reach -= IMPLICIT_ROAD / 2
        return c.x + ux * reach, c.y + uy * reach

    def _new_road(self, kind: str, segments: list[Segment], **kw) -> Road:
        road = Road(len(self.roads) + 1, kind, segments, **kw)
        self.roads[road.id] = road
        return road

    # -- ordinary roads ------------------------------------------------------------------------
    def walk(self, start: Cell, side_in: int) -> None:
        """Follow non-junction tiles from ``start`` (entered across ``side_in``) into one road."""
        steps: list[tuple[Cell, int, int]] = []
        p, sin = start, side_in
        end: Link | None = None
        end_arm: tuple[Cell, int] | None = None
        while True:
            others = [d for d in sorted(self.net.cells[p].openings) if d != sin]
            sout = others[0] if others else OPPOSITE[sin]
            steps.append((p, sin, sout))
            q = (p[0] + DELTAS[sout][0], p[1] + DELTAS[sout][1])
            if not others or q not in self.net.cells:
                break
            if q in self.jid:
                end_arm = (q, OPPOSITE[sout])
                break
            if q == start:  # a loop without junctions: the road links to itself
                end = Link("road", len(self.roads) + 1, "start")
                break
            p, sin = q, OPPOSITE[sout]
        segments: list[Segment] = []
        spans: dict[Cell, tuple[float, float]] = {}
        s = 0.0
        for cell, sin, sout in steps:
            a = (*self.port(cell, sin), DIR_YAW[OPPOSITE[sin]])
            b = (*self.port(cell, sout), DIR_YAW[sout])
            segs = connect(a, b, s)
            segments += segs
            spans[cell] = (s, segs[-1].s + segs[-1].length)
            s = spans[cell][1]
        road = self._new_road("road", merge_lines(segments), spans=spans)
        first, sin0, _ = steps[0]
        q0 = (first[0] + DELTAS[sin0][0], first[1] + DELTAS[sin0][1])
        if q0 in self.jid:
            road.predecessor = Link("junction", self.jid[q0])
            self.arms[(q0, OPPOSITE[sin0])] = (road.id, "start")
        if end_arm is not None:
            road.successor = Link("junction", self.jid[end_arm[0]])
            self.arms[end_arm] = (road.id, "end")
        elif end is not None:
            road.successor = end
            road.predecessor = Link("road", road.id, "end")
            road.lane_successor = road.lane_predecessor = {1: 1, -1: -1}
        for cell in spans:
            self.road_of[cell] = road.id

    def implicit(self, p: Cell, d: int) -> None:
        """The short road from junction ``p`` to the adjacent junction in direction ``d``."""
        q = (p[0] + DELTAS[d][0], p[1] + DELTAS[d][1])
        h = DIR_YAW[d]
        segs = connect((*self.port(p, d), h), (*self.port(q, OPPOSITE[d]), h))
        road = self._new_road(
            "implicit",
            segs,
            predecessor=Link("junction", self.jid[p]),
            successor=Link("junction", self.jid[q]),
        )
        self.arms[(p, d)] = (road.id, "start")
        self.arms[(q, OPPOSITE[d])] = (road.id, "end")

    # -- junctions -----------------------------------------------------------------------------
    def junction(self, p: Cell) -> Junction:
        j = Junction(self.jid[p], p)
        arms = sorted(self.net.cells[p].openings)
        for a in arms:
            in_road, in_contact = self.arms[(p, a)]
            in_lane = -1 if in_contact == "end" else 1  # the lane driving into the junction
            for b in arms:
                if b == a:
                    continue
                out_road, out_contact = self.arms[(p, b)]
                out_lane = -1 if out_contact == "start" else 1  # the lane driving away
                start = (*self.port(p, a), DIR_YAW[OPPOSITE[a]])
                end = (*self.port(p, b), DIR_YAW[b])
                road = self._new_road(
                    "connecting",
                    connect(start, end),
                    junction=j.id,
                    predecessor=Link("road", in_road, in_contact),
                    successor=Link("road", out_road, out_contact),
                    lanes=(-1,),
                    lane_predecessor={-1: in_lane},
                    lane_successor={-1: out_lane},
                )
                j.connections.append(
                    Connection(len(j.connections), in_road, road.id, "start", ((in_lane, -1),))
                )
        return j

    # -- stalls --------------------------------------------------------------------------------
    def parking(self, junctions: dict[int, Junction]) -> list[ParkingSpace]:
        out = []
        for stall in self.stalls.stalls:
            cell = stall.road_cell
            if cell in self.jid:
                candidates = []
                for conn in junctions[self.jid[cell]].connections:
                    road = self.roads[conn.connecting]
                    if len(road.segments) == 1 and road.segments[0].curvature == 0.0:
                        s, t = road.project(stall.x, stall.y)
                        if t < 0:  # the stall on the right: lane -1 is its near lane
                            candidates.append((abs(t), road.id, s, t))
                _, rid, s, t = min(candidates)
            else:
                rid = self.road_of[cell]
                s, t = self.roads[rid].project(stall.x, stall.y, *self.roads[rid].spans[cell])
            x, y, h = self.roads[rid].pose(s)
            ox, oy = x - t * math.sin(h), y + t * math.cos(h)  # origin: (s, t) on the road
            c, n = math.cos(stall.yaw), math.sin(stall.yaw)
            du, dv = (stall.x - ox) * c + (stall.y - oy) * n, -(stall.x - ox) * n + (stall.y - oy) * c
            du, dv = (0.0 if abs(v) < 1e-9 else v for v in (du, dv))
            out.append(ParkingSpace(stall, rid, s, t, wrap(stall.yaw - h), du, dv))
        return out

    def build(self) -> RoadModel:
        net, g = self.net, self.garage
        ent = net.cells[g.entrance]
        self.walk(g.entrance, OPPOSITE[min(ent.openings)])
        for p in self.jcells:
            for d in sorted(net.cells[p].openings):
                q = (p[0] + DELTAS[d][0], p[1] + DELTAS[d][1])
                if (p, d) in self.arms:
                    continue
                if q in self.jid:
                    self.implicit(p, d)
                else:
                    self.walk(q, OPPOSITE[d])
        ends = [p for p, c in sorted(net.cells.items()) if len(c.openings) == 1 and p != g.exit]
        for p in [*ends, g.exit]:
            if p not in self.road_of:
                self.walk(p, OPPOSITE[min(net.cells[p].openings)])
        for p in sorted(net.cells):
            if p not in self.road_of and p not in self.jid:  # loops with no junction
                self.walk(p, min(net.cells[p].openings))
        junctions = {j.id: j for j in (self.junction(p) for p in self.jcells)}
        exit_road = self.roads[self.road_of[g.exit]]
        exit_lane = -1 if exit_road.spans and next(reversed(exit_road.spans)) == g.exit else 1
        rows, cols = g.shape
        return RoadModel(
            name=g.name,
            rows=rows,
            cols=cols,
            world=self.world,
            roads=self.roads,
            junctions=junctions,
            parking=self.parking(junctions),
            entrance_road=self.road_of[g.entrance],
            entrance_lane=-1,
            exit_road=exit_road.id,
            exit_lane=exit_lane,
        )


def build_road_model(garage: Garage, world: WorldConfig = DEFAULT_WORLD, *, network: RoadNetwork | None = None,
                     stalls: StallLayout | None = None) -> RoadModel:
    """The road model of ``garage``: roads, junctions, connecting roads and parking spaces.

    ``network`` and ``stalls`` (the garage's road network matrix and stall layout) are derived
    when not given; :class:`garage_mj.scene.GarageScene` passes the ones it already holds.
    """
    return _Builder(garage, world, network, stalls).build()
