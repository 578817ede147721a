"""Outcome of one cruise test, decided by the environment (docs/spec.md section 7), never by the driver.

Every outcome kind is declared once, in :data:`OUTCOMES` (one :class:`OutcomeSpec` each, in display
order): its name in ``tests.csv``, its count column in ``summary.csv``, whether it is a failure and
its class among the paper's three, and what the report says of it. :class:`OutcomeKind`,
:data:`FAILURES`, :data:`PAPER_CLASS` and the other tables here are derived from it, and so is every
column, count and table of failures elsewhere; a new kind is one entry there and its check in
:class:`OutcomeMonitor` (or, for a kind the runner decides, where the runner decides it).

:class:`OutcomeMonitor` is pure: ``update(time, position, speed, contacts)`` looks at the car's
state and the contacts of this step and returns an :class:`Outcome` once the test is over.
:func:`ego_contacts` turns MuJoCo contacts into the (semantic class, geom name) pairs it reads.

Checks, in this order: collision (ego touches a wall, pillar, obstacle or parked car), success
(within ``goal_tolerance`` of the goal pose, heading within ``goal_heading_tolerance``, slower
than ``goal_speed``), deadlock (farther than ``max_deviation`` from the route, past the goal by
more than ``goal_tolerance``, or less than ``stuck_progress`` of progress along the route in
``stuck_time``), missed goal (that lack of progress, but stopped within ``missed_goal_radius`` of
the goal: the car meant to park there and ended outside the tolerance, it was not stuck), timeout
(``time_limit = route length / min_mean_speed + time_slack``).

The paper has three failure classes (collision, timeout, deadlock); in them a missed goal counts as
a deadlock (:data:`PAPER_CLASS`).

``driver_crash`` and ``driver_timeout`` are not decided here either: the cruise runner
(:mod:`garage_mj.driving.cruise`) gives them when the process driving a test dies on every try, or
the test runs past its wall-clock limit (``CruiseSettings.test_timeout``). They are failures of the
driver, not of the garage; in the paper's classes a crash counts as a deadlock (the car stops where
it is) and a wall-clock overrun as a timeout.

``outside_stall`` is the parking twin of ``missed_goal``, decided by
:class:`~garage_mj.driving.sim.park_outcomes.ParkMonitor` for park and AVP tests (docs/spec.md section 8);
a cruise test never ends so.

``infeasible`` is not decided here: the drive env gives it before the drive, from the scene alone
(:mod:`garage_mj.scene.drivable`), and such a test is never driven. Nor is ``unproven``, a park test's verdict
when the reference park planner (:mod:`garage_mj.scene.park_planning`) finds no path within its escalated
budget and no proof that none exists: never driven, counted apart from both feasible and infeasible tests
(:data:`NOT_DRIVEN`).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from garage_mj.scene.route_line import Route
from garage_mj.scene.semantics import COLLIDABLE, Semantic


@dataclass(frozen=True)
class OutcomeSpec:
    """One outcome kind: how the files name it, whether it is a failure, and what the report says of it."""

    kind: str  # the ``outcome`` column of tests.csv, the value of OutcomeKind
    column: str  # its count column in summary.csv (and failures.csv, the tables of a driver's tests)
    description: str  # what happened, in one line
    failure: bool = False  # a driven test that did not succeed
    paper_class: str | None = None  # a failure's class among the paper's three
    hit: bool = False  # it ends on touching something: tests.csv's hit and hit_geom say what
    truncates: bool = False  # the drive env truncates the episode (a time limit) instead of terminating it
    runner: bool = False  # decided by the cruise runner (the driver's process died or hung), not the env: never replayed
    note: str = ""  # what the report explains of it, with {OutcomeConfig field} slots ("": its name says it)


#: Every outcome kind, in display order: the one place a kind is declared.
OUTCOMES = (
    OutcomeSpec("success", "successes", "stopped on the goal pose"),
    OutcomeSpec("collision", "collisions", "touched a wall, pillar, obstacle, parked car or actor",
                failure=True, paper_class="collision", hit=True),
    OutcomeSpec("timeout", "timeouts", "still driving at the time limit",
                failure=True, paper_class="timeout", truncates=True),
    OutcomeSpec("deadlock", "deadlocks", "stuck, off the route, or past the goal",
                failure=True, paper_class="deadlock",
                note="the car made no progress for {stuck_time:g} s farther than {missed_goal_radius:g} m from the "
                     "goal, left the route by more than {max_deviation:g} m or drove past the goal"),
    OutcomeSpec("missed_goal", "missed_goals", "stopped near the goal, outside the tolerance of its pose",
                failure=True, paper_class="deadlock",
                note="it stopped within {missed_goal_radius:g} m of the goal but outside the parking tolerance "
                     "({goal_tolerance:g} m, {goal_heading_tolerance:g} rad)"),
    OutcomeSpec("outside_stall", "outside_stalls", "stopped near the target stall, not parked inside it "
                "(park and AVP tests)", failure=True, paper_class="deadlock"),
    OutcomeSpec("driver_crash", "driver_crashes", "the driver's process died (a signal or an exit) on every try, "
                "or the driver called sys.exit",
                failure=True, paper_class="deadlock", runner=True,
                note="the process running the driver died (a segfault, the OOM killer, kill -9) on each try, or the "
                     "driver raised SystemExit (sys.exit): the car stopped where it was; the reason names the signal, "
                     "exit code or exception"),
    OutcomeSpec("driver_timeout", "driver_timeouts", "the test ran past its wall-clock limit (--test-timeout)",
                failure=True, paper_class="timeout", runner=True,
                note="the test ran past its wall-clock limit (a driver whose act() blocks); its process was "
                     "stopped and the run went on"),
    OutcomeSpec("unproven", "unproven", "the reference park planner found no path within its escalated budget "
                "and no proof that none exists (park and AVP tests); never driven, neither feasible nor infeasible, "
                "excluded from rates and counted apart"),
    OutcomeSpec("infeasible", "infeasible", "no driver of this car can drive it; decided from the scene, "
                "never driven, excluded from rates"),
)
#: How a test ended: one member per entry of :data:`OUTCOMES` (``OutcomeKind.MISSED_GOAL.value == "missed_goal"``).
OutcomeKind = enum.Enum("OutcomeKind", [(s.kind.upper(), s.kind) for s in OUTCOMES], type=str,
                        module=__name__, qualname="OutcomeKind")
OutcomeKind.__doc__ = "How a test ended: " + "; ".join(f"``{s.kind}``: {s.description}" for s in OUTCOMES) + "."

#: The failure kinds, in display order.
FAILURES = tuple(OutcomeKind(s.kind) for s in OUTCOMES if s.failure)
#: Each failure kind's class among the paper's three (collision, timeout, deadlock).
PAPER_CLASS = {s.kind: s.paper_class for s in OUTCOMES if s.failure}
#: The paper's three failure classes, in display order.
PAPER_CLASSES = tuple(dict.fromkeys(PAPER_CLASS.values()))
#: The kinds that end on touching something (tests.csv's ``hit`` and ``hit_geom`` say what).
HIT_KINDS = tuple(OutcomeKind(s.kind) for s in OUTCOMES if s.hit)
#: The kinds on which the drive env truncates the episode instead of terminating it.
TRUNCATING = tuple(OutcomeKind(s.kind) for s in OUTCOMES if s.truncates)
#: The kinds decided before the drive (the test is never driven, and left out of every rate): ``infeasible`` (proven
#: impossible) and ``unproven`` (a park test without a plan within the planner's escalated budget, nor a proof).
NOT_DRIVEN = ("infeasible", "unproven")
#: The kinds the cruise runner decides when the driver's process dies or hangs (no video, no replay: it would again).
RUNNER_KINDS = tuple(OutcomeKind(s.kind) for s in OUTCOMES if s.runner)


@dataclass(frozen=True)
class OutcomeConfig:
    """Thresholds of the outcome classes."""

    goal_tolerance: float = 1.0  # [m] car centre this close to the goal point ...
    goal_heading_tolerance: float = 0.35  # [rad] ... heading this close to the goal's ...
    goal_speed: float = 0.5  # [m/s] ... and slower than this: success
    min_mean_speed: float = 0.7  # [m/s] slowest mean speed still in time
    time_slack: float = 10.0  # [s] added to the time limit (start-up, junctions)
    max_deviation: float = 3.5  # [m] farther than this from the route: deadlock (lost)
    stuck_time: float = 8.0  # [s] window in which the car must make progress
    stuck_progress: float = 0.5  # [m] progress along the route needed in that window
    missed_goal_radius: float = 7.0  # [m] no progress this close to the goal: missed_goal, not deadlock


@dataclass(frozen=True)
class Contact:
    """One contact of the ego car: the other geom's class and name."""

    semantic: Semantic
    geom: str


@dataclass(frozen=True)
class Outcome:
    """The end of a test: kind, simulated time [s], a readable reason, and what was hit (collisions)."""

    kind: OutcomeKind
    time: float
    reason: str
    hit_class: str | None = None  # semantic class name, e.g. "pillar"
    hit_geom: str | None = None  # MJCF geom name, e.g. "pillar_2_4/column"

    @property
    def success(self) -> bool:
        return self.kind is OutcomeKind.SUCCESS

    def as_dict(self) -> dict:
        d = asdict(self)
        d["kind"] = self.kind.value
        return d


def ego_contacts(model, data, ego_geoms, geom_classes: np.ndarray) -> list[Contact]:
    """Contacts between an ego geom and a non-ego geom of a collidable class in ``data``, with its class.

    ``ego_geoms``: a boolean mask over the model's geoms (:attr:`garage_mj.driving.sim.vehicle.Car.geom_mask`,
    the fast path) or the ego geom ids. Vectorised over ``data.contact``: the car's wheels touch
    the floor at every physics step, so only contacts with something collidable are named (name
    lookups cost more than the test).
    """
    import mujoco

    n = data.ncon
    if not n:
        return []
    ego = ego_geoms
    if not (isinstance(ego, np.ndarray) and ego.dtype == bool):
        ego = np.zeros(model.ngeom, dtype=bool)
        ego[list(ego_geoms)] = True
    g1 = data.contact.geom1[:n]
    g2 = data.contact.geom2[:n]
    e1, e2 = ego[g1], ego[g2]
    other = np.where(e1, g2, g1)
    keep = (e1 != e2) & _COLLIDABLE_TABLE[geom_classes[other]]
    out = []
    for o in other[keep]:
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, int(o)) or f"#{int(o)}"
        out.append(Contact(Semantic(int(geom_classes[o])), name))
    return out


#: Whether each semantic class id is collidable (a touch ends the test).
_COLLIDABLE_TABLE = np.zeros(max(Semantic) + 1, dtype=bool)
_COLLIDABLE_TABLE[[int(c) for c in COLLIDABLE]] = True


class BaseMonitor:
    """What every outcome monitor shares: a test ends once, and a touch of anything collidable ends it.

    A monitor sets ``outcome`` (None while the test runs) and puts its own checks of a step in
    :meth:`_update`, calling :meth:`_collision` where the collision check belongs among them.
    """

    outcome: Outcome | None

    def update(self, time: float, position, speed: float, contacts: Iterable[Contact] = (),
               yaw: float | None = None, hold: bool = False) -> Outcome | None:
        """Feed one step; returns the outcome when the test ends (and keeps returning it).

        ``hold``: an actor is moving, so the car may wait: the no-progress clock restarts.
        """
        if self.outcome is not None:
            return self.outcome
        return self._update(time, position, speed, contacts, yaw, hold)

    def _update(self, time: float, position, speed: float, contacts: Iterable[Contact], yaw: float | None,
                hold: bool) -> Outcome | None:
        """The monitor's own checks of one step of a running test."""
        raise NotImplementedError

    def _collision(self, time: float, speed: float, contacts: Iterable[Contact]) -> Outcome | None:
        """The collision outcome of the first collidable contact of ``contacts`` (None: no such contact)."""
        for c in contacts:
            if c.semantic in COLLIDABLE:
                # the car's speed tells a ram from being walked into while stopped (actors do not yield)
                return self._end(OutcomeKind.COLLISION, time,
                                 f"hit {c.semantic.name.lower()} {c.geom} at {abs(speed):.1f} m/s",
                                 c.semantic.name.lower(), c.geom)
        return None

    def _end(self, kind: OutcomeKind, time: float, reason: str, hit_class=None, hit_geom=None) -> Outcome:
        self.outcome = Outcome(kind, float(time), reason, hit_class, hit_geom)
        return self.outcome


class OutcomeMonitor(BaseMonitor):
    """Watches one test on ``route`` and says when and how it ended."""

    def __init__(self, route: Route, config: OutcomeConfig | None = None, goal=None, extra_time: float = 0.0) -> None:
        """``goal``: (x, y) or (x, y, yaw) [m, rad]; default the route's last point and heading.

        ``extra_time`` [s] is added to the time limit: how long the test's moving actors may
        keep the car waiting (:attr:`garage_mj.driving.actors.scenario.Scenario.duration`).
        """
        self.route = route
        self.config = config or OutcomeConfig()
        self.extra_time = float(extra_time)
        g = np.asarray(route.goal if goal is None else goal, dtype=float).reshape(-1)
        self.goal = g[:2]
        self.goal_yaw = float(g[2]) if len(g) > 2 else route.heading_at(route.length)
        # the goal as floats, for update()'s per-step arithmetic (the same numbers as numpy's norm and dot)
        self._goal_xy = (float(g[0]), float(g[1]))
        self._goal_dir = (math.cos(self.goal_yaw), math.sin(self.goal_yaw))
        self.reset()

    @property
    def goal_pose(self) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) of the goal."""
        return float(self.goal[0]), float(self.goal[1]), self.goal_yaw

    @property
    def time_limit(self) -> float:
        """[s] from the route length and the minimum mean speed."""
        return self.route.length / self.config.min_mean_speed + self.config.time_slack + self.extra_time

    def reset(self) -> None:
        self.progress = 0.0  # [m] furthest arc length reached
        self.deviation = 0.0  # [m] distance to the route at the last update
        self.outcome: Outcome | None = None
        self._mark_time = 0.0  # start of the current progress window
        self._mark_progress = 0.0

    def _update(self, time: float, position, speed: float, contacts: Iterable[Contact], yaw: float | None,
                hold: bool) -> Outcome | None:
        cfg = self.config
        hit = self._collision(time, speed, contacts)
        if hit is not None:
            return hit
        x, y = float(position[0]), float(position[1])
        dx, dy = x - self._goal_xy[0], y - self._goal_xy[1]
        goal_dist = math.sqrt(dx * dx + dy * dy)
        yaw_err = 0.0 if yaw is None else abs(math.remainder(yaw - self.goal_yaw, math.tau))
        if goal_dist <= cfg.goal_tolerance and yaw_err <= cfg.goal_heading_tolerance and abs(speed) <= cfg.goal_speed:
            return self._end(OutcomeKind.SUCCESS, time, f"stopped at the goal ({goal_dist:.2f} m, {yaw_err:.2f} rad)")
        past = dx * self._goal_dir[0] + dy * self._goal_dir[1]  # [m] along the goal's heading
        near_end = self.progress >= self.route.length - cfg.goal_tolerance - 1.0  # [m] (a route may pass the goal's axis earlier)
        if near_end and past > cfg.goal_tolerance:
            return self._end(OutcomeKind.DEADLOCK, time, f"overshot the goal by {past:.1f} m")
        window = 2.0 * cfg.max_deviation + cfg.stuck_progress + abs(speed) * 1.0
        s, dist = self.route.project((x, y), self.progress - window, self.progress + window)
        self.deviation = dist
        if dist > cfg.max_deviation:
            return self._end(OutcomeKind.DEADLOCK, time, f"{dist:.1f} m off the route")
        self.progress = max(self.progress, s)
        if hold:
            self._mark_time, self._mark_progress = time, self.progress
        elif self.progress - self._mark_progress >= cfg.stuck_progress:
            self._mark_time, self._mark_progress = time, self.progress
        elif time - self._mark_time >= cfg.stuck_time:
            why = f"no progress for {time - self._mark_time:.1f} s"
            if goal_dist <= cfg.missed_goal_radius:  # stopped near the goal, but not on its pose
                moving = f", still at {abs(speed):.1f} m/s" if abs(speed) > cfg.goal_speed else ""
                return self._end(OutcomeKind.MISSED_GOAL, time,
                                 f"stopped {goal_dist:.2f} m and {yaw_err:.2f} rad from the goal pose (tolerance "
                                 f"{cfg.goal_tolerance:g} m, {cfg.goal_heading_tolerance:g} rad), {why}{moving}")
            return self._end(OutcomeKind.DEADLOCK, time, why)
        if time >= self.time_limit:
            return self._end(OutcomeKind.TIMEOUT, time, f"time limit {self.time_limit:.1f} s reached")
        return None
