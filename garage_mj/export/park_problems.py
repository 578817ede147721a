"""Park problems as files: each park test's start pose, stall pose and obstacles, for any parking planner.

``garage-mj export --park-problems DIR`` (:func:`write_park_problems`) writes one problem per park test
(SPEC 8): per garage, per stall whose cruise test is feasible (the cruise goal, on the lane beside the
stall, is where the park test starts) and per maneuver (``reverse``: reverse-in, ``forward``: nose-in):

- ``DIR/<garage>/stall<NNN>_<maneuver>.json``: the problem (schema below); :func:`read_park_problem`
  reads it back, and refuses a malformed file in one line (:class:`ParkProblemError`).
- ``DIR/<garage>/stall<NNN>_<maneuver>.csv``: the same problem as a case of the TPCAP benchmark (the
  Trajectory Planning Competition for Automated Parking, Tsinghua; its ``CaseX.csv`` files), in its
  layout exactly: an N-row, one-column vector V, one number per line. V[1..3] = x0, y0, theta0, the
  start pose; V[4..6] = xf, yf, thetaf, the goal pose (both of the rear-axle midpoint, yaw in
  radians); V[7] = the number of obstacles; V[7 + i] = the number of vertices of obstacle i; then
  the vertices of each obstacle in turn, x and y alternating (x11, y11, x12, y12, ..., x21, y21, ...).
  :func:`read_tpcap_case` reads one.
- ``DIR/park_problems.json``: the index of this export: every problem's two files, and the stalls
  left out (no feasible cruise test, so no start pose) with the reason.

``<garage>`` is the garage's asset pack folder name (its name and 12 hex digits of its hash).

The obstacles are those of the reference planner (:mod:`garage_mj.scene.park_planning`) within reach
of its planning area: walls, obstacle blocks, pillars, and a parked car in every other stall (the
outline of the stall, which a parked car lies inside: the worst case of any occupancy), each an
axis-aligned rectangle written as its four corners, counter-clockwise. The target stall is empty.

JSON schema (``format`` ``"garage-mj park problem"``, ``version`` 1; lengths in metres, angles in radians)::

    garage, garage_hash        the garage's name and canonical hash (Garage.canonical_hash)
    stall, maneuver            the stall id and "reverse" or "forward"
    start, goal                [x, y, yaw] of the rear-axle midpoint (TPCAP's reference point)
    start_centre, goal_centre  [x, y, yaw] of the car's centre (the drive env's Car.pose)
    stall_outline              the stall's four corners [[x, y], ...], counter-clockwise
    region                     [xmin, ymin, xmax, ymax]: the planning area of the rear axle
    car                        wheelbase, length, width, front_overhang, rear_overhang (from the
                               axles), max_steer [rad], min_turning_radius (rear axle, full lock)
    planner                    the reference planner's margin and turning radius (with its margin)
    obstacles                  [{"class": "wall" | "obstacle" | "pillar" | "parked_car",
                                 "vertices": [[x, y], ...]}, ...]
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write, ensure_dir, write_json
from garage_mj.export.pack import pack_name
from garage_mj.grid.garage import Garage
from garage_mj.scene.car import CarGeometry, car_geometry
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import (
    DEFAULT_PARK,
    MANEUVERS,
    ParkConfig,
    ParkPlanner,
    centre_to_rear,
    park_obstacles,
    park_pose,
)

FORMAT = "garage-mj park problem"
VERSION = 1
INDEX = "park_problems.json"
_POSE = ("x", "y", "yaw")


class ParkProblemError(GarageMJError):
    """A park problem file that cannot be read; the message names the file and what is wrong."""


@dataclass(frozen=True)
class ParkProblem:
    """One park test as a planning problem (the JSON schema of the module docstring)."""

    garage: str
    garage_hash: str
    stall: int
    maneuver: str
    start: tuple[float, float, float]  # rear-axle midpoint
    goal: tuple[float, float, float]
    start_centre: tuple[float, float, float]  # car centre
    goal_centre: tuple[float, float, float]
    stall_outline: tuple[tuple[float, float], ...]
    region: tuple[float, float, float, float]
    car: dict[str, float]
    planner: dict[str, float]
    obstacles: tuple[tuple[str, tuple[tuple[float, float], ...]], ...]  # (class, vertices)

    @property
    def name(self) -> str:
        """File stem of the problem: ``stall<NNN>_<maneuver>``."""
        return f"stall{self.stall:03d}_{self.maneuver}"

    def to_json(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, "garage": self.garage, "garage_hash": self.garage_hash,
                "stall": self.stall, "maneuver": self.maneuver, "start": list(self.start), "goal": list(self.goal),
                "start_centre": list(self.start_centre), "goal_centre": list(self.goal_centre),
                "stall_outline": [list(p) for p in self.stall_outline], "region": list(self.region),
                "car": dict(self.car), "planner": dict(self.planner),
                "obstacles": [{"class": c, "vertices": [list(v) for v in vs]} for c, vs in self.obstacles]}

    def tpcap(self) -> str:
        """The problem as a TPCAP case file: one number per line (module docstring)."""
        values: list[float] = [*self.start, *self.goal, len(self.obstacles)]
        values += [len(vs) for _, vs in self.obstacles]
        values += [c for _, vs in self.obstacles for v in vs for c in v]
        return "".join(f"{_num(v)}\n" for v in values)


def _num(v: float) -> str:
    """A number as TPCAP's files spell it: integers plain, floats to the last bit (repr)."""
    return str(int(v)) if isinstance(v, int) else repr(float(v))


def _car(car: CarGeometry) -> dict[str, float]:
    return {"wheelbase": car.wheelbase, "length": car.front - car.rear, "width": 2 * car.half_width,
            "front_overhang": car.front - (car.rear_axle + car.wheelbase), "rear_overhang": car.rear_axle - car.rear,
            "max_steer": car.max_steer, "min_turning_radius": car.min_radius}


def park_problems(scene: GarageScene, car: CarGeometry | None = None, config: ParkConfig = DEFAULT_PARK
                  ) -> tuple[list[ParkProblem], dict[int, str]]:
    """Every park test of ``scene`` as a :class:`ParkProblem`, and the stalls left out with the reason."""
    car = car or car_geometry()
    planner, cruise = ParkPlanner(scene, car, config), drive_planner(scene, car)
    problems, skipped = [], {}
    for stall in scene.stalls.stalls:
        test = cruise.plan(stall.id)
        if not test.feasible:
            skipped[stall.id] = f"no feasible cruise test to the stall, so no start pose: {test.reason}"
            continue
        obs = park_obstacles(planner.obstacles(), stall.id)
        for name in MANEUVERS:
            region = planner.area(test.goal, stall.id, name)
            near = planner.near(obs, region)
            goal = park_pose(stall, car, name)
            problems.append(ParkProblem(
                garage=scene.name, garage_hash=scene.garage.canonical_hash(), stall=stall.id, maneuver=name,
                start=_pose(centre_to_rear(test.goal, car)), goal=_pose(centre_to_rear(goal, car)),
                start_centre=_pose(test.goal), goal_centre=_pose(goal),
                stall_outline=tuple((float(x), float(y)) for x, y in stall.corners),
                region=tuple(float(v) for v in region), car=_car(car),
                planner={"margin": config.margin, "turning_radius": planner.radius},
                obstacles=tuple((c, _corners(b)) for c, b in zip(near.classes, near.boxes.tolist(), strict=True))))
    return problems, skipped


def _pose(p) -> tuple[float, float, float]:
    return float(p[0]), float(p[1]), float(p[2])


def _corners(box: list[float]) -> tuple[tuple[float, float], ...]:
    x0, y0, x1, y1 = box
    return (x0, y0), (x1, y0), (x1, y1), (x0, y1)


def write_park_problems(garages: Iterable[Garage | GarageScene], out_dir: str | Path, car: CarGeometry | None = None,
                        config: ParkConfig = DEFAULT_PARK) -> Path:
    """Write every park test of ``garages`` under ``out_dir`` (module docstring); returns the index file."""
    out_dir = ensure_dir(out_dir)
    entries, left_out = [], []
    for item in garages:
        scene = item if isinstance(item, GarageScene) else GarageScene(item)
        folder = ensure_dir(out_dir / pack_name(scene.garage))
        problems, skipped = park_problems(scene, car, config)
        for p in problems:
            write_json(folder / f"{p.name}.json", p.to_json())
            atomic_write(folder / f"{p.name}.csv", p.tpcap())
            entries.append({"garage": p.garage, "stall": p.stall, "maneuver": p.maneuver,
                            "json": f"{folder.name}/{p.name}.json", "csv": f"{folder.name}/{p.name}.csv"})
        left_out += [{"garage": scene.name, "folder": folder.name, "stall": s, "reason": r} for s, r in skipped.items()]
    return write_json(out_dir / INDEX, {"format": "garage-mj park problems", "version": VERSION,
                                        "problems": entries, "skipped": left_out})


# -- reading ------------------------------------------------------------------------------------------
def read_park_problem(path: str | Path) -> ParkProblem:
    """The :class:`ParkProblem` in a JSON file written by :func:`write_park_problems`; ParkProblemError otherwise."""
    path = Path(path)
    try:
        data = json.loads(path.read_bytes())
    except OSError as exc:
        raise ParkProblemError(f"cannot read park problem {path}: {exc.strerror or exc}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise ParkProblemError(f"park problem {path} is not JSON ({exc}); write it again with "
                               "garage-mj export --park-problems") from None
    try:
        return _problem(data)
    except (KeyError, TypeError, ValueError) as exc:
        why = f"no {exc.args[0]!r} key" if isinstance(exc, KeyError) else str(exc)
        raise ParkProblemError(f"park problem {path} is malformed: {why}; write it again with "
                               "garage-mj export --park-problems") from None


def _problem(data: Any) -> ParkProblem:
    if not isinstance(data, dict):
        raise TypeError("the file holds no JSON object")
    if data.get("format") != FORMAT or data.get("version") != VERSION:
        raise ValueError(f"format {data.get('format')!r} version {data.get('version')!r}, "
                         f"not {FORMAT!r} version {VERSION}")
    if data["maneuver"] not in MANEUVERS:
        raise ValueError(f"maneuver {data['maneuver']!r} is not one of {', '.join(MANEUVERS)}")
    if not isinstance(data["stall"], int) or isinstance(data["stall"], bool) or data["stall"] < 0:
        raise ValueError(f"stall {data['stall']!r} is not a stall id")
    for key in ("garage", "garage_hash"):
        if not isinstance(data[key], str):
            raise TypeError(f"{key} is not a string")
    obstacles = data["obstacles"]
    if not isinstance(obstacles, list) or not all(isinstance(o, dict) for o in obstacles):
        raise TypeError("obstacles is not a list of objects")
    return ParkProblem(
        garage=data["garage"], garage_hash=data["garage_hash"], stall=data["stall"], maneuver=data["maneuver"],
        start=_numbers(data, "start", 3), goal=_numbers(data, "goal", 3),
        start_centre=_numbers(data, "start_centre", 3), goal_centre=_numbers(data, "goal_centre", 3),
        stall_outline=_polygon(data["stall_outline"], "stall_outline"), region=_numbers(data, "region", 4),
        car=_table(data, "car"), planner=_table(data, "planner"),
        obstacles=tuple((_name(o["class"], k), _polygon(o["vertices"], f"obstacle {k}"))
                        for k, o in enumerate(obstacles)))


def _finite(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{what} holds {v!r}, not a finite number")
    return float(v)


def _numbers(data: dict, key: str, n: int) -> tuple[float, ...]:
    v = data[key]
    if not isinstance(v, list) or len(v) != n:
        raise ValueError(f"{key} is not a list of {n} numbers")
    return tuple(_finite(x, key) for x in v)


def _polygon(v: Any, what: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(v, list) or len(v) < 3 or not all(isinstance(p, list) and len(p) == 2 for p in v):
        raise ValueError(f"{what} is not a list of at least 3 [x, y] vertices")
    return tuple((_finite(p[0], what), _finite(p[1], what)) for p in v)


def _table(data: dict, key: str) -> dict[str, float]:
    v = data[key]
    if not isinstance(v, dict):
        raise TypeError(f"{key} is not an object")
    return {str(k): _finite(x, f"{key}.{k}") for k, x in v.items()}


def _name(v: Any, k: int) -> str:
    if not isinstance(v, str):
        raise TypeError(f"the class of obstacle {k} is not a string")
    return v


def read_tpcap_case(path: str | Path) -> tuple[tuple[float, ...], tuple[float, ...], list[list[tuple[float, float]]]]:
    """A TPCAP case file: start pose, goal pose (rear-axle midpoint) and obstacle polygons; ParkProblemError
    when it is not one."""
    path = Path(path)
    try:
        v = [float(line) for line in path.read_text().split()]
    except OSError as exc:
        raise ParkProblemError(f"cannot read TPCAP case {path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise ParkProblemError(f"TPCAP case {path} holds a line that is not a number ({exc})") from None
    if len(v) < 7 or v[6] != int(v[6]) or v[6] < 0:
        raise ParkProblemError(f"TPCAP case {path} is too short or its obstacle count V[7] is not a count")
    n = int(v[6])
    counts = v[7:7 + n]
    if len(counts) < n or any(c != int(c) or c < 3 for c in counts) or len(v) != 7 + n + 2 * int(sum(counts)):
        raise ParkProblemError(f"TPCAP case {path} does not hold the vertices its counts announce")
    polys, at = [], 7 + n
    for c in map(int, counts):
        polys.append([(v[at + 2 * j], v[at + 2 * j + 1]) for j in range(c)])
        at += 2 * c
    return tuple(v[0:3]), tuple(v[3:6]), polys
