"""Placing the actors of a cruise test around its planned route: :func:`draw_scenario`.

Each actor of a :class:`~garage_mj.driving.actors.config.ScenarioConfig` gets a behaviour and a
trajectory (see the table in :mod:`garage_mj.scene.actor_spec`) drawn from the test's random
stream, so the same seed gives the same actors. A moving actor's trigger point lies
``stopping distance + lead`` before the first place where its motion comes within
``clearance_margin`` of the car's swept path (its *conflict*), with ``lead`` drawn from the
config: the event is adverse (it starts as the car approaches) but avoidable. Static clutter is
placed only where the swept path stays clear; an actor for which no valid place is found in
:data:`PLACEMENT_TRIES` draws is left out, and counted
(:attr:`~garage_mj.driving.actors.scenario.Scenario.missing`). The drawn scenario is then judged
(:func:`garage_mj.driving.actors.judging.judge`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from garage_mj.core.geometry import DELTAS
from garage_mj.driving.actors.config import ScenarioConfig
from garage_mj.driving.actors.judging import judge
from garage_mj.driving.actors.scenario import (
    CONTROL_LAG,
    Corridor,
    Scenario,
    actor_poses,
    circle_points,
    sample_times,
    shape_circles,
)
from garage_mj.scene.actor_spec import CRUISE_BEHAVIOURS, KINDS, SHAPE_SIZE, SHAPES, ActorSpec
from garage_mj.scene.drivable import DrivePlanner, TestPlan
from garage_mj.scene.world import WORLD_DIR, cell_center, world_to_cell

PLACEMENT_TRIES = 20  # draws per actor before it is left out
MIN_SPACING = 2.0  # [m] between the start poses of two actors


class _Placer:
    """Draws actor trajectories around one test's route."""

    def __init__(self, config: ScenarioConfig, plan: TestPlan, planner: DrivePlanner, rng: np.random.Generator,
                 margin: float) -> None:
        self.cfg = config
        self.planner = planner
        self.corr = Corridor(plan, planner.car)
        self.rng = rng
        self.margin = margin
        self.world = planner.world
        self.lane = self.world.drive_lane_width
        self.v_max = planner.car.max_speed
        self.d_stop = config.stopping_distance(self.v_max)
        obs = planner.obstacles()
        hard = np.array([c in ("wall", "obstacle", "pillar") for c in obs.classes], dtype=bool)
        self.hard_boxes = obs.boxes[hard]
        self.stall_boxes = obs.boxes[~hard]
        self.taken: set[int] = {plan.stall}
        self.starts: list[np.ndarray] = []
        curved = np.abs(np.asarray(plan.curvature, dtype=float)) > 1e-9
        self.straight = ~curved

    # geometry helpers
    def _box_distance(self, boxes: np.ndarray, pts: np.ndarray) -> np.ndarray:
        if not len(boxes):
            return np.full(len(pts), np.inf)
        dx = np.maximum(np.maximum(boxes[None, :, 0] - pts[:, None, 0], pts[:, None, 0] - boxes[None, :, 2]), 0.0)
        dy = np.maximum(np.maximum(boxes[None, :, 1] - pts[:, None, 1], pts[:, None, 1] - boxes[None, :, 3]), 0.0)
        return np.hypot(dx, dy).min(axis=1)

    def _free(self, shape: str, poses: np.ndarray, stalls_too: bool = False, clear: float = 0.05) -> bool:
        """No wall, obstacle or pillar (and, with ``stalls_too``, no stall outline) within ``clear``."""
        pts, r = circle_points(shape, poses)
        flat = pts.reshape(-1, 2)
        if (self._box_distance(self.hard_boxes, flat) < r + clear).any():
            return False
        if stalls_too and (self._box_distance(self.stall_boxes, flat) < r).any():
            return False
        return True

    def _spaced(self, xy: np.ndarray) -> bool:
        return all(np.linalg.norm(xy - p) >= MIN_SPACING for p in self.starts)

    def _station(self, lo: float, hi: float, straight: bool = True) -> int | None:
        """A random path index with station in [lo, hi] (on a straight piece when asked)."""
        s = self.corr.s
        ok = (s >= lo) & (s <= hi)
        if straight:
            ok &= self.straight
        idx = np.flatnonzero(ok)
        return int(self.rng.choice(idx)) if len(idx) else None

    def _frame(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        p, h = self.corr.pose(i)
        u = np.array([math.cos(h), math.sin(h)])
        return p, u, np.array([u[1], -u[0]]), h  # point, forward, right, heading

    def _earliest(self) -> float:
        """[m] the first station a conflict may start at: the car can stop before it after any trigger."""
        front = self.planner.car.front  # a crossing reaches the path this far before its line (the bumper)
        return self.corr.s[self.corr.i0] + self.d_stop + max(self.cfg.lead[0], 0.0) + front + 1.0

    def _path(self, points: list[np.ndarray], speed: float, yaw: float | None = None, t0: float = 0.0) -> list[list[float]]:
        """Waypoints walking through ``points`` at ``speed`` (yaw along the motion unless given)."""
        rows, t = [], t0
        for k, p in enumerate(points):
            if k:
                t += float(np.linalg.norm(p - points[k - 1])) / speed
            nxt = points[min(k + 1, len(points) - 1)] - points[max(k - 1, 0)] if len(points) > 1 else np.array([1.0, 0.0])
            th = yaw if yaw is not None else math.atan2(nxt[1], nxt[0])
            rows.append([t, float(p[0]), float(p[1]), th])
        return rows

    def _moving(self, name: str, kind: str, behaviour: str, rows: list[list[float]], stall: int = -1,
                from_stall: bool = False) -> ActorSpec | None:
        """A moving actor along ``rows``, if its way is free of walls, obstacles and pillars and it starts
        apart from the others, with its trigger; else None. ``from_stall``: it starts parked in a
        stall, so its first pose is not checked."""
        poses = np.asarray(rows)[:, 1:]
        if (not self._free(SHAPES[behaviour], self._densify(poses[1:] if from_stall else poses))
                or not self._spaced(poses[0, :2])):
            return None
        return self._with_trigger(name, kind, behaviour, rows, stall)

    def _with_trigger(self, name: str, kind: str, behaviour: str, rows: list[list[float]], stall: int = -1
                      ) -> ActorSpec | None:
        """Attach the trigger: ``stopping distance + lead`` before the first conflict (or a fixed lead)."""
        corr, cfg = self.corr, self.cfg
        w = np.asarray(rows, dtype=float)
        proto = ActorSpec(name, kind, behaviour, w, (0.0, 0.0), cfg.trigger_radius, stall)
        times = sample_times(proto)
        hit = corr.conflicts(proto.shape, actor_poses(proto, times), self.margin)  # (T, N)
        hit[:, : corr.i0] = False
        if hit[0].any() or hit[-1].any():
            return None  # starts or ends in the car's path
        cols = np.flatnonzero(hit.any(axis=0))
        lead = float(self.rng.uniform(*cfg.lead))
        if len(cols):
            s_conflict = corr.s[cols[0]]
            s_trig = s_conflict - self.d_stop - lead
        else:  # passes beside the path: start it as the car comes near its first waypoint
            near = int(np.argmin(np.linalg.norm(corr.centre - w[0, 1:3], axis=1)))
            s_trig = corr.s[near] - self.d_stop - lead
        s_trig -= self.v_max * CONTROL_LAG  # judge() lets the trigger fire one control step late
        s_trig = max(s_trig, corr.s[corr.i0])
        k = max(int(np.searchsorted(corr.s, s_trig, side="right")) - 1, 0)  # the path point at or before it
        p = corr.centre[k]
        return ActorSpec(name, kind, behaviour, w, (float(p[0]), float(p[1])), cfg.trigger_radius, stall)

    # pedestrians
    def pedestrian(self, name: str, behaviour: str) -> ActorSpec | None:
        cfg, lane = self.cfg, self.lane
        v = float(self.rng.uniform(*cfg.pedestrian_speed))
        lo, hi = self._earliest(), self.corr.s[-1] - 1.0
        if behaviour == "step_out":
            return self._step_out(name, v, lo, hi)
        length = float(self.rng.uniform(6.0, 12.0))  # [m] of an "along" walk
        i = self._station(lo + (0.0 if behaviour == "cross" else length), hi)
        if i is None:
            return None
        p, u, right, h = self._frame(i)
        if behaviour == "along":  # the whole walk beside a straight stretch, beyond the earliest conflict
            back = self.corr.index_at(self.corr.s[i] - length)
            if not self.straight[back:i + 1].all():
                return None
        if behaviour == "cross":
            side = 1.0 if self.rng.random() < 0.5 else -1.0
            near, far = lane / 2 + 1.4, 1.5 * lane + 1.0  # [m] right edge + 1.4; left edge + 1.0
            a = p + right * (near if side > 0 else -far)
            b = p + right * (-far if side > 0 else near)
            pts = [a, b]
        else:  # along: the right edge of the car's lane, walking toward the car
            off = lane / 2 + 0.25
            a = p + right * off
            b = a - u * length
            pts = [a, b]
        return self._moving(name, "pedestrian", behaviour, self._path(pts, v))

    def _densify(self, poses: np.ndarray, step: float = 0.5) -> np.ndarray:
        out = [poses[0]]
        for a, b in zip(poses[:-1], poses[1:], strict=True):
            n = max(1, int(math.ceil(np.linalg.norm(b[:2] - a[:2]) / step)))
            for k in range(1, n + 1):
                out.append(a + (b - a) * k / n)
        return np.array(out)

    def _stalls_near(self, lo: float, hi: float, side: str | None = None) -> list[tuple[Any, int]]:
        """(stall, path index) of stalls whose entry lies beside the route between stations lo and hi."""
        corr = self.corr
        out = []
        for st in self.planner.scene.stalls.stalls:
            if st.id in self.taken or st.obstructed or st.angle == 0.0:  # a parallel slot's car leaves along the aisle
                continue
            e = np.array(st.entry)
            d = np.linalg.norm(corr.centre - e, axis=1)
            i = int(np.argmin(d))
            if d[i] > 1.5 * self.lane + 2.0 or not lo <= corr.s[i] <= hi or not self.straight[i]:
                continue
            _, u, right, _ = self._frame(i)
            o = np.array([math.cos(st.yaw), math.sin(st.yaw)])
            if abs(float(o @ u)) > 0.2:  # the stall must face the route across, not along
                continue
            st_side = "right" if float((e - corr.centre[i]) @ right) > 0 else "left"
            if side is None or st_side == side:
                out.append((st, i))
        return out

    def _step_out(self, name: str, v: float, lo: float, hi: float) -> ActorSpec | None:
        cands = self._stalls_near(lo, hi)
        if not cands:
            return None
        st, i = cands[int(self.rng.integers(len(cands)))]
        o = np.array([math.cos(st.yaw), math.sin(st.yaw)])  # out of the stall, toward the road
        t = np.array([-o[1], o[0]])
        sgn = 1.0 if self.rng.random() < 0.5 else -1.0
        e = np.array(st.entry) + t * sgn * st.width / 2
        p, _, _, _ = self._frame(i)
        across = float((p - e) @ o)  # entry to the route's lane centre
        pts = [e - o * st.length * 0.6, e, e + o * (across + self.lane * 1.5 + 0.8)]
        return self._moving(name, "pedestrian", "step_out", self._path(pts, v))

    # moving cars
    def moving_car(self, name: str, behaviour: str) -> ActorSpec | None:
        cfg = self.cfg
        v = float(self.rng.uniform(*cfg.moving_car_speed))
        lo, hi = self._earliest(), self.corr.s[-1] - 1.0
        if behaviour == "reverse_out":
            cands = self._stalls_near(lo, hi, side="left")
            if not cands:
                return None
            st, i = cands[int(self.rng.integers(len(cands)))]
            _, u, _, h = self._frame(i)
            c = np.array([st.x, st.y])
            o = np.array([math.cos(st.yaw), math.sin(st.yaw)])
            road = np.array([st.road_x, st.road_y])
            lane_pt = c + o * float((road - c) @ o)  # the opposite lane's centre in front of the stall
            back = float(self.rng.uniform(0.0, 1.0))
            away = math.atan2(-u[1], -u[0])  # the opposite lane runs against the car
            dwell = float(self.rng.uniform(*cfg.dwell))
            t1 = float(np.linalg.norm(lane_pt - c)) / max(v * 0.6, 0.3)  # reversing is slower
            far = lane_pt - u * float(self.rng.uniform(8.0, 15.0))
            rows = [[0.0, c[0], c[1], st.yaw + math.pi],
                    [t1, lane_pt[0] + u[0] * back, lane_pt[1] + u[1] * back, away],
                    [t1 + dwell, lane_pt[0] + u[0] * back, lane_pt[1] + u[1] * back, away]]
            rows.append([rows[-1][0] + float(np.linalg.norm(far - lane_pt)) / v, far[0], far[1], away])
            spec = self._moving(name, "moving_car", "reverse_out", rows, stall=st.id, from_stall=True)
            if spec is not None:
                self.taken.add(st.id)
            return spec
        if behaviour == "oncoming":
            i = self._station(lo, hi)
            if i is None:
                return None
            p, u, right, h = self._frame(i)
            length = float(self.rng.uniform(10.0, 20.0))
            # the straight stretch ahead of i must hold the whole drive
            end = self.corr.index_at(self.corr.s[i] + length)
            if not self.straight[i:end + 1].all():
                return None
            q = self.corr.centre[end]
            a = q - right * self.lane  # opposite lane, far end
            b = p - right * self.lane  # near end
            return self._moving(name, "moving_car", "oncoming", self._path([a, b], v, yaw=h + math.pi))
        return self._junction_wait(name, v, lo, hi)

    def _junction_wait(self, name: str, v: float, lo: float, hi: float) -> ActorSpec | None:
        corr, net, world = self.corr, self.planner.net, self.world
        rows_n = self.planner.rows
        cells: list[tuple[tuple[int, int], int]] = []  # junction cells the route crosses, first path index
        seen = set()
        for i in range(corr.i0, len(corr.s)):
            if not lo <= corr.s[i] <= hi:
                continue
            cell = world_to_cell(float(corr.centre[i, 0]), float(corr.centre[i, 1]), rows_n, world)
            if cell in seen or cell not in net.cells:
                continue
            seen.add(cell)
            if len(net.cells[cell].openings) >= 3:
                cells.append((cell, i))
        if not cells:
            return None
        cell, i = cells[int(self.rng.integers(len(cells)))]
        centre = np.array(cell_center(*cell, rows_n, world))
        on_route = {world_to_cell(float(x), float(y), rows_n, world) for x, y in corr.centre}
        branches = []
        for d in sorted(net.cells[cell].openings):
            q = (cell[0] + DELTAS[d][0], cell[1] + DELTAS[d][1])
            if q in net.cells and q not in on_route:
                branches.append(d)
        if not branches:
            return None
        d = branches[int(self.rng.integers(len(branches)))]
        u = np.array(WORLD_DIR[d], dtype=float)  # from the junction into the branch
        h = -u  # the waiting car faces the junction
        right = np.array([h[1], -h[0]])
        stop = centre + u * (world.block / 2 + SHAPE_SIZE["car"][0] + 0.5) + right * self.lane / 2
        creep = float(self.rng.uniform(1.0, 2.0))
        start = stop + u * creep
        yaw = math.atan2(h[1], h[0])
        rows = [[0.0, start[0], start[1], yaw], [creep / min(v, 1.0), stop[0], stop[1], yaw]]
        return self._moving(name, "moving_car", "junction_wait", rows)

    # clutter
    def clutter(self, name: str, behaviour: str) -> ActorSpec | None:
        corr = self.corr
        lo, hi = corr.s[corr.i0] + 4.0, corr.s[-1] - 1.0
        if behaviour == "bad_parking":
            cands = self._stalls_near(lo, hi)
            if not cands:
                return None
            st, _ = cands[int(self.rng.integers(len(cands)))]
            o = np.array([math.cos(st.yaw), math.sin(st.yaw)])
            rot = float(self.rng.uniform(-0.3, 0.3))
            for shift in np.arange(float(self.rng.uniform(0.6, 1.6)), -0.01, -0.2):
                c = np.array([st.x, st.y]) + o * shift
                pose = np.array([[c[0], c[1], st.yaw + math.pi + rot]])
                if corr.clearance("car", pose) >= self.margin and self._spaced(c):
                    self.taken.add(st.id)
                    return ActorSpec(name, "clutter", "bad_parking", np.array([[0.0, *pose[0]]]), stall=st.id)
            return None
        shape = SHAPES[behaviour]
        i = self._station(lo, hi)
        if i is None:
            return None
        p, u, right, h = self._frame(i)
        _, r = shape_circles(shape)
        need = self.planner.car.half_width + self.margin + r + 0.05
        if self.rng.random() < 0.5:  # right edge of the car's lane (toward the stall row)
            off = float(self.rng.uniform(need, max(need, self.lane / 2 + 0.5)))
        else:  # somewhere in the opposite lane
            off = -float(self.rng.uniform(need, 1.5 * self.lane - r))
        c = p + right * off
        pose = np.array([[c[0], c[1], h + float(self.rng.uniform(-math.pi, math.pi))]])
        if (corr.clearance(shape, pose) < self.margin or not self._free(shape, pose, stalls_too=True)
                or not self._spaced(c)):
            return None
        return ActorSpec(name, "clutter", behaviour, np.array([[0.0, *pose[0]]]))


def place_actors(placer: Any, config: ScenarioConfig, table: dict[str, Any], rng: np.random.Generator,
                 out: Scenario) -> None:
    """Place ``config``'s actors, kind by kind, with ``placer`` (a method per kind: ``placer.pedestrian(name,
    behaviour)`` ...) into ``out``: per actor up to :data:`PLACEMENT_TRIES` draws of a behaviour it lists that
    ``table`` holds for its kind (cruise or park behaviours); one never placed counts in ``out.missing``."""
    todo = ([("pedestrian", config.pedestrian_behaviours)] * config.pedestrians
            + [("moving_car", config.moving_car_behaviours)] * config.moving_cars
            + [("clutter", config.clutter_behaviours)] * config.clutter)
    counters = {k: 0 for k in KINDS}
    for kind, listed in todo:
        spec = None
        name = f"{kind.replace('_', '')}_{counters[kind]}"
        behaviours = [b for b in listed if b in table[kind]]  # a park behaviour is a park test's, and back
        for _ in range(PLACEMENT_TRIES if behaviours else 0):
            behaviour = behaviours[int(rng.integers(len(behaviours)))]
            spec = getattr(placer, kind)(name, behaviour)
            if spec is not None:
                break
        if spec is None:
            out.missing[kind] = out.missing.get(kind, 0) + 1
            continue
        counters[kind] += 1
        placer.starts.append(spec.waypoints[0, 1:3].copy())
        out.actors.append(spec)
        if spec.stall >= 0:
            out.free_stalls.add(spec.stall)


def draw_scenario(config: ScenarioConfig, plan: TestPlan, planner: DrivePlanner, rng: np.random.Generator,
                  margin: float | None = None) -> Scenario:
    """Place ``config``'s actors around a feasible test ``plan`` with ``rng``, and judge avoidability.

    Actors that take a stall (a car reversing out, a car parked badly) list it in
    :attr:`Scenario.free_stalls`: no parked car stands there. The draws use ``rng`` only, so the
    same seed gives the same actors.
    """
    out = Scenario()
    if config.count == 0 or not plan.feasible:
        return out
    margin = planner.config.clearance_margin if margin is None else float(margin)
    placer = _Placer(config, plan, planner, rng, margin)
    place_actors(placer, config, CRUISE_BEHAVIOURS, rng, out)
    out.feasible, out.reason = judge(out.actors, plan, planner, config, margin)
    return out
