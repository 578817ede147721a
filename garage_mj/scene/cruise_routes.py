"""Forward routes of the ego car on the road network matrix, as filleted right-hand lane lines (docs/spec.md section 7).

A route is planned on the road network matrix, not on the OpenDRIVE lanes: a Dijkstra search
over (cell, heading) from the entrance finds every forward route (no U-turns; a turn costs a
little, so straight drives win ties). The car drives the right-hand lane centre lines of the
cells it crosses (straight lines), and every turn is a circular fillet between two such lines.
A left turn keeps its lane (radius B/2 + w/2 = 6.25 m); a right turn, whose lane arc
(B/2 - w/2 = 2.75 m) is tighter than the car can steer, swings wide into the road's full width
with the smallest radius the car takes with margin (``r_min``). Where two turns follow too
closely for both fillets, their radii shrink toward that limit; where they still do not fit,
the route is infeasible. The path is that of the rear-axle midpoint, so its curvature is
exactly what the bicycle model steers.

Which route a test takes, and the checks on it, are decided in :mod:`garage_mj.scene.drivable`.
"""

from __future__ import annotations

import heapq
import math
from typing import TYPE_CHECKING

import numpy as np

from garage_mj.core.geometry import DELTAS, OPPOSITE
from garage_mj.scene.road_matrix import RoadNetwork
from garage_mj.scene.world import WORLD_DIR, WorldConfig, cell_center

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry

START_OFFSET = 3.0  # [m] the car's centre starts this far along the route from the grid edge
SAMPLE_STEP = 0.25  # [m] spacing of the route samples (and of the footprint sweep)

Cell = tuple[int, int]
Node = tuple[Cell, int]  # (cell, heading direction when entering it)


class LaneRoutes:
    """Every forward route from the entrance of ``net``, and the filleted rear-axle path along any of them.

    ``r_min`` [m] is the smallest fillet radius a route may use; ``car`` gives the rear axle's
    offset from the car's centre (the route starts with the car's centre ``START_OFFSET`` past the
    grid edge) and its own limit, named in the reason of a turn that does not fit.
    """

    def __init__(self, net: RoadNetwork, world: WorldConfig, rows: int, car: CarGeometry, r_min: float) -> None:
        self.net = net
        self.world = world
        self.rows = rows
        self.car = car
        self.r_min = r_min
        self.b = -car.rear_axle  # [m] rear axle to centre
        self.dist, self.prev = self._search()

    # -- the cell-level search ---------------------------------------------------------------------
    def openings(self, p: Cell) -> frozenset[int]:
        return self.net.cells[p].openings

    def _start(self) -> Node:
        ent = self.net.entrance
        return (ent, min(self.openings(ent)))

    def _next(self, node: Node) -> list[tuple[Node, int]]:
        (p, d_in) = node
        outs = [d for d in self.openings(p) if d != OPPOSITE[d_in]]
        res = []
        for d in sorted(outs):
            q = (p[0] + DELTAS[d][0], p[1] + DELTAS[d][1])
            if q in self.net.cells and OPPOSITE[d] in self.openings(q):
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

    def path_to(self, node: Node) -> list[Node]:
        """The (cell, heading) nodes of the shortest forward route from the entrance to ``node``."""
        out = []
        cur: Node | None = node
        while cur is not None:
            out.append(cur)
            cur = self.prev[cur]
        return out[::-1]

    # -- lane lines and fillets ---------------------------------------------------------------------
    def _line(self, p: Cell, d: int) -> tuple[np.ndarray, np.ndarray]:
        """(a point, unit direction) of the right-hand lane centre line crossing cell ``p`` heading ``d``."""
        u = np.array(WORLD_DIR[d], dtype=float)
        right = np.array([u[1], -u[0]])
        c = np.array(cell_center(*p, self.rows, self.world))
        return c + right * self.world.drive_lane_width / 2, u

    def polyline(self, path: list[Node], final: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
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
        if final in self.openings(last_cell) and nxt in self.net.cells:
            end = end + u * self.world.block  # open ahead: room for the last turn's fillet
        verts.append(end)
        return verts, dirs

    def fillets(self, verts: list[np.ndarray], dirs: list[np.ndarray]) -> tuple[list[float], str]:
        """Radius [m] of every turn (left turns keep their lane; right turns the car's smallest), or a reason."""
        n_turns = len(verts) - 2
        lane = self.world.drive_lane_width / 2
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


def sample(verts: list[np.ndarray], dirs: list[np.ndarray],
           radii: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rear-axle points, headings and curvatures along the filleted polyline (every ``SAMPLE_STEP``)."""
    pts: list[np.ndarray] = []  # (n, 2) chunks
    hdg: list[float] = []
    kap: list[float] = []

    def line(p, q, u):
        n = max(1, math.ceil(float(np.linalg.norm(q - p)) / SAMPLE_STEP))
        pts.append(p + (q - p) * (np.arange(n) / n)[:, None])
        hdg.extend([math.atan2(u[1], u[0])] * n)
        kap.extend([0.0] * n)

    cur = verts[0]
    for k, r in enumerate(radii):
        v, u1, u2 = verts[k + 1], dirs[k], dirs[k + 1]
        rad = abs(r)
        t1 = v - u1 * rad  # tangent points (90 degree turns: tangent length = radius)
        t2 = v + u2 * rad
        line(cur, t1, u1)
        left = np.array([-u1[1], u1[0]]) * math.copysign(1.0, r)
        centre = t1 + left * rad
        cx, cy = float(centre[0]), float(centre[1])
        h0 = math.atan2(u1[1], u1[0])
        sweep = math.pi / 2
        n = max(2, math.ceil(rad * sweep / SAMPLE_STEP))
        a0 = math.atan2(t1[1] - centre[1], t1[0] - centre[0])
        arc = []
        for i in range(n):
            a = a0 + math.copysign(sweep * i / n, r)
            arc.append((cx + rad * math.cos(a), cy + rad * math.sin(a)))
            hdg.append(h0 + math.copysign(sweep * i / n, r))
        kap.extend([1.0 / r] * n)
        pts.append(np.array(arc))
        cur = t2
    line(cur, verts[-1], dirs[-1])
    pts.append(np.asarray(verts[-1], dtype=float).reshape(1, 2))
    hdg.append(math.atan2(dirs[-1][1], dirs[-1][0]))
    kap.append(0.0)
    return np.concatenate(pts), np.array(hdg), np.array(kap)


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    """z of the cross product of two 2D vectors."""
    return float(a[0] * b[1] - a[1] * b[0])
