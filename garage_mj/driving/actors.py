"""Adverse events of a cruise test: pedestrians, moving cars and clutter (issue 12).

A :class:`ScenarioConfig` says how many actors of each kind a test gets; :func:`draw_scenario`
places them from the test's random stream, around the test's planned route
(:class:`~garage_mj.scene.drivable.TestPlan`), and decides from the scene and the trigger rule alone
whether every event stays avoidable. Nothing here runs MuJoCo: the drive env moves the actors
(kinematic mocap bodies) along their :class:`ActorSpec` trajectories, and the OpenSCENARIO writer
exports the same specs.

Actors
------
=============  ===============  ==============================================================
kind           behaviour        what it does
=============  ===============  ==============================================================
pedestrian     ``cross``        walks across the aisle ahead of the car, edge to edge
pedestrian     ``step_out``     steps out between two parked cars and crosses the aisle
pedestrian     ``along``        walks along the right edge of the car's lane, toward the car
moving_car     ``reverse_out``  reverses out of a stall on the car's left into the opposite lane,
                                waits, then drives off past the car
moving_car     ``oncoming``     drives the opposite lane of a straight stretch toward the car
moving_car     ``junction_wait``  waits on a side road at a junction the car crosses, creeps
                                up to the junction as the car approaches
clutter        ``cone``         a traffic cone at the edge of the aisle (static)
clutter        ``trolley``      a shopping trolley at the edge of the aisle (static)
clutter        ``bad_parking``  a car parked crooked, its nose out of its stall into the aisle
=============  ===============  ==============================================================

The trigger rule
----------------
A moving actor waits at its first waypoint until the ego car's centre comes within
``trigger_radius`` of its trigger point (a point of the car's route), then follows its waypoints
(time measured from the trigger, linear in between) and stays at the last one. The trigger point
lies ``stopping distance + lead`` before the first place where the actor's motion comes within
``clearance_margin`` of the car's swept path (its *conflict*), with ``lead`` drawn from the
config: the event is adverse (it starts as the car approaches) but avoidable.

Feasibility (decided before the drive, never from its outcome): a test with actors is infeasible
when an actor starts or ends in the car's swept path (no room to pass, nothing to wait for), or
when an actor's motion reaches the car's path less than the stopping distance
``v t_react + v^2 / (2 a_brake)`` (``v`` the car's top speed) beyond the place where the trigger
fires. Static clutter is placed only where the swept path stays clear; an actor for which no
valid place is found in :data:`PLACEMENT_TRIES` draws is left out, and counted
(:attr:`Scenario.missing`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.core.config import ConfigError, load_config, read_toml
from garage_mj.core.geometry import DELTAS
from garage_mj.scene.drivable import START_OFFSET, DrivePlanner, TestPlan
from garage_mj.scene.world import WORLD_DIR, cell_center, world_to_cell

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry

KINDS = ("pedestrian", "moving_car", "clutter")
BEHAVIOURS = {
    "pedestrian": ("cross", "step_out", "along"),
    "moving_car": ("reverse_out", "oncoming", "junction_wait"),
    "clutter": ("cone", "trolley", "bad_parking"),
}
#: Body shape of each behaviour (the MJCF template the env moves).
SHAPES = {"cross": "pedestrian", "step_out": "pedestrian", "along": "pedestrian", "reverse_out": "car",
          "oncoming": "car", "junction_wait": "car", "cone": "cone", "trolley": "trolley", "bad_parking": "car"}
#: Half extents (length/2 along the actor's yaw, width/2, height/2) [m] of each shape's body.
SHAPE_SIZE = {"pedestrian": (0.25, 0.25, 0.85), "car": (2.15, 0.95, 0.7), "cone": (0.18, 0.18, 0.35),
              "trolley": (0.45, 0.3, 0.5)}
ROUND = frozenset({"pedestrian", "cone"})  # shapes whose body is a vertical cylinder (capsule) of radius hx
PLACEMENT_TRIES = 20  # draws per actor before it is left out
SAMPLE_DT = 0.1  # [s] trajectories are checked against the swept path at this time step
MIN_SPACING = 2.0  # [m] between the start poses of two actors
CONTROL_LAG = 0.1  # [s] a trigger is checked once per control step: it may fire this late
_EPS = 1e-6


@dataclass(frozen=True)
class ScenarioConfig:
    """Actors per test and the rules they are drawn by (TOML-loadable: ``[scenario]`` or top level)."""

    pedestrians: int = 0
    moving_cars: int = 0
    clutter: int = 0
    pedestrian_behaviours: tuple[str, ...] = BEHAVIOURS["pedestrian"]  # drawn uniformly
    moving_car_behaviours: tuple[str, ...] = BEHAVIOURS["moving_car"]
    clutter_behaviours: tuple[str, ...] = BEHAVIOURS["clutter"]
    pedestrian_speed: tuple[float, float] = (0.8, 1.5)  # [m/s] walking speed, uniform
    moving_car_speed: tuple[float, float] = (1.0, 2.5)  # [m/s]
    lead: tuple[float, float] = (0.5, 8.0)  # [m] the trigger lies this much beyond the stopping distance
    trigger_radius: float = 2.0  # [m] the ego's centre this close to the trigger point starts the actor
    reaction_time: float = 0.5  # [s] feasibility: a driver reacts within this
    brake_decel: float = 3.0  # [m/s^2] feasibility: a driver brakes at least this hard
    dwell: tuple[float, float] = (1.0, 3.0)  # [s] a reversing car waits this long in the aisle

    def __post_init__(self) -> None:
        for name in ("pedestrians", "moving_cars", "clutter"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise ConfigError(f"ScenarioConfig: {name} must be an integer >= 0, got {v!r}")
        for kind, name in (("pedestrian", "pedestrian_behaviours"), ("moving_car", "moving_car_behaviours"),
                           ("clutter", "clutter_behaviours")):
            got = tuple(getattr(self, name))
            bad = [b for b in got if b not in BEHAVIOURS[kind]]
            if bad or not got:
                raise ConfigError(f"ScenarioConfig: {name} must be a non-empty subset of {list(BEHAVIOURS[kind])}, "
                                  f"got {list(got)}")
            object.__setattr__(self, name, got)
        for name in ("pedestrian_speed", "moving_car_speed", "lead", "dwell"):
            v = getattr(self, name)
            try:
                lo, hi = (float(x) for x in v)
            except (TypeError, ValueError):
                raise ConfigError(f"ScenarioConfig: {name} must be a pair [lo, hi], got {v!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ConfigError(f"ScenarioConfig: {name} needs finite lo <= hi, got {v!r}")
            if name != "lead" and lo < 0:
                raise ConfigError(f"ScenarioConfig: {name} must be >= 0, got {v!r}")
            if name.endswith("speed") and lo <= 0:
                raise ConfigError(f"ScenarioConfig: {name} must be > 0, got {v!r}")
            object.__setattr__(self, name, (lo, hi))
        for name in ("trigger_radius", "reaction_time", "brake_decel"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"ScenarioConfig: {name} must be a finite number >= 0, got {v!r}")
        if self.brake_decel <= 0:
            raise ConfigError("ScenarioConfig: brake_decel must be > 0")

    @property
    def count(self) -> int:
        return self.pedestrians + self.moving_cars + self.clutter

    def stopping_distance(self, speed: float) -> float:
        """[m] a driver at ``speed`` needs this far to stop (reaction, then braking)."""
        return speed * self.reaction_time + speed * speed / (2.0 * self.brake_decel)


NO_ACTORS = ScenarioConfig()


def load_scenario_config(source: str | dict[str, Any] | ScenarioConfig | None, **overrides: Any) -> ScenarioConfig:
    """A :class:`ScenarioConfig` from a TOML file (``[scenario]`` table or top level), a dict or None.

    ``overrides`` (e.g. ``pedestrians=2``; None values ignored) replace the file's values.
    """
    if isinstance(source, ScenarioConfig):
        data: dict[str, Any] = {f: getattr(source, f) for f in source.__dataclass_fields__}
    elif isinstance(source, dict):
        data = dict(source)
    elif source is None:
        data = {}
    else:
        raw = read_toml(source)
        data = dict(raw.get("scenario", raw)) if isinstance(raw.get("scenario", raw), dict) else {}
        if "scenario" in raw and set(raw) - {"scenario"}:
            raise ConfigError(f"{source}: unknown table(s) {sorted(set(raw) - {'scenario'})}; known: scenario")
    data.update({k: v for k, v in overrides.items() if v is not None})
    return load_config(ScenarioConfig, data)


@dataclass(frozen=True)
class ActorSpec:
    """One actor of a test: its body, its trajectory and what starts it.

    ``waypoints`` is (K, 4): time after the trigger [s], x [m], y [m], yaw [rad]; the actor stands
    at the first until triggered, moves linearly between them, and stays at the last. A static
    actor has one waypoint and no trigger.
    """

    name: str  # unique in the test, e.g. "pedestrian_0" (also its MJCF body)
    kind: str  # "pedestrian" | "moving_car" | "clutter"
    behaviour: str  # see the module table
    waypoints: np.ndarray
    trigger: tuple[float, float] | None = None  # (x, y) [m]: the ego's centre within trigger_radius starts it
    trigger_radius: float = 0.0
    stall: int = -1  # the stall it takes (kept free of a parked car), or -1

    @property
    def shape(self) -> str:
        return SHAPES[self.behaviour]

    @property
    def static(self) -> bool:
        return self.trigger is None or len(self.waypoints) < 2

    @property
    def duration(self) -> float:
        """[s] from the trigger to the last waypoint."""
        return float(self.waypoints[-1, 0]) if len(self.waypoints) else 0.0

    def pose_at(self, tau: float | None) -> tuple[float, float, float]:
        """(x, y, yaw) ``tau`` seconds after the trigger (None or < 0: not triggered yet)."""
        w = self.waypoints
        if tau is None or tau <= w[0, 0] or len(w) == 1:
            return float(w[0, 1]), float(w[0, 2]), float(w[0, 3])
        if tau >= w[-1, 0]:
            return float(w[-1, 1]), float(w[-1, 2]), float(w[-1, 3])
        k = int(np.searchsorted(w[:, 0], tau, side="right")) - 1
        t0, t1 = w[k, 0], w[k + 1, 0]
        a = (tau - t0) / (t1 - t0) if t1 > t0 else 1.0
        yaw = w[k, 3] + a * math.remainder(w[k + 1, 3] - w[k, 3], math.tau)
        return (float(w[k, 1] + a * (w[k + 1, 1] - w[k, 1])), float(w[k, 2] + a * (w[k + 1, 2] - w[k, 2])),
                float(yaw))

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "behaviour": self.behaviour,
                "waypoints": [[round(float(v), 6) for v in row] for row in self.waypoints],
                "trigger": None if self.trigger is None else [float(self.trigger[0]), float(self.trigger[1])],
                "trigger_radius": float(self.trigger_radius), "stall": int(self.stall)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ActorSpec:
        try:
            kind, behaviour = str(d["kind"]), str(d["behaviour"])
            if kind not in KINDS or behaviour not in BEHAVIOURS[kind]:
                raise ValueError(f"unknown actor kind/behaviour {kind!r}/{behaviour!r}")
            w = np.asarray(d["waypoints"], dtype=float).reshape(-1, 4)
            if not len(w) or not np.isfinite(w).all() or (np.diff(w[:, 0]) < 0).any():
                raise ValueError("waypoints must be finite rows (t, x, y, yaw) with non-decreasing t")
            trig = d.get("trigger")
            trig = None if trig is None else (float(trig[0]), float(trig[1]))
            return cls(str(d["name"]), kind, behaviour, w, trig, float(d.get("trigger_radius", 0.0)),
                       int(d.get("stall", -1)))
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"malformed actor {d!r}: {exc}") from None


@dataclass
class Scenario:
    """The actors of one test and whether every event stays avoidable."""

    actors: list[ActorSpec] = field(default_factory=list)
    feasible: bool = True
    reason: str = ""
    missing: dict[str, int] = field(default_factory=dict)  # kind -> actors asked for but not placed
    free_stalls: set[int] = field(default_factory=set)  # stalls the actors take (no parked car)

    def count(self, kind: str) -> int:
        return sum(a.kind == kind for a in self.actors)

    @property
    def duration(self) -> float:
        """[s] summed over moving actors: how long a driver may have to wait for them."""
        return float(sum(a.duration for a in self.actors if not a.static))


# -- shapes as circles ---------------------------------------------------------------------------------
def _circles(shape: str) -> tuple[np.ndarray, float]:
    """Circle centres along the body's length (local x) and their radius, covering the body's outline."""
    hx, hy, _ = SHAPE_SIZE[shape]
    if shape in ROUND:
        return np.array([0.0]), hx
    n = max(2, int(math.ceil(hx / hy)))
    step = 2 * hx / n
    xs = -hx + step / 2 + step * np.arange(n)
    return xs, math.hypot(step / 2, hy)


def _circle_points(shape: str, poses: np.ndarray) -> tuple[np.ndarray, float]:
    """(P, C, 2) circle centres of ``shape`` at each of P poses (x, y, yaw), and the radius."""
    xs, r = _circles(shape)
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    return np.stack([poses[:, 0:1] + c * xs, poses[:, 1:2] + s * xs], axis=-1), r


class Corridor:
    """The ego car's swept path of a feasible test: body footprints along the planned route."""

    def __init__(self, plan: TestPlan, car: CarGeometry) -> None:
        self.car = car
        self.rear = np.asarray(plan.rear, dtype=float)
        self.heading = np.asarray(plan.heading, dtype=float)
        self.centre = np.asarray(plan.centre, dtype=float)
        seg = np.linalg.norm(np.diff(self.centre, axis=0), axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])  # [m] centre-path stations
        self.i0 = int(min(np.searchsorted(self.s, START_OFFSET), len(self.s) - 1))  # where the car starts
        self._cos, self._sin = np.cos(self.heading), np.sin(self.heading)

    def distance(self, points: np.ndarray, first: int = 0) -> np.ndarray:
        """(N', M) distance [m] of each of M points to the car body at path poses ``first``..N-1."""
        car = self.car
        x0, x1 = car.rear - car.rear_axle, car.front - car.rear_axle  # body along x from the rear axle
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        dx = pts[None, :, 0] - self.rear[first:, None, 0]
        dy = pts[None, :, 1] - self.rear[first:, None, 1]
        c, s = self._cos[first:, None], self._sin[first:, None]
        lx = c * dx + s * dy
        ly = -s * dx + c * dy
        ex = np.maximum(np.maximum(x0 - lx, lx - x1), 0.0)
        ey = np.maximum(np.abs(ly) - car.half_width, 0.0)
        return np.hypot(ex, ey)

    def conflicts(self, shape: str, poses: np.ndarray, margin: float) -> np.ndarray:
        """(P, N) whether the body at each pose comes within ``margin`` of the car body at each path pose."""
        pts, r = _circle_points(shape, np.asarray(poses, dtype=float).reshape(-1, 3))
        p, c = pts.shape[:2]
        d = self.distance(pts.reshape(-1, 2))  # (N, P * C)
        near = (d < r + margin).reshape(len(self.s), p, c).any(axis=2)
        return near.T

    def clearance(self, shape: str, poses: np.ndarray) -> float:
        """[m] smallest distance of the body at any of ``poses`` to the car body anywhere on the drive."""
        pts, r = _circle_points(shape, np.asarray(poses, dtype=float).reshape(-1, 3))
        return float(self.distance(pts.reshape(-1, 2), self.i0).min()) - r

    def pose(self, i: int) -> tuple[np.ndarray, float]:
        """Centre-path point and heading at path index ``i``."""
        return self.centre[i], float(self.heading[i])

    def index_at(self, station: float) -> int:
        return int(min(max(np.searchsorted(self.s, station), 0), len(self.s) - 1))


def sample_times(actor: ActorSpec) -> np.ndarray:
    """Times after the trigger at which an actor's trajectory is checked (its waypoints included)."""
    if actor.static:
        return np.zeros(1)
    t = np.arange(0.0, actor.duration, SAMPLE_DT)
    return np.unique(np.concatenate([t, actor.waypoints[:, 0]]))


def actor_poses(actor: ActorSpec, times: np.ndarray) -> np.ndarray:
    return np.array([actor.pose_at(float(t)) for t in times], dtype=float).reshape(-1, 3)


# -- placement ------------------------------------------------------------------------------------------
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
        self.lane = self.world.lane_width
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
        pts, r = _circle_points(shape, poses)
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
            if st.id in self.taken or st.obstructed:
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
        _, r = _circles(shape)
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
    todo = ([("pedestrian", config.pedestrian_behaviours)] * config.pedestrians
            + [("moving_car", config.moving_car_behaviours)] * config.moving_cars
            + [("clutter", config.clutter_behaviours)] * config.clutter)
    counters = {k: 0 for k in KINDS}
    for kind, behaviours in todo:
        spec = None
        name = f"{kind.replace('_', '')}_{counters[kind]}"
        for _ in range(PLACEMENT_TRIES):
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
    out.feasible, out.reason = judge(out.actors, plan, planner, config, margin)
    return out


def judge(actors: list[ActorSpec], plan: TestPlan, planner: DrivePlanner, config: ScenarioConfig,
          margin: float | None = None) -> tuple[bool, str]:
    """Whether a driver of this car can avoid every actor (and why not), from the scene and the trigger rule.

    Used by :func:`draw_scenario` and on a replayed scenario (a ``.xosc``), whose actors were not drawn here.
    """
    if not actors or not plan.feasible:
        return True, ""
    margin = planner.config.clearance_margin if margin is None else float(margin)
    corr = Corridor(plan, planner.car)
    v = planner.car.max_speed
    d_stop = config.stopping_distance(v)
    for a in actors:
        noun = a.name.replace("_", " ")
        if a.static:
            gap = corr.clearance(a.shape, a.waypoints[:1, 1:])
            if gap < margin:
                return False, f"{noun} ({a.behaviour}) stands {max(gap, 0.0):.2f} m from the car's path (margin {margin:.2f} m)"
            continue
        times = sample_times(a)
        hit = corr.conflicts(a.shape, actor_poses(a, times), margin)
        hit[:, : corr.i0] = False
        if hit[0].any():
            return False, f"{noun} ({a.behaviour}) waits in the car's path"
        if hit[-1].any():
            return False, f"{noun} ({a.behaviour}) stops in the car's path: no room to pass"
        # where the trigger fires at the latest: at the trigger point (or at the start, if already inside)
        trig = np.asarray(a.trigger, dtype=float)
        d = np.linalg.norm(corr.centre - trig, axis=1)
        inside = np.flatnonzero(d <= a.trigger_radius)
        if not len(inside) or corr.s[corr.i0] >= corr.s[inside[-1]]:
            fire = corr.s[corr.i0]  # the car starts within reach of the trigger
        else:
            fire = corr.s[int(np.argmin(d))]
        fire = max(fire, corr.s[corr.i0]) + v * CONTROL_LAG  # one control step late
        cols = np.flatnonzero(hit.any(axis=0))
        body = planner.car.front - planner.car.rear + a.trigger_radius
        bad = cols[(corr.s[cols] >= fire - body) & (corr.s[cols] < fire + d_stop)]
        if len(bad):
            gap = corr.s[bad[0]] - fire
            return False, (f"{noun} ({a.behaviour}) reaches the car's path {gap:.1f} m after its trigger; "
                           f"stopping from {v:.1f} m/s needs {d_stop:.1f} m")
    return True, ""
