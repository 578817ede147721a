"""The parked cars of one test as real bodies: which class each is, and where it stands (docs/spec.md section 9).

A scene holds one parked car per stall (``models/parked_car``: 4.3 x 1.9 m, centred in its stall, square to
it, heading as ``Stall.car_yaw`` says). :class:`ParkedFleet` says what a test makes of them:

- ``uniform`` (the default): every parked car is that model, centred, square, exactly as the scene was built;
- ``mixed``: each parked car's class is drawn from the fleet table (:data:`~garage_mj.scene.vehicles.FLEET`:
  compact, sedan, SUV, van), seeded per test; in a bay, a car that fits with :data:`END_GAP` at each end is
  centred along it, a longer one stands with its back :data:`END_GAP` from the back line and overhangs the
  aisle-side end; in a parallel slot, a car is centred along it, and a class that does not fit the slot with
  END_GAP at each end stands as the longest class that does (the compact in a 4.5 m slot: a longer car would stand
  in the next slot, or in its car);
- ``jitter`` [m] (0 to :data:`MAX_PARKED_JITTER`): each parked car is moved sideways (across a parallel slot) by up to
  that much, in a parallel slot also along it by up to that much, and turned by up to :data:`JITTER_YAW` x that much
  (radians), drawn per test. A car may stand over its lines,
  never into the target stall's paint (its inner edges, :func:`stall_inner`) nor within :data:`CAR_GAP` of another
  parked car (as placed, or where a car placed later stands without jitter): a draw that would is halved toward the
  stall's axis until it does not (:data:`JITTER_HALVINGS` times, then the car stands as without jitter).

A test that drives a cruise route (a cruise or an AVP test) passes ``lane`` (:class:`RouteLane`): the route's swept
footprint, which the drive planner keeps its clearance margin from every stall's outline. A parked car that comes
closer to it than that margin (a van overhanging its bay into a 6.5 m aisle at a turn, which the route would hit)
stands as the longest class of the fleet that keeps the margin, with the same jitter (as a parallel slot's car that
does not fit stands as the longest that does): the route the test is planned along is clear of the real bodies, as
of the stall outlines.

:func:`draw_parked` makes those draws from a generator of their own, never the test's other draws (so a
uniform
fleet without jitter draws nothing and every other draw of a test stays what it was). The result is one
:class:`ParkedBody` per parked car: its class, pose and outline, which the drive env writes into its compiled
MuJoCo model (:meth:`garage_mj.scene.mjcf_scene.ParkedCars.place`) and the park planner takes as obstacles
(:func:`body_obstacles`): what the cameras see, what the car can hit and what the planner avoids are the same
boxes.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from garage_mj.scene.car import CarGeometry
from garage_mj.scene.clearance import Obstacles, nearest_obstacle
from garage_mj.scene.stalls import Stall
from garage_mj.scene.templates import PARKED_CAR, load_template
from garage_mj.scene.vehicles import FLEET, VehicleClass
from garage_mj.scene.world import DEFAULT_WORLD

#: The parked fleets a run may ask for.
PARKED_FLEETS = ("uniform", "mixed")
MAX_PARKED_JITTER = 0.5  # [m] the largest lateral jitter a run may ask for
JITTER_YAW = 0.2  # [rad per m of jitter] the heading jitter's bound: 0.1 rad (5.7 deg) at 0.5 m
END_GAP = 0.1  # [m] a parked car's ends to the stall's back line (and open end, when it fits)
CAR_GAP = 0.05  # [m] the least gap between two parked cars
JITTER_HALVINGS = 6  # halvings of a draw that enters the target stall or another car, before it is dropped
UNIFORM = "parked_car"  # the class name of models/parked_car, the uniform fleet's car
#: The seed stream of the parked fleet's draws (a generator of its own, seeded by the test's seed and this).
FLEET_STREAM = 0x9A2CED


@dataclass(frozen=True)
class ParkedFleet:
    """What the parked cars of a test are: ``fleet`` (one of :data:`PARKED_FLEETS`) and ``jitter`` [m]."""

    fleet: str = "uniform"
    jitter: float = 0.0  # [m] lateral offset bound; the heading's is JITTER_YAW x this [rad]

    def __post_init__(self) -> None:
        if self.fleet not in PARKED_FLEETS:
            raise ValueError(f"parked fleet {self.fleet!r}: use one of {', '.join(PARKED_FLEETS)}")
        j = self.jitter
        if isinstance(j, bool) or not isinstance(j, (int, float)) or not 0.0 <= j <= MAX_PARKED_JITTER:
            raise ValueError(f"parked jitter {j!r}: give metres from 0 to {MAX_PARKED_JITTER:g}")
        object.__setattr__(self, "jitter", float(j))

    @property
    def default(self) -> bool:
        """The scene's own cars, as built: nothing to draw, nothing to move."""
        return self.fleet == "uniform" and self.jitter == 0.0


@dataclass(frozen=True)
class ParkedBody:
    """One parked car as it stands: its stall, class, pose (centre on the floor, heading [rad]) and size [m]."""

    stall: int
    vehicle: str  # a FLEET class, or UNIFORM
    x: float
    y: float
    yaw: float
    length: float
    width: float
    height: float

    def corners(self) -> np.ndarray:
        """(4, 2) the outline on the floor, counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        hl, hw = self.length / 2, self.width / 2
        local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
        return np.column_stack([self.x + local[:, 0] * c - local[:, 1] * s, self.y + local[:, 0] * s + local[:, 1] * c])


@functools.cache
def parked_car_parts() -> dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]]:
    """``models/parked_car``'s geoms: name -> (pos, half size) [m] in the car's frame (origin on the floor)."""
    out = {}
    for g in load_template(PARKED_CAR).geoms:
        out[g["name"]] = (tuple(float(v) for v in g.get("pos", (0, 0, 0))), tuple(float(v) for v in g["size"]))
    return out


def uniform_size() -> tuple[float, float, float]:
    """(length, width, height) [m] of ``models/parked_car`` (its hull's outline, its cabin's roof)."""
    (_, (hx, hy, _)), (cabin_pos, cabin_half) = parked_car_parts()["hull"], parked_car_parts()["cabin"]
    return 2 * hx, 2 * hy, cabin_pos[2] + cabin_half[2]


def part_boxes(body: ParkedBody) -> dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]]:
    """The geoms of ``body`` in its own frame: ``models/parked_car``'s hull and cabin resized to its class (the hull
    to its outline at the model's heights, the cabin in proportion, up to its roof). name -> (pos, half size)."""
    parts = parked_car_parts()
    length, width, height = uniform_size()
    (hull_pos, hull_half), (cabin_pos, cabin_half) = parts["hull"], parts["cabin"]
    if (body.length, body.width, body.height) == (length, width, height):
        return dict(parts)
    sx = body.length / length
    hull_top = hull_pos[2] + hull_half[2]
    cabin_hz = (body.height - hull_top) / 2
    inset = hull_half[1] - cabin_half[1]  # [m] hull side to cabin side
    return {"hull": (hull_pos, (body.length / 2, body.width / 2, hull_half[2])),
            "cabin": ((cabin_pos[0] * sx, 0.0, hull_top + cabin_hz), (cabin_half[0] * sx, body.width / 2 - inset, cabin_hz))}


def stall_inner(stall: Stall, marking: float = DEFAULT_WORLD.marking_width) -> np.ndarray:
    """(4, 2) the stall inside its paint: the side and back lines' inner edges and the open end, counter-clockwise."""
    ux, uy = math.cos(stall.yaw), math.sin(stall.yaw)
    hw = stall.width / 2 - marking / 2
    s0, s1 = -stall.length / 2 + marking / 2, stall.length / 2  # along the axis, back line to open end
    pts = [(s1, hw), (s0, hw), (s0, -hw), (s1, -hw)]
    return np.array([(stall.x + s * ux - t * uy, stall.y + s * uy + t * ux) for s, t in pts])


def _overlap(a: np.ndarray, b: np.ndarray, gap: float = 0.0) -> bool:
    """Whether convex polygons ``a`` and ``b`` (K, 2) come closer than ``gap`` along any of their edges' normals
    (separating axes; with a gap, the polygons grown by it along those axes). Plain floats: a handful of corners."""
    pa, pb = a.tolist(), b.tolist()
    for poly in (pa, pb):
        for (x0, y0), (x1, y1) in zip(poly, poly[1:] + poly[:1], strict=True):
            nx, ny = y0 - y1, x1 - x0
            norm = math.hypot(nx, ny)
            if norm < 1e-12:
                continue
            nx, ny = nx / norm, ny / norm
            da = [x * nx + y * ny for x, y in pa]
            db = [x * nx + y * ny for x, y in pb]
            if max(da) + gap <= min(db) or max(db) + gap <= min(da):
                return False
    return True


def _place(stall: Stall, name: str, size: tuple[float, float, float], lateral: float, dyaw: float,
           shift: float = 0.0) -> ParkedBody:
    """A car of ``size`` in ``stall``, heading as a parked car there does (``Stall.car_yaw``: a bay's axis, nose out;
    a parallel slot's length): centred, or in a bay too short for it with :data:`END_GAP` at each end, its rear
    END_GAP from the back line; then moved ``lateral`` to its left, ``shift`` ahead and turned by ``dyaw``."""
    length, width, height = size
    parallel = stall.angle == 0.0
    room = stall.width if parallel else stall.length  # [m] the stall along the car's axis
    along = shift + (0.0 if parallel or length + 2 * END_GAP <= room else -room / 2 + END_GAP + length / 2)
    yaw = stall.car_yaw
    ux, uy = math.cos(yaw), math.sin(yaw)
    return ParkedBody(stall.id, name, stall.x + along * ux - lateral * uy, stall.y + along * uy + lateral * ux,
                      yaw + dyaw, length, width, height)


def _fitting(stall: Stall, vehicle: VehicleClass) -> VehicleClass:
    """The class a parked car drawn as ``vehicle`` is in ``stall``: itself, except in a parallel slot it does not fit
    with :data:`END_GAP` at each end, where the longest class of the fleet that does stands instead (the slot's ends
    are another slot's, or its car's: a longer car would stand in them), the shortest when none does."""
    if stall.angle != 0.0 or vehicle.length + 2 * END_GAP <= stall.width:
        return vehicle
    fits = [v for v in FLEET.values() if v.length + 2 * END_GAP <= stall.width]
    return max(fits, key=lambda v: v.length) if fits else min(FLEET.values(), key=lambda v: v.length)


@dataclass(frozen=True)
class RouteLane:
    """The swept footprint of a test's cruise route: ``car``'s body along the rear-axle path ``rear`` (N, 2) with
    ``heading`` (N,), which parked cars keep ``margin`` [m] clear of (:func:`draw_parked`)."""

    rear: np.ndarray
    heading: np.ndarray
    car: CarGeometry
    margin: float

    @functools.cached_property
    def _centres(self) -> np.ndarray:
        """(N, 2) the car body's centre along the route."""
        off = (self.car.front + self.car.rear) / 2 - self.car.rear_axle  # [m] rear axle to the body's centre
        return self.rear + off * np.stack([np.cos(self.heading), np.sin(self.heading)], axis=1)

    def clear(self, body: ParkedBody) -> bool:
        """Whether ``body`` keeps :attr:`margin` from the car anywhere along the route."""
        car = self.car
        radius = math.hypot((car.front - car.rear) / 2, car.half_width)  # [m] the car body's centre to a corner
        c = self._centres
        near = np.hypot(c[:, 0] - body.x, c[:, 1] - body.y) <= (
            radius + math.hypot(body.length, body.width) / 2 + self.margin)  # the poses that may come that near
        if not near.any():
            return True
        obstacle = Obstacles.from_polygons([body.corners()], ["parked_car"], [body.stall])
        dist, _ = nearest_obstacle(obstacle, car, self.rear[near], self.heading[near])
        return bool(dist.min() >= self.margin)


def _shorter_clear(stall: Stall, body: ParkedBody, lateral: float, dyaw: float, shift: float, lane: RouteLane,
                   ok) -> ParkedBody:
    """``body``, or where it comes within ``lane``'s margin of the route, the longest shorter class of the fleet in its
    place with the same jitter that keeps the margin and ``ok(corners)`` (clear of the target stall and the other
    cars); ``body`` where none does."""
    if lane.clear(body):
        return body
    for v in sorted(FLEET.values(), key=lambda v: -v.length):
        if v.length < body.length:
            trial = _place(stall, v.name, (v.length, v.width, v.height), lateral, dyaw, shift)
            if lane.clear(trial) and ok(trial.corners()):
                return trial
    return body


def fleet_rng(seed: int) -> np.random.Generator:
    """The generator of a test's parked-fleet draws: seeded by the test's seed, apart from its other draws."""
    return np.random.default_rng([FLEET_STREAM, int(seed)])


def draw_parked(stalls: list[Stall], occupied, target: int | None, fleet: ParkedFleet, rng: np.random.Generator,
                marking: float = DEFAULT_WORLD.marking_width, lane: RouteLane | None = None) -> dict[int, ParkedBody]:
    """The parked car of each ``occupied`` stall (module docstring), stall id -> :class:`ParkedBody`.

    ``stalls``: every stall of the scene, by id. Per stall in id order, whether occupied or not (so the same seed
    gives each stall the same draw whatever the occupancy): one class index (mixed), then the lateral and heading
    uniforms (jitter; in a garage of parallel slots a third, along the slot); then the cars are placed in stall id
    order. ``target``: the stall under test, kept clear inside its paint (None: no test stall). ``lane``: the test's
    cruise route, which the cars keep its margin from (module docstring; None: no route).
    """
    want = {int(s) for s in occupied} - ({int(target)} if target is not None else set())
    names = list(FLEET)
    n = len(stalls)
    kinds = rng.integers(len(names), size=n) if fleet.fleet == "mixed" else None
    # a parallel slot's car is also moved along it: a third uniform per stall, drawn only in a garage of parallel slots
    cols = 3 if any(s.angle == 0.0 for s in stalls) else 2
    jit = rng.uniform(-1.0, 1.0, size=(n, cols)) if fleet.jitter > 0 else np.zeros((n, cols))
    keep_out = stall_inner(stalls[target], marking) if target is not None else None
    cars: dict[int, tuple[str, tuple[float, float, float], float, float, float]] = {}  # stall -> class, size, jitter
    for k, stall in enumerate(stalls):
        if stall.id in want:
            if kinds is None:
                name, size = UNIFORM, uniform_size()
            else:
                v = _fitting(stall, FLEET[names[int(kinds[k])]])
                name, size = v.name, (v.length, v.width, v.height)
            shift = jit[k, 2] * fleet.jitter if stall.angle == 0.0 else 0.0
            cars[stall.id] = (name, size, jit[k, 0] * fleet.jitter, jit[k, 1] * JITTER_YAW * fleet.jitter, shift)
    # where each car stands without jitter: what a car placed before it must leave free, so that it can always fall back
    square = {sid: _place(stalls[sid], name, size, 0.0, 0.0) for sid, (name, size, *_) in cars.items()}
    placed: dict[int, ParkedBody] = {}
    for sid, (name, size, lateral, dyaw, shift) in cars.items():
        me = square[sid]
        moved = lateral != 0.0 or dyaw != 0.0 or shift != 0.0
        if not moved and (lane is None or lane.clear(me)):  # no jitter, the route clear: nothing to check
            placed[sid] = me
            continue
        # [m] farther cars cannot touch it (moved across, and in a parallel slot along, by up to MAX_PARKED_JITTER)
        reach = math.hypot(me.length, me.width) / 2 + math.sqrt(2) * MAX_PARKED_JITTER + CAR_GAP
        near = [b for b in (*placed.values(), *(square[o] for o in cars if o != sid and o not in placed))
                if math.hypot(b.x - me.x, b.y - me.y) <= reach + math.hypot(b.length, b.width) / 2]
        others = [b.corners() for b in near]

        def ok(c: np.ndarray, others: list[np.ndarray] = others) -> bool:
            return not ((keep_out is not None and _overlap(c, keep_out)) or any(_overlap(c, o, CAR_GAP) for o in others))

        body = me
        if moved:  # the jitter, halved toward the stall's axis until the car stands clear
            for _ in range(JITTER_HALVINGS + 1):
                trial = _place(stalls[sid], name, size, lateral, dyaw, shift)
                if ok(trial.corners()):
                    body = trial
                    break
                lateral, dyaw, shift = lateral / 2, dyaw / 2, shift / 2
        if body is me:
            lateral = dyaw = shift = 0.0
        placed[sid] = body if lane is None else _shorter_clear(stalls[sid], body, lateral, dyaw, shift, lane, ok)
    return placed


def body_obstacles(obstacles: Obstacles, target: int, bodies: dict[int, ParkedBody]) -> Obstacles:
    """The obstacles of a park test into ``target`` among real parked cars: every non-stall obstacle of
    ``obstacles`` (walls, obstacle blocks, pillars), then each parked car's outline (class ``parked_car``, its
    stall id), in stall order."""
    base = obstacles.take(np.flatnonzero(obstacles.stall < 0))
    cars = [bodies[s] for s in sorted(bodies) if s != target]
    if not cars:
        return base
    return base.plus(Obstacles.from_polygons([b.corners() for b in cars], ["parked_car"] * len(cars),
                                             [b.stall for b in cars]))


__all__ = ["CAR_GAP", "END_GAP", "JITTER_YAW", "MAX_PARKED_JITTER", "PARKED_FLEETS", "UNIFORM", "ParkedBody",
           "ParkedFleet", "body_obstacles", "draw_parked", "fleet_rng", "part_boxes", "stall_inner", "uniform_size"]
