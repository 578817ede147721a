"""Park and AVP tests in the drive env (docs/spec.md section 8): what a reset draws and plans for them.

:class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv` with ``task="park"`` or ``task="avp"`` calls
:func:`draw_park_test` at reset, and keeps the :class:`ParkTest` it returns for the whole test; a cruise
test (``task="cruise"``, the default) never comes here.

- ``park``: the target stall is drawn as a cruise test draws it (or fixed); the start is the cruise plan's
  goal for that stall (:attr:`~garage_mj.scene.drivable.TestPlan.goal`, on the lane beside the stall)
  with the usual start noise (lateral and yaw), at rest, in D. The reference plan is the
  :class:`~garage_mj.scene.park_planning.ParkPlanner`'s from that start into the stall, around the test's
  parked cars as they stand (their bodies, :mod:`~garage_mj.scene.parked_fleet`; never the stall outlines).
- ``avp``: the start is the cruise test's, at the entrance; the reference is the cruise route followed by
  the park plan from the cruise goal; one test, a success only when parked.

The draws come from the reset's generator in this order: target, parked cars, lateral and yaw noise (as a
cruise test draws them: :meth:`~garage_mj.driving.sim.drive_env.GarageDriveEnv.draw_parked_and_noise`), then
the maneuver where it is ``"any"``, then (a park env with ``handover_start``) how far before or after the plan's
start the car stands, as an AVP test's handover leaves it. A test without a cruise route to the stall, or with a
proof that no park plan exists, is ``infeasible`` with the planner's reason; one without a park plan within the
planner's escalated budget and without a proof is ``unproven`` (docs/spec.md section 9); with ``infeasible="skip"``
another stall is drawn instead of either (unless the stall is fixed), while one is left.

Every test, driven or not, has a level (:func:`test_level`, docs/spec.md section 9), from the solid bodies of the
reset scene (:func:`~garage_mj.driving.sim.solid_bodies.solid_bodies`); a driven one ends with the metrics of
:func:`end_info`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.driving.sim.park_outcomes import ParkMonitor, park_time_limit
from garage_mj.scene.body_outlines import BodyOutlines
from garage_mj.scene.drivable import START_OFFSET, TestPlan
from garage_mj.scene.park_levels import ParkLevel, park_level
from garage_mj.scene.park_planning import MANEUVERS, ParkPlan, park_obstacles
from garage_mj.scene.parked_fleet import ParkedBody, body_obstacles
from garage_mj.scene.route_line import Route
from garage_mj.scene.stalls import Stall

if TYPE_CHECKING:
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

#: The tasks of the drive env: cruise (SPEC 7) and the park and AVP tests of SPEC 8.
TASKS = ("cruise", "park", "avp")
#: The park maneuvers a run may ask for; ``"any"`` draws one per test from the reset seed.
MANEUVER_CHOICES = (*MANEUVERS, "any")


@dataclass(frozen=True)
class ParkTest:
    """One park or AVP test as a reset drew and planned it."""

    task: str  # "park" or "avp"
    stall: int
    maneuver: str  # "reverse" or "forward"
    occupied: list[int]  # stalls with a parked car
    cruise: TestPlan  # the cruise plan to the stall (park: it ends at the start pose)
    plan: ParkPlan | None  # the park plan (None: the cruise plan is infeasible, so the start is unknown)
    start: tuple[float, float, float]  # car centre, at rest
    reason: str  # why the test is infeasible ("" when feasible)
    reference: Route  # the path progress is measured along (park plan, or cruise route + park plan)
    progress: float  # [m] the start along ``reference``
    park_from: float  # [m] where along ``reference`` the parking begins
    bodies: dict[int, ParkedBody] = field(default_factory=dict)  # the parked cars as they stand (the plan avoids them)

    @property
    def feasible(self) -> bool:
        return not self.reason

    @property
    def verdict(self) -> str:
        """The verdict before the drive (docs/spec.md section 9): ``feasible``; ``infeasible`` (no cruise route, or a
        proof that no park plan exists: the reason names it); ``unproven`` (no plan within the escalated budget,
        and no proof)."""
        if self.feasible:
            return "feasible"
        return "unproven" if self.plan is not None and self.plan.verdict == "unproven" else "infeasible"

    @property
    def stall_pose(self) -> tuple[float, float, float]:
        return self.plan.goal if self.plan is not None else (math.nan, math.nan, math.nan)

    def plan_info(self) -> dict[str, Any]:
        """The reference park plan for a privileged driver: ``poses`` ((N, 3) car centre x, y, yaw), ``directions``
        ((N,) +1 forward / -1 reverse, driving from pose i to i + 1) and ``stall_pose`` (x, y, yaw)."""
        plan = self.plan
        if plan is None or not plan.found:
            return {"poses": np.zeros((0, 3)), "directions": np.zeros(0, dtype=np.int8),
                    "stall_pose": self.stall_pose}
        return {"poses": plan.poses, "directions": plan.directions, "stall_pose": tuple(plan.goal)}


#: The largest ``handover_start`` of a park env [m]: beyond a car length the start is no longer beside the stall.
MAX_HANDOVER_START = 5.0


def _noisy(pose, lateral: float, dyaw: float) -> tuple[float, float, float]:
    """``pose`` moved ``lateral`` metres to its left and turned by ``dyaw``."""
    x, y, yaw = (float(v) for v in pose)
    return x - math.sin(yaw) * lateral, y + math.cos(yaw) * lateral, yaw + dyaw


def _handed_over(route: Route, start: tuple[float, float, float], lateral: float, dyaw: float,
                 along: float) -> tuple[float, float, float]:
    """Where an AVP test's cruise may leave the car for a park test that would start at ``start`` (the noised end of
    ``route``): ``along`` metres after it along its heading, or before it (``along`` < 0) on the route, with the same
    lateral and yaw noise."""
    if along >= 0:
        x, y, yaw = start
        return x + along * math.cos(yaw), y + along * math.sin(yaw), yaw
    s = max(0.0, route.length + along)
    p = route.point_at(s)
    return _noisy((p[0], p[1], route.heading_at(s)), lateral, dyaw)


def _draw_one(env: GarageDriveEnv, rng: np.random.Generator, options: dict[str, Any], candidates: list[int],
              fixed: int | None) -> ParkTest:
    """Draw and plan one test on a stall of ``candidates`` (or ``fixed``)."""
    target = fixed if fixed is not None else int(rng.choice(candidates))
    occupied, lateral, dyaw = env.draw_parked_and_noise(rng, target, options)
    name = env.maneuver if env.maneuver != "any" else tuple(MANEUVERS)[int(rng.integers(len(MANEUVERS)))]
    cruise = env.planner.plan(target)
    bodies = env.draw_parked_bodies(target, occupied, cruise if env.task == "avp" else None)  # an AVP test drives it
    if not cruise.feasible:  # no start pose: never driven, the car waits at the entrance
        x0, y0, h0 = env.scene.entrance_pose
        ahead = Route([(x0 + k * math.cos(h0), y0 + k * math.sin(h0)) for k in (0.0, START_OFFSET + 5.0)])
        start = (*(float(v) for v in ahead.point_at(START_OFFSET)), h0)
        return ParkTest(env.task, target, name, occupied, cruise, None, start, cruise.reason, ahead, START_OFFSET, 0.0,
                        bodies)
    route = Route(cruise.centre)
    if env.task == "park":
        start = _noisy(cruise.goal, lateral, dyaw)
    else:  # avp: the cruise test's start
        heading = route.heading_at(START_OFFSET)
        p = route.point_at(START_OFFSET)
        start = _noisy((p[0], p[1], heading), lateral, dyaw)
    if "start" in options:
        start = tuple(float(v) for v in options["start"])
    plan_from = start if env.task == "park" else cruise.goal
    if env.task == "park" and env.handover_start > 0 and "start" not in options:
        start = _handed_over(route, start, lateral, dyaw, float(rng.uniform(-1.0, 1.0)) * env.handover_start)
    plan = env.park_planner.plan(plan_from, target, name, occupied=occupied,
                                 obstacles=body_obstacles(env.park_planner.obstacles(), target, bodies))
    if not plan.found:
        pts = [start[:2], np.add(start[:2], (math.cos(start[2]), math.sin(start[2])))]
        return ParkTest(env.task, target, name, occupied, cruise, plan, start, plan.reason, Route(pts), 0.0, 0.0, bodies)
    if env.task == "park":
        return ParkTest(env.task, target, name, occupied, cruise, plan, start, "", Route(plan.poses[:, :2]), 0.0, 0.0,
                        bodies)
    reference = Route(np.vstack([cruise.centre, plan.poses[:, :2]]))
    return ParkTest(env.task, target, name, occupied, cruise, plan, start, "", reference, START_OFFSET, route.length,
                    bodies)


def draw_park_test(env: GarageDriveEnv, rng: np.random.Generator, options: dict[str, Any]) -> ParkTest:
    """The park or AVP test of this reset (module docstring); ``options`` may fix ``target``, ``occupied``, ``start``."""
    fixed = options.get("target", env.stall)
    if fixed is not None:
        fixed = int(fixed)
        if not 0 <= fixed < len(env.stalls):
            raise ValueError(f"stall {fixed} does not exist; garage {env.garage.name!r} has stalls "
                             f"0..{len(env.stalls) - 1}")
    candidates = list(env.targets)
    while True:
        test = _draw_one(env, rng, options, candidates, fixed)
        if test.feasible or env.infeasible == "report" or fixed is not None or len(candidates) == 1:
            return test
        candidates.remove(test.stall)


def park_monitor(env: GarageDriveEnv, test: ParkTest) -> ParkMonitor:
    """The outcome monitor of ``test``: its time limit from the plan (and, for AVP, the cruise route)."""
    cfg = env.park_outcome_config
    stall = env.stalls[test.stall]
    marking = env.scene.world.marking_width
    if not test.feasible:
        monitor = ParkMonitor(test.reference, stall, env.car_geometry, test.maneuver, 0.0, cfg, test.park_from,
                              marking)
    else:
        limit = park_time_limit(cfg, test.plan.length, test.plan.cusps)
        if test.task == "avp":
            oc = env.outcome_config
            limit += test.park_from / oc.min_mean_speed + oc.time_slack
        monitor = ParkMonitor(test.reference, stall, env.car_geometry, test.maneuver, limit, cfg, test.park_from,
                              marking)
    monitor.start(test.start, test.progress)
    return monitor


def test_level(env: GarageDriveEnv, test: ParkTest, bodies: BodyOutlines) -> ParkLevel:
    """The level of ``test`` (docs/spec.md section 9, :func:`~garage_mj.scene.park_levels.park_level`): the car under
    test's outline, the target stall, the scene's aisle width, the test's start and the reset scene's solid bodies."""
    car = env.car_geometry
    return park_level(env.stalls[test.stall], car.front - car.rear, 2 * car.half_width, env.scene.world.aisle_width,
                      test.start, bodies)


def test_room(env: GarageDriveEnv, test: ParkTest) -> dict[str, Any]:
    """The room a park test leaves, known before the drive (``tests.csv``'s ``bay_margin_m``, ``aisle_width_m``,
    ``start_distance_m``): the stall's width less the car's width (a parallel slot's length along its aisle, which
    is its width, less the car's length), the scene's aisle width, and the straight-line distance from the start
    to the stall's centre [m] (the distance the level measures, :func:`test_level`)."""
    car = env.car_geometry
    stall = env.stalls[test.stall]
    across = car.front - car.rear if float(stall.angle) == 0.0 else 2 * car.half_width
    return {"bay_margin": float(stall.width) - across, "aisle_width": float(env.scene.world.aisle_width),
            "start_distance": math.hypot(test.start[0] - stall.x, test.start[1] - stall.y)}


def park_info(test: ParkTest, level: ParkLevel, stall: Stall) -> dict[str, Any]:
    """What the env's info says of a park test for all of it (with the cruise entries); ``stall``: its target."""
    plan = test.plan
    found = plan is not None and plan.found
    return {"task": test.task, "maneuver": test.maneuver, "stall_pose": test.stall_pose,
            "plan_length": plan.length if found else math.nan, "plan_cusps": plan.cusps if found else -1,
            "plan_clearance": plan.min_clearance if found else math.nan,
            "park_level": level.level, "park_level_reason": level.reason, "stall_angle": float(stall.angle)}


def end_info(env: GarageDriveEnv, test: ParkTest, monitor: ParkMonitor, bodies: BodyOutlines) -> dict[str, Any]:
    """The parking metrics of SPEC 8 and 9 at the end of a driven test (``tests.csv``'s park columns): ``min_clearance``
    along the driven path to the solid ``bodies`` of the test (parked cars as they stand, pillars, walls, obstacle
    blocks), ``outline_clearance`` the same to the occupied stalls' outlines and the rest (section 8's figure),
    ``inner_margin`` the final footprint's smallest margin inside the stall's limits (negative: over one),
    ``guide_replans`` the new plans the park guide showed."""
    fit = monitor.fit
    outcome = monitor.outcome
    obstacles = park_obstacles(env.park_planner.obstacles(), test.stall, test.occupied)
    park_time = None if monitor.park_start is None or outcome is None else outcome.time - monitor.park_start
    return {"position_error": fit.position_error if fit else math.nan,
            "heading_error": fit.heading_error if fit else math.nan,
            "lateral_offset": fit.lateral_offset if fit else math.nan,
            "inner_margin": fit.margin if fit else math.nan,
            "direction_changes": monitor.direction_changes,
            "park_time": math.nan if park_time is None else park_time,
            "min_clearance": monitor.body_clearance(bodies),
            "outline_clearance": monitor.min_clearance(obstacles),
            "guide_replans": 0 if env.park_guide is None else env.park_guide.replans}


__all__ = ["MANEUVER_CHOICES", "TASKS", "ParkTest", "draw_park_test", "end_info", "park_info", "park_monitor",
           "test_level", "test_room"]
