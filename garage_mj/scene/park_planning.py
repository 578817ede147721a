"""Park tests: the stall pose, the success geometry and the reference planner that certifies feasibility (SPEC 8).

**Poses.** Every pose here is ``(x [m], y [m], yaw [rad])`` of the car's **centre** (the origin of the
car frame, the chassis centre): what the drive env reports (``Car.pose``) and what the cruise plan's goal
is (``TestPlan.goal``, the park test's start). Planning runs on the **rear-axle midpoint** (the point a
Reeds-Shepp curve describes for a bicycle-model car, and the point ``clearance.footprint`` takes):
:func:`centre_to_rear` and :func:`rear_to_centre` convert, ``ParkPlan.rear_poses`` holds both.

**The stall pose** (:func:`park_pose`): the car centred between the stall's side lines, its axis along the
stall, its rear (``reverse``: reverse-in) or nose (``forward``: nose-in) :data:`BACK_GAP` from the stall's
back line. A parallel slot (``Stall.angle`` 0): the car along the slot heading ``Stall.car_yaw`` (its lane's traffic
direction, its right side to the kerb), centred along the slot, its right side :data:`BACK_GAP` from the kerb-side
line; the maneuver says how the plan enters (:data:`MANEUVERS`). :func:`in_stall` is the success geometry and the
parking metrics.

**The reference planner** (:class:`ParkPlanner`) plans *from the stall outward* (leaving a stall is the
narrow passage) in OMPL's ``ReedsSheppStateSpace`` with the car's turning radius (less a curvature
margin), a pose being valid when the car's footprint grown by ``margin`` on every side overlaps no
obstacle (walls, obstacle blocks, pillars and the outlines of the occupied stalls, parked cars lying
wholly inside their outlines; the target stall is empty) and its rear axle lies in the planning area
(the box around the start, the stall pose and the straight exit, grown by ``region``). First the
analytic path, as Hybrid A* does: straight out of the stall along its axis by one of a few distances,
then one Reeds-Shepp curve to the start pose, the whole curve checked; the shortest valid one wins. A parallel slot,
which the car leaves sideways, has its own analytic attempt (:meth:`ParkPlanner._analytic_parallel`: one curve out of
the slot, straight to the start or through a pre-park pose beside the slot, the classic S, its first stretch in the
exit gear), and its sampled plans leave the stall pose by a nudge in the exit gear.
Else a seeded sampling planner (BIT* by default) over the Reeds-Shepp space from the straight exit
(the car just out of the stall), with a budget of loop iterations (not wall time: the same seed gives
the same plan on a loaded machine), then OMPL's path simplification. The path is then reversed (its
gears flip) so it runs start -> stall.

**Verdicts** (``ParkPlan.verdict``, docs/spec.md section 8): ``feasible`` with a plan; ``infeasible`` only with a
proof, named in the reason: a parallel slot too short for the car (the stall pose is not inside its end lines' inner
edges, so no success exists), the stall pose or the start pose is not clear, or (checked once the first attempt
found nothing) the stall is closed at the car's width (:meth:`ParkPlanner._closed`: the footprint's inscribed
disc cannot leave the stall among the obstacles alone). Without a proof the planner escalates
(``ParkConfig.escalation``: seeded sampling stages, each with its own seed, by default RRT-Connect restarts
from the stall pose and from the exit, the last ones in a wider planning area); a plan found there is
feasible like any other (``attempt`` says which stage). None found and nothing proven: ``unproven``, the
budget ran out, never read as infeasible. The first attempt is the same with or without escalation.
Every pose of a plan (``step`` apart, each cusp on a pose) is checked; OMPL checks its motions at the
same poses. Sampled paths may hold a few more cusps than a driver would make: they certify
feasibility, and a reference driver tracks them.

OMPL's Python bindings (nanobind) print a "nanobind: leaked N instances" report to stderr at interpreter
exit for every OMPL object still alive then. The planner keeps OMPL objects only inside one ``plan``
call (none on the planner or the plan), and an ``atexit`` handler collects garbage cycles before that
report runs, so a run prints nothing. OMPL's own log (a reseeding notice at each plan) is silenced
around each call and its level restored. Planning sets OMPL's global seed: not thread-safe.
"""

from __future__ import annotations

import atexit
import gc
import math
import time
from collections.abc import Callable, Iterable
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from garage_mj.core.words import a_noun
from garage_mj.scene.clearance import (
    Obstacles,
    footprint,
    nearest_obstacle,
    polygon_axes,
    polygon_distance,
    scene_obstacles,
)
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.world import DEFAULT_WORLD

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry
    from garage_mj.scene.stalls import Stall

BACK_GAP = 0.15  # [m] the car's rear (reverse-in) or nose (nose-in) to the stall's back line
#: [m] how far past the stall pose's own overhang the car's far end may stand beyond the stall's open, aisle-side edge
#: (:func:`far_end_allowance`: 0.3 m for the default car in a 4.5 m stall, section 8's figure)
FAR_END_SLACK = 0.05
#: The limits of the footprint in a stall (:func:`in_stall`), as a reason names them; sides looking out of the stall
STALL_LINES = ("left side line", "right side line", "back line", "aisle-side limit")
#: [m] a parallel slot's sampled plans start where a turn out of the slot has taken the car's centre this far past its
#: open edge (:meth:`ParkPlanner._slot_exit`)
SLOT_EXIT_PAST = 0.5
#: the curvatures of those turns, as shares of the plan's tightest (a gentler turn clears what the tightest swings into)
SLOT_EXIT_TURNS = (1.0, 0.7, 0.4)
#: [m] how far ahead of a parallel slot's stall pose (behind it, nose-in) the analytic attempt's pre-park poses lie
PRE_PARK_AHEAD = (1.5, 2.5, 3.5, 4.5, 5.5, 6.5)
#: [m] the lengths of a correction's arcs (:meth:`ParkPlanner.correct`)
CORRECTION_RUNS = (0.3, 0.4, 0.6, 0.8, 1.2)
#: [deg] the headings off the stall pose's a correction's first arc may end on, to shift the car sideways on its second
CORRECTION_TURNS = (0.0, 1.0, -1.0, 2.0, -2.0, 4.0, -4.0)
CORRECTION_MIN_STRETCH = 0.3  # [m] every stretch of a correction is at least this long
CORRECTION_NEAR = (0.5, 15.0)  # [m], [deg] a car this near the stall pose (centre, heading) is corrected
HEADING_TOLERANCE = 10.0  # [deg] the car's axis to the stall's, in the maneuver's direction
_EPS = 1e-9  # [m] geometric tolerance of the inside test


@dataclass(frozen=True)
class Maneuver:
    """How the car stands in the stall at the end of a park test."""

    name: str
    turn: float  # [rad] car heading = stall yaw (towards the aisle) + this
    at_back: str  # the car's end at the back line: "rear" or "front"
    exit_gear: int  # +1: the car leaves the stall driving forward, -1 reversing

    def heading(self, stall: Stall) -> float:
        """[rad] the car's heading at the stall pose: along a bay's axis as :attr:`turn` says; along a parallel slot
        in the traffic direction of its lane (``Stall.car_yaw``) for either maneuver."""
        return _wrap(stall.car_yaw) if is_parallel(stall) else _wrap(stall.yaw + self.turn)


#: The park maneuvers (SPEC 8): reverse-in is the default. In a bay the maneuver says which end is at the back line. In a
#: parallel slot both end in the same pose (along the slot, in its lane's traffic direction) and the maneuver says how
#: the reference plan enters it, the gear of its last stretch: ``reverse`` backs in (the classic parallel park: past
#: the slot, then back in on an S), ``forward`` noses in (forward into the slot, straightening in it: it needs more
#: room, or more shuffles). Success judges the final pose alone, as in a bay: a driver under test may enter either way.
MANEUVERS: dict[str, Maneuver] = {
    "reverse": Maneuver("reverse", 0.0, "rear", +1),
    "forward": Maneuver("forward", math.pi, "front", -1),
}


def is_parallel(stall: Stall) -> bool:
    """Whether ``stall`` is a parallel slot along its aisle (``Stall.angle`` 0): its ``width`` is the slot's length along
    the aisle, its ``length`` the depth from the kerb-side line to the aisle, ``yaw`` points at the aisle."""
    return float(stall.angle) == 0.0


def maneuver(name: str) -> Maneuver:
    """The :class:`Maneuver` named ``name``; a ValueError naming the known ones otherwise."""
    if name not in MANEUVERS:
        raise ValueError(f"unknown park maneuver {name!r}; known: {', '.join(MANEUVERS)}")
    return MANEUVERS[name]


def _wrap(a):
    """Angle(s) wrapped to [-pi, pi)."""
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi if isinstance(a, np.ndarray) \
        else (a + math.pi) % (2 * math.pi) - math.pi


# -- reference points --------------------------------------------------------------------------------
def centre_to_rear(pose, car: CarGeometry) -> np.ndarray:
    """Pose(s) ``(..., 3)`` of the car's centre as poses of its rear-axle midpoint (same heading)."""
    p = np.array(pose, dtype=float)
    b = car.rear_axle  # [m] rear axle x in the car frame (< 0)
    p[..., 0] += b * np.cos(p[..., 2])
    p[..., 1] += b * np.sin(p[..., 2])
    return p


def rear_to_centre(pose, car: CarGeometry) -> np.ndarray:
    """Pose(s) ``(..., 3)`` of the car's rear-axle midpoint as poses of its centre (same heading)."""
    p = np.array(pose, dtype=float)
    b = car.rear_axle
    p[..., 0] -= b * np.cos(p[..., 2])
    p[..., 1] -= b * np.sin(p[..., 2])
    return p


# -- the stall pose and the success geometry -----------------------------------------------------------
def park_pose(stall: Stall, car: CarGeometry, maneuver_name: str = "reverse") -> tuple[float, float, float]:
    """The target pose (car centre, SPEC 8) of a park test into ``stall`` with maneuver ``maneuver_name``.

    A parallel slot (:func:`is_parallel`): the car along the slot heading ``Stall.car_yaw`` (the traffic direction of
    the slot's lane: its right side to the kerb, as a driver parallel-parks), its outline centred along the slot and
    its right side :data:`BACK_GAP` from the kerb-side line; the same pose for either maneuver (the maneuver says
    how the reference plan enters: :data:`MANEUVERS`)."""
    m = maneuver(maneuver_name)
    if is_parallel(stall):
        h = stall.car_yaw
        ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)  # from the kerb-side line towards the aisle
        across = BACK_GAP + car.half_width - stall.length / 2  # [m] the car's centre line from the slot's centre
        along = -(car.front + car.rear) / 2  # [m] the outline's middle on the slot's middle
        return (stall.x + across * ux + along * math.cos(h), stall.y + across * uy + along * math.sin(h),
                float(_wrap(h)))
    ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)  # from the back line towards the aisle
    # the centre lies this far from the back line: the gap plus the centre-to-end length of the end there
    d = BACK_GAP + (-car.rear if m.at_back == "rear" else car.front)
    s = d - stall.length / 2  # along the stall axis from the stall's centre
    return stall.x + s * ux, stall.y + s * uy, float(m.heading(stall))


def far_end_allowance(stall: Stall, car: CarGeometry) -> float:
    """[m] how far the car's far end may stand beyond ``stall``'s open (aisle-side) edge: none for a car that fits
    the stall with its :data:`BACK_GAP`, else the stall pose's own overhang plus :data:`FAR_END_SLACK` (SPEC 8: the
    default 4.6 m car in a 4.5 m stall, 0.3 m; a longer class, what the same rule gives). None for a parallel slot: the
    car stands along it, its side to the open end, and its ends between the slot's painted end lines."""
    if is_parallel(stall):
        return 0.0
    return max(0.0, (car.front - car.rear) + BACK_GAP + FAR_END_SLACK - stall.length)


@dataclass(frozen=True)
class ParkFit:
    """How a car pose sits in a stall: the success geometry (SPEC 9) and the parking metrics of SPEC 8."""

    inside: bool  # the footprint inside the paint's inner edges (the far end up to far_end_allowance past the open end)
    aligned: bool  # heading within HEADING_TOLERANCE of the stall axis in the maneuver's direction
    position_error: float  # [m] car centre to the target pose's centre
    heading_error: float  # [deg] |car heading - target heading|
    lateral_offset: float  # [m] car centre off the stall axis, > 0 left looking out of the stall (parallel slot: off the
    #                        target's line along the slot, > 0 towards the aisle)
    longitudinal_offset: float  # [m] car centre to the target along the stall axis, > 0 towards the aisle (parallel
    #                             slot: along the slot, > 0 ahead of the target)
    overhang: float  # [m] how far the footprint crosses a line it may not (0 when inside)
    margin: float = math.inf  # [m] the footprint's smallest distance inside a limit of STALL_LINES (< 0: over it)
    line: str = ""  # the limit of STALL_LINES with that smallest margin (the one crossed when not inside)

    @property
    def parked(self) -> bool:
        """Inside and aligned: the geometry of a success (the env adds: at rest for the dwell, no contact)."""
        return self.inside and self.aligned


def in_stall(stall: Stall, car: CarGeometry, pose, maneuver_name: str = "reverse",
             marking: float = DEFAULT_WORLD.marking_width) -> ParkFit:
    """The success geometry and parking metrics of the car at ``pose`` (car centre) in ``stall``.

    Inside (SPEC 9) means inside the paint's inner edges: the side and back lines are ``marking`` [m] wide and centred
    on the stall's outline, so the footprint keeps ``marking / 2`` inside each outline edge there (a 2.5 m stall has
    2.35 m); the open, aisle-side end is not painted, and the far end may stand :func:`far_end_allowance` beyond it.
    ``margin`` is the smallest of the four distances (negative: over that limit), ``line`` names it.
    """
    tx, ty, tyaw = park_pose(stall, car, maneuver_name)
    x, y, yaw = (float(v) for v in pose)
    ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)
    rear = centre_to_rear((x, y, yaw), car)
    corners = footprint(car, rear[None, :2], np.array([yaw]))[0]  # (4, 2)
    rel = corners - (stall.x, stall.y)
    s = rel @ (ux, uy)  # along the stall axis, towards the aisle
    t = rel @ (-uy, ux)  # across it, to the left
    half_w, half_l = stall.width / 2 - marking / 2, stall.length / 2 - marking / 2  # [m] the inner edges
    margins = (half_w - float(t.max()), half_w + float(t.min()), half_l + float(s.min()),
               stall.length / 2 + far_end_allowance(stall, car) - float(s.max()))
    k = int(np.argmin(margins))
    heading = abs(math.degrees(_wrap(yaw - tyaw)))
    cx, cy = x - stall.x, y - stall.y
    lateral, longitudinal = -uy * cx + ux * cy, (x - tx) * ux + (y - ty) * uy
    if is_parallel(stall):  # off the target's line along the slot (> 0 towards the aisle), and along it (> 0 ahead)
        hx, hy = math.cos(tyaw), math.sin(tyaw)
        lateral, longitudinal = -hy * (x - tx) + hx * (y - ty), hx * (x - tx) + hy * (y - ty)
    return ParkFit(inside=margins[k] >= -_EPS, aligned=heading <= HEADING_TOLERANCE,
                   position_error=math.hypot(x - tx, y - ty), heading_error=heading,
                   lateral_offset=lateral, longitudinal_offset=longitudinal, overhang=max(0.0, -margins[k]),
                   margin=margins[k], line=STALL_LINES[k])


def stall_limits(stall: Stall, car: CarGeometry, marking: float = DEFAULT_WORLD.marking_width) -> dict[str, np.ndarray]:
    """The four limits :func:`in_stall` holds the footprint within, as world segments: name (:data:`STALL_LINES`) ->
    (2, 2) end points [m]. The side lines and the back line are the paint's inner edges (``marking / 2`` inside the
    outline); the aisle-side limit lies :func:`far_end_allowance` beyond the open end. A side line runs from the back
    of the outline to the aisle-side limit; the back line and the aisle-side limit span the stall's width. What a
    picture draws for an ``outside_stall`` reason's line."""
    ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)
    half_w, half_l = stall.width / 2 - marking / 2, stall.length / 2 - marking / 2  # [m] the inner edges
    far = stall.length / 2 + far_end_allowance(stall, car)
    back = -stall.length / 2

    def world(s: float, t: float) -> tuple[float, float]:  # s along the axis towards the aisle, t across to the left
        return stall.x + s * ux - t * uy, stall.y + s * uy + t * ux

    ends = ((back, half_w, far, half_w), (back, -half_w, far, -half_w), (-half_l, -stall.width / 2, -half_l,
            stall.width / 2), (far, -stall.width / 2, far, stall.width / 2))
    return {name: np.array([world(s0, t0), world(s1, t1)]) for name, (s0, t0, s1, t1) in zip(STALL_LINES, ends,
                                                                                           strict=True)}


# -- the obstacles of one park test --------------------------------------------------------------------
def park_obstacles(obstacles: Obstacles, target: int, occupied: Iterable[int] | None = None) -> Obstacles:
    """The obstacles of a park test into stall ``target``: every non-stall obstacle, and the outlines of the
    ``occupied`` stalls (None: every stall, the worst case the cruise checks use) except ``target``."""
    keep = obstacles.stall < 0
    if occupied is None:
        keep |= obstacles.stall != target
    else:
        occ = np.array(sorted({int(s) for s in occupied} - {int(target)}), dtype=int)
        keep |= np.isin(obstacles.stall, occ)
    return obstacles.take(np.flatnonzero(keep))


# -- configuration and result ---------------------------------------------------------------------------
@dataclass(frozen=True)
class _Sampler:
    """A sampling planner of ``ompl.geometric``: its class name and whether it takes a range."""

    cls: str
    ranged: bool


#: The sampling planners ParkConfig.planner may name.
SAMPLERS: dict[str, _Sampler] = {
    "bitstar": _Sampler("BITstar", False),
    "rrtstar": _Sampler("RRTstar", True),
    "rrtconnect": _Sampler("RRTConnect", True),
}


#: Where an escalation stage's sampling starts: the straight exit (the car just out of the stall) or the stall pose.
EXITS = ("out", "stall")
#: The default escalation (:attr:`ParkConfig.escalation`): ten seeded RRT-Connect restarts of 800 iterations, alternately
#: from the stall pose and the straight exit, then four more in a planning area grown by 12 m instead of ``region``
#: (eval/bench_park_verdicts.py measured restarts of a short RRT-Connect to find the multi-point turns of a narrow
#: aisle where a larger BIT* budget found none; the wider area lets a car pinned beside a wall leave it on gentle arcs).
ESCALATION: tuple[tuple, ...] = (*(("rrtconnect", 800, at) for at in ("stall", "out") * 5),
                                 *(("rrtconnect", 800, at, 12.0) for at in ("stall", "out") * 2))
#: The verdicts of a park test before its drive (SPEC 9).
VERDICTS = ("feasible", "infeasible", "unproven")


@dataclass(frozen=True)
class ParkConfig:
    """Settings of the reference park planner (units in the comments)."""

    margin: float = 0.1  # [m] the footprint to every obstacle, on every side
    curvature_margin: float = 0.1  # the path's curvature stays <= (1 - this) x the car's limit
    iterations: int = 1500  # budget of the sampling planner: loop iterations (calls of its termination check)
    step: float = 0.1  # [m] spacing of the plan's poses (rear-axle path length), each one checked
    seed: int = 1  # OMPL's RNG seed: the same seed gives the same plan
    region: float = 6.0  # [m] the planning area: the box around start, stall and exit poses grown by this
    exit_step: float = 0.5  # [m] spacing of the straight exits the analytic path tries
    planner: str = "bitstar"  # a key of SAMPLERS
    planner_range: float = 4.0  # [m] longest motion of a ranged sampler (rrtstar, rrtconnect)
    #: the escalation after the first attempt fails without a proof: (planner, iterations, exit[, region]) stages in
    #: order, each a seeded sampling run from the straight exit (``"out"``) or from the stall pose itself
    #: (``"stall"``), in the planning area grown by ``region`` metres (left out: this config's ``region``)
    escalation: tuple[tuple, ...] = ESCALATION
    escalation_range: float = 2.0  # [m] longest motion of a ranged sampler (rrtstar, rrtconnect) in the escalation
    proof_cell: float = 0.05  # [m] grid cell of the closed-stall proof (a finer grid proves more, never wrongly)

    def __post_init__(self) -> None:
        object.__setattr__(self, "escalation", tuple(tuple(stage) for stage in self.escalation))  # JSON gives lists
        if any(len(stage) not in (3, 4) for stage in self.escalation):
            raise ValueError("ParkConfig.escalation: each stage is (planner, iterations, exit) or (..., region)")
        if self.planner not in SAMPLERS:
            raise ValueError(f"unknown park planner {self.planner!r}; known: {', '.join(SAMPLERS)}")
        for name, iterations, start, *grow in self.escalation:
            if name not in SAMPLERS or iterations < 0 or start not in EXITS or not all(r > 0 for r in grow):
                raise ValueError(f"ParkConfig.escalation: stage ({name!r}, {iterations!r}, {start!r}) is not (one of "
                                 f"{', '.join(SAMPLERS)}, iterations >= 0, one of {', '.join(EXITS)}[, region > 0])")
        if not self.proof_cell > 0:
            raise ValueError(f"ParkConfig.proof_cell must be > 0, got {self.proof_cell}")
        for name in ("step", "exit_step", "planner_range", "escalation_range"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ParkConfig.{name} must be > 0, got {getattr(self, name)}")
        if self.margin < 0 or not 0 <= self.curvature_margin < 1 or self.iterations < 0:
            raise ValueError("ParkConfig: margin >= 0, 0 <= curvature_margin < 1 and iterations >= 0")


DEFAULT_PARK = ParkConfig()


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class ParkPlan:
    """The reference plan of one park test, start -> stall, or why none was found (``verdict`` infeasible or unproven).

    ``poses[i]`` is the car centre (the drive env's ``Car.pose``), ``rear_poses[i]`` the rear-axle
    midpoint, both ``(x, y, yaw)``; ``directions[i]`` the gear (+1 forward, -1 reverse) driving from
    pose ``i`` to ``i + 1`` (the last pose repeats the last gear). A cusp (gear change, at rest) lies
    exactly on a pose; :meth:`segments` splits the path there.
    """

    stall: int
    maneuver: str
    found: bool
    reason: str = ""  # why not found ("" when found)
    start: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # car centre at the start
    goal: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # car centre at the stall pose
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) car centre
    rear_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) rear-axle midpoint
    directions: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))  # (N,) +1 / -1
    length: float = 0.0  # [m] of the rear-axle path
    cusps: int = 0  # gear changes
    min_clearance: float = math.nan  # [m] the footprint to the nearest obstacle, over the poses
    planning_time: float = 0.0  # [s] CPU time of the plan call
    method: str = ""  # "analytic" (straight out + one Reeds-Shepp curve), the sampling planner's name, or
    #                   "correction" (ParkPlanner.correct)
    iterations: int = 0  # sampling planner iterations used (0: analytic), escalation stages included
    verdict: str = "feasible"  # VERDICTS: found; proven impossible (the reason is the proof); or neither
    attempt: int = 0  # 0: the first attempt (analytic or ParkConfig.planner); k: the k-th escalation stage

    def segments(self) -> list[tuple[int, int, int]]:
        """``(first, last, gear)`` pose index ranges (inclusive) of one gear; consecutive ones share the cusp pose."""
        d = self.directions
        if not len(d):
            return []
        cut = [0, *(np.flatnonzero(d[1:-1] != d[:-2]) + 1).tolist(), len(d) - 1]
        return [(a, b, int(d[a])) for a, b in zip(cut[:-1], cut[1:], strict=True) if b > a]

    def summary(self) -> dict[str, Any]:
        """The plan's numbers as JSON-able values (no path)."""
        def r(v):
            return None if not math.isfinite(v) else round(float(v), 4)
        return {"stall": self.stall, "maneuver": self.maneuver, "found": self.found, "reason": self.reason,
                "length": r(self.length), "cusps": self.cusps, "min_clearance": r(self.min_clearance),
                "planning_time": r(self.planning_time), "method": self.method, "iterations": self.iterations,
                "verdict": self.verdict, "attempt": self.attempt}


# -- collision checks ------------------------------------------------------------------------------------
class _Checker:
    """Is the car's footprint, grown by a margin on every side, clear of a set of axis-aligned boxes?

    Separating axes between the grown car rectangle and each box: vectorized for a path
    (:meth:`clear`), and one pose at a time through a 1 m grid of nearby boxes for OMPL (``__call__``,
    taking an OMPL state of the rear-axle midpoint). A pose whose rear axle lies outside ``region`` is
    not valid: ``boxes`` need only hold the obstacles the car can reach from inside it. Holds no OMPL
    object. The grown rectangle has square corners: the check is a little stricter than ``margin``
    at the car's corners, never looser.
    """

    CELL = 1.0  # [m] grid cell of the per-pose look-up

    def __init__(self, obstacles: Obstacles | np.ndarray, car: CarGeometry, margin: float,
                 region: tuple[float, float, float, float]) -> None:
        if not isinstance(obstacles, Obstacles):  # bare boxes
            obstacles = Obstacles(np.asarray(obstacles, dtype=float).reshape(-1, 4), [], np.zeros(0, dtype=int))
        boxes = obstacles.boxes
        self.region = region  # [m] xmin, ymin, xmax, ymax: a rear axle outside is not valid
        self.hl = (car.front - car.rear) / 2 + margin  # [m] half length of the grown rectangle
        self.hw = car.half_width + margin  # [m] half width
        self.off = (car.front + car.rear) / 2 - car.rear_axle  # [m] rear axle to the rectangle's centre
        self.centre = (boxes[:, :2] + boxes[:, 2:]) / 2  # (M, 2)
        self.half = (boxes[:, 2:] - boxes[:, :2]) / 2
        # an obstacle that is not its box (a turned polygon): its edges' normals and its extent along each,
        # tested after its box fails to separate it from the car
        turned = obstacles.rotated
        self.axes: list[tuple[np.ndarray, np.ndarray] | None] = [
            (obstacles.polygons[j], polygon_axes(obstacles.polygons[j])) if turned[j] else None
            for j in range(len(boxes))]
        self.turned = np.flatnonzero(turned)
        self.calls = 0
        reach = math.hypot(self.hl, self.hw) + self.CELL * math.sqrt(0.5)
        self.grid: dict[tuple[int, int], list[tuple[float, float, float, float]]] = {}
        if len(boxes):
            self.lo = boxes[:, :2].min(axis=0) - reach
            hi = boxes[:, 2:].max(axis=0) + reach
            nx, ny = (int(v) + 1 for v in np.ceil((hi - self.lo) / self.CELL))
            ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
            cells = self.lo + (np.stack([ix.ravel(), iy.ravel()], axis=1) + 0.5) * self.CELL  # cell centres
            gap = np.maximum(np.abs(cells[:, None, :] - self.centre[None]) - self.half[None], 0.0)
            near = np.hypot(gap[..., 0], gap[..., 1]) <= reach  # (cells, M)
            entries = [(*map(float, self.centre[j]), *map(float, self.half[j]), self.axes[j]) for j in range(len(boxes))]
            cell, box = np.nonzero(near)  # by cell, then by box: each cell's boxes in their order
            starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]]) if len(cell) else np.zeros(0, int)
            for k, j in zip(cell[starts].tolist(), np.split(box, starts[1:])):
                self.grid[(k // ny, k % ny)] = [entries[i] for i in j.tolist()]

    def __call__(self, state) -> bool:
        self.calls += 1
        return self.pose_clear(state.getX(), state.getY(), state.getYaw())

    def pose_clear(self, x: float, y: float, yaw: float) -> bool:
        """One rear-axle pose: inside the region, the grown footprint clear of every box?"""
        r = self.region
        if not (r[0] <= x <= r[2] and r[1] <= y <= r[3]):
            return False
        if not self.grid:
            return True
        c, s = math.cos(yaw), math.sin(yaw)
        cx, cy = x + self.off * c, y + self.off * s
        boxes = self.grid.get((int((cx - self.lo[0]) // self.CELL), int((cy - self.lo[1]) // self.CELL)), ())
        hl, hw, ac, as_ = self.hl, self.hw, abs(c), abs(s)
        for bx, by, hx, hy, axes in boxes:
            dx, dy = cx - bx, cy - by
            if abs(dx) > hx + hl * ac + hw * as_ or abs(dy) > hy + hl * as_ + hw * ac:
                continue
            if axes is not None:  # a turned polygon: the car's axes against its corners, then its own edges
                if _polygon_separates(axes, cx, cy, c, s, hl, hw):
                    continue
            elif abs(dx * c + dy * s) > hl + hx * ac + hy * as_ or abs(-dx * s + dy * c) > hw + hx * as_ + hy * ac:
                continue
            return False
        return True

    def clear(self, rear: np.ndarray) -> np.ndarray:
        """(N,) whether each rear-axle pose ``(N, 3)`` is inside the region and clear."""
        r = self.region
        inside = (rear[:, 0] >= r[0]) & (rear[:, 0] <= r[2]) & (rear[:, 1] >= r[1]) & (rear[:, 1] <= r[3])
        if not len(self.centre):
            return inside
        c, s = np.cos(rear[:, 2])[:, None], np.sin(rear[:, 2])[:, None]
        dx = rear[:, 0:1] + self.off * c - self.centre[None, :, 0]
        dy = rear[:, 1:2] + self.off * s - self.centre[None, :, 1]
        hx, hy = self.half[None, :, 0], self.half[None, :, 1]
        ac, as_ = np.abs(c), np.abs(s)
        sep = (np.abs(dx) > hx + self.hl * ac + self.hw * as_) | (np.abs(dy) > hy + self.hl * as_ + self.hw * ac)
        sep |= np.abs(dx * c + dy * s) > self.hl + hx * ac + hy * as_
        sep |= np.abs(-dx * s + dy * c) > self.hw + hx * as_ + hy * ac
        if len(self.turned):  # a turned polygon: the car's axes against its corners, then its own edges
            cx = rear[:, 0:1] + self.off * c  # (N, 1)
            cy = rear[:, 1:2] + self.off * s
            for j in self.turned:
                poly, axes = self.axes[j]
                px, py = poly[None, :, 0] - cx, poly[None, :, 1] - cy  # (N, K) corners from the car's centre
                along, across = px * c + py * s, -px * s + py * c
                sep_j = (along.min(1) > self.hl) | (along.max(1) < -self.hl)
                sep_j |= (across.min(1) > self.hw) | (across.max(1) < -self.hw)
                nx, ny, lo, hi = axes.T  # (E,) each
                mid = cx * nx + cy * ny  # (N, E) the car centre along each normal
                half = self.hl * np.abs(c * nx + s * ny) + self.hw * np.abs(-s * nx + c * ny)
                sep_j |= ((mid + half < lo) | (mid - half > hi)).any(axis=1)
                sep[:, j] |= sep_j  # its box separates it too where it does (the box holds the polygon)
        return inside & sep.all(axis=1)


def _polygon_separates(axes: tuple[np.ndarray, np.ndarray], cx: float, cy: float, c: float, s: float, hl: float,
                       hw: float) -> bool:
    """Whether the car rectangle centred at (cx, cy), heading (c, s), half sizes ``hl`` x ``hw`` and a convex polygon
    (its corners and :func:`~garage_mj.scene.clearance.polygon_axes`) are apart: an axis of the car or an edge
    normal of the polygon separates them."""
    poly, normals = axes
    px, py = poly[:, 0] - cx, poly[:, 1] - cy
    along, across = px * c + py * s, -px * s + py * c
    if along.min() > hl or along.max() < -hl or across.min() > hw or across.max() < -hw:
        return True
    for nx, ny, lo, hi in normals:
        mid = cx * nx + cy * ny
        half = hl * abs(c * nx + s * ny) + hw * abs(-s * nx + c * ny)
        if mid + half < lo or mid - half > hi:
            return True
    return False


# -- OMPL ---------------------------------------------------------------------------------------------------
_OMPL: tuple[Any, Any, Any] | None = None


def _ompl() -> tuple[Any, Any, Any]:
    """OMPL's ``base``, ``geometric`` and ``util`` modules, imported on first use.

    The first import also registers an ``atexit`` garbage collection: OMPL objects caught in a
    reference cycle are freed before nanobind's leak report runs at interpreter exit.
    """
    global _OMPL
    if _OMPL is None:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou

        atexit.register(gc.collect)
        _OMPL = (ob, og, ou)
    return _OMPL


@contextmanager
def _ompl_seeded(seed: int):
    """OMPL's modules with its RNG seeded and its log silenced (restored on the way out)."""
    ob, og, ou = _ompl()
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)  # reseeding logs an error-level notice; a quiet planner prints nothing
    try:
        ou.RNG.setSeed(int(seed) + 1)  # OMPL reads a seed of 0 as "random": ours start at 0
        yield ob, og
    finally:
        ou.setLogLevel(level)


def _stage_seed(seed: int, stage: int) -> int:
    """OMPL's seed for escalation stage ``stage`` (1, 2, ...) of a plan seeded ``seed`` (never 0: OMPL's "random")."""
    return int(seed) + 1 + 7919 * stage


class _Curves:
    """Reeds-Shepp curves of one turning radius through OMPL, sampled into rear-axle poses."""

    def __init__(self, ob, radius: float, region: tuple[float, float, float, float], step: float) -> None:
        self.space = ob.ReedsSheppStateSpace(radius)
        bounds = ob.RealVectorBounds(2)
        bounds.setLow(0, region[0])
        bounds.setLow(1, region[1])
        bounds.setHigh(0, region[2])
        bounds.setHigh(1, region[3])
        self.space.setBounds(bounds)
        #: the fraction of the space's extent that makes OMPL check a motion every ``step`` metres
        self.resolution = step / self.space.getMaximumExtent()
        self.space.setLongestValidSegmentFraction(self.resolution)
        self.space.setup()
        self._a, self._b, self._at = (self.space.allocState() for _ in range(3))

    def state(self, pose, st=None):
        """``pose`` (x, y, yaw) as a state of the space (a new one unless ``st`` is given)."""
        st = self.space.allocState() if st is None else st
        st.setX(float(pose[0]))
        st.setY(float(pose[1]))
        yaw = float(pose[2])
        # OMPL's yaw bounds are [-pi, pi) (a yaw of pi is out); a yaw inside keeps its bits: shortest curves can
        # tie, and which one OMPL picks may change with the last bit of a pose
        st.setYaw(yaw if -math.pi <= yaw < math.pi else float(_wrap(yaw)))
        return st

    def length(self, a, b) -> float:
        """[m] of the shortest Reeds-Shepp curve from pose ``a`` to pose ``b``."""
        return float(self.space.distance(self.state(a, self._a), self.state(b, self._b)))

    def _pose(self, t: float) -> tuple[float, float, float]:
        self.space.interpolate(self._a, self._b, t, self._at)
        return self._at.getX(), self._at.getY(), self._at.getYaw()

    def curve(self, a, b, keep=None) -> np.ndarray:
        """(N, 3) poses along the curve from ``a`` to ``b`` (both exact): the poses OMPL's motion check of this
        curve visits (at most ``step`` apart), and the pose of each cusp where ``keep(x, y, yaw)`` accepts it."""
        n = max(1, int(self.space.validSegmentCount(self.state(a, self._a), self.state(b, self._b))))
        ts = np.arange(n + 1) / n
        pts = np.array([a, *(self._pose(t) for t in ts[1:-1]), b], dtype=float)
        gear = _gears(pts)
        cusps = []
        for k in np.flatnonzero(gear[1:] != gear[:-1]) + 1:  # a cusp between ts[k-1] and ts[k+1]
            t, cusp = self._cusp(ts[k - 1], ts[k + 1], pts[k - 1], gear[k - 1])
            if min(np.linalg.norm(cusp[:2] - pts[j, :2]) for j in (k - 1, k, k + 1)) > 1e-6 and \
                    (keep is None or keep(*cusp)):
                cusps.append((t, cusp))
        if not cusps:
            return pts
        at = np.concatenate([ts, [t for t, _ in cusps]])
        return np.concatenate([pts, [c for _, c in cusps]])[np.argsort(at, kind="stable")]

    def _cusp(self, lo: float, hi: float, p0: np.ndarray, gear: int) -> tuple[float, np.ndarray]:
        """Where (curve parameter, pose) the car stops and changes gear: farthest along its heading in its gear
        from ``p0`` (golden section search between ``lo`` and ``hi``, each probe's reach kept for the next step)."""
        ux, uy = math.cos(p0[2]) * gear, math.sin(p0[2]) * gear
        x0, y0 = float(p0[0]), float(p0[1])

        def reach(t: float) -> float:
            x, y, _ = self._pose(t)
            return (x - x0) * ux + (y - y0) * uy

        g = (math.sqrt(5) - 1) / 2
        a, b = lo, hi
        c, d = b - g * (b - a), a + g * (b - a)
        rc, rd = reach(c), reach(d)
        for _ in range(40):
            if rc >= rd:  # the farthest lies in [a, d]: d becomes the upper probe
                b, d, rd = d, c, rc
                c = b - g * (b - a)
                rc = reach(c)
            else:
                a, c, rc = c, d, rd
                d = a + g * (b - a)
                rd = reach(d)
        return (a + b) / 2, np.array(self._pose((a + b) / 2))


def _gears(pts: np.ndarray) -> np.ndarray:
    """(N - 1,) the gear (+1 / -1) of each step between consecutive poses: its motion along the heading."""
    d = np.diff(pts[:, :2], axis=0)
    along = d[:, 0] * np.cos(pts[:-1, 2]) + d[:, 1] * np.sin(pts[:-1, 2])
    gear = np.where(along < 0, -1, 1).astype(np.int8)
    still = np.abs(along) < 1e-12  # a repeated pose keeps the gear before it
    for i in np.flatnonzero(still):
        gear[i] = gear[i - 1] if i > 0 else gear[i]
    return gear


def _directions(pts: np.ndarray) -> np.ndarray:
    """(N,) gear per pose: of the step leaving it (the last pose repeats the last step's)."""
    if len(pts) < 2:
        return np.ones(len(pts), dtype=np.int8)
    g = _gears(pts)
    return np.append(g, g[-1]).astype(np.int8)


def _stretches(pts: np.ndarray) -> list[float]:
    """[m] the lengths of the stretches of one gear of the path ``pts``, in order."""
    gear, step = _gears(pts), np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)
    cut = np.flatnonzero(gear[1:] != gear[:-1]) + 1
    return [float(step[a:b].sum()) for a, b in zip(np.r_[0, cut], np.r_[cut, len(step)], strict=True)]


def _straight(p: np.ndarray, gear: int, dist: float, step: float) -> np.ndarray:
    """(N, 3) poses from rear-axle pose ``p`` straight along its heading in ``gear`` for ``dist`` metres."""
    n = max(1, math.ceil(dist / step - 1e-9))
    s = np.linspace(0.0, dist, n + 1) * gear
    return np.column_stack([p[0] + s * math.cos(p[2]), p[1] + s * math.sin(p[2]), np.full(n + 1, p[2])])


def _arc(p: np.ndarray, gear: int, kappa: float, step: float, turn: float) -> np.ndarray:
    """(N, 3) poses from rear-axle pose ``p`` along a circle of curvature ``kappa`` [1/m] (> 0 turning left) in
    ``gear``, ``step`` apart, until the heading has turned by ``turn`` [rad]."""
    length = turn / abs(kappa)
    n = max(1, math.ceil(length / step - 1e-9))
    t = np.linspace(0.0, length, n + 1) * gear  # [m] signed arc length
    yaw = p[2] + kappa * t
    return np.column_stack([p[0] + (np.sin(yaw) - math.sin(p[2])) / kappa,
                            p[1] - (np.cos(yaw) - math.cos(p[2])) / kappa, yaw])


def _join(*parts: np.ndarray) -> np.ndarray:
    """Pose arrays end to end, each one's first pose (the previous one's last) dropped."""
    return np.concatenate([parts[0], *(q[1:] for q in parts[1:])])


# -- the planner -----------------------------------------------------------------------------------------------
class _NoPlan(Exception):
    """Why a park test has no plan (its message is the plan's reason): none found, none proven impossible."""


class _Proof(_NoPlan):
    """A proof that a park test has no plan (its message names it): the verdict ``infeasible``."""


class ParkPlanner:
    """The reference planner of the park tests of one :class:`GarageScene` for one car (module docstring)."""

    def __init__(self, scene: GarageScene, car: CarGeometry | None = None, config: ParkConfig = DEFAULT_PARK) -> None:
        if car is None:
            from garage_mj.scene.car import car_geometry  # reads the car's MuJoCo model

            car = car_geometry()
        self.scene = scene
        self.car = car
        self.config = config
        self._obstacles: Obstacles | None = None
        rows, cols = scene.garage.shape
        self.extent = (0.0, 0.0, cols * scene.world.block, rows * scene.world.block)  # [m] the garage's area
        far = max(car.front - car.rear_axle, car.rear_axle - car.rear)
        self.reach = math.hypot(far, car.half_width) + config.margin  # [m] rear axle to the grown footprint's corner

    @property
    def radius(self) -> float:
        """[m] the turning radius of the plans (of the rear-axle midpoint): the car's, plus the curvature margin."""
        return self.car.min_radius / (1.0 - self.config.curvature_margin)

    def obstacles(self) -> Obstacles:
        """Walls, obstacle blocks, pillars and every stall's outline of the scene (built once)."""
        if self._obstacles is None:
            self._obstacles = scene_obstacles(self.scene)
        return self._obstacles

    def plan(self, start, stall_id: int, maneuver_name: str = "reverse", occupied: Iterable[int] | None = None,
             obstacles: Obstacles | None = None) -> ParkPlan:
        """The reference plan from ``start`` (car centre, at rest) into stall ``stall_id`` with the maneuver.

        The obstacles: ``obstacles`` as given (the caller's own set), else the scene's walls, obstacle
        blocks and pillars with the outlines of the ``occupied`` stalls (None: every other stall).
        """
        t0 = time.process_time()
        stall = self.scene.stalls.stalls[stall_id]
        m = maneuver(maneuver_name)
        goal = park_pose(stall, self.car, m.name)
        start = tuple(float(v) for v in start)
        obs = obstacles if obstacles is not None else park_obstacles(self.obstacles(), stall_id, occupied)
        base = dict(stall=int(stall_id), maneuver=m.name, start=start, goal=goal)
        try:
            rear, method, iterations, attempt = self._search(stall, m, start, goal, obs)
        except _NoPlan as why:
            return ParkPlan(found=False, reason=str(why), planning_time=time.process_time() - t0,
                            verdict="infeasible" if isinstance(why, _Proof) else "unproven", **base)
        return self._found(rear, obs, t0, method=method, iterations=iterations, attempt=attempt, **base)

    def _found(self, rear: np.ndarray, obs: Obstacles, t0: float, **fields) -> ParkPlan:
        """The plan of rear-axle poses ``rear`` planned from the stall pose outward (driven the other way), its
        clearance to ``obs``, the CPU time since ``t0`` and the other ``fields`` of :class:`ParkPlan`."""
        rear = rear[::-1].copy()  # planned from the stall outward: driven from the start inward
        yaw = rear[:, 2]
        rear[:, 2] = np.where((yaw >= -math.pi) & (yaw < math.pi), yaw, _wrap(yaw))  # in range: kept to the bit
        directions = _directions(rear)
        dist, _ = nearest_obstacle(obs, self.car, rear[:, :2], rear[:, 2])
        return ParkPlan(found=True, poses=_frozen(rear_to_centre(rear, self.car)), rear_poses=_frozen(rear),
                        directions=_frozen(directions),
                        length=float(np.linalg.norm(np.diff(rear[:, :2], axis=0), axis=1).sum()),
                        cusps=int((directions[1:-1] != directions[:-2]).sum()), min_clearance=float(dist.min()),
                        planning_time=time.process_time() - t0, **fields)

    def correct(self, start, stall_id: int, maneuver_name: str = "reverse", occupied: Iterable[int] | None = None,
                obstacles: Obstacles | None = None) -> ParkPlan:
        """A correction for a car at ``start`` (car centre, at rest) that stopped near the stall pose, not parked, as a
        park assist straightens a car in its slot: one arc of :data:`CORRECTION_RUNS` (along a parallel slot in either
        gear, out of a bay towards the aisle) that turns the car onto the stall pose's heading, or
        :data:`CORRECTION_TURNS` off it, then back in the other gear: straight, level with the stall pose, or on a
        second arc of those lengths onto the stall pose's heading (a shift sideways). Each stretch at least
        :data:`CORRECTION_MIN_STRETCH` (a shorter one is no move to drive). Of the paths that keep the planner's margin
        to ``obstacles`` (as :meth:`plan` takes them) and end parked (:func:`in_stall`), the one ending farthest inside
        the stall's limits (to the centimetre), then the shortest; ``method`` "correction". Not found when the car is
        not within :data:`CORRECTION_NEAR` of the stall pose, or no path is clear and ends parked (then :meth:`plan` is
        the way in)."""
        t0 = time.process_time()
        cfg, car, marking = self.config, self.car, self.scene.world.marking_width
        stall = self.scene.stalls.stalls[stall_id]
        m = maneuver(maneuver_name)
        goal = park_pose(stall, car, m.name)
        start = tuple(float(v) for v in start)
        base = dict(stall=int(stall_id), maneuver=m.name, start=start, goal=goal, method="correction")
        near, turn = CORRECTION_NEAR
        if math.hypot(start[0] - goal[0], start[1] - goal[1]) > near or \
                abs(math.degrees(_wrap(goal[2] - start[2]))) > turn:
            return ParkPlan(found=False, reason=f"the car is not within {near:g} m and {turn:g} deg of the stall pose",
                            planning_time=time.process_time() - t0, verdict="unproven", **base)
        obs = obstacles if obstacles is not None else park_obstacles(self.obstacles(), stall_id, occupied)
        g, s = centre_to_rear(goal, car), centre_to_rear(start, car)
        hx, hy = math.cos(g[2]), math.sin(g[2])
        kappa = 1.0 / self.radius

        def arc(p: np.ndarray, gear: int, to: float, length: float) -> np.ndarray | None:
            """From ``p`` in ``gear`` over ``length`` onto heading ``to`` (None: tighter than the plans' turns)."""
            miss = float(_wrap(to - p[2]))
            if abs(miss) < 1e-9:
                return _straight(p, gear, length, cfg.step)
            return None if abs(miss) > kappa * length else _arc(p, gear, miss / (gear * length), cfg.step, abs(miss))

        paths = []
        for d in CORRECTION_RUNS:
            for gear in ((1, -1) if is_parallel(stall) else (m.exit_gear,)):
                for off in CORRECTION_TURNS:
                    first = arc(s, gear, g[2] + math.radians(off), d)
                    if first is None:
                        continue
                    if off == 0:  # the arc alone, or with a straight move back level with the stall pose
                        back = (first[-1, 0] - g[0]) * hx + (first[-1, 1] - g[1]) * hy  # [m] past the stall pose
                        moves = [first, *([_join(first, _straight(first[-1], -gear, abs(back), cfg.step))]
                                          if np.sign(back) == gear else [])]
                    else:  # the arc, then a second one back onto the stall pose's heading
                        seconds = (arc(first[-1], -gear, g[2], d2) for d2 in CORRECTION_RUNS)
                        moves = [_join(first, second) for second in seconds if second is not None]
                    for path in moves:
                        stretches = _stretches(path)
                        if min(stretches) < CORRECTION_MIN_STRETCH:
                            continue
                        fit = in_stall(stall, car, rear_to_centre(path[-1:], car)[0], m.name, marking)
                        if fit.parked:
                            paths.append((-round(fit.margin, 2), sum(stretches), len(paths), path))
        region = self._region(np.array([s, *(p[-1][-1] for p in paths)]))
        checker = _Checker(self.near(obs, region), car, cfg.margin, region)
        for *_, path in sorted(paths, key=lambda p: p[:3]):
            if checker.clear(path).all():
                return self._found(path[::-1], obs, t0, **base)
        return ParkPlan(found=False, reason="no correction is clear and ends parked", planning_time=time.process_time()
                        - t0, verdict="unproven", **base)

    # -- steps of a plan ---------------------------------------------------------------------------------------
    def _search(self, stall: Stall, m: Maneuver, start, goal, obs: Obstacles) -> tuple[np.ndarray, str, int, int]:
        """Rear-axle poses from the stall pose out to the start, the method, the iterations used and the attempt
        (0: the first; k: escalation stage k); or _NoPlan (no path, no proof), or _Proof (none can exist)."""
        cfg, car = self.config, self.car
        g, s = centre_to_rear(goal, car), centre_to_rear(start, car)
        parallel = is_parallel(stall)
        if parallel:
            fit = in_stall(stall, car, goal, m.name, self.scene.world.marking_width)
            if not fit.inside:  # no pose along the slot lies inside its lines: no success exists, whatever the path
                inner = stall.width - self.scene.world.marking_width
                raise _Proof(f"the slot is too short for the car: {inner:.2f} m between its end lines' inner edges, "
                             f"the car {car.front - car.rear:.2f} m long")
        d_out = self._exit_run(stall)  # [m] straight out this far, the car has left the stall (a slot: along it)
        out = _straight(g, m.exit_gear, d_out, cfg.step)
        region = self._region(np.array([g, s, out[-1]]))
        checker = _Checker(self.near(obs, region), car, cfg.margin, region)
        for what, pose in (("stall pose", g), ("start pose", s)):
            if not checker.pose_clear(*pose):
                raise _Proof(self._blocked(obs, pose, f"the {what}"))
        ok = checker.clear(out)
        d_ok = d_out if ok.all() else float(np.hypot(*(out[int(np.argmin(ok)) - 1, :2] - g[:2]))) if ok[0] else 0.0
        # a parallel slot's sampled plans leave the stall pose by a nudge in the exit gear: they end in the maneuver's
        nudge = min(cfg.step, d_ok) if parallel else 0.0
        off = (car.front + car.rear) / 2 - car.rear_axle  # [m] rear axle to the footprint's centre
        accept = (lambda rear: _enters(stall, rear, m.exit_gear, off)) if parallel else None
        with _ompl_seeded(cfg.seed) as (ob, og):
            curves = _Curves(ob, self.radius, region, cfg.step)
            path = self._analytic_parallel(curves, checker, g, s, m, stall, d_ok) if parallel else \
                self._analytic(curves, checker, g, s, m, d_ok)
            if path is not None:
                return path, "analytic", 0, 0
            # a parallel slot's sampling (but the escalation's stages from the exit) starts where a turn in the exit
            # gear has taken the car out of the slot
            lead = self._slot_exit(checker, g, m, stall, d_ok) if parallel else None
            if cfg.iterations == 0:
                first = _NoPlan("no straight exit and one Reeds-Shepp curve reach the start (sampling is off)")
            else:
                try:
                    return (*self._sample(ob, og, curves, checker, g, s, m, min(d_ok, d_out), cfg.planner,
                                          cfg.iterations, accept=accept, lead=lead), 0)
                except _NoPlan as why:
                    first = why
            closed = self._closed(obs, g, s)
            if closed:
                raise _Proof(f"{closed}; {first}")
            used, tried, areas = 0, [], {cfg.region: (curves, checker)}
            for k, (name, iterations, at, *grow) in enumerate(cfg.escalation, start=1):
                wide = float(grow[0]) if grow else cfg.region
                if wide not in areas:  # the planning area grown by this stage's region instead
                    area = self._region(np.array([g, s, out[-1]]), wide)
                    areas[wide] = (_Curves(ob, self.radius, area, cfg.step),
                                   _Checker(self.near(obs, area), car, cfg.margin, area))
                _ompl()[2].RNG.setSeed(_stage_seed(cfg.seed, k))  # each stage its own seed: a restart
                try:
                    path, method, n = self._sample(ob, og, *areas[wide], g, s, m,
                                                   min(d_ok, d_out) if at == "out" else nudge, name, iterations,
                                                   cfg.escalation_range, accept,
                                                   lead if at == "stall" and lead is not None else None)
                    return path, method, n + used, k
                except _NoPlan:
                    used += iterations
                    tried.append(f"{name} {iterations} from the {'exit' if at == 'out' else 'stall pose'}"
                                 + (f" ({wide:g} m area)" if grow else ""))
            runs = {t: tried.count(t) for t in tried}  # in order, repeats counted
            more = "; escalated ({}) without a path".format(
                ", ".join(t if n == 1 else f"{t} x{n}" for t, n in runs.items())) if tried else ""
            raise _NoPlan(f"unproven: {first}{more}, and no proof that none exists")

    def _closed(self, obs: Obstacles, g: np.ndarray, s: np.ndarray) -> str:
        """A proof that no path leads from the stall pose ``g`` to the start ``s`` (rear axles), or "".

        The footprint grown by the margin holds the disc of radius (half width + margin) about its centre,
        so along any valid path that centre stays at least that far from every obstacle. The cells of a
        grid wholly within that distance of one obstacle box are closed to it; when the cells reachable
        (8-neighbours) from the stall pose's centre include neither the start's nor the edge of a window
        around the stall, the centre cannot leave: the stall is closed at the car's width. Only the
        obstacles prove it (not the planning area), so the proof holds for every planner.
        """
        car, cfg = self.car, self.config
        off = (car.front + car.rear) / 2 - car.rear_axle  # [m] rear axle to the footprint's centre
        a, b = (p[:2] + off * np.array([math.cos(p[2]), math.sin(p[2])]) for p in (g, s))
        r = car.half_width + cfg.margin  # [m] the disc's radius
        cell = cfg.proof_cell
        lo = a - (car.front - car.rear + 2 * cfg.margin + 2 * r)  # a window the car's length and more about the stall
        n = int(math.ceil(2 * (a - lo).max() / cell)) + 1
        boxes = obs.boxes
        if not len(boxes):
            return ""
        xs, ys = lo[0] + cell * np.arange(n + 1), lo[1] + cell * np.arange(n + 1)  # grid lines
        keep = (boxes[:, 2] >= xs[0] - r) & (boxes[:, 0] <= xs[-1] + r) & (boxes[:, 3] >= ys[0] - r) & \
            (boxes[:, 1] <= ys[-1] + r)
        closed = np.zeros((n, n), dtype=bool)  # [ix, iy]: the cell [xs[ix], xs[ix+1]] x [ys[iy], ys[iy+1]]
        turned = obs.rotated
        for j in np.flatnonzero(keep):
            # the farthest point of a cell from a convex obstacle is one of its corners: every corner nearer than r
            # closes it
            if turned[j]:  # the polygon itself, not its box
                gx, gy = np.meshgrid(xs, ys, indexing="ij")
                d = polygon_distance(np.column_stack([gx.ravel(), gy.ravel()]), obs.polygons[j])
                near = (d < r).reshape(n + 1, n + 1)
            else:
                x0, y0, x1, y1 = boxes[j]
                dx = np.maximum(np.maximum(x0 - xs, xs - x1), 0.0)  # (n + 1,) per grid line
                dy = np.maximum(np.maximum(y0 - ys, ys - y1), 0.0)
                near = dx[:, None] ** 2 + dy[None, :] ** 2 < r * r  # (n + 1, n + 1) grid corners
            closed |= near[:-1, :-1] & near[1:, :-1] & near[:-1, 1:] & near[1:, 1:]
        ia, ib = (tuple(int(v) for v in (p - lo) // cell) for p in (a, b))
        if closed[ia]:
            return ""  # the stall pose's own cell is closed (cannot be, for a clear pose): prove nothing
        seen = np.zeros_like(closed)
        seen[ia] = True
        todo = [ia]
        while todo:
            i, j = todo.pop()
            if i in (0, n - 1) or j in (0, n - 1) or (i, j) == ib:
                return ""  # out to the window's edge, or at the start: no proof
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    q = (i + di, j + dj)
                    if not seen[q] and not closed[q]:
                        seen[q] = True
                        todo.append(q)
        return (f"the stall is closed at the car's width: its centre cannot leave the stall {2 * r:.2f} m clear of "
                f"every obstacle ({cfg.margin:.2f} m margin)")

    def area(self, start, stall_id: int, maneuver_name: str = "reverse") -> tuple[float, float, float, float]:
        """[m] ``(xmin, ymin, xmax, ymax)``: the planning area of a park test (a plan's rear axle stays inside)."""
        stall, m = self.scene.stalls.stalls[stall_id], maneuver(maneuver_name)
        g = centre_to_rear(park_pose(stall, self.car, m.name), self.car)
        out = _straight(g, m.exit_gear, self._exit_run(stall), 1.0)[-1]
        return self._region(np.array([g, centre_to_rear(start, self.car), out]))

    def _exit_run(self, stall: Stall) -> float:
        """[m] the straight exit: out of a bay along its axis until the car has left it; along a parallel slot (which
        the car leaves sideways) the car's length, as far as a straight run along the kerb can help."""
        if is_parallel(stall):
            return self.car.front - self.car.rear
        return stall.length - BACK_GAP + self.config.margin

    def _region(self, poses: np.ndarray, grow: float | None = None) -> tuple[float, float, float, float]:
        """[m] the planning area: the box around ``poses`` grown by ``grow`` (None: ``region``), within the garage."""
        r, (x0, y0, x1, y1) = self.config.region if grow is None else grow, self.extent
        lo, hi = poses[:, :2].min(axis=0) - r, poses[:, :2].max(axis=0) + r
        return max(lo[0], x0), max(lo[1], y0), min(hi[0], x1), min(hi[1], y1)

    def near(self, obs: Obstacles, region: tuple[float, float, float, float]) -> Obstacles:
        """The obstacles of ``obs`` the footprint (grown by the margin) can touch with its rear axle inside ``region``."""
        b, r = obs.boxes, self.reach
        keep = (b[:, 2] >= region[0] - r) & (b[:, 0] <= region[2] + r) & (b[:, 3] >= region[1] - r) & \
            (b[:, 1] <= region[3] + r)
        return obs.take(np.flatnonzero(keep))

    def _blocked(self, obs: Obstacles, rear: np.ndarray, what: str) -> str:
        """Why the pose ``rear`` (rear axle) is not valid: the nearest obstacle and the margin, or the area."""
        dist, near = nearest_obstacle(obs, self.car, rear[None, :2], rear[None, 2])
        if near[0] < 0 or dist[0] >= self.config.margin:
            return f"{what} lies outside the planning area"
        x, y = rear[:2]
        return (f"{what} ({x:.1f}, {y:.1f}) is not clear: {a_noun(obs.classes[int(near[0])])} {dist[0]:.2f} m from the car "
                f"(margin {self.config.margin:.2f} m)")

    def _analytic(self, curves: _Curves, checker: _Checker, g: np.ndarray, s: np.ndarray, m: Maneuver,
                  d_ok: float) -> np.ndarray | None:
        """Straight out of the stall by one of the exit distances, then one Reeds-Shepp curve to the start:
        the shortest such path that is clear, or None."""
        cfg = self.config
        exits = [k * cfg.exit_step for k in range(int(d_ok / cfg.exit_step + 1e-9) + 1)]

        def exit_pose(d: float) -> np.ndarray:
            return _straight(g, m.exit_gear, d, d)[-1] if d > 0 else g

        for d in sorted(exits, key=lambda d: (d + curves.length(exit_pose(d), s), d)):
            e = exit_pose(d)
            curve = curves.curve(e, s, checker.pose_clear)
            path = _join(_straight(g, m.exit_gear, d, cfg.step), curve) if d > 0 else curve
            if checker.clear(path).all():
                return path
        return None

    def _analytic_parallel(self, curves: _Curves, checker: _Checker, g: np.ndarray, s: np.ndarray, m: Maneuver,
                           stall: Stall, d_ok: float) -> np.ndarray | None:
        """A parallel slot's analytic attempt: out of the slot on one Reeds-Shepp curve, either straight to the start or
        to a pre-park pose beside the slot (heading along it, between the slot and its lane's centre, ahead of the slot
        for a reverse-in park and behind it for a nose-in one: the classic S), then one curve to the start; optionally
        after a straight run along the slot in the exit gear. The shortest clear path that leaves the slot in the
        exit gear (:func:`_enters`: driven, it enters the slot in the maneuver's gear), or None."""
        cfg = self.config
        h = float(g[2])
        fx, fy, lx, ly = math.cos(h), math.sin(h), -math.sin(h), math.cos(h)
        lane = (stall.road_x - g[0]) * lx + (stall.road_y - g[1]) * ly  # [m] the lane's centre left of the stall pose
        sides = sorted({round(v, 2) for v in (lane, lane - 0.5, lane - 1.0, lane + 0.5) if v >= 2 * self.car.half_width})
        runs = [d for d in (0.0, 0.25, 0.5, 1.0) if d <= d_ok + 1e-9]

        def along(p: np.ndarray, d: float, side: float = 0.0) -> np.ndarray:
            return np.array([p[0] + d * fx + side * lx, p[1] + d * fy + side * ly, h])

        candidates = []  # (estimated length, run, pre-park pose or None)
        for d in runs:
            e = along(g, d * m.exit_gear)
            candidates.append((d + curves.length(e, s), d, None))
            for side in sides:
                for ahead in PRE_PARK_AHEAD:
                    pre = along(g, ahead * m.exit_gear, side)
                    candidates.append((d + curves.length(e, pre) + curves.length(pre, s), d, pre))
        candidates.sort(key=lambda c: (c[0], c[1]))
        for _, d, pre in candidates:
            e = along(g, d * m.exit_gear)
            parts = [_straight(g, m.exit_gear, d, cfg.step)] if d > 0 else []
            if pre is None:
                parts.append(curves.curve(e, s, checker.pose_clear))
            else:
                parts += [curves.curve(e, pre, checker.pose_clear), curves.curve(pre, s, checker.pose_clear)]
            path = _join(*parts)
            if _enters(stall, path, m.exit_gear, checker.off) and checker.clear(path).all():
                return path
        return None

    def _slot_exit(self, checker: _Checker, g: np.ndarray, m: Maneuver, stall: Stall, d_ok: float
                   ) -> np.ndarray | None:
        """Rear-axle poses from the stall pose of parallel slot ``stall`` out of it in the exit gear: a run along the
        slot (in either gear, at most ``d_ok`` in the exit gear), then one turn at a share of the plan's tightest
        curvature (:data:`SLOT_EXIT_TURNS`), either way, in the exit gear until the car's centre is
        :data:`SLOT_EXIT_PAST` past the slot's open edge; the shortest clear one, or None. Driven the other way it
        enters the slot in the maneuver's gear."""
        cfg = self.config
        ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)
        off = checker.off
        best: np.ndarray | None = None
        for run in sorted((r for r in (0.0, 0.5, -0.5, 1.0, -1.0) if r <= d_ok + 1e-9), key=abs):
            gear = m.exit_gear if run >= 0 else -m.exit_gear
            start = _straight(g, gear, abs(run), cfg.step) if run else g[None]
            if not checker.clear(start).all():
                continue
            for turn in (k * side for k in SLOT_EXIT_TURNS for side in (1.0, -1.0)):
                arc = _arc(start[-1], m.exit_gear, turn / self.radius, cfg.step, math.pi / 2)
                cx, cy = arc[:, 0] + off * np.cos(arc[:, 2]), arc[:, 1] + off * np.sin(arc[:, 2])
                past = np.flatnonzero((cx - stall.x) * ux + (cy - stall.y) * uy > stall.length / 2 + SLOT_EXIT_PAST)
                if not len(past):
                    continue
                arc = arc[:past[0] + 1]
                if checker.clear(arc).all():
                    path = _join(start, arc)
                    if best is None or len(path) < len(best):
                        best = path
            if best is not None:
                return best
        return None

    def _sample(self, ob, og, curves: _Curves, checker: _Checker, g: np.ndarray, s: np.ndarray, m: Maneuver,
                d_exit: float, name: str, iterations: int, reach: float | None = None,
                accept: Callable[[np.ndarray], bool] | None = None,
                lead: np.ndarray | None = None) -> tuple[np.ndarray, str, int]:
        """The seeded sampling planner ``name`` (a key of SAMPLERS) with a budget of ``iterations`` from the straight
        exit (``d_exit`` out of the stall) to the start; a ranged one's range ``reach`` (None: ``planner_range``);
        a path ``accept`` (given) refuses is no path (a parallel slot's: one that enters in the other gear); ``lead``
        (given): the poses from the stall pose to where the sampling starts instead of the straight exit."""
        cfg = self.config
        si = ob.SpaceInformation(curves.space)
        si.setStateValidityChecker(checker)
        si.setStateValidityCheckingResolution(curves.resolution)
        si.setup()
        e = lead[-1] if lead is not None else _straight(g, m.exit_gear, d_exit, d_exit)[-1] if d_exit > 0 else g
        pdef = ob.ProblemDefinition(si)
        pdef.setStartAndGoalStates(curves.state(e), curves.state(s), 1e-3)
        objective = ob.PathLengthOptimizationObjective(si)
        objective.setCostThreshold(ob.Cost(math.inf))  # any path satisfies it: stop at the first
        pdef.setOptimizationObjective(objective)
        spec = SAMPLERS[name]
        planner = getattr(og, spec.cls)(si)
        if spec.ranged:
            planner.setRange(cfg.planner_range if reach is None else reach)
        planner.setProblemDefinition(pdef)
        planner.setup()
        used = [0]

        def spent() -> bool:
            used[0] += 1
            return used[0] > iterations

        planner.solve(ob.PlannerTerminationCondition(spent))
        if not pdef.hasExactSolution():
            raise _NoPlan(f"no path found: the straight exit and one Reeds-Shepp curve hit an obstacle, and "
                          f"{name} found none in {iterations} iterations")
        path = pdef.getSolutionPath()
        og.PathSimplifier(si).simplifyMax(path)
        way = [e, *([st.getX(), st.getY(), st.getYaw()] for st in path.getStates()[1:])]
        if np.linalg.norm(np.subtract(way[-1], s)) > 1e-9:
            way.append(s)
        parts = [_edge(curves, checker, np.asarray(a), np.asarray(b)) for a, b in zip(way[:-1], way[1:], strict=True)]
        if lead is not None and len(lead) > 1:
            parts.insert(0, lead)
        elif lead is None and d_exit > 0:
            parts.insert(0, _straight(g, m.exit_gear, d_exit, cfg.step))
        dense = _join(*parts)
        if not checker.clear(dense).all():
            raise _NoPlan(f"{name}'s path grazes an obstacle between the poses it checked")
        if accept is not None and not accept(dense):
            raise _NoPlan(f"{name}'s path enters the slot in the other gear than the maneuver's")
        return dense, name, min(used[0], iterations)


def _enters(stall: Stall, rear: np.ndarray, gear: int, off: float) -> bool:
    """Whether the rear-axle path ``rear``, planned from the stall pose of parallel slot ``stall`` outward, takes the
    car's centre (``off`` ahead of the rear axle) out past the slot's open, aisle-side edge in ``gear``: driven the other
    way, the move that brings the car into the slot is in the maneuver's gear (shuffles inside it may follow)."""
    ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)
    cx, cy = rear[:, 0] + off * np.cos(rear[:, 2]), rear[:, 1] + off * np.sin(rear[:, 2])
    out = np.flatnonzero((cx - stall.x) * ux + (cy - stall.y) * uy > stall.length / 2)
    if not len(out) or out[0] == 0:
        return False
    return bool(_gears(rear[out[0] - 1:out[0] + 1])[0] == gear)


def _edge(curves: _Curves, checker: _Checker, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The poses of one edge of a sampled path, ``a`` to ``b``: the curve from ``a`` to ``b``, or where that one is
    not clear, the curve from ``b`` to ``a`` driven backwards (two shortest curves can tie, and OMPL may
    have checked the edge either way)."""
    forward = curves.curve(a, b, checker.pose_clear)
    if checker.clear(forward).all():
        return forward
    return curves.curve(b, a, checker.pose_clear)[::-1]


def park_planner(scene: GarageScene, car: CarGeometry | None = None, config: ParkConfig | None = None) -> ParkPlanner:
    """The reference park planner of ``scene`` for ``car`` (default ``models/car``) and ``config``."""
    return ParkPlanner(scene, car, config or DEFAULT_PARK)


__all__ = ["BACK_GAP", "FAR_END_SLACK", "HEADING_TOLERANCE", "MANEUVERS", "SAMPLERS", "DEFAULT_PARK", "Maneuver",
           "STALL_LINES", "ParkConfig", "ParkFit", "ParkPlan", "ParkPlanner", "centre_to_rear", "far_end_allowance",
           "in_stall", "maneuver", "stall_limits",
           "park_obstacles", "park_planner", "park_pose", "rear_to_centre"]
