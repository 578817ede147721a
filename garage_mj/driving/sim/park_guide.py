"""The park route as a parking assistant shows it: the stretch the car is on, in its gear.

A park test's route (:class:`~garage_mj.driving.sim.park_task.ParkTest`'s reference plan) is a path with cusps:
the car drives one stretch forward, stops, and reverses into the stall (or the other way). The ``waypoint`` and
``remaining`` entries read it as one polyline, which at a cusp points back along the way the car came.
:class:`ParkGuide` reads it stretch by stretch, as a park assist display does: which gear the current stretch is
driven in, how far the car is off it and turned from it, how it bends ahead, how much of it is left and how many
stretches come after it. The guide moves on to the next stretch when the car has come to rest at the end of the
current one (or past it), by the rule the privileged oracle's tracker keeps
(:class:`~garage_mj.driving.drivers.park_tracking.ParkTracker`), so a driver imitating the oracle sees the stretch
the oracle drives. The guide's rule (:data:`GUIDE_TRACKING`) takes a cusp as reached at rest within
:data:`CUSP_WITHIN` of it, and a car at rest farther short stays on its stretch. In an AVP test the plan begins
where the cruise to the stall ends: the guide reads zeros (no gear) until the car has come within
:data:`START_RADIUS` of the plan's start, and follows it from there.

Like a park assist, it plans again when the plan has not brought the car into the stall: a car at rest, not parked,
for :data:`REPLAN_AT_END` where the plan ends or :data:`REPLAN_STUCK` anywhere else is shown a new plan from where
it stands into the stall, around the parked cars as they stand (the env plans it with the test's own planner and
obstacles, :meth:`ParkGuide.replace`; at most ``guide_replans`` times a test, :data:`MAX_REPLANS` by default; a
failed try counts); where the planner finds none, a car that stopped less than :data:`STUCK_CUSP_WITHIN` short of a
cusp is shown the next stretch (:meth:`ParkGuide.skip_to_next`). A car that stopped near the stall pose is shown a
correction where one is clear (an arc onto the stall's heading and back:
:meth:`~garage_mj.scene.park_planning.ParkPlanner.correct`). And at each cusp, where the next stretch, driven from
where the car stands, would hit something (the car took the cusp a few degrees off the plan, whose stretches keep
0.1 m to the walls and parked cars), it is shown a new plan from there (:meth:`ParkGuide.stretch_from`, at most
:data:`MAX_CUSP_PLANS` a test). The test is still judged along its own reference plan.

It is route information (where the planned way goes, like ``waypoint``), not the car's pose in the garage or
another road user's state; the observation table (:mod:`~garage_mj.driving.sim.observations`) has it as the
``park_guide`` entry of park and AVP tests.
"""

from __future__ import annotations

import math

import numpy as np

from garage_mj.driving.drivers.park_tracking import ParkTrackConfig, ParkTracker
from garage_mj.scene.car import CarGeometry

NEAR = 0.25  # [m] the curvature read this far ahead of the car on its stretch ...
FAR = 1.0  # [m] ... and this far
CUSP_WITHIN = 0.1  # [m] at rest this close to a cusp (or past it), the car has reached it
RESUME = 0.05  # [m] at rest more than this short of where a stop begins, the stretch goes on
#: how the guide follows the stretches (and the trainer's expert with it): a cusp reached at rest within CUSP_WITHIN;
#: at rest farther short, the stretch goes on
GUIDE_TRACKING = ParkTrackConfig(cusp_within=CUSP_WITHIN, resume=RESUME)
START_RADIUS = 1.5  # [m] the guide follows the car once it has come this close to the plan's start
REPLAN_AT_END = 1.5  # [s] at rest this long at its plan's end, not parked: the guide plans again from where the car is
REPLAN_STUCK = 4.0  # [s] at rest this long anywhere else on the plan, not parked: the same (half the monitor's window)
MAX_REPLANS = 3  # new plans after the test's own, at most (the default of the env's ``guide_replans``)
#: [m] a car at rest :data:`REPLAN_STUCK` this close short of a cusp (over :data:`CUSP_WITHIN`), for which no new plan
#: is found, is shown the next stretch (a park assist telling a driver who stopped a little early to change gear)
STUCK_CUSP_WITHIN = 0.3
#: [m] a plan's first stretch shorter than this is shown as driven: the car, at rest where the plan starts, is shown the
#: second (a move of a few centimetres from rest, which a learned driver does not start; later shuffles are shown)
SHORT_FIRST = 0.2
#: new plans shown at cusps, at most, a test (apart from the ``max_replans`` of a car at rest): at a cusp the car is
#: shown the next stretch as planned, unless that stretch, driven from where the car stands, would hit something
#: (:meth:`ParkGuide.stretch_from`); then it is shown a new plan from there, as a park assist plans again when the car
#: is off its plan
MAX_CUSP_PLANS = 8
MAX_CURVATURE = 10.0  # [1/m] the curvature read is clipped to this (a plan's turns are under 0.3)
#: the ``park_guide`` entry, in order
GUIDE_KEYS = ("gear", "lateral", "heading", "curvature_near", "curvature_far", "stretch_left", "stretches_after")


class ParkGuide:
    """The stretch of a park plan the car is on (module docstring).

    Args:
        poses: the plan's car-centre poses (N, 3).
        directions: the plan's gear per step (N,): +1 forward, -1 reverse.
        car: the car's geometry (the rear axle is what the path is measured at).
    """

    def __init__(self, poses, directions, car: CarGeometry, max_replans: int = MAX_REPLANS) -> None:
        self.max_replans = int(max_replans)
        self.tracker = self._tracker(poses, directions, car)
        self.poses, self.directions = np.asarray(poses, dtype=float), np.asarray(directions)  # the plan shown
        self._start = np.asarray(poses, dtype=float)[0, :2]
        self.started = False  # the car has come within START_RADIUS of the plan's start (an AVP test's comes later)
        self.replans = 0  # new plans shown after the test's own (:meth:`replace`)
        self.tries = 0  # new plans tried for (a try the planner found no plan for counts too)
        self.skips = 0  # cusps taken as reached for a car stopped a little short of them (:meth:`skip_to_next`)
        self.cusp_plans = 0  # new plans tried for at cusps (of them, the ones found count in :attr:`replans`)
        self.left = math.inf  # [m] the stretch left at the last update

    def _tracker(self, poses, directions, car: CarGeometry) -> ParkTracker:
        """The tracker of the plan shown; past a first stretch shorter than :data:`SHORT_FIRST` when the guide plans
        again (``max_replans`` > 0: with none it shows the test's plan as it is, as the shipped models were trained)."""
        tracker = ParkTracker(poses, directions, car, GUIDE_TRACKING)
        if self.max_replans > 0 and len(tracker.segments) > 1 and tracker.segments[0].length < SHORT_FIRST:
            tracker.next_segment()
        return tracker

    def _near_start(self, pose) -> bool:
        if not self.started:
            self.started = math.hypot(float(pose[0]) - self._start[0], float(pose[1]) - self._start[1]) <= START_RADIUS
        return self.started

    def replace(self, poses, directions, at_cusp: bool = False) -> None:
        """Show a new plan (from the car's pose), from its first stretch: one more of :attr:`replans`, and of
        :attr:`tries` unless it is shown ``at_cusp`` (those have their own budget, :data:`MAX_CUSP_PLANS`)."""
        self.tracker = self._tracker(poses, directions, self.tracker.car)
        self.poses, self.directions = np.asarray(poses, dtype=float), np.asarray(directions)
        self.started = True
        self.replans += 1
        self.tries += not at_cusp

    def wants_cusp_check(self) -> bool:
        """Whether a cusp just taken should be checked (:meth:`stretch_from`): the guide plans again
        (``max_replans`` > 0) and fewer than :data:`MAX_CUSP_PLANS` plans were tried for at cusps."""
        return self.max_replans > 0 and self.cusp_plans < MAX_CUSP_PLANS

    def stretch_from(self, pose) -> tuple[np.ndarray, np.ndarray]:
        """The rest of the stretch the car is on, from the car's place on it, moved rigidly so that it starts at the
        car's rear axle as the car at ``pose`` (centre x, y, yaw) stands: ``(rear (N, 2), heading (N,))``, where the
        car would go driving the stretch's shape from here. A plan is clear from the pose it was planned from; a car
        that took a cusp turned a few degrees off it may not be."""
        t = self.tracker
        keep = t.index
        t.errors(pose)  # the car's place on the stretch
        i, t.index = t.index, keep
        seg = t.segment
        x, y, yaw = (float(v) for v in pose)
        b = t.car.rear_axle
        turn = math.remainder(yaw - float(seg.yaw[i]), math.tau)
        c, s = math.cos(turn), math.sin(turn)
        rel = seg.points[i:] - seg.points[i]
        rear = np.column_stack([x + b * math.cos(yaw) + c * rel[:, 0] - s * rel[:, 1],
                                y + b * math.sin(yaw) + s * rel[:, 0] + c * rel[:, 1]])
        return rear, seg.yaw[i:] + turn

    def wants_plan(self, rested: float) -> bool:
        """Whether a car at rest for ``rested`` seconds, not parked, is due a new plan: once the plan has begun, at
        rest :data:`REPLAN_AT_END` where the last stretch ends (the guide stopping it there, or within
        :data:`CUSP_WITHIN` of its end), or :data:`REPLAN_STUCK` anywhere else, while fewer than ``max_replans`` new
        plans were tried."""
        if not self.started or self.tries >= self.max_replans:
            return False
        t = self.tracker
        at_end = t.k == len(t.segments) - 1 and (t.stopping or self.left <= CUSP_WITHIN)
        return rested >= (REPLAN_AT_END if at_end else REPLAN_STUCK)

    def skip_to_next(self) -> bool:
        """For a car at rest that was due a new plan (:meth:`wants_plan`) and got none, on a stretch before the last
        and at most :data:`STUCK_CUSP_WITHIN` short of its end: show the next stretch (the cusp counts as reached);
        whether it did. One of :attr:`skips`."""
        t = self.tracker
        if t.k >= len(t.segments) - 1 or not 0.0 <= self.left <= STUCK_CUSP_WITHIN:
            return False
        t.next_segment()
        self.skips += 1
        return True

    @property
    def stretch(self) -> int:
        """The index of the stretch the car is on."""
        return self.tracker.k

    def update(self, pose, speed: float) -> None:
        """Move on to the next stretch when the car at ``pose`` (centre x, y, yaw) with signed ``speed`` [m/s] has
        come to rest at the end of its stretch: the tracker's own rule (:meth:`ParkTracker.take_next`, with
        :data:`GUIDE_TRACKING`)."""
        if not self._near_start(pose):  # an AVP test's cruise to the stall: the plan has not begun
            return
        self.left = self.tracker.errors(pose)[3]
        self.tracker.take_next(self.left, float(speed))

    def read(self, pose) -> np.ndarray:
        """:data:`GUIDE_KEYS` for the car at ``pose``: the stretch's gear (+1 D, -1 R); the rear axle's offset from
        it [m] (left of the direction of travel) and the car's heading off it [rad]; its curvature [1/m] (signed as
        the road wheels must turn, left positive, in the stretch's gear) :data:`NEAR` and :data:`FAR` ahead; the
        stretch left [m] (negative past its end) and the stretches after it. Zeros (no gear) until the car has come
        within :data:`START_RADIUS` of the plan's start: in an AVP test, while it cruises to the stall."""
        if not self._near_start(pose):
            return np.zeros(len(GUIDE_KEYS), dtype=np.float32)
        t = self.tracker
        s_now, lateral, heading, left = t.errors(pose)
        seg = t.segment
        sign = seg.gear.sign
        near, far = (float(np.clip(seg.kappa[min(int(np.searchsorted(seg.s, s_now + d)), len(seg.s) - 1)] * sign,
                                   -MAX_CURVATURE, MAX_CURVATURE)) for d in (NEAR, FAR))
        return np.array([sign, lateral, math.remainder(heading, math.tau), near, far, left,
                         min(len(t.segments) - 1 - t.k, 1000)], dtype=np.float32)
