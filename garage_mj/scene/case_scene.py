"""Park cases from elsewhere (docs/spec.md section 9): one park test given as obstacle polygons, a start and a goal.

A :class:`ParkCase` is what a problem file holds, whoever wrote it (this project's park problems, or a TPCAP case:
the readers live in :mod:`garage_mj.export.park_problems`, the runner in :mod:`garage_mj.driving.cases`): the start
and goal poses of the rear-axle midpoint, the obstacles as polygons with a class, the vehicle, and for this
project's problems the stall outline and the maneuver. Coordinates are the file's less its start point
(``origin``): TPCAP places some cases 10^10 m from the origin, where float32 tools (MuJoCo's meshes) would lose them.

:class:`CaseScene` is the case as the simulator and the reference planner see it, built once:

- ``obstacles``: every polygon as convex pieces (:func:`convex_pieces`: a concave polygon of TPCAP's is cut along
  diagonals into as few convex pieces as the greedy merge finds), in one :class:`~garage_mj.scene.clearance.Obstacles`
  the clearance checks and the planner read; their union is the polygon.
- ``stall``: the target, a stall outline drawn at the goal (a problem file's own outline where it has one): a
  :class:`~garage_mj.scene.stalls.Stall` whose stall pose (:func:`~garage_mj.scene.park_planning.park_pose`) is the
  goal, :data:`STALL_END_GAP` longer than the vehicle at each end and :data:`STALL_SIDE_GAP` wider at each side, so
  success is judged as in a garage's park test. The maneuver is the file's, else ``reverse`` when the car can leave
  the goal forward at least as far as backward (its nose faces the way out), else ``forward``.
- ``extent``: the floor and the planning area, the box around the case's points grown by :data:`CASE_MARGIN`.

:class:`CasePlanner` is the reference planner (:class:`~garage_mj.scene.park_planning.ParkPlanner`: the same
search, margins, escalation and verdicts) over these obstacles instead of a garage's; a case that starts farther
than :data:`FAR_START` from its goal escalates further (:data:`CASE_PARK`). :func:`build_case_scene` is the MuJoCo
scene: a floor, each convex piece extruded to its class's height (a rectangle as a box geom, any other piece as a
convex mesh geom: walls and parked cars as bodies a car can hit), the stall outline painted, an overview camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from garage_mj.scene.car import CarGeometry
from garage_mj.scene.clearance import Obstacles, nearest_obstacle
from garage_mj.scene.layout import CLASS_RGBA
from garage_mj.scene.park_planning import (
    BACK_GAP,
    DEFAULT_PARK,
    ESCALATION,
    ParkConfig,
    ParkPlanner,
    maneuver,
    rear_to_centre,
)
from garage_mj.scene.semantics import Semantic, geom_name
from garage_mj.scene.stalls import Stall, StallLayout
from garage_mj.scene.vehicles import VehicleClass
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

CASE_MARGIN = 10.0  # [m] the floor and the planning area reach this far beyond the case's points
STALL_SIDE_GAP = 0.3  # [m] the drawn stall outline beyond each side of the vehicle (a 2.5 m bay for a 1.9 m car)
STALL_END_GAP = BACK_GAP  # [m] beyond each end: the stall pose stands BACK_GAP from the back line, as in a garage
#: [m] how high each class of obstacle is extruded.
HEIGHTS = {"wall": 2.5, "pillar": 2.5, "obstacle": 1.0, "parked_car": 1.5}
#: The semantic class each obstacle class renders and collides as.
SEMANTICS = {"wall": Semantic.WALL, "pillar": Semantic.PILLAR, "obstacle": Semantic.OBSTACLE,
             "parked_car": Semantic.PARKED_CAR}
#: A TPCAP polygon is a parked car when it is a rectangle this long and this wide [m] (else a wall).
CAR_LENGTHS, CAR_WIDTHS = (3.5, 6.0), (1.4, 2.5)
SMALL = 3.0  # [m] a TPCAP polygon less than this across (in x and in y) is an obstacle, not a wall
_EPS = 1e-9
#: The reference planner's settings for a case whose start lies more than :data:`FAR_START` from its goal:
#: :data:`~garage_mj.scene.park_planning.DEFAULT_PARK`'s, its escalation ending with two longer BIT* runs from the
#: straight exit (20,000 and 60,000 iterations). A garage's park test starts on the lane beside its stall; a case may
#: start tens of metres away round obstacles (TPCAP's cases 19 and 20), where eval/bench_tpcap.py measured the short
#: RRT-Connect restarts find no path and BIT* find one. A near case keeps DEFAULT_PARK: in a cramped scene without a
#: path BIT*'s cost grows much faster than its iterations (TPCAP's case 7: 16 CPU-s for 1,000, 176 for 4,000).
FAR_START = 15.0  # [m] rear axle to rear axle: docs/spec.md section 9's far start
CASE_PARK = ParkConfig(escalation=(*ESCALATION, ("bitstar", 20_000, "out"), ("bitstar", 60_000, "out")))


@dataclass(frozen=True)
class CaseObstacle:
    """One obstacle of a case: its class (a key of :data:`HEIGHTS`) and its outline [m], counter-clockwise."""

    cls: str
    vertices: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class ParkCase:
    """One park test from a problem file (module docstring); poses and points less ``origin``."""

    name: str  # the file's name
    source: str  # the file's path, as given
    digest: str  # sha256 of the file's bytes: the case's identity in tests.csv
    kind: str  # "tpcap" or "garage-mj"
    origin: tuple[float, float]  # [m] subtracted from every point of the file (its start point)
    vehicle: VehicleClass
    start: tuple[float, float, float]  # rear-axle midpoint (x [m], y [m], yaw [rad])
    goal: tuple[float, float, float]
    obstacles: tuple[CaseObstacle, ...]
    stall_outline: tuple[tuple[float, float], ...] | None = None  # the file's, if it has one
    maneuver: str | None = None  # the file's, if it has one


# -- polygons ----------------------------------------------------------------------------------------------------
def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def signed_area(poly) -> float:
    """[m²] of ``poly`` (positive: counter-clockwise), about its first vertex."""
    p = np.asarray(poly, dtype=float)
    r = p - p[0]
    return float((r[:, 0] * np.roll(r[:, 1], -1) - np.roll(r[:, 0], -1) * r[:, 1]).sum() / 2)


def simple_outline(poly) -> np.ndarray:
    """``poly`` counter-clockwise, without repeated vertices and without vertices on a straight line between their
    neighbours (TPCAP's case 19 has such): the same region, fewer corners. ValueError when nothing of an area is left
    or two of its edges cross."""
    p = np.asarray(poly, dtype=float).reshape(-1, 2)
    if signed_area(p) < 0:
        p = p[::-1]
    scale = max(float(np.ptp(p, axis=0).max()), 1.0)
    changed = True
    while changed and len(p) >= 3:
        changed = False
        for i in range(len(p)):
            a, b, c = p[i - 1], p[i], p[(i + 1) % len(p)]
            if np.hypot(*(b - a)) <= _EPS * scale or abs(_cross(a, b, c)) <= 1e-12 * scale * scale:
                p = np.delete(p, i, axis=0)
                changed = True
                break
    if len(p) < 3 or signed_area(p) <= 0:
        raise ValueError("the polygon has no area")
    n = len(p)
    for i in range(n):
        for j in range(i + 2, n):
            if (j + 1) % n != i and _segments_cross(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]):
                raise ValueError(f"the polygon crosses itself (its edges {i + 1} and {j + 1})")
    return p


def _segments_cross(a, b, c, d) -> bool:
    """Whether the segments ab and cd (of non-adjacent edges) touch or cross."""
    d1, d2, d3, d4 = _cross(c, d, a), _cross(c, d, b), _cross(a, b, c), _cross(a, b, d)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and 0 not in (d1, d2, d3, d4):
        return True

    def on(p, q, r) -> bool:  # r on the segment pq, given the three are collinear
        return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])

    return (d1 == 0 and on(c, d, a)) or (d2 == 0 and on(c, d, b)) or (d3 == 0 and on(a, b, c)) or \
        (d4 == 0 and on(a, b, d))


def is_convex(p: np.ndarray) -> bool:
    """Whether the counter-clockwise polygon ``p`` is convex."""
    n = len(p)
    return all(_cross(p[i - 1], p[i], p[(i + 1) % n]) >= -1e-12 for i in range(n))


def _in_triangle(q, a, b, c) -> bool:
    return _cross(a, b, q) >= -1e-12 and _cross(b, c, q) >= -1e-12 and _cross(c, a, q) >= -1e-12


def _triangles(p: np.ndarray) -> list[list[int]]:
    """Ear clipping of the counter-clockwise simple polygon ``p``: triangles as vertex indices."""
    idx = list(range(len(p)))
    out: list[list[int]] = []
    while len(idx) > 3:
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = p[i0], p[i1], p[i2]
            if _cross(a, b, c) <= 1e-12:
                continue  # a reflex corner: no ear
            if any(_in_triangle(p[j], a, b, c) for j in idx if j not in (i0, i1, i2)):
                continue
            out.append([i0, i1, i2])
            idx.pop(k)
            break
        else:
            raise ValueError("the polygon crosses itself")
    out.append(idx)
    return out


def convex_pieces(poly) -> list[np.ndarray]:
    """Convex counter-clockwise pieces whose union is the simple polygon ``poly``: itself when convex, else its ear
    triangulation with neighbouring pieces merged while the merge stays convex (Hertel and Mehlhorn's rule: at most
    four times the fewest pieces). ValueError for a polygon that crosses itself or has no area."""
    p = simple_outline(poly)
    if is_convex(p):
        return [p]
    pieces = _triangles(p)
    merged = True
    while merged:
        merged = False
        for a in range(len(pieces)):
            for b in range(len(pieces)):
                if a == b:
                    continue
                A, B = pieces[a], pieces[b]
                for i in range(len(A)):
                    u, v = A[i], A[(i + 1) % len(A)]
                    if not any(B[j] == v and B[(j + 1) % len(B)] == u for j in range(len(B))):
                        continue
                    ra = A[(i + 1):] + A[:(i + 1)]  # from v round to u
                    jb = B.index(u)
                    rb = B[jb:] + B[:jb]  # from u round to v
                    joined = ra + rb[1:-1]
                    if is_convex(p[joined]):
                        pieces[a] = joined
                        del pieces[b]
                        merged = True
                        break
                if merged:
                    break
            if merged:
                break
    return [p[piece] for piece in pieces]


def tpcap_class(poly) -> str:
    """``parked_car`` for a rectangle of a car's size (:data:`CAR_LENGTHS` x :data:`CAR_WIDTHS`), ``obstacle`` for
    anything smaller than :data:`SMALL` across (TPCAP's clutter), else ``wall``: a TPCAP case gives no classes."""
    try:
        p = simple_outline(poly)
    except ValueError:
        return "wall"
    if float(np.ptp(p, axis=0).max()) < SMALL:
        return "obstacle"
    if len(p) != 4 or not is_convex(p):
        return "wall"
    e = np.roll(p, -1, axis=0) - p
    sides = np.hypot(e[:, 0], e[:, 1])
    square = all(abs(float(np.dot(e[i], e[(i + 1) % 4]))) <= 0.05 * sides[i] * sides[(i + 1) % 4] for i in range(4))
    long, short = max(sides[0], sides[1]), min(sides[0], sides[1])
    fits = CAR_LENGTHS[0] <= long <= CAR_LENGTHS[1] and CAR_WIDTHS[0] <= short <= CAR_WIDTHS[1]
    return "parked_car" if square and fits else "wall"


# -- the scene of a case -------------------------------------------------------------------------------------------
def _stall(x: float, y: float, yaw: float, length: float, width: float) -> Stall:
    return Stall(id=0, block=(0, 0), x=float(x), y=float(y), yaw=float(yaw), side=0, road_cell=(0, 0),
                 road_x=float(x), road_y=float(y), obstructed=False, length=float(length), width=float(width))


@dataclass
class CaseScene:
    """A :class:`ParkCase` as the simulator and the planner see it (module docstring), built once."""

    case: ParkCase
    car: CarGeometry = field(init=False)

    def __post_init__(self) -> None:
        self.car = self.case.vehicle.geometry()

    @property
    def name(self) -> str:
        return self.case.name

    @property
    def world(self) -> WorldConfig:
        """The 3D conventions the case is drawn and judged with: the defaults (docs/spec.md section 6; its painted
        lines are :data:`~garage_mj.scene.world.DEFAULT_WORLD`'s)."""
        return DEFAULT_WORLD

    @cached_property
    def obstacles(self) -> Obstacles:
        """Every obstacle of the case as convex pieces, each with its obstacle's class (stall id -1)."""
        pieces, classes = [], []
        for o in self.case.obstacles:
            for piece in convex_pieces(o.vertices):
                pieces.append(piece)
                classes.append(o.cls)
        if not pieces:
            return Obstacles(np.zeros((0, 4)), [], np.zeros(0, dtype=int))
        return Obstacles.from_polygons(pieces, classes)

    @cached_property
    def extent(self) -> tuple[float, float, float, float]:
        """[m] (xmin, ymin, xmax, ymax): the floor and the planning area."""
        pts = [self.case.start[:2], self.case.goal[:2], *(v for o in self.case.obstacles for v in o.vertices)]
        a = np.asarray(pts, dtype=float)
        lo, hi = a.min(axis=0) - CASE_MARGIN, a.max(axis=0) + CASE_MARGIN
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    @cached_property
    def maneuver(self) -> str:
        """``reverse`` or ``forward``: the file's, else by the way out of the goal (module docstring)."""
        if self.case.maneuver is not None:
            return self.case.maneuver
        ahead, behind = (self._free_run(gear) for gear in (1, -1))
        return "reverse" if ahead >= behind else "forward"

    def _free_run(self, gear: int, step: float = 0.1) -> float:
        """[m] how far the car drives straight from the goal in ``gear`` before it comes within the planner's margin
        of an obstacle (at most one car length and a metre)."""
        x, y, yaw = self.case.goal
        reach = self.car.front - self.car.rear + 1.0
        s = np.arange(0.0, reach + step / 2, step)
        rear = np.column_stack([x + gear * s * math.cos(yaw), y + gear * s * math.sin(yaw)])
        dist, _ = nearest_obstacle(self.obstacles, self.car, rear, np.full(len(s), yaw))
        bad = np.flatnonzero(dist < DEFAULT_PARK.margin)
        return float(s[bad[0]]) if len(bad) else float(reach)

    @cached_property
    def stall(self) -> Stall:
        """The target stall: its pose the goal (module docstring)."""
        m = maneuver(self.maneuver)
        cx, cy, heading = (float(v) for v in rear_to_centre(self.case.goal, self.car))
        yaw = heading - m.turn  # the stall opens towards the aisle: the car's heading less the maneuver's turn
        outline = self.case.stall_outline
        if outline is None:
            return _stall(cx, cy, yaw, self.car.front - self.car.rear + 2 * STALL_END_GAP,
                          2 * self.car.half_width + 2 * STALL_SIDE_GAP)
        p = np.asarray(outline, dtype=float)
        u = np.array([math.cos(yaw), math.sin(yaw)])
        along, across = p @ u, p @ np.array([-u[1], u[0]])
        mid = p.mean(axis=0)
        return _stall(mid[0], mid[1], yaw, float(np.ptp(along)), float(np.ptp(across)))

    @property
    def stalls(self) -> StallLayout:
        """The case's one stall (id 0), as a garage's stall layout holds its stalls."""
        return StallLayout((self.stall,), ())

    @property
    def start_centre(self) -> tuple[float, float, float]:
        """The start pose of the car's centre (the drive env's ``Car.pose``)."""
        return tuple(float(v) for v in rear_to_centre(self.case.start, self.car))

    @property
    def park_config(self) -> ParkConfig:
        """The reference planner's settings for this case: :data:`CASE_PARK` for a start farther than
        :data:`FAR_START` from the goal, else :data:`~garage_mj.scene.park_planning.DEFAULT_PARK`."""
        far = math.dist(self.case.start[:2], self.case.goal[:2]) > FAR_START
        return CASE_PARK if far else DEFAULT_PARK

    def planner(self, config: ParkConfig | None = None) -> CasePlanner:
        """The reference planner of this case (``config``: default :attr:`park_config`)."""
        return CasePlanner(self, config)


class CasePlanner(ParkPlanner):
    """The reference park planner (:class:`~garage_mj.scene.park_planning.ParkPlanner`) of one case: its obstacles,
    its stall (id 0) and its extent instead of a garage's. ``plan(start, 0, scene.maneuver)`` plans it."""

    def __init__(self, scene: CaseScene, config: ParkConfig | None = None) -> None:
        self.scene = scene  # what ParkPlanner reads of a scene: .stalls.stalls
        self.car = scene.car
        self.config = config = scene.park_config if config is None else config
        self._obstacles = scene.obstacles
        self.extent = scene.extent
        far = max(self.car.front - self.car.rear_axle, self.car.rear_axle - self.car.rear)
        self.reach = math.hypot(far, self.car.half_width) + config.margin

    def plan_case(self):
        """The reference plan of the case: from its start into its stall with its maneuver."""
        return self.plan(self.scene.start_centre, 0, self.scene.maneuver, obstacles=self.obstacles())


# -- MuJoCo --------------------------------------------------------------------------------------------------------
def _rectangle(p: np.ndarray) -> tuple[tuple[float, float], tuple[float, float], float] | None:
    """``((cx, cy), (half x, half y), yaw)`` of the convex piece ``p`` when it is a rectangle (to a micrometre), else
    None."""
    if len(p) != 4:
        return None
    e = np.roll(p, -1, axis=0) - p
    if np.abs(e[0] + e[2]).max() > 1e-6 or np.abs(e[1] + e[3]).max() > 1e-6 or abs(float(e[0] @ e[1])) > 1e-6:
        return None
    c = p.mean(axis=0)
    return (float(c[0]), float(c[1])), (float(np.hypot(*e[0])) / 2, float(np.hypot(*e[1])) / 2), \
        float(math.atan2(e[0][1], e[0][0]))


def build_case_scene(scene: CaseScene):
    """The MuJoCo scene of a case (module docstring) as a ``dm_control.mjcf.RootElement`` (no car: attach one)."""
    from dm_control import mjcf

    from garage_mj.scene.mjcf_scene import TIMESTEP

    x0, y0, x1, y1 = scene.extent
    root = mjcf.RootElement(model=f"case_{''.join(c if c.isalnum() else '_' for c in scene.name)[:40]}")
    root.compiler.angle = "radian"
    root.option.timestep = TIMESTEP
    root.option.integrator = "implicitfast"
    glob = getattr(root.visual, "global")
    glob.offwidth, glob.offheight = 1280, 960
    root.visual.quality.shadowsize = 0
    root.visual.map.znear = 0.002
    solid = root.default.add("default", dclass="structure")
    solid.geom.set_attributes(contype=1, conaffinity=1, group=0, friction=[0.9, 0.005, 0.0001])
    paint = root.default.add("default", dclass="marking")
    paint.geom.set_attributes(type="box", contype=0, conaffinity=0, group=2, mass=0)
    wb = root.worldbody
    wb.add("light", name="sun", type="directional", pos=[(x0 + x1) / 2, (y0 + y1) / 2, 30], dir=[0.2, 0.3, -1],
           diffuse=[0.6, 0.6, 0.6], castshadow=False)
    wb.add("geom", name="floor", dclass="structure", type="box", pos=[(x0 + x1) / 2, (y0 + y1) / 2, -0.05],
           size=[(x1 - x0) / 2, (y1 - y0) / 2, 0.05], rgba=list(CLASS_RGBA[Semantic.FLOOR]))
    extent = max(x1 - x0, y1 - y0) * 1.05
    wb.add("camera", name="overview", pos=[(x0 + x1) / 2, (y0 + y1) / 2, 40.0], projection="orthographic",
           fovy=min(extent, 179.0))
    for o_id, o in enumerate(scene.case.obstacles):
        sem, h = SEMANTICS[o.cls], HEIGHTS[o.cls]
        for j, piece in enumerate(convex_pieces(o.vertices)):
            name, rgba = geom_name(sem, o_id, j), list(CLASS_RGBA[sem])
            box = _rectangle(piece)
            if box is not None:  # a box geom: exact for MuJoCo and for whatever reads geoms back as boxes
                (cx, cy), (hx, hy), yaw = box
                wb.add("geom", name=name, dclass="structure", type="box", pos=[cx, cy, h / 2], size=[hx, hy, h / 2],
                       euler=[0, 0, yaw], rgba=rgba)
                continue
            vertex = np.concatenate([np.column_stack([piece, np.zeros(len(piece))]),
                                     np.column_stack([piece, np.full(len(piece), h)])])
            root.asset.add("mesh", name=name, vertex=vertex.ravel())
            wb.add("geom", name=name, dclass="structure", type="mesh", mesh=name, rgba=rgba)
    corners = scene.stall.corners
    for i in range(4):
        a, b = np.asarray(corners[i]), np.asarray(corners[(i + 1) % 4])
        mid, d = (a + b) / 2, b - a
        wb.add("geom", name=geom_name(Semantic.STALL_MARKING, "target", i), dclass="marking",
               pos=[mid[0], mid[1], 0.001], size=[np.hypot(*d) / 2, scene.world.marking_width / 2, 0.001],
               euler=[0, 0, math.atan2(d[1], d[0])], rgba=list(CLASS_RGBA[Semantic.STALL_MARKING]))
    return root


__all__ = ["CASE_MARGIN", "CASE_PARK", "FAR_START", "HEIGHTS", "STALL_END_GAP", "STALL_SIDE_GAP", "CaseObstacle",
           "CasePlanner", "CaseScene",
           "ParkCase", "build_case_scene", "convex_pieces", "tpcap_class"]
