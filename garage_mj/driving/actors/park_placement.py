"""Placing the actors of a park or AVP test around its target stall and reference park plan: :func:`draw_park_scenario`.

A park test's hazards are the stall's own (docs/spec.md section 8): a pedestrian crossing behind the reversing car
(``behind_stall``, started as the car reaches the plan's first reverse stretch), a pedestrian walking along the aisle
past the stall (``beside_stall``), a car pulling out of an occupied stall near the target (``pull_out``: it stands
where that stall's parked car stood, reverses into the aisle, waits, and drives off away from the target) and clutter
beside the plan's swept path (``cone``, ``trolley``). The behaviours are listed in :mod:`garage_mj.scene.actor_spec`;
a :class:`~garage_mj.driving.actors.config.ScenarioConfig` asks for them like for a cruise test's (its park
behaviours; :data:`~garage_mj.driving.actors.config.SCENARIOS` names ready-made ones).

The swept path is the park plan's (:func:`park_corridor`; for an AVP test the parking part, where these hazards
are). Every draw comes from the test's actor generator (:func:`actor_rng`, seeded by the test's seed, apart from
its other draws), so a test's target, parked cars, start and plan are the same with or without actors. Feasibility
is judged as in a cruise test (:func:`~garage_mj.driving.actors.judging.judge_path`), with the park planner's
margin and the parking speed ``park_speed``: no actor waits or ends in the path, static clutter keeps the margin
from it (so the reference plan itself stays a feasible way), and a moving actor reaches the path no earlier than
the stopping distance after its trigger.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.driving.actors.config import NO_ACTORS, ScenarioConfig
from garage_mj.driving.actors.judging import judge_path
from garage_mj.driving.actors.placement import place_actors
from garage_mj.driving.actors.scenario import (
    CONTROL_LAG,
    Corridor,
    Scenario,
    actor_poses,
    circle_points,
    sample_times,
    shape_circles,
)
from garage_mj.scene.actor_spec import PARK_BEHAVIOURS, SHAPE_SIZE, SHAPES, ActorSpec
from garage_mj.scene.drivable import START_OFFSET, TestPlan
from garage_mj.scene.park_planning import centre_to_rear

if TYPE_CHECKING:
    from garage_mj.driving.sim.drive_env import GarageDriveEnv
    from garage_mj.driving.sim.park_task import ParkTest
    from garage_mj.scene.car import CarGeometry
    from garage_mj.scene.stalls import Stall

ACTOR_STREAM = 0x61637472  # seeds a test's actor generator apart from its other draws ("actr")
MIN_SPACING = 2.0  # [m] between the start poses of two actors
NEIGHBOURS = 3.6  # [stall widths] a stall this close along the row to the target is a neighbour (three each side)
CLUTTER_GAP = (0.3, 1.0)  # [m] clutter stands this much beyond the margin from the plan's swept path
# [m] clutter keeps at least this beyond the margin: a driven path strays centimetres from the plan, and a round
# body's outline (its box, which the parking metrics measure to) reaches past its circle
CLUTTER_SLACK = 0.2
# Timing a pedestrian behind the car (adverse, not feasibility: the judge decides that): a parking car stands about
# REVERSE_SETTLE at a cusp (gear, wheels), then reverses at about REVERSE_SPEED; the pedestrian waits after its
# trigger so as to reach the reverse path about when the car does, give or take MEET_JITTER.
REVERSE_SETTLE = 2.0  # [s]
REVERSE_SPEED = 0.8  # [m/s]
MEET_JITTER = 1.0  # [s]


def actor_rng(seed: int) -> np.random.Generator:
    """The generator of a park test's actor draws: seeded by the test's seed, apart from its other draws."""
    return np.random.default_rng([ACTOR_STREAM, int(seed)])


def park_corridor(poses: np.ndarray, car: CarGeometry, start: float = 0.0) -> Corridor:
    """The swept path of car-centre poses ``(N, 3)`` (a park plan's), the car starting ``start`` metres along."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    rear = centre_to_rear(poses, car)
    plan = TestPlan(0, True, "", centre=poses[:, :2], rear=rear[:, :2], heading=poses[:, 2],
                    curvature=np.zeros(len(poses)))
    return Corridor(plan, car, start=start)


def test_path(env: GarageDriveEnv, test: ParkTest) -> tuple[np.ndarray, np.ndarray, float]:
    """The car-centre poses ``(N, 3)`` a feasible ``test`` drives, their directions (+1/-1) and the station it starts
    at: a park test's plan from its start; an AVP test's cruise route (from :data:`START_OFFSET`), then its plan."""
    plan = test.plan
    if test.task == "park":
        return plan.poses, np.asarray(plan.directions), 0.0
    centre = np.asarray(test.cruise.centre, dtype=float)
    head = np.asarray(test.cruise.heading, dtype=float)
    poses = np.vstack([np.column_stack([centre, head]), plan.poses])
    directions = np.concatenate([np.ones(len(centre), dtype=np.int8), np.asarray(plan.directions)])
    return poses, directions, START_OFFSET


class _ParkPlacer:
    """Draws actor trajectories around one park test's stall and plan."""

    def __init__(self, config: ScenarioConfig, env: GarageDriveEnv, test: ParkTest, rng: np.random.Generator
                 ) -> None:
        self.cfg, self.rng, self.margin = config, rng, env.park_planner.config.margin
        self.car = env.car_geometry
        poses, directions, start = test_path(env, test)
        self.corr = park_corridor(poses, self.car, start)
        self.rest_start = test.task == "park"  # a park test starts at rest; an AVP test reaches its plan moving
        self.directions = np.asarray(directions).reshape(-1)
        self.plan_from = len(self.directions) - len(test.plan.poses)  # the first index of the park plan
        stall, stalls, occupied = env.stalls[test.stall], env.stalls, test.occupied
        self.stall, self.stalls, self.occupied = stall, stalls, set(occupied)
        self.d_stop = config.stopping_distance(config.park_speed)
        obs = env.planner.obstacles()
        hard = np.array([c in ("wall", "obstacle", "pillar") for c in obs.classes], dtype=bool)
        self.hard_boxes, self.stall_boxes = obs.boxes[hard], obs.boxes[~hard]
        self.o = np.array([math.cos(stall.yaw), math.sin(stall.yaw)])  # out of the stall, into the aisle
        self.t = np.array([-self.o[1], self.o[0]])  # along the row
        self.entry = np.array(stall.entry, dtype=float)
        self.aisle = float(env.scene.world.aisle_width)
        self.taken: set[int] = set()
        self.starts: list[np.ndarray] = []

    # geometry helpers
    def _box_distance(self, boxes: np.ndarray, pts: np.ndarray) -> np.ndarray:
        if not len(boxes):
            return np.full(len(pts), np.inf)
        dx = np.maximum(np.maximum(boxes[None, :, 0] - pts[:, None, 0], pts[:, None, 0] - boxes[None, :, 2]), 0.0)
        dy = np.maximum(np.maximum(boxes[None, :, 1] - pts[:, None, 1], pts[:, None, 1] - boxes[None, :, 3]), 0.0)
        return np.hypot(dx, dy).min(axis=1)

    def _free(self, shape: str, poses: np.ndarray, stalls_too: bool = False) -> bool:
        """No wall, obstacle or pillar (and, with ``stalls_too``, no stall outline) touches the body at ``poses``."""
        pts, r = circle_points(shape, _densify(np.asarray(poses, dtype=float).reshape(-1, 3)))
        flat = pts.reshape(-1, 2)
        if (self._box_distance(self.hard_boxes, flat) < r + 0.05).any():
            return False
        return not (stalls_too and (self._box_distance(self.stall_boxes, flat) < r).any())

    def _spaced(self, xy: np.ndarray) -> bool:
        return all(np.linalg.norm(xy - p) >= MIN_SPACING for p in self.starts)

    def _reverse_start(self) -> int | None:
        """The plan index where its first reverse stretch begins (None: the plan never reverses)."""
        rev = np.flatnonzero(self.directions < 0)
        return int(rev[0]) if len(rev) else None

    def _trigger(self, name: str, kind: str, behaviour: str, rows: list[list[float]], stall: int = -1,
                 at: int | None = None) -> ActorSpec | None:
        """The actor along ``rows`` with its trigger: at plan index ``at``, else ``stopping distance + lead`` before
        its first conflict with the plan (at the plan's start when that is too close); None when it waits or ends
        in the path, or reaches it too soon after the trigger (:func:`judge_path`)."""
        corr, cfg = self.corr, self.cfg
        w = np.asarray(rows, dtype=float)
        proto = ActorSpec(name, kind, behaviour, w, (0.0, 0.0), cfg.trigger_radius, stall)
        hit = corr.conflicts(proto.shape, actor_poses(proto, sample_times(proto)), self.margin)
        if hit[0].any() or hit[-1].any():
            return None
        if at is None:
            cols = np.flatnonzero(hit.any(axis=0))
            lead = float(self.rng.uniform(*cfg.lead))
            s_conflict = corr.s[cols[0]] if len(cols) else corr.s[int(np.argmin(
                np.linalg.norm(corr.centre - w[0, 1:3], axis=1)))]
            s_trig = max(s_conflict - self.d_stop - lead - cfg.park_speed * CONTROL_LAG, corr.s[corr.i0])
            at = max(int(np.searchsorted(corr.s, s_trig, side="right")) - 1, 0)
        p = corr.centre[at]
        spec = ActorSpec(name, kind, behaviour, w, (float(p[0]), float(p[1])), cfg.trigger_radius, stall)
        ok = judge_path([spec], corr, cfg, self.margin, cfg.park_speed, self.rest_start)[0]
        return spec if ok else None  # else drawn again

    # pedestrians
    def pedestrian(self, name: str, behaviour: str) -> ActorSpec | None:
        v = float(self.rng.uniform(*self.cfg.pedestrian_speed))
        side = 1.0 if self.rng.random() < 0.5 else -1.0
        if behaviour == "behind_stall":  # across the stall's mouth, behind the reversing car
            off = float(self.rng.uniform(0.3, 1.5))  # [m] into the aisle from the stall's entry line
            reach = self.stall.width / 2 + float(self.rng.uniform(2.0, 3.5))
            mid = self.entry + self.o * off
            a, b = mid - self.t * side * reach, mid + self.t * side * reach
            at = self._reverse_start()
        else:  # beside_stall: along the aisle past the stall, at a drawn distance out from the stall row
            off = float(self.rng.uniform(0.5, max(0.6, self.aisle - 0.5)))
            mid = self.entry + self.o * off
            a = mid - self.t * side * float(self.rng.uniform(4.0, 8.0))
            b = mid + self.t * side * float(self.rng.uniform(4.0, 8.0))
            at = None
        yaw = math.atan2(*(b - a)[::-1])
        rows = [[0.0, a[0], a[1], yaw], [float(np.linalg.norm(b - a)) / v, b[0], b[1], yaw]]
        if not self._free("pedestrian", np.asarray(rows)[:, 1:]) or not self._spaced(a):
            return None
        if at is not None:
            rows = self._meet(rows, at)
        return self._trigger(name, "pedestrian", behaviour, rows, at=at)

    def _meet(self, rows: list[list[float]], at: int) -> list[list[float]]:
        """``rows`` delayed so that the walker reaches the path beyond plan index ``at`` (a cusp) about when the
        car, reversing from there, does (:data:`REVERSE_SETTLE`, :data:`REVERSE_SPEED`, :data:`MEET_JITTER`)."""
        w = np.asarray(rows, dtype=float)
        proto = ActorSpec("p", "pedestrian", "behind_stall", w, (0.0, 0.0), 0.0)
        times = sample_times(proto)
        hit = self.corr.conflicts("pedestrian", actor_poses(proto, times), 0.0)[:, at:]
        if not hit.any():
            return rows
        k = int(np.flatnonzero(hit.any(axis=1))[0])  # when it first reaches the reverse path
        j = at + int(np.flatnonzero(hit.any(axis=0))[0])  # where the car first meets its line
        car_t = REVERSE_SETTLE + (self.corr.s[j] - self.corr.s[at]) / REVERSE_SPEED
        wait = max(0.0, car_t - float(times[k]) + float(self.rng.uniform(-MEET_JITTER, MEET_JITTER)))
        if wait <= 0.0:
            return rows
        return [rows[0], [wait, *rows[0][1:]], *[[t + wait, *r] for t, *r in rows[1:]]]

    # moving cars
    def _neighbours(self) -> list[Stall]:
        """Occupied stalls of the target's row within :data:`NEIGHBOURS` stall widths (perpendicular or angled)."""
        out = []
        for st in self.stalls:
            if st.id == self.stall.id or st.id not in self.occupied or st.id in self.taken \
                    or st.angle == 0.0 or abs(math.remainder(st.yaw - self.stall.yaw, math.tau)) > 0.1:
                continue
            d = np.array([st.x - self.stall.x, st.y - self.stall.y])
            if abs(float(d @ self.o)) < 0.5 and abs(float(d @ self.t)) <= NEIGHBOURS * self.stall.width:
                out.append(st)
        return out

    def moving_car(self, name: str, behaviour: str) -> ActorSpec | None:
        cands = self._neighbours()
        if not cands:
            return None
        st = cands[int(self.rng.integers(len(cands)))]
        v = float(self.rng.uniform(*self.cfg.moving_car_speed))
        c = np.array([st.x, st.y])
        away = np.sign(float((c - np.array([self.stall.x, self.stall.y])) @ self.t)) * self.t  # along the row
        if self.rng.random() < 0.25:  # now and then it leaves the other way, past the target
            away = -away
        hx = SHAPE_SIZE["car"][0]
        out = np.array(st.entry) + self.o * (hx + float(self.rng.uniform(0.3, 1.2)))  # its nose clear of the row
        yaw_in, yaw_away = st.yaw + math.pi, math.atan2(away[1], away[0])
        turn = out + away * 1.5 + self.o * 0.5  # a short turn onto the aisle
        t1 = float(np.linalg.norm(out - c)) / max(0.6 * v, 0.3)  # reversing is slower
        t2 = t1 + float(self.rng.uniform(*self.cfg.dwell))
        t3 = t2 + float(np.linalg.norm(turn - out)) / max(0.6 * v, 0.3)
        rows = [[0.0, c[0], c[1], yaw_in], [t1, out[0], out[1], yaw_in], [t2, out[0], out[1], yaw_in],
                [t3, turn[0], turn[1], yaw_away]]
        way = np.asarray(rows)[:, 1:]
        way[0, :2] += self.o * 1.0  # a pillar beside its stall is no obstacle where it stands, parked
        if not self._free("car", way) or not self._spaced(c):
            return None
        # it drives off as far along the aisle as it is free, up to a drawn length (a wall ends a short aisle)
        for length in np.arange(float(self.rng.uniform(6.0, 12.0)), 2.9, -1.5):
            far = turn + away * length
            if self._free("car", np.array([[*turn, yaw_away], [*far, yaw_away]])):
                rows.append([t3 + float(length) / v, far[0], far[1], yaw_away])
                break
        else:
            return None
        spec = self._trigger(name, "moving_car", behaviour, rows, stall=st.id)
        if spec is not None:
            self.taken.add(st.id)
        return spec

    # clutter
    def clutter(self, name: str, behaviour: str) -> ActorSpec | None:
        shape = SHAPES[behaviour]
        corr = self.corr
        i = int(self.rng.integers(self.plan_from, len(corr.s)))  # beside the park plan (an AVP test's too)
        p, h = corr.pose(i)
        n = np.array([-math.sin(h), math.cos(h)]) * (1.0 if self.rng.random() < 0.5 else -1.0)
        _, r = shape_circles(shape)
        gap = self.margin + float(self.rng.uniform(*CLUTTER_GAP))
        c = p + n * (self.car.half_width + r + gap)
        pose = np.array([[c[0], c[1], float(self.rng.uniform(-math.pi, math.pi))]])
        # clear of the whole swept path by the margin: the reference plan stays a feasible way past it
        if corr.clearance(shape, pose) < self.margin + CLUTTER_SLACK or not self._free(shape, pose, stalls_too=True) \
                or not self._spaced(c):
            return None
        return ActorSpec(name, "clutter", behaviour, np.array([[0.0, *pose[0]]]))


def _densify(poses: np.ndarray, step: float = 0.5) -> np.ndarray:
    out = [poses[0]]
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        n = max(1, int(math.ceil(np.linalg.norm(b[:2] - a[:2]) / step)))
        out += [a + (b - a) * k / n for k in range(1, n + 1)]
    return np.array(out)


def draw_park_scenario(config: ScenarioConfig, env: GarageDriveEnv, test: ParkTest, rng: np.random.Generator
                       ) -> Scenario:
    """Place ``config``'s park actors around a feasible park or AVP ``test`` of ``env`` with ``rng``, and judge them.

    A ``pull_out`` car takes an occupied stall (:attr:`Scenario.free_stalls`: its parked car gives way to it). A
    kind whose listed behaviours hold no park behaviour is left out (``missing``), as is an actor no valid place
    was found for in :data:`~garage_mj.driving.actors.placement.PLACEMENT_TRIES` draws.
    """
    out = Scenario()
    if config.count == 0 or not test.feasible:
        return out
    placer = _ParkPlacer(config, env, test, rng)
    place_actors(placer, config, PARK_BEHAVIOURS, rng, out)
    out.feasible, out.reason = judge_park(out.actors, env, test, config)
    return out


def judge_park(actors: list[ActorSpec], env: GarageDriveEnv, test: ParkTest, config: ScenarioConfig
               ) -> tuple[bool, str]:
    """Whether a driver can avoid every actor of a park or AVP ``test`` (and why not): on the park plan's swept path,
    with the park planner's margin, at ``park_speed`` (a park test's car starts at rest)."""
    if not actors or not test.feasible:
        return True, ""
    poses, _, start = test_path(env, test)
    corr = park_corridor(poses, env.car_geometry, start)
    return judge_path(actors, corr, config, env.park_planner.config.margin, config.park_speed, test.task == "park")


def park_scenario(env: GarageDriveEnv, test: ParkTest, seed: int | None, rng: np.random.Generator,
                  given: list[Any] | None) -> tuple[Scenario, ParkTest]:
    """The actors of a park or AVP test as the env's reset draws them (or ``given``, a replay's), and the test with
    the stalls they take freed of their parked cars."""
    cfg = env.scenario_config
    if given is None:
        scen = draw_park_scenario(cfg, env, test, actor_rng(seed) if seed is not None else rng)
    else:
        actors = [a if isinstance(a, ActorSpec) else ActorSpec.from_dict(a) for a in given]
        if actors and env.actor_bodies is None:
            raise ValueError("this env has no actor bodies: build it with scenario= room for the replayed actors")
        ok, why = judge_park(actors, env, test, cfg if cfg.count else NO_ACTORS)
        scen = Scenario(actors, ok, why, {}, {a.stall for a in actors if a.stall >= 0})
    if scen.free_stalls:
        test = dataclasses.replace(test, occupied=[s for s in test.occupied if s not in scen.free_stalls],
                                   bodies={k: b for k, b in test.bodies.items() if k not in scen.free_stalls})
    return scen, test
