"""Drivable tests for the ego car, and the checks that prove a cruise test can be driven (docs/spec.md section 7).

The route to a stall is a forward route of :mod:`garage_mj.scene.cruise_routes` (right-hand lane
centre lines filleted into turns the car can steer, the path of the rear-axle midpoint); the
route handed to drivers is the path of the car's centre (the rear-axle path moved
``-rear_axle`` metres forward along the heading).

The goal of a test is the pose on the route nearest the target stall's entry, inside the stall's
road cell: on the lane on the stall's side when a forward route reaches it, else on the car's own
lane across from it (the car never reverses and never U-turns). It must lie within
``lane_tolerance`` of a lane centre line of the OpenDRIVE road model. The car's swept footprint
from the start to the goal must stay ``clearance_margin`` clear of walls, obstacle blocks,
pillars and every other stall's outline (:mod:`garage_mj.scene.clearance`). A goal whose
footprint is not clear (a dead end facing stalls) moves back along the lane, at most
``max_pullback``.

Everything is decided from the scene alone, before any drive: a test that fails a check is
``infeasible`` with the reason, and is never driven. :func:`drive_planner` gives the scene's
planner for a car (one per car and margins), :func:`drivability` sums it up per garage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from garage_mj.core.geometry import OPPOSITE
from garage_mj.core.words import a_noun
from garage_mj.scene.clearance import Obstacles, footprint, nearest_obstacle, nearest_two, scene_obstacles
from garage_mj.scene.cruise_routes import START_OFFSET, LaneRoutes, Node, sample
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.world import WORLD_DIR, cell_center

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry

__all__ = ["START_OFFSET", "DEFAULT_DRIVE", "DriveConfig", "TestPlan", "Obstacles", "DrivePlanner",
           "drive_planner", "drivability", "pose_keys"]

MIN_DRIVE = 2.0  # [m] the goal lies at least this far along the route beyond the start
GOAL_ON_STRAIGHT = 1.0  # [m] a straight goal this much farther from the stall than a curved one still wins


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
    """The planned drive to one stall: feasible with its route and goal, or infeasible with a reason.

    The path arrays (``centre``, ``rear``, ``heading``, ``curvature``) are read-only views: the stalls
    along one route share them.
    """

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
    drive_from: int = 0  # index of the start pose on the path (START_OFFSET along it)
    clearances: np.ndarray | None = None  # (N - drive_from,) [m] swept clearance per pose, start to goal

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


class _Route(NamedTuple):
    """A candidate's sampled route: rear-axle path, heading, curvature, centre path, arc length, pose keys."""

    rear: np.ndarray
    heading: np.ndarray
    curvature: np.ndarray
    centre: np.ndarray
    s: np.ndarray
    keys: list[bytes]
    dist: np.ndarray  # per pose, the clearance to the nearest obstacle over all, once known ...
    near: np.ndarray  # ... and that obstacle's index (-1: none near; _UNKNOWN: not measured yet)
    dist2: np.ndarray  # ... and the same without the nearest obstacle's stall (nearest_two)
    near2: np.ndarray


_UNKNOWN = -2


@dataclass
class _Candidate:
    cost: float
    side_rank: int
    path: list[Node]
    final: int  # heading after the last turn (in the goal cell)
    side: str = ""


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
        self.routes = LaneRoutes(self.net, self.world, self.rows, car, self.r_min)
        self._dist = self.routes.dist  # (cell, heading) -> cost of the best forward route to it
        self._obstacles: Obstacles | None = None
        # pose -> (clearance, nearest obstacle) over all, and without that obstacle's stall (nearest_two)
        self._clear_cache: dict[bytes, tuple[float, int, float, int]] = {}
        self._routes: dict[tuple, _Route | str] = {}  # (path, final heading) -> its sampled route, or why none
        self._plan_keys: dict[int, list[bytes]] = {}  # stall -> pose keys of its feasible plan's path
        self._names: np.ndarray | None = None  # obstacle classes by index, "" last (for index -1)
        self._lanes: tuple[np.ndarray, np.ndarray] | None = None
        self._lanes_along: dict[float, np.ndarray] = {}  # heading -> lane points driving within 45 degrees of it

    # -- obstacles and the footprint (garage_mj.scene.clearance) --------------------------------------
    def obstacles(self) -> Obstacles:
        """Walls, obstacle blocks, pillars and stall outlines as axis-aligned rectangles (built once)."""
        if self._obstacles is None:
            self._obstacles = scene_obstacles(self.scene)
        return self._obstacles

    def footprint(self, rear: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """(N, 4, 2) corners of the car's body with its rear-axle midpoint at ``rear`` and ``heading``."""
        return footprint(self.car, rear, heading)

    def clearance(self, rear: np.ndarray, heading: np.ndarray, exclude_stall: int = -1) -> tuple[np.ndarray, list[str]]:
        """Per pose, the distance [m] of the car body to the nearest obstacle (0 when touching), and its class.

        The routes to a garage's stalls share most of their poses (they fan out from one start), so
        each pose's nearest obstacle over all of them is computed once and kept; only the poses whose
        nearest obstacle is the outline of ``exclude_stall`` itself are measured again without it.
        """
        obs = self.obstacles()
        keys = pose_keys(rear, heading)
        cache = self._clear_cache
        miss = [i for i, k in enumerate(keys) if k not in cache]
        if miss:
            for i, *got in zip(miss, *(a.tolist() for a in nearest_two(obs, self.car, rear[miss], heading[miss])),
                               strict=True):
                cache[keys[i]] = tuple(got)
        got = [cache[k] for k in keys]
        dist = np.array([g[0] for g in got])
        near = np.array([g[1] for g in got], dtype=int)
        if exclude_stall >= 0:
            redo = np.flatnonzero((near >= 0) & (obs.stall[np.maximum(near, 0)] == exclude_stall))
            if len(redo):
                dist[redo], near[redo] = nearest_obstacle(obs, self.car, rear[redo], heading[redo], exclude_stall)
        return dist, self._class_names(near)

    def _class_names(self, near: np.ndarray) -> list[str]:
        """The class of each obstacle index in ``near`` ("" for -1, none)."""
        if self._names is None:
            self._names = np.array([*self.obstacles().classes, ""], dtype=object)
        return self._names[near].tolist()

    def _route_clearance(self, route: _Route, lo: int, hi: int, exclude_stall: int) -> tuple[np.ndarray, list[str]]:
        """:meth:`clearance` of the poses ``lo:hi`` of a candidate's route toward stall ``exclude_stall``, the
        poses' two nearest obstacles kept on the route (the stalls along it ask for the same poses again).

        Where a pose's nearest obstacle is the target stall's own outline, the answer is the nearest
        obstacle of another stall or none, found in the same pass (``nearest_two``) instead of a
        second pass over the obstacles near these poses: the same obstacle and distance wherever it
        is below ``EXACT_BELOW`` (2 m, where distances are exact); above, where both are lower bounds,
        it may differ in the last bits or come from another far obstacle (route features cap
        clearance at 2 m). Poses within a micrometre share one cached value, whichever came first.
        """
        if (route.near[lo:hi] == _UNKNOWN).any():  # the whole route from its start pose at once: its stalls ask
            start = min(lo, int(np.searchsorted(route.s, START_OFFSET)))
            unknown = (np.flatnonzero(route.near[start:] == _UNKNOWN) + start).tolist()
            cache, keys = self._clear_cache, route.keys
            miss = [i for i in unknown if keys[i] not in cache]  # the others are shared with other routes
            if miss:
                found = nearest_two(self.obstacles(), self.car, route.rear[miss], route.heading[miss])
                for i, *got in zip(miss, *(a.tolist() for a in found), strict=True):
                    cache[keys[i]] = tuple(got)
            # from the cache: poses with one key (within a micrometre) get one value
            columns = list(zip(*[cache[keys[i]] for i in unknown], strict=True))
            for array, values in zip((route.dist, route.near, route.dist2, route.near2), columns, strict=True):
                array[unknown] = values
        dist, near = route.dist[lo:hi].copy(), route.near[lo:hi].copy()
        if exclude_stall >= 0:
            obs = self.obstacles()
            own = (near >= 0) & (obs.stall[np.maximum(near, 0)] == exclude_stall)
            dist[own], near[own] = route.dist2[lo:hi][own], route.near2[lo:hi][own]
        return dist, self._class_names(near)

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
        if yaw not in self._lanes_along:  # goals share a few headings: their lane points found once each
            pos, hdg = self._lane_points()
            self._lanes_along[yaw] = pos[np.cos(hdg - yaw) > math.cos(math.pi / 4)]
        along = self._lanes_along[yaw]
        if not len(along):
            return math.inf
        d = np.linalg.norm(along - (x, y), axis=1)
        return float(d.min())

    # -- plans ---------------------------------------------------------------------------------------
    def plan(self, stall_id: int) -> TestPlan:
        """The drive to stall ``stall_id`` (cached): the best feasible candidate, else the first reason."""
        if stall_id not in self._plans:
            self._plans[stall_id] = self._plan(stall_id)
        return self._plans[stall_id]

    def plans(self) -> list[TestPlan]:
        return [self.plan(s.id) for s in self.scene.stalls.stalls]

    def plan_keys(self, plan: TestPlan) -> list[bytes]:
        """:func:`pose_keys` of ``plan``'s path (``rear``, ``heading``): kept from planning when this planner made it."""
        if self._plans.get(plan.stall) is plan and plan.stall in self._plan_keys:
            return self._plan_keys[plan.stall]
        return pose_keys(plan.rear, plan.heading)

    def _candidates(self, stall_id: int) -> list[_Candidate]:
        stall = self.scene.stalls.stalls[stall_id]
        q = stall.road_cell
        out = []
        for node, cost in self._dist.items():
            if node[0] != q:
                continue
            d_in = node[1]
            # stop on the entering line, or turn within the cell onto a line that leaves it
            finals = {d_in} | {d for d in self.routes.openings(q) if d != OPPOSITE[d_in]}
            for final in sorted(finals):
                side = _side(stall, math.atan2(WORLD_DIR[final][1], WORLD_DIR[final][0]))
                rank = {"right": 0, "ahead": 1, "left": 2}[side]
                out.append(_Candidate(cost, rank, self.routes.path_to(node), final, side))
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

    def _route(self, cand: _Candidate) -> _Route | str:
        """The sampled route of a candidate's path and final heading, or why it cannot be filleted; kept,
        since the stalls along a road cell share it (read-only arrays: plans hold views of them)."""
        key = (tuple(cand.path), cand.final)
        if key not in self._routes:
            verts, dirs = self.routes.polyline(cand.path, cand.final)
            radii, why = self.routes.fillets(verts, dirs)
            if why:
                self._routes[key] = why
            else:
                rear, hdg, kap = sample(verts, dirs, radii)
                centre = rear + self.b * np.stack([np.cos(hdg), np.sin(hdg)], axis=1)
                seg = np.linalg.norm(np.diff(centre, axis=0), axis=1)
                s = np.concatenate([[0.0], np.cumsum(seg)])
                for a in (rear, hdg, kap, centre, s):
                    a.flags.writeable = False
                n = len(rear)
                self._routes[key] = _Route(rear, hdg, kap, centre, s, pose_keys(rear, hdg), np.full(n, np.inf),
                                           np.full(n, _UNKNOWN), np.full(n, np.inf), np.full(n, _UNKNOWN))
        return self._routes[key]

    def _try(self, stall, cand: _Candidate) -> TestPlan:
        cfg = self.config
        route = self._route(cand)
        if isinstance(route, str):
            return TestPlan(stall.id, False, route, stall_side=cand.side)
        rear, hdg, kap, centre, s, keys = route[:6]
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
        clear_g, what = self._route_clearance(route, g, g + 1, stall.id)
        first = (clear_g[0], what[0])
        while clear_g[0] < cfg.clearance_margin:
            g -= 1
            pull = float(s[int(np.argmin(dist))] - s[g])
            if g <= 0 or pull > cfg.max_pullback or s[g] < START_OFFSET + MIN_DRIVE:
                return TestPlan(stall.id, False, f"no clear place to stop beside the stall within {cfg.max_pullback:.0f} m "
                                f"({a_noun(first[1])} {first[0]:.2f} m from the car; margin {cfg.clearance_margin:.2f} m)",
                                stall_side=cand.side)
            clear_g, _ = self._route_clearance(route, g, g + 1, stall.id)
        goal = (float(centre[g, 0]), float(centre[g, 1]), float(hdg[g]))
        offset = self.lane_offset(*goal)
        side = _side(stall, hdg[g])  # where the stall lies seen from the goal pose
        # the drive: from the start pose to the goal
        i0 = int(np.searchsorted(s, START_OFFSET))
        clear, names = self._route_clearance(route, i0, g + 1, stall.id)
        k = int(np.argmin(clear))
        max_k = float(np.abs(kap[: g + 1]).max())
        common = dict(centre=centre[: g + 1], rear=rear[: g + 1], heading=hdg[: g + 1], curvature=kap[: g + 1],
                      goal=goal, stall_side=side, clearance=float(clear[k]), clearance_to=names[k],
                      max_curvature=max_k, lane_offset=offset, pullback=pull, drive_from=i0, clearances=clear)
        if max_k > self.kappa_limit + 1e-6:
            return TestPlan(stall.id, False, f"route curvature {max_k:.3f} 1/m above the car's {self.kappa_limit:.3f}",
                            **common)
        if clear[k] < cfg.clearance_margin:
            x, y = rear[i0 + k]
            return TestPlan(stall.id, False, f"the car passes {clear[k]:.2f} m from {a_noun(names[k])} at "
                            f"({x:.1f}, {y:.1f}) (margin {cfg.clearance_margin:.2f} m)", **common)
        if offset > cfg.lane_tolerance:
            return TestPlan(stall.id, False, f"the goal lies {offset:.2f} m off the lane centre", **common)
        self._plan_keys[stall.id] = keys[: g + 1]
        return TestPlan(stall.id, True, "", **common)


def pose_keys(rear: np.ndarray, heading: np.ndarray) -> list[bytes]:
    """A hashable key per pose (micrometres and microradians): what the per-pose caches of a garage's
    routes, which share most of their poses, are keyed on."""
    return list(map(bytes, np.round(np.column_stack([rear, heading]) * 1e6).astype(np.int64)))


def _side(stall, heading: float) -> str:
    """Where ``stall`` lies for a car heading ``heading``: "right", "left" or "ahead" (facing it)."""
    towards = (-math.cos(stall.yaw), -math.sin(stall.yaw))  # from the road into the stall
    right = (math.sin(heading), -math.cos(heading))
    dot = towards[0] * right[0] + towards[1] * right[1]
    return "right" if dot > 0.5 else ("left" if dot < -0.5 else "ahead")


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
