"""Drivable routes for the ego car, and the checks that prove a cruise test can be driven (SPEC section 7).

A route is planned on the road network matrix, not on the OpenDRIVE lanes: the car drives the
right-hand lane centre lines of the cells it crosses (straight lines), and every turn is a circular
fillet between two such lines. A left turn keeps its lane (radius B/2 + w/2 = 6.25 m); a right
turn, whose lane arc (B/2 - w/2 = 2.75 m) is tighter than the car can steer, swings wide into the
road's full width with the smallest radius the car takes with margin (``curvature_margin``). Where
two turns follow too closely for both fillets, their radii shrink toward that limit; where they
still do not fit, the route is infeasible. The path is that of the rear-axle midpoint, so its
curvature is exactly what the bicycle model steers; the route handed to drivers is the path of
the car's centre (the rear-axle path moved ``-rear_axle`` metres forward along the heading).

The goal of a test is the pose on the route nearest the target stall's entry, inside the stall's
road cell: on the lane on the stall's side when a forward route reaches it, else on the car's own
lane across from it (the car never reverses and never U-turns). It must lie within
``lane_tolerance`` of a lane centre line of the OpenDRIVE road model. The car's swept footprint
from the start to the goal must stay ``clearance_margin`` clear of walls, obstacle blocks,
pillars and every other stall's outline (parked cars lie wholly inside stall outlines, so any
occupancy is covered). A goal whose footprint is not clear (a dead end facing stalls) moves back
along the lane, at most ``max_pullback``.

Everything is decided from the scene alone, before any drive: a test that fails a check is
``infeasible`` with the reason, and is never driven.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.core.geometry import DELTAS, OPPOSITE
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.semantics import Semantic
from garage_mj.scene.world import WORLD_DIR, cell_center

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry

START_OFFSET = 3.0  # [m] the car's centre starts this far along the route from the grid edge
MIN_DRIVE = 2.0  # [m] the goal lies at least this far along the route beyond the start
SAMPLE_STEP = 0.25  # [m] spacing of the route samples (and of the footprint sweep)
NEAR_OBSTACLE = 6.0  # [m] obstacles farther than this from every path point are not tested
GOAL_ON_STRAIGHT = 1.0  # [m] a straight goal this much farther from the stall than a curved one still wins
EXACT_BELOW = 2.0  # [m] clearances above this are reported as the bounding-circle lower bound

Cell = tuple[int, int]
Node = tuple[Cell, int]  # (cell, heading direction when entering it)


@dataclass(frozen=True)
class DriveConfig:
    """Margins of the drivability checks (one place, used by the env, the drivers and ``check``)."""

    curvature_margin: float = 0.15  # the route's curvature stays <= (1 - this) x the car's limit
    clearance_margin: float = 0.25  # [m] swept footprint to walls, pillars, obstacles, stall outlines
    lane_tolerance: float = 1.0  # [m] goal to the nearest OpenDRIVE lane centre line
    max_pullback: float = 5.0  # [m] a blocked goal may move this far back along its lane


DEFAULT_DRIVE = DriveConfig()


@dataclass(frozen=True)
class TestPlan:
    """The planned drive to one stall: feasible with its route and goal, or infeasible with a reason."""

    stall: int
    feasible: bool
    reason: str  # why infeasible ("" when feasible)
    centre: np.ndarray | None = None  # (N, 2) [m] path of the car's centre: the route drivers get
    rear: np.ndarray | None = None  # (N, 2) [m] path of the rear-axle midpoint
    heading: np.ndarray | None = None  # (N,) [rad] car heading along the path
    curvature: np.ndarray | None = None  # (N,) [1/m] of the rear-axle path (> 0 turns left)
    goal: tuple[float, float, float] | None = None  # (x, y, yaw) of the car's centre at the goal
    stall_side: str = ""  # "right" (the stall's own lane), "left" (across) or "ahead" (dead end)
    clearance: float = math.nan  # [m] smallest distance of the swept footprint to an obstacle
    clearance_to: str = ""  # the class of that obstacle
    max_curvature: float = math.nan  # [1/m] largest |curvature| on the route
    lane_offset: float = math.nan  # [m] goal to the nearest lane centre line
    pullback: float = 0.0  # [m] how far the goal moved back from the stall's projection

    @property
    def length(self) -> float:
        """[m] route length (centre path)."""
        if self.centre is None:
            return 0.0
        return float(np.linalg.norm(np.diff(self.centre, axis=0), axis=1).sum())

    def summary(self) -> dict[str, Any]:
        return {"stall": self.stall, "feasible": self.feasible, "reason": self.reason,
                "stall_side": self.stall_side, "clearance": _r(self.clearance),
                "clearance_to": self.clearance_to, "max_curvature": _r(self.max_curvature),
                "lane_offset": _r(self.lane_offset), "pullback": _r(self.pullback),
                "route_length": _r(self.length)}


def _r(v: float) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), 4)


@dataclass
class _Candidate:
    cost: float
    side_rank: int
    path: list[Node]
    final: int  # heading after the last turn (in the goal cell)
    side: str = ""


@dataclass
class Obstacles:
    """Axis-aligned obstacle rectangles [xmin, ymin, xmax, ymax] with their class and stall id (or -1)."""

    boxes: np.ndarray
    classes: list[str]
    stall: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))


class DrivePlanner:
    """Routes and drivability of one :class:`GarageScene` for one car (use ``drive_planner(scene, car)``)."""

    def __init__(self, scene: GarageScene, car: CarGeometry, config: DriveConfig = DEFAULT_DRIVE) -> None:
        self.scene = scene
        self.car = car
        self.config = config
        self.world = scene.world
        self.net = scene.network
        self.rows = scene.garage.shape[0]
        self.kappa_limit = car.max_curvature * (1.0 - config.curvature_margin)  # [1/m]
        self.r_min = 1.0 / self.kappa_limit  # [m] smallest fillet radius the route may use
        self.b = -car.rear_axle  # [m] rear axle to centre
        self._plans: dict[int, TestPlan] = {}
        self._dist, self._prev = self._search()
        self._obstacles: Obstacles | None = None
        self._lanes: tuple[np.ndarray, np.ndarray] | None = None

    # -- the cell-level search ---------------------------------------------------------------------
    def _openings(self, p: Cell) -> frozenset[int]:
        return self.net.cells[p].openings

    def _start(self) -> Node:
        ent = self.net.entrance
        return (ent, min(self._openings(ent)))

    def _next(self, node: Node) -> list[tuple[Node, int]]:
        (p, d_in) = node
        outs = [d for d in self._openings(p) if d != OPPOSITE[d_in]]
        res = []
        for d in sorted(outs):
            q = (p[0] + DELTAS[d][0], p[1] + DELTAS[d][1])
            if q in self.net.cells and OPPOSITE[d] in self._openings(q):
                res.append(((q, d), d))
        return res

    def _search(self) -> tuple[dict[Node, float], dict[Node, Node | None]]:
        """Dijkstra over (cell, heading) from the entrance: every forward route, no U-turns."""
        start = self._start()
        dist: dict[Node, float] = {start: 0.0}
        prev: dict[Node, Node | None] = {start: None}
        heap = [(0.0, start)]
        b = self.world.block
        while heap:
            d0, node = heapq.heappop(heap)
            if d0 > dist[node]:
                continue
            for nxt, _ in self._next(node):
                nd = d0 + b + (0.5 if nxt[1] != node[1] else 0.0)  # a turn costs a little: prefer straight
                if nd < dist.get(nxt, math.inf) - 1e-9:
                    dist[nxt], prev[nxt] = nd, node
                    heapq.heappush(heap, (nd, nxt))
        return dist, prev

    def _path_to(self, node: Node) -> list[Node]:
        out = []
        cur: Node | None = node
        while cur is not None:
            out.append(cur)
            cur = self._prev[cur]
        return out[::-1]

    # -- lane lines and fillets ---------------------------------------------------------------------
    def _line(self, p: Cell, d: int) -> tuple[np.ndarray, np.ndarray]:
        """(a point, unit direction) of the right-hand lane centre line crossing cell ``p`` heading ``d``."""
        u = np.array(WORLD_DIR[d], dtype=float)
        right = np.array([u[1], -u[0]])
        c = np.array(cell_center(*p, self.rows, self.world))
        return c + right * self.world.lane_width / 2, u

    def _polyline(self, path: list[Node], final: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Vertices (start, turn corners, end) and the unit direction of each leg, for the rear axle."""
        half = self.world.block / 2
        (p0, d0) = path[0]
        a, u = self._line(p0, d0)
        c0 = np.array(cell_center(*p0, self.rows, self.world))
        start = a + u * (float((c0 - a) @ u) - half) - u * self.b  # the rear axle b behind the grid edge
        verts, dirs = [start], [u]
        steps = [(cell, d_in) for cell, d_in in path]
        for i, (cell, d_in) in enumerate(steps):
            d_out = steps[i + 1][1] if i + 1 < len(steps) else final
            if d_out != d_in:
                a1, u1 = self._line(cell, d_in)
                a2, u2 = self._line(cell, d_out)
                # intersection of the two perpendicular lines
                t = _cross(a2 - a1, u2) / _cross(u1, u2)
                verts.append(a1 + u1 * t)
                dirs.append(u2)
        last_cell = steps[-1][0]
        a, u = self._line(last_cell, final)
        c = np.array(cell_center(*last_cell, self.rows, self.world))
        end = a + u * (float((c - a) @ u) + half)  # the far edge of the goal cell
        nxt = (last_cell[0] + DELTAS[final][0], last_cell[1] + DELTAS[final][1])
        if final in self._openings(last_cell) and nxt in self.net.cells:
            end = end + u * self.world.block  # open ahead: room for the last turn's fillet
        verts.append(end)
        return verts, dirs

    def _fillets(self, verts: list[np.ndarray], dirs: list[np.ndarray]) -> tuple[list[float], str]:
        """Radius [m] of every turn (left turns keep their lane; right turns the car's smallest), or a reason."""
        n_turns = len(verts) - 2
        lane = self.world.lane_width / 2
        half = self.world.block / 2
        want, turn_sign = [], []
        for k in range(n_turns):
            cross = _cross(dirs[k], dirs[k + 1])
            turn_sign.append(1.0 if cross > 0 else -1.0)
            lane_r = half + lane if cross > 0 else half - lane
            want.append(max(lane_r, self.r_min))
        legs = [float(np.linalg.norm(verts[i + 1] - verts[i])) for i in range(len(verts) - 1)]
        legs[0] -= START_OFFSET  # the first turn begins after the car's start pose
        radii = list(want)

        def excess(i: int) -> float:
            """How far the fillets at both ends of leg ``i`` overrun it."""
            used = (radii[i - 1] if i > 0 else 0.0) + (radii[i] if i < n_turns else 0.0)
            return used - legs[i]

        for _ in range(2 * n_turns + 2):
            changed = False
            for i in range(n_turns + 1):
                over = excess(i)
                if over <= 1e-9:
                    continue
                ends = [k for k in (i - 1, i) if 0 <= k < n_turns]
                # shrink the fillet with the most room above the car's limit
                k = max(ends, key=lambda k: (radii[k] - self.r_min, k))
                if radii[k] - self.r_min > 1e-9:
                    radii[k] = max(self.r_min, radii[k] - over)
                    changed = True
            if not changed:
                break
        for i in range(n_turns + 1):
            if excess(i) > 1e-6:
                where = "after the start" if i == 0 else ("between two turns" if i < n_turns else "after the turn")
                return [], (f"a turn needs a radius of {self.r_min:.2f} m (the car's {1 / self.car.max_curvature:.2f} m "
                            f"plus margin) but only {max(legs[i], 0.0):.2f} m of road lies {where}")
        return [r * s for r, s in zip(radii, turn_sign)], ""

    def _sample(self, verts: list[np.ndarray], dirs: list[np.ndarray], radii: list[float]):
        """Rear-axle points, headings and curvatures along the filleted polyline."""
        pts, hdg, kap = [], [], []

        def line(p, q, u):
            n = max(1, math.ceil(float(np.linalg.norm(q - p)) / SAMPLE_STEP))
            h = math.atan2(u[1], u[0])
            for i in range(n):
                pts.append(p + (q - p) * (i / n))
                hdg.append(h)
                kap.append(0.0)

        cur = verts[0]
        for k, r in enumerate(radii):
            v, u1, u2 = verts[k + 1], dirs[k], dirs[k + 1]
            rad = abs(r)
            t1 = v - u1 * rad  # tangent points (90 degree turns: tangent length = radius)
            t2 = v + u2 * rad
            line(cur, t1, u1)
            left = np.array([-u1[1], u1[0]]) * math.copysign(1.0, r)
            centre = t1 + left * rad
            h0 = math.atan2(u1[1], u1[0])
            sweep = math.pi / 2
            n = max(2, math.ceil(rad * sweep / SAMPLE_STEP))
            a0 = math.atan2(t1[1] - centre[1], t1[0] - centre[0])
            for i in range(n):
                a = a0 + math.copysign(sweep * i / n, r)
                pts.append(centre + rad * np.array([math.cos(a), math.sin(a)]))
                hdg.append(h0 + math.copysign(sweep * i / n, r))
                kap.append(1.0 / r)
            cur = t2
        line(cur, verts[-1], dirs[-1])
        pts.append(verts[-1])
        hdg.append(math.atan2(dirs[-1][1], dirs[-1][0]))
        kap.append(0.0)
        return np.array(pts), np.array(hdg), np.array(kap)

    # -- obstacles and the footprint ------------------------------------------------------------------
    def obstacles(self) -> Obstacles:
        """Walls, obstacle blocks, pillars and stall outlines as axis-aligned rectangles."""
        if self._obstacles is None:
            boxes, classes, stall = [], [], []
            lay = self.scene.layout
            for box in lay.boxes:
                if box.collides and box.cls in (Semantic.WALL, Semantic.OBSTACLE):
                    (cx, cy, _), (hx, hy, _) = box.center, box.half
                    boxes.append((cx - hx, cy - hy, cx + hx, cy + hy))
                    classes.append(box.cls.name.lower())
                    stall.append(-1)
            h = self.world.pillar_size / 2
            for p in lay.pillars:
                boxes.append((p.x - h, p.y - h, p.x + h, p.y + h))
                classes.append("pillar")
                stall.append(-1)
            for s in self.scene.stalls.stalls:
                xs, ys = zip(*s.corners)
                boxes.append((min(xs), min(ys), max(xs), max(ys)))
                classes.append("parked_car")
                stall.append(s.id)
            self._obstacles = Obstacles(np.array(boxes, dtype=float).reshape(-1, 4), classes,
                                        np.array(stall, dtype=int))
        return self._obstacles

    def footprint(self, rear: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """(N, 4, 2) corners of the car's body with its rear-axle midpoint at ``rear`` and ``heading``."""
        car = self.car
        x0, x1 = car.rear - car.rear_axle, car.front - car.rear_axle
        w = car.half_width
        local = np.array([[x1, w], [x0, w], [x0, -w], [x1, -w]])
        c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
        x = rear[:, 0:1] + c * local[:, 0] - s * local[:, 1]
        y = rear[:, 1:2] + s * local[:, 0] + c * local[:, 1]
        return np.stack([x, y], axis=-1)

    def clearance(self, rear: np.ndarray, heading: np.ndarray, exclude_stall: int = -1) -> tuple[np.ndarray, list[str]]:
        """Per pose, the distance [m] of the car body to the nearest obstacle (0 when touching), and its class."""
        obs = self.obstacles()
        keep = obs.stall != exclude_stall if exclude_stall >= 0 else np.ones(len(obs.boxes), dtype=bool)
        boxes = obs.boxes
        # only obstacles near the path
        lo, hi = rear.min(axis=0) - NEAR_OBSTACLE, rear.max(axis=0) + NEAR_OBSTACLE
        keep &= (boxes[:, 2] >= lo[0]) & (boxes[:, 0] <= hi[0]) & (boxes[:, 3] >= lo[1]) & (boxes[:, 1] <= hi[1])
        idx = np.flatnonzero(keep)
        if not len(idx):
            return np.full(len(rear), np.inf), [""] * len(rear)
        boxes = boxes[idx]
        car = self.footprint(rear, heading)  # (N, 4, 2)
        # a cheap lower bound from the body's bounding circle; exact distances only where it is small
        mid = car.mean(axis=1)  # (N, 2) body centre
        radius = float(np.linalg.norm(car[0, 0] - mid[0]))
        dx = np.maximum(np.maximum(boxes[None, :, 0] - mid[:, None, 0], mid[:, None, 0] - boxes[None, :, 2]), 0.0)
        dy = np.maximum(np.maximum(boxes[None, :, 1] - mid[:, None, 1], mid[:, None, 1] - boxes[None, :, 3]), 0.0)
        bound = np.hypot(dx, dy) - radius  # (N, M) <= the true distance
        dist = np.maximum(bound, 0.0)
        n_i, m_i = np.nonzero(bound < EXACT_BELOW)
        if len(n_i):
            cars, bx = car[n_i], boxes[m_i]  # (K, 4, 2), (K, 4)
            bc = _box_corners(bx)
            exact = np.minimum(_points_to_edges(cars, bc), _points_to_edges(bc, cars))
            exact[_overlap_pairs(cars, bx, bc)] = 0.0
            dist[n_i, m_i] = exact
        j = np.argmin(dist, axis=1)
        names = [obs.classes[idx[k]] for k in j]
        return dist[np.arange(len(rear)), j], names

    # -- lanes of the road model ----------------------------------------------------------------
    def _lane_points(self) -> tuple[np.ndarray, np.ndarray]:
        if self._lanes is None:
            g = self.scene.lane_graph
            pos = np.array([g.nodes[n]["pos"] for n in g.nodes], dtype=float)
            hdg = np.array([g.nodes[n]["heading"] for n in g.nodes], dtype=float)
            self._lanes = (pos, hdg)
        return self._lanes

    def lane_offset(self, x: float, y: float, yaw: float) -> float:
        """[m] distance of (x, y) to the nearest lane centre point driving within 45 degrees of ``yaw``."""
        pos, hdg = self._lane_points()
        same = np.cos(hdg - yaw) > math.cos(math.pi / 4)
        if not same.any():
            return math.inf
        d = np.linalg.norm(pos[same] - (x, y), axis=1)
        return float(d.min())

    # -- plans ---------------------------------------------------------------------------------------
    def plan(self, stall_id: int) -> TestPlan:
        """The drive to stall ``stall_id`` (cached): the best feasible candidate, else the first reason."""
        if stall_id not in self._plans:
            self._plans[stall_id] = self._plan(stall_id)
        return self._plans[stall_id]

    def plans(self) -> list[TestPlan]:
        return [self.plan(s.id) for s in self.scene.stalls.stalls]

    def _candidates(self, stall_id: int) -> list[_Candidate]:
        stall = self.scene.stalls.stalls[stall_id]
        q = stall.road_cell
        out = []
        for node, cost in self._dist.items():
            if node[0] != q:
                continue
            d_in = node[1]
            # stop on the entering line, or turn within the cell onto a line that leaves it
            finals = {d_in} | {d for d in self._openings(q) if d != OPPOSITE[d_in]}
            for final in sorted(finals):
                side = _side(stall, math.atan2(WORLD_DIR[final][1], WORLD_DIR[final][0]))
                rank = {"right": 0, "ahead": 1, "left": 2}[side]
                out.append(_Candidate(cost, rank, self._path_to(node), final, side))
        out.sort(key=lambda c: (c.side_rank, c.cost, c.final))
        return out

    def _plan(self, stall_id: int) -> TestPlan:
        stall = self.scene.stalls.stalls[stall_id]
        cands = self._candidates(stall_id)
        if not cands:
            return TestPlan(stall_id, False, f"no forward route reaches road cell {stall.road_cell} of the stall")
        first_reason = ""
        for cand in cands:
            plan = self._try(stall, cand)
            if plan.feasible:
                return plan
            first_reason = first_reason or plan.reason
        return TestPlan(stall_id, False, first_reason)

    def _try(self, stall, cand: _Candidate) -> TestPlan:
        cfg = self.config
        verts, dirs = self._polyline(cand.path, cand.final)
        radii, why = self._fillets(verts, dirs)
        if why:
            return TestPlan(stall.id, False, why, stall_side=cand.side)
        rear, hdg, kap = self._sample(verts, dirs, radii)
        centre = rear + self.b * np.stack([np.cos(hdg), np.sin(hdg)], axis=1)
        seg = np.linalg.norm(np.diff(centre, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        # the goal: the centre-path point nearest the stall's entry, within the stall's road cell
        cx, cy = cell_center(*stall.road_cell, self.rows, self.world)
        half = self.world.block / 2 + 0.5
        inside = (np.abs(centre[:, 0] - cx) <= half) & (np.abs(centre[:, 1] - cy) <= half)
        inside &= s >= START_OFFSET + MIN_DRIVE
        if not inside.any():
            return TestPlan(stall.id, False, "the stall lies beside the start: no room to drive to it",
                            stall_side=cand.side)
        entry = np.array(stall.entry)
        dist = np.where(inside, np.linalg.norm(centre - entry, axis=1), np.inf)
        straight = np.where(inside & (np.abs(kap) < 1e-9), dist, np.inf)
        g = int(np.argmin(dist))
        if straight.min() <= dist[g] + GOAL_ON_STRAIGHT:  # stop on a straight piece of lane if one is near
            g = int(np.argmin(straight))
            dist = straight
        # the footprint at the goal must be clear; else move back along the lane
        pull = 0.0
        clear_g, what = self.clearance(rear[g:g + 1], hdg[g:g + 1], exclude_stall=stall.id)
        first = (clear_g[0], what[0])
        while clear_g[0] < cfg.clearance_margin:
            g -= 1
            pull = float(s[int(np.argmin(dist))] - s[g])
            if g <= 0 or pull > cfg.max_pullback or s[g] < START_OFFSET + MIN_DRIVE:
                return TestPlan(stall.id, False, f"no clear place to stop beside the stall within {cfg.max_pullback:.0f} m "
                                f"(a {first[1]} {first[0]:.2f} m from the car; margin {cfg.clearance_margin:.2f} m)",
                                stall_side=cand.side)
            clear_g, _ = self.clearance(rear[g:g + 1], hdg[g:g + 1], exclude_stall=stall.id)
        goal = (float(centre[g, 0]), float(centre[g, 1]), float(hdg[g]))
        offset = self.lane_offset(*goal)
        side = _side(stall, hdg[g])  # where the stall lies seen from the goal pose
        # the drive: from the start pose to the goal
        i0 = int(np.searchsorted(s, START_OFFSET))
        clear, names = self.clearance(rear[i0:g + 1], hdg[i0:g + 1], exclude_stall=stall.id)
        k = int(np.argmin(clear))
        max_k = float(np.abs(kap[: g + 1]).max())
        common = dict(centre=centre[: g + 1], rear=rear[: g + 1], heading=hdg[: g + 1], curvature=kap[: g + 1],
                      goal=goal, stall_side=side, clearance=float(clear[k]), clearance_to=names[k],
                      max_curvature=max_k, lane_offset=offset, pullback=pull)
        if max_k > self.kappa_limit + 1e-6:
            return TestPlan(stall.id, False, f"route curvature {max_k:.3f} 1/m above the car's {self.kappa_limit:.3f}",
                            **common)
        if clear[k] < cfg.clearance_margin:
            x, y = rear[i0 + k]
            return TestPlan(stall.id, False, f"the car passes {clear[k]:.2f} m from a {names[k]} at "
                            f"({x:.1f}, {y:.1f}) (margin {cfg.clearance_margin:.2f} m)", **common)
        if offset > cfg.lane_tolerance:
            return TestPlan(stall.id, False, f"the goal lies {offset:.2f} m off the lane centre", **common)
        return TestPlan(stall.id, True, "", **common)


def _side(stall, heading: float) -> str:
    """Where ``stall`` lies for a car heading ``heading``: "right", "left" or "ahead" (facing it)."""
    towards = (-math.cos(stall.yaw), -math.sin(stall.yaw))  # from the road into the stall
    right = (math.sin(heading), -math.cos(heading))
    dot = towards[0] * right[0] + towards[1] * right[1]
    return "right" if dot > 0.5 else ("left" if dot < -0.5 else "ahead")


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    """z of the cross product of two 2D vectors."""
    return float(a[0] * b[1] - a[1] * b[0])


def _points_to_edges(points: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Smallest distance from any of ``points`` (..., 4, 2) to any edge of ``polys`` (..., 4, 2)."""
    a = polys
    b = np.roll(polys, -1, axis=-2)
    ab = b - a  # (..., 4, 2) edges
    p = points[..., :, None, :]  # (..., 4 points, 1, 2)
    ap = p - a[..., None, :, :]
    denom = np.maximum((ab * ab).sum(-1), 1e-12)[..., None, :]
    t = np.clip((ap * ab[..., None, :, :]).sum(-1) / denom, 0.0, 1.0)
    closest = a[..., None, :, :] + t[..., None] * ab[..., None, :, :]
    d = np.linalg.norm(p - closest, axis=-1)
    return d.min(axis=(-1, -2))


def _box_corners(boxes: np.ndarray) -> np.ndarray:
    """(K, 4, 2) corners, counter-clockwise, of axis-aligned boxes (K, 4) [xmin, ymin, xmax, ymax]."""
    return np.stack([boxes[:, [0, 1]], boxes[:, [2, 1]], boxes[:, [2, 3]], boxes[:, [0, 3]]], axis=1)


def _overlap_pairs(car: np.ndarray, boxes: np.ndarray, bc: np.ndarray) -> np.ndarray:
    """(K,) whether each car rectangle (K, 4, 2) overlaps its axis-aligned box (K, 4), corners ``bc``."""
    sep = ((car[..., 0].max(-1) < boxes[:, 0]) | (car[..., 0].min(-1) > boxes[:, 2])
           | (car[..., 1].max(-1) < boxes[:, 1]) | (car[..., 1].min(-1) > boxes[:, 3]))
    for e in (0, 1):  # the car's two axes
        axis = car[:, e + 1] - car[:, e]
        axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        pc = np.einsum("kcd,kd->kc", car, axis)
        pb = np.einsum("kcd,kd->kc", bc, axis)
        sep |= (pc.max(-1) < pb.min(-1)) | (pc.min(-1) > pb.max(-1))
    return ~sep


def drive_planner(scene: GarageScene, car: CarGeometry | None = None,
                  config: DriveConfig | None = None) -> DrivePlanner:
    """The ego car's route planner and drivability checks of ``scene`` for ``car`` (default ``models/car``).

    One planner per (car, config), kept on the scene: every consumer of a garage shares its routes.
    """
    from garage_mj.scene.car import car_geometry  # reads the car's MuJoCo model: keeps this module light

    key = (car or car_geometry(), config or DEFAULT_DRIVE)
    if key not in scene._planners:
        scene._planners[key] = DrivePlanner(scene, *key)
    return scene._planners[key]


def drivability(scene: GarageScene, car: CarGeometry | None = None) -> dict[str, Any]:
    """Per-garage drivability: share of stalls with a feasible test, smallest clearance, curvature vs limit."""
    planner = drive_planner(scene, car)
    plans = planner.plans()
    ok = [p for p in plans if p.feasible]
    reasons: dict[str, int] = {}
    for p in plans:
        if not p.feasible:
            key = p.reason.split(" at (")[0].split(":")[0]
            reasons[key] = reasons.get(key, 0) + 1
    return {
        "stalls": len(plans),
        "feasible_stalls": len(ok),
        "feasible_share": round(len(ok) / len(plans), 4) if plans else 0.0,
        "min_clearance": _r(min((p.clearance for p in ok), default=math.nan)),
        "max_curvature": _r(max((p.max_curvature for p in ok), default=math.nan)),
        "curvature_limit": _r(planner.kappa_limit),
        "car_curvature_limit": _r(planner.car.max_curvature),
        "clearance_margin": planner.config.clearance_margin,
        "infeasible_reasons": reasons,
    }
