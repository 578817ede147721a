"""Park problems as files: each park test's start pose, stall pose and obstacles, for any parking planner.

``garage-mj export --park-problems DIR`` (:func:`write_park_problems`) writes one problem per park test
(SPEC 8): per garage, per stall whose cruise test is feasible (the cruise goal, on the lane beside the
stall, is where the park test starts) and per maneuver (``reverse``: reverse-in, ``forward``: nose-in):

- ``DIR/<garage>/stall<NNN>_<maneuver>.json``: the problem (schema below); :func:`read_park_problem`
  reads it back, and refuses a malformed file in one line (:class:`ParkProblemError`).
- ``DIR/<garage>/stall<NNN>_<maneuver>.csv``: the same problem as a case of the TPCAP benchmark (the
  Trajectory Planning Competition for Automated Parking; its ``Case1.csv`` ... ``Case20.csv``), laid out
  as TPCAP publishes them: one line of comma-separated numbers V, ended by CRLF, no header, no spaces.
  V[1..3] = x0, y0, theta0, the start pose; V[4..6] = xf, yf, thetaf, the goal pose (both of the
  rear-axle midpoint, yaw in radians); V[7] = n, the number of obstacles; V[7 + i] = the number of
  vertices of obstacle i (i = 1..n); then the vertices of each obstacle in turn, x and y alternating
  (x11, y11, x12, y12, ..., x21, y21, ...). TPCAP's own readers take it: its MATLAB demo
  (``readmatrix``, then V(1), V(2), ...) and its Python one (``csv.reader``, the first row's fields as
  floats). Integers are written plain and every other number to its last bit (Python's ``repr``).
  The format has no place for the vehicle: the car of these cases is the one in the JSON beside each
  (``car``) and in the index (TPCAP's own cases are for :data:`TPCAP_CAR`). :func:`read_tpcap_case`
  reads a case: this layout, and also one number per line (the column vector V, which ``readmatrix``
  reads the same; park problem folders holding that layout read as they are).
- ``DIR/park_problems.json``: the index of this export: the car of every problem (``car``, the keys of
  the JSON's), every problem's two files, and the stalls left out (no feasible cruise test, so no start
  pose) with the reason.

``<garage>`` is the garage's asset pack folder name (its name and 12 hex digits of its hash). The export
holds the lock of ``DIR`` (:class:`~garage_mj.core.fsutil.FolderLock`), so a second export into it meanwhile
stops in one line; a folder it cannot write is named in one line before anything is written.

The obstacles are those of the reference planner (:mod:`garage_mj.scene.park_planning`) within reach
of its planning area: walls, obstacle blocks, pillars, and a parked car in every stall except the target one
(every stall is occupied but the one to park in: the worst case of any occupancy), each written as its corners, counter-clockwise: a parked car is its body as a park test
plans around it (``models/parked_car``, 4.3 x 1.9 m, centred and square in its stall: the default fleet of
:mod:`garage_mj.scene.parked_fleet`), never the whole stall outline. The target stall is empty.

JSON schema (``format`` ``"garage-mj park problem"``, ``version`` 3; lengths in metres, angles in radians; the
world frame: x east, y north, z up, yaw counter-clockwise from +x; the machine-readable schema is
``park_problem.schema.json`` beside this module, documented in docs/park-problems.md)::

    garage, garage_hash        the garage's name and canonical hash (Garage.canonical_hash)
    garage_grid, six_stall_axis  the garage's block codes, one string of digits per row, and its six-stall
                               axis: what garage_hash is the hash of, so a reader can check it
    stall, maneuver            the stall id and "reverse" or "forward"
    start, goal                [x, y, yaw] of the rear-axle midpoint (TPCAP's reference point); every yaw
                               is written in [-pi, pi) (read: any finite yaw, wrapped into it)
    start_centre, goal_centre  [x, y, yaw] of the car's centre (the drive env's Car.pose)
    stall_outline              the stall's four corners [[x, y], ...], counter-clockwise
    region                     [xmin, ymin, xmax, ymax]: the planning area of the rear axle
    car                        wheelbase, length, width, front_overhang, rear_overhang (from the
                               axles), max_steer [rad], min_turning_radius (rear axle, full lock)
    planner                    the reference planner's margin and turning radius (with its margin)
    obstacles                  [{"class": "wall" | "obstacle" | "pillar" | "parked_car",
                                 "vertices": [[x, y], ...]}, ...]
    geometry                   the park geometry the garage was built in (docs/spec.md section 9):
                               stall_width, stall_depth, aisle_width [m], stall_angle [deg], slot_length
                               [m]; optional, a file without it was built in the defaults
    reference                  the reference planner's plan of this problem (version 3; a version 2 file, still
                               read, has none): found, verdict, reason, length [m of rear-axle path], cusps,
                               min_clearance [m], method, attempt, spacing [m], poses ([x, y, yaw] of the
                               rear axle every `spacing` metres of path, cusps and both ends kept), directions
                               (+1 forward / -1 reverse from each pose to the next), settings (the planner's)
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import stat
from collections.abc import Collection, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError, control_character
from garage_mj.core.fsutil import FolderLock, atomic_write, clean_temp
from garage_mj.core.words import a_noun
from garage_mj.export.pack import pack_name
from garage_mj.grid.blocks import AXES, STALL_TABLE
from garage_mj.grid.garage import MAX_NAME, MAX_SIDE, Garage, grid_hash
from garage_mj.scene.car import CarGeometry, car_geometry
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import (
    DEFAULT_PARK,
    MANEUVERS,
    VERDICTS,
    ParkConfig,
    ParkPlan,
    ParkPlanner,
    centre_to_rear,
    park_pose,
)
from garage_mj.scene.parked_fleet import ParkedFleet, body_obstacles, draw_parked
from garage_mj.scene.world import DEFAULT_WORLD, GeometryError, geometry, world_with

FORMAT = "garage-mj park problem"
VERSION = 3  # 2: the garage's grid and six-stall axis, so that garage_hash can be checked; 3: the reference plan
VERSIONS = (2, 3)  # read: a version 2 file has no reference plan
INDEX = "park_problems.json"
#: The JSON Schema (draft 2020-12) of a problem file, shipped beside this module (docs/park-problems.md).
SCHEMA = Path(__file__).with_name("park_problem.schema.json")
_POSE = ("x", "y", "yaw")
#: The keys of a problem file, each required; any other key is refused.
KEYS = ("format", "version", "garage", "garage_hash", "garage_grid", "six_stall_axis", "stall", "maneuver", "start",
        "goal", "start_centre", "goal_centre", "stall_outline", "region", "car", "planner", "obstacles")
#: Keys a problem file may hold: ``geometry``, the park geometry it was built in (docs/spec.md section 9; a file
#: without it was built in the defaults).
OPTIONAL_KEYS = ("geometry",)
CAR_KEYS = ("wheelbase", "length", "width", "front_overhang", "rear_overhang", "max_steer", "min_turning_radius")
PLANNER_KEYS = ("margin", "turning_radius")
CLASSES = ("wall", "obstacle", "pillar", "parked_car")
REFERENCE_SPACING = 0.5  # [m] of rear-axle path between two poses of the reference plan (cusps and ends always kept)
#: The keys of ``reference`` (version 3), each required.
REFERENCE_KEYS = ("found", "verdict", "reason", "length", "cusps", "min_clearance", "method", "attempt", "spacing",
                  "poses", "directions", "settings")
#: The keys of ``reference.settings``: the reference planner's :class:`ParkConfig` and its turning radius.
SETTINGS_KEYS = ("planner", "iterations", "seed", "step", "region", "margin", "curvature_margin", "turning_radius")
MAX_BYTES = 16 << 20  # [bytes] of a file read: far above any problem (a 64x64 garage's is some 100 kB)
MAX_COORD = 10_000.0  # [m] |x| and |y| of any point: a garage is at most 576 m across
MAX_CAR = 100.0  # [m] any length of the car
#: [rad] |yaw| of a pose a reader takes (then wraps into [-pi, pi)): any yaw a writer means, and small enough that
#: wrapping it keeps it to 1e-9 rad (a float64 near 1e6 resolves 1.2e-10).
MAX_YAW = 1e6
_FIX = "write it again with garage-mj export --park-problems"
#: The vehicle of TPCAP's own cases [m] (its demos' ``InitializeParams``): a case file has no place for it.
TPCAP_CAR = {"wheelbase": 2.8, "front_overhang": 0.96, "rear_overhang": 0.929, "width": 1.942}
#: [m] |x| and |y| of a point of a TPCAP case. Cases of TPCAP's set lie some 10^10 m from the origin (Case15's
#: x is 7.0e9), where a float64 still resolves 2e-6 m; :data:`MAX_COORD` bounds a case's span instead
#: (every point within it of the start). Subtract the start before float32 tools see a case.
MAX_CASE_COORD = 1e11


class ParkProblemError(GarageMJError):
    """A park problem file that cannot be read, or a park problems folder that cannot be written; the
    message names the file or folder, what is wrong and the fix."""


@dataclass(frozen=True)
class ParkProblem:
    """One park test as a planning problem (the JSON schema of the module docstring)."""

    garage: str
    garage_hash: str
    garage_grid: tuple[str, ...]  # block codes, one string of digits per row
    six_stall_axis: str
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
    geometry: dict[str, float] = dataclass_field(default_factory=lambda: geometry(DEFAULT_WORLD))  # the park geometry
    reference: dict[str, Any] | None = None  # the reference plan (version 3; None: a version 2 file)

    @property
    def name(self) -> str:
        """File stem of the problem: ``stall<NNN>_<maneuver>``."""
        return f"stall{self.stall:03d}_{self.maneuver}"

    def to_json(self) -> dict[str, Any]:
        out = {"format": FORMAT, "version": VERSION if self.reference is not None else 2, "garage": self.garage, "garage_hash": self.garage_hash,
                "garage_grid": list(self.garage_grid), "six_stall_axis": self.six_stall_axis, "stall": self.stall, "maneuver": self.maneuver, "start": list(self.start), "goal": list(self.goal),
                "start_centre": list(self.start_centre), "goal_centre": list(self.goal_centre),
                "stall_outline": [list(p) for p in self.stall_outline], "region": list(self.region),
                "car": dict(self.car), "planner": dict(self.planner),
                "obstacles": [{"class": c, "vertices": [list(v) for v in vs]} for c, vs in self.obstacles],
                "geometry": dict(self.geometry)}
        if self.reference is not None:
            out["reference"] = self.reference
        return out

    def tpcap(self) -> str:
        """The problem as a TPCAP case file: one line of comma-separated numbers ended by CRLF, as TPCAP's
        ``CaseN.csv`` (module docstring)."""
        values: list[float] = [*self.start, *self.goal, len(self.obstacles)]
        values += [len(vs) for _, vs in self.obstacles]
        values += [c for _, vs in self.obstacles for v in vs for c in v]
        return ",".join(_num(v) for v in values) + "\r\n"


def _num(v: float) -> str:
    """A number as TPCAP's files spell it: integers plain, floats to the last bit (repr)."""
    return str(int(v)) if isinstance(v, int) else repr(float(v))


def _car(car: CarGeometry) -> dict[str, float]:
    return {"wheelbase": car.wheelbase, "length": car.front - car.rear, "width": 2 * car.half_width,
            "front_overhang": car.front - (car.rear_axle + car.wheelbase), "rear_overhang": car.rear_axle - car.rear,
            "max_steer": car.max_steer, "min_turning_radius": car.min_radius}


def park_problems(scene: GarageScene, car: CarGeometry | None = None, config: ParkConfig = DEFAULT_PARK,
                  stalls: Collection[int] | None = None, maneuvers: Sequence[str] = MANEUVERS
                  ) -> tuple[list[ParkProblem], dict[int, str]]:
    """Every park test of ``scene`` as a :class:`ParkProblem` (only those of ``stalls`` and ``maneuvers`` when
    given), and the stalls left out with the reason."""
    check_problem_choice([scene], stalls, maneuvers)
    car = car or car_geometry()
    planner, cruise = ParkPlanner(scene, car, config), drive_planner(scene, car)
    problems, skipped = [], {}
    garage = scene.garage
    rows = tuple("".join(str(int(v)) for v in row) for row in garage.grid)
    every = scene.stalls.stalls
    parked = draw_parked(every, [s.id for s in every], None, ParkedFleet(), None, scene.world.marking_width)
    chosen = [s for s in every if stalls is None or s.id in stalls]
    for stall in chosen:
        test = cruise.plan(stall.id)
        if not test.feasible:
            skipped[stall.id] = f"no feasible cruise test to the stall, so no start pose: {test.reason}"
            continue
        obs = body_obstacles(planner.obstacles(), stall.id, parked)
        for name in maneuvers:
            region = planner.area(test.goal, stall.id, name)
            near = planner.near(obs, region)
            goal = park_pose(stall, car, name)
            plan = planner.plan(test.goal, stall.id, name, obstacles=obs)
            problems.append(ParkProblem(
                garage=scene.name, garage_hash=garage.canonical_hash(), garage_grid=rows,
                six_stall_axis=garage.six_stall_axis, stall=stall.id, maneuver=name,
                start=_pose(centre_to_rear(test.goal, car)), goal=_pose(centre_to_rear(goal, car)),
                start_centre=_pose(test.goal), goal_centre=_pose(goal),
                stall_outline=tuple((float(x), float(y)) for x, y in stall.corners),
                region=tuple(float(v) for v in region), car=_car(car),
                planner={"margin": config.margin, "turning_radius": planner.radius},
                obstacles=tuple((c, _corners(o)) for c, o in zip(near.classes, near.outlines, strict=True)),
                geometry=geometry(scene.world), reference=reference_plan(plan, planner)))
    return problems, skipped


def reference_plan(plan: ParkPlan, planner: ParkPlanner, spacing: float = REFERENCE_SPACING) -> dict[str, Any]:
    """The ``reference`` object of a problem file: the reference planner's verdict on the problem and, when it found
    a plan, the rear-axle path subsampled every ``spacing`` metres (cusps and both ends kept), its length, cusps and
    smallest clearance, with the planner's settings, so another planner can be scored against it."""
    cfg = planner.config
    found = bool(plan.found)
    poses, gears = [], []
    if found:
        rear, d = plan.rear_poses, plan.directions
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(rear[:, :2], axis=0), axis=1))])
        last = -math.inf
        for i in range(len(rear)):
            cusp = 0 < i < len(rear) - 1 and d[i] != d[i - 1]
            if i in (0, len(rear) - 1) or cusp or s[i] - last >= spacing - 1e-9:
                poses.append(list(_pose(rear[i])))
                gears.append(int(d[i]))
                last = s[i]
    return {"found": found, "verdict": plan.verdict, "reason": plan.reason,
            "length": float(plan.length) if found else None, "cusps": int(plan.cusps) if found else 0,
            "min_clearance": float(plan.min_clearance) if found else None, "method": plan.method,
            "attempt": int(plan.attempt), "spacing": spacing, "poses": poses, "directions": gears,
            "settings": {"planner": cfg.planner, "iterations": cfg.iterations, "seed": cfg.seed, "step": cfg.step,
                         "region": cfg.region, "margin": cfg.margin, "curvature_margin": cfg.curvature_margin,
                         "turning_radius": planner.radius}}


def _pose(p) -> tuple[float, float, float]:
    return float(p[0]), float(p[1]), wrap_yaw(float(p[2]))


def wrap_yaw(yaw: float) -> float:
    """``yaw`` [rad] wrapped into [-pi, pi): the interval every angle of a problem file lies in, which OMPL's SO2
    bounds (and its Reeds-Shepp space's) take; pi itself becomes -pi."""
    a = (yaw + math.pi) % math.tau - math.pi
    return -math.pi if a >= math.pi else a


def _corners(outline) -> tuple[tuple[float, float], ...]:
    """An obstacle's outline (K, 2) as its corners, without the repeats that pad a short one."""
    out: list[tuple[float, float]] = []
    for x, y in outline.tolist():
        if not out or (x, y) != out[-1]:
            out.append((float(x), float(y)))
    return tuple(out)


def write_park_problems(garages: Iterable[Garage | GarageScene], out_dir: str | Path, car: CarGeometry | None = None,
                        config: ParkConfig = DEFAULT_PARK, *, stalls: Collection[int] | None = None,
                        maneuvers: Sequence[str] = MANEUVERS, locked: bool = False) -> Path:
    """Write every park test of ``garages`` under ``out_dir`` (module docstring); returns the index file. With
    ``stalls`` and ``maneuvers``, only those stalls' problems in those maneuvers (``export --stall --maneuver``).

    ``locked``: the caller holds :func:`park_problems_lock` on ``out_dir`` (the CLI takes it before any
    work); else this takes it. A folder that cannot be written is a :class:`ParkProblemError` naming it.
    """
    if not locked:
        with park_problems_lock(out_dir):
            return write_park_problems(garages, out_dir, car, config, stalls=stalls, maneuvers=maneuvers,
                                       locked=True)
    out_dir = Path(out_dir)
    items = [item if isinstance(item, GarageScene) else GarageScene(item) for item in garages]
    check_problem_choice(items, stalls, maneuvers)
    folders = check_park_problems_targets(items, out_dir)
    entries, left_out = [], []
    try:
        for item, folder in zip(items, folders, strict=True):
            scene = item
            problems, skipped = park_problems(scene, car, config, stalls, maneuvers)
            if folder.is_dir():
                clean_temp(folder)  # what a killed export left (under the lock: no other writer)
            else:
                folder.mkdir()
            for p in problems:
                for target, text in ((folder / f"{p.name}.json", json.dumps(p.to_json(), indent=2) + "\n"),
                                     (folder / f"{p.name}.csv", p.tpcap())):
                    _write(out_dir, target, text)
                entries.append({"garage": p.garage, "stall": p.stall, "maneuver": p.maneuver,
                                "json": f"{folder.name}/{p.name}.json", "csv": f"{folder.name}/{p.name}.csv"})
            left_out += [{"garage": scene.name, "folder": folder.name, "stall": s, "reason": r}
                         for s, r in skipped.items()]
    except OSError as exc:  # a folder made read-only meanwhile, a full disk: name it, not a temp file
        raise _write_error(out_dir, Path(exc.filename) if exc.filename else out_dir, exc) from None
    index = {"format": "garage-mj park problems", "version": VERSION, "car": _car(car or car_geometry()),
             "problems": entries, "skipped": left_out}
    return _write(out_dir, out_dir / INDEX, json.dumps(index, indent=2) + "\n")


def check_problem_choice(scenes: Iterable[GarageScene], stalls: Collection[int] | None,
                         maneuvers: Sequence[str] = MANEUVERS) -> None:
    """Refuse, in one :class:`ParkProblemError` line, a stall id that a garage of ``scenes`` lacks (naming the ids
    every garage has) or a maneuver that is not one of :data:`MANEUVERS`, before anything is written."""
    bad = [m for m in maneuvers if m not in MANEUVERS]
    if bad or not maneuvers:
        raise ParkProblemError(f"maneuver {bad[0] if bad else 'none'!r} is not a park maneuver; give one of "
                               f"{', '.join(MANEUVERS)}")
    if stalls is None:
        return
    counts = [(scene, len(scene.stalls.stalls)) for scene in scenes]
    for scene, n in counts:
        missing = sorted(s for s in stalls if not 0 <= s < n)
        if missing:
            common = min(c for _, c in counts)
            has = f"its stalls are 0..{n - 1}" if n else "it has no stall"
            fix = f"stalls in 0..{common - 1} (every garage has those)" if common > 0 else "another garage"
            raise ParkProblemError(f"--stall {missing[0]}: garage {scene.name!r} has no such stall ({has}); give "
                                   f"{fix}, or leave --stall out for every stall")


def check_park_problems_targets(garages: Iterable[Garage | GarageScene], out_dir: str | Path) -> list[Path]:
    """The folder of each garage's problems in ``out_dir``; ParkProblemError naming one that is there already and
    cannot be written (read-only, or a file), so that nothing is written (the CLI checks before any pack)."""
    out_dir = Path(out_dir)
    folders = [out_dir / (pack_name(item.garage, item.world) if isinstance(item, GarageScene) else pack_name(item))
               for item in garages]
    for folder in folders:
        if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
            raise ParkProblemError(f"--park-problems {out_dir}: {folder} is not a folder; remove it or choose "
                                   "another folder")
        if folder.is_dir():
            _check_writable(out_dir, folder)
    return folders


@contextmanager
def park_problems_lock(out_dir: str | Path) -> Iterator[Path]:
    """Check that ``out_dir`` can be written and hold its lock (:class:`FolderLock`, ``garage-mj export``) for
    the whole export: a second export into it meanwhile stops in one line naming this one. Under the lock a
    killed export's temp files are removed; the lock file goes when the export ends, and so does a folder
    made only to hold it."""
    out_dir = Path(out_dir)
    if out_dir.is_symlink() or (out_dir.exists() and not out_dir.is_dir()):
        raise ParkProblemError(f"--park-problems {out_dir} is not a folder; give a new folder or one of park "
                               "problems")
    _check_writable(out_dir, out_dir)
    with FolderLock(out_dir, "garage-mj export", remove=True):
        clean_temp(out_dir)
        yield out_dir


def _check_writable(out_dir: Path, folder: Path) -> None:
    """Refuse ``folder`` (``out_dir`` or one of its garage folders) when this process cannot write in it; a
    folder not made yet is made in the nearest folder above that exists, so that one must be writable."""
    there = folder if folder.is_dir() else next((p for p in folder.resolve().parents if p.exists()), None)
    if there is not None and not os.access(there, os.W_OK | os.X_OK):
        raise ParkProblemError(f"--park-problems {out_dir}: the folder {there} is read-only; make it writable or "
                               "choose another folder")


def _write(out_dir: Path, target: Path, text: str) -> Path:
    """:func:`atomic_write` ``text`` to ``target``; a failure names ``target`` (not the temp file) and the fix."""
    try:
        return atomic_write(target, text)
    except OSError as exc:
        raise _write_error(out_dir, target, exc) from None


def _write_error(out_dir: Path, target: Path, exc: OSError) -> ParkProblemError:
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        hint = "free some disk space and run again"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        hint = "the folder is read-only; make it writable or choose another folder"
    else:
        hint = "check the path and run again"
    if target.name.startswith("."):  # a temp file beside the target: name the folder it was made in
        target = target.parent
    return ParkProblemError(f"--park-problems {out_dir}: cannot write {target} ({exc.strerror or exc}); {hint}")


# -- reading ------------------------------------------------------------------------------------------
def _read(path: Path, what: str) -> bytes:
    """The bytes of the file ``path`` (a ``what``), at most :data:`MAX_BYTES`; ParkProblemError otherwise."""
    fix = f"give the path of {a_noun(what)} file (garage-mj export --park-problems writes them)"
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # a folder, or a pipe that would block the read for ever
            raise ParkProblemError(f"{what} {path} is not a file; {fix}")
        with open(path, "rb") as f:
            raw = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise ParkProblemError(f"cannot read {what} {path}: {exc.strerror or exc}; {fix}") from None
    if len(raw) > MAX_BYTES:
        raise ParkProblemError(f"{what} {path} is larger than {MAX_BYTES >> 20} MiB, far larger than any park "
                               f"problem; {fix}")
    return raw


class _Duplicate(ValueError):
    """A JSON object holding a key twice."""


def _object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``json.loads``'s ``object_pairs_hook``: a dict, refusing a key given twice (which one would count?)."""
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _Duplicate(f"it holds the key {k[:40]!r} twice; keep one")
        out[k] = v
    return out


def read_park_problem(path: str | Path) -> ParkProblem:
    """The :class:`ParkProblem` in a JSON file written by :func:`write_park_problems`; ParkProblemError otherwise.

    Every key is checked: types, ranges (finite numbers, points within :data:`MAX_COORD`, positive car
    lengths, a region with min < max holding start and goal, counter-clockwise polygons), that the
    ``garage_hash`` is the hash of the ``garage_grid`` the file holds, and that no key is missing, unknown
    or given twice.
    """
    path = Path(path)
    raw = _read(path, "park problem")
    try:
        data = json.loads(raw.decode("utf-8-sig"), object_pairs_hook=_object)  # a BOM is harmless
    except UnicodeDecodeError as exc:
        raise ParkProblemError(f"park problem {path} is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                               f"{_FIX}") from None
    except _Duplicate as exc:
        raise ParkProblemError(f"park problem {path} is malformed: {exc}; {_FIX}") from None
    except RecursionError:
        raise ParkProblemError(f"park problem {path} is not a park problem: JSON nested too deeply; {_FIX}") from None
    except ValueError as exc:
        raise ParkProblemError(f"park problem {path} is not JSON ({exc}); {_FIX}") from None
    try:
        return _problem(data)
    except (KeyError, TypeError, ValueError) as exc:
        why = f"no {exc.args[0]!r} key" if isinstance(exc, KeyError) else str(exc)
        raise ParkProblemError(f"park problem {path} is malformed: {why}; {_FIX}") from None


def _problem(data: Any) -> ParkProblem:
    if not isinstance(data, dict):
        raise TypeError("the file holds no JSON object")
    version = data.get("version")
    if data.get("format") != FORMAT or type(version) is not int or version not in VERSIONS:
        raise ValueError(f"format {repr(data.get('format'))[:40]} version {repr(version)[:20]}, "
                         f"not {FORMAT!r} version {' or '.join(map(str, VERSIONS))}")
    keys = KEYS + (("reference",) if version >= 3 else ())
    for key in keys:
        if key not in data:
            raise KeyError(key)
    extra = [k for k in data if k not in keys + OPTIONAL_KEYS]
    if extra:
        raise ValueError(f"unknown key {extra[0][:40]!r} (a park problem of version {version} holds "
                         f"{', '.join(keys + OPTIONAL_KEYS)}); remove it")
    if not isinstance(data["maneuver"], str) or data["maneuver"] not in MANEUVERS:
        raise ValueError(f"maneuver {str(data['maneuver'])[:40]!r} is not one of {', '.join(MANEUVERS)}")
    grid, stalls = _grid(data)
    stall = data["stall"]
    if type(stall) is not int or not 0 <= stall < stalls:
        raise ValueError(f"stall {str(stall)[:20]} is not a stall id of the garage (an integer in [0, {stalls - 1}])")
    obstacles = data["obstacles"]
    if not isinstance(obstacles, list) or not all(isinstance(o, dict) for o in obstacles):
        raise TypeError("obstacles is not a list of objects")
    region = _numbers(data, "region", 4)
    if not (region[0] < region[2] and region[1] < region[3]):
        raise ValueError(f"region {list(region)} is inverted or empty; it needs xmin < xmax and ymin < ymax")
    start, goal = _read_pose(data, "start"), _read_pose(data, "goal")
    for key, (x, y, _) in (("start", start), ("goal", goal)):
        if not (region[0] <= x <= region[2] and region[1] <= y <= region[3]):
            raise ValueError(f"{key} ({x!r}, {y!r}) lies outside the region {list(region)}, the planning area "
                             "of the rear axle")
    return ParkProblem(
        garage=_garage_name(data["garage"]), garage_hash=data["garage_hash"], garage_grid=grid,
        six_stall_axis=data["six_stall_axis"], stall=stall, maneuver=data["maneuver"], start=start, goal=goal,
        start_centre=_read_pose(data, "start_centre"), goal_centre=_read_pose(data, "goal_centre"),
        stall_outline=_polygon(data["stall_outline"], "stall_outline"), region=region,
        car=_car_table(data["car"]), planner=_planner_table(data["planner"]),
        obstacles=tuple(_obstacle(o, k) for k, o in enumerate(obstacles)),
        geometry=_geometry(data.get("geometry")),
        reference=_reference(data["reference"]) if version >= 3 else None)


def _reference(v: Any) -> dict[str, Any]:
    """The ``reference`` object, checked: its keys, types and ranges (the schema's)."""
    ref = _keys(v, "reference", REFERENCE_KEYS)
    found = ref["found"]
    if type(found) is not bool:
        raise TypeError("reference.found is not true or false")
    if ref["verdict"] not in VERDICTS or (ref["verdict"] == "feasible") != found:
        raise ValueError(f"reference.verdict {str(ref['verdict'])[:20]!r} is not one of {', '.join(VERDICTS)} "
                         "(feasible exactly when found)")
    for key in ("reason", "method"):
        if not isinstance(ref[key], str):
            raise TypeError(f"reference.{key} is not a string")
    for key in ("cusps", "attempt"):
        if type(ref[key]) is not int or ref[key] < 0:
            raise ValueError(f"reference.{key} {str(ref[key])[:20]} is not an integer >= 0")
    spacing = _bounded(ref["spacing"], "reference.spacing", 0.0, MAX_CAR, open_lo=True)
    poses, gears = ref["poses"], ref["directions"]
    if not isinstance(poses, list) or not isinstance(gears, list) or len(poses) != len(gears):
        raise ValueError("reference.poses and reference.directions are not lists of one length")
    if found != bool(poses) or (found and len(poses) < 2):
        raise ValueError("reference.poses: a found plan has two poses or more, none found has none")
    out_poses = [list(_read_pose({"reference pose": p}, "reference pose")) for p in poses]
    if any(type(g) is not int or g not in (-1, 1) for g in gears):
        raise ValueError("reference.directions holds a value that is not 1 or -1")
    measures = {}
    for key in ("length", "min_clearance"):
        if found:
            lo = 0.0 if key == "length" else -MAX_COORD
            measures[key] = _bounded(ref[key], f"reference.{key}", lo, MAX_COORD)
        elif ref[key] is not None:
            raise ValueError(f"reference.{key} is not null, though no plan was found")
        else:
            measures[key] = None
    s = _keys(ref["settings"], "reference.settings", SETTINGS_KEYS)
    if not isinstance(s["planner"], str):
        raise TypeError("reference.settings.planner is not a string")
    for key in ("iterations", "seed"):
        if type(s[key]) is not int:
            raise TypeError(f"reference.settings.{key} is not an integer")
    settings = {"planner": s["planner"], "iterations": s["iterations"], "seed": s["seed"]}
    for key in ("step", "region", "margin", "curvature_margin", "turning_radius"):
        settings[key] = _bounded(s[key], f"reference.settings.{key}", 0.0, MAX_COORD)
    return {"found": found, "verdict": ref["verdict"], "reason": ref["reason"], "length": measures["length"],
            "cusps": ref["cusps"], "min_clearance": measures["min_clearance"], "method": ref["method"],
            "attempt": ref["attempt"], "spacing": spacing, "poses": out_poses, "directions": list(gears),
            "settings": settings}


def _geometry(v: Any) -> dict[str, float]:
    """The park geometry of a problem file (none: the defaults); a bad one is a ValueError naming the key."""
    if v is not None and not isinstance(v, dict):
        raise TypeError("geometry is not an object")
    try:
        return geometry(world_with(v, where="geometry"))
    except GeometryError as exc:
        raise ValueError(str(exc)) from None


def _garage_name(v: Any) -> str:
    if not isinstance(v, str):
        raise TypeError("garage is not a string")
    if len(v) > MAX_NAME:
        raise ValueError(f"garage name {v[:40]!r}... is longer than {MAX_NAME} characters")
    bad = control_character(v)
    if bad is not None:
        raise ValueError(f"garage name {v[:40]!r} holds the control character {bad!r}")
    return v


_ROW = re.compile(r"[0-9]+", re.ASCII)


def _grid(data: dict) -> tuple[tuple[str, ...], int]:
    """The garage grid rows, checked against ``garage_hash``; and the garage's number of stalls."""
    rows, axis, digest = data["garage_grid"], data["six_stall_axis"], data["garage_hash"]
    if not isinstance(rows, list) or not 3 <= len(rows) <= MAX_SIDE or \
            not all(isinstance(r, str) and _ROW.fullmatch(r) and 3 <= len(r) <= MAX_SIDE for r in rows):
        raise ValueError(f"garage_grid is not a list of 3 to {MAX_SIDE} rows, each a string of 3 to {MAX_SIDE} "
                         "block codes 0-9")
    if any(len(r) != len(rows[0]) for r in rows):
        raise ValueError(f"garage_grid is ragged, not rectangular; every row needs {len(rows[0])} codes")
    if axis not in AXES:
        raise ValueError(f"six_stall_axis {str(axis)[:20]!r} is not one of {', '.join(AXES)}")
    if not isinstance(digest, str):
        raise TypeError("garage_hash is not a string")
    grid = np.array([[int(c) for c in r] for r in rows], dtype=np.int8)
    actual = grid_hash(grid, axis)
    if digest != actual:
        shown = repr(digest) if len(digest) <= 16 else f"{digest[:16]!r}..."
        raise ValueError(f"garage_hash {shown} is not the hash of the garage the file holds "
                         f"(garage_grid and six_stall_axis hash to {actual[:16]}...)")
    return tuple(rows), int(STALL_TABLE[grid].sum())


def _finite(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{what} holds {str(v)[:20]!r}, not a number")
    try:
        x = float(v)
    except OverflowError:  # an integer of hundreds of digits
        raise ValueError(f"{what} holds an integer of {len(str(abs(v)))} digits, not a finite number") from None
    if not math.isfinite(x):
        raise ValueError(f"{what} holds {x!r}, not a finite number")
    return x


def _bounded(v: Any, what: str, lo: float, hi: float, *, open_lo: bool = False, unit: str = "m") -> float:
    """``v`` as a float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``), or ValueError in the config's words."""
    x = _finite(v, what)
    if x > hi or x < lo or (open_lo and x == lo):
        span = f"{'(' if open_lo else '['}{lo:g}, {hi:g}]"
        raise ValueError(f"{what} = {x!r} is not allowed: it must be a number in {span} ({unit})")
    return x


def _coord(v: Any, what: str) -> float:
    return _bounded(v, what, -MAX_COORD, MAX_COORD)


def _numbers(data: dict, key: str, n: int) -> tuple[float, ...]:
    v = data[key]
    if not isinstance(v, list) or len(v) != n:
        raise ValueError(f"{key} is not a list of {n} numbers")
    return tuple(_coord(x, key) for x in v)


def _read_pose(data: dict, key: str) -> tuple[float, float, float]:
    v = data[key]
    if not isinstance(v, list) or len(v) != 3:
        raise ValueError(f"{key} is not a list of 3 numbers")
    return _coord(v[0], f"{key} x"), _coord(v[1], f"{key} y"), \
        wrap_yaw(_bounded(v[2], f"{key} yaw", -MAX_YAW, MAX_YAW, unit="radians"))


def _polygon(v: Any, what: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(v, list) or len(v) < 3 or not all(isinstance(p, list) and len(p) == 2 for p in v):
        raise ValueError(f"{what} is not a list of at least 3 [x, y] vertices")
    poly = tuple((_coord(p[0], f"{what} vertex {j} x"), _coord(p[1], f"{what} vertex {j} y")) for j, p in enumerate(v))
    if _area(poly) <= 0:
        raise ValueError(f"{what} is not counter-clockwise with a positive area (signed area {_area(poly):.6g} m²)")
    return poly


def _area(poly) -> float:
    """The signed area of ``poly`` (positive: counter-clockwise), about its first vertex: far from the origin
    (a TPCAP case at 10^9 m) the products of raw coordinates would lose the area to rounding."""
    ox, oy = poly[0]
    rel = [(x - ox, y - oy) for x, y in poly]
    return sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(rel, rel[1:] + rel[:1])) / 2


def _keys(v: Any, key: str, keys: tuple[str, ...]) -> dict:
    if not isinstance(v, dict):
        raise TypeError(f"{key} is not an object")
    for k in keys:
        if k not in v:
            raise ValueError(f"{key} has no {k!r} key")
    extra = [k for k in v if k not in keys]
    if extra:
        raise ValueError(f"{key}.{extra[0][:40]} is not a key of {key} (it holds {', '.join(keys)}); remove it")
    return v


def _car_table(v: Any) -> dict[str, float]:
    v = _keys(v, "car", CAR_KEYS)
    car = {k: _bounded(v[k], f"car.{k}", 0.0, MAX_CAR, open_lo=k not in ("front_overhang", "rear_overhang"))
           for k in CAR_KEYS if k != "max_steer"}
    car["max_steer"] = _bounded(v["max_steer"], "car.max_steer", 0.0, math.pi / 2, open_lo=True, unit="radians")
    if car["max_steer"] == math.pi / 2:
        raise ValueError("car.max_steer = pi/2 is not allowed: the wheels would turn across the car")
    parts = car["front_overhang"] + car["wheelbase"] + car["rear_overhang"]
    if not math.isclose(car["length"], parts, rel_tol=1e-6, abs_tol=1e-6):
        raise ValueError(f"car.length = {car['length']!r} is not front_overhang + wheelbase + rear_overhang "
                         f"= {parts!r}")
    radius = car["wheelbase"] / math.tan(car["max_steer"])
    if not math.isclose(car["min_turning_radius"], radius, rel_tol=1e-6):
        raise ValueError(f"car.min_turning_radius = {car['min_turning_radius']!r} is not wheelbase / "
                         f"tan(max_steer) = {radius!r}")
    return {k: car[k] for k in CAR_KEYS}


def _planner_table(v: Any) -> dict[str, float]:
    v = _keys(v, "planner", PLANNER_KEYS)
    return {"margin": _bounded(v["margin"], "planner.margin", 0.0, MAX_CAR),
            "turning_radius": _bounded(v["turning_radius"], "planner.turning_radius", 0.0, MAX_COORD, open_lo=True)}


def _obstacle(o: dict, k: int) -> tuple[str, tuple[tuple[float, float], ...]]:
    extra = [key for key in o if key not in ("class", "vertices")]
    if extra:
        raise ValueError(f"obstacle {k} holds the unknown key {extra[0][:40]!r} (it holds class and vertices); "
                         "remove it")
    cls = o["class"]
    if not isinstance(cls, str):
        raise TypeError(f"the class of obstacle {k} is not a string")
    if cls not in CLASSES:
        raise ValueError(f"the class {cls[:40]!r} of obstacle {k} is not one of {', '.join(CLASSES)}")
    return cls, _polygon(o["vertices"], f"obstacle {k}")


_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_CASE_FIX = ("give a TPCAP case: one line of comma-separated numbers, as TPCAP's CaseN.csv (garage-mj export "
             "--park-problems writes them)")
TpcapCase = tuple[tuple[float, float, float], tuple[float, float, float], list[list[tuple[float, float]]]]


def read_tpcap_case(path: str | Path) -> TpcapCase:
    """A TPCAP case file: start pose, goal pose (rear-axle midpoint, yaw in radians) and the obstacle polygons
    (lists of (x, y)); the vehicle is not in the file (TPCAP's own cases: :data:`TPCAP_CAR`).

    Read as TPCAP's readers read it: one line of comma-separated numbers (its ``CaseN.csv``: fields may be
    padded with spaces, the line may end in one trailing comma, CRLF, LF or nothing, blank lines after it
    are ignored), or the same vector V one number per line (a column, as MATLAB's ``readmatrix`` also reads
    it). ParkProblemError, one line naming the file, when it is not one: several lines of comma-separated
    numbers (a matrix ``readmatrix`` would read column by column), an empty field, a word that is not a
    decimal number, a NaN or infinite one, counts that are not counts or do not match the vertices, a point
    beyond :data:`MAX_CASE_COORD` or more than :data:`MAX_COORD` from the start, a yaw beyond two turns, a
    polygon of zero area.
    """
    path = Path(path)
    raw = _read(path, "TPCAP case")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ParkProblemError(f"TPCAP case {path} is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                               f"{_CASE_FIX}") from None
    try:
        words = _case_words(text)
    except ValueError as exc:
        raise ParkProblemError(f"TPCAP case {path} {exc}; {_CASE_FIX}") from None
    v = []
    for i, word in enumerate(words, 1):
        if not _NUMBER.fullmatch(word):
            try:
                x = float(word)
            except ValueError:
                x = 0.0
            if math.isfinite(x):  # a word float() would take, but no decimal number: 1_0, a digit of another script
                raise ParkProblemError(f"TPCAP case {path}: V[{i}] holds {word[:20]!r}, not a number; {_CASE_FIX}")
        x = float(word)
        if not math.isfinite(x):
            raise ParkProblemError(f"TPCAP case {path}: V[{i}] holds {word[:20]}, not a finite number; {_CASE_FIX}")
        v.append(x)
    try:
        return _case(v)
    except ValueError as exc:
        raise ParkProblemError(f"TPCAP case {path} {exc}; {_CASE_FIX}") from None


def _case_words(text: str) -> list[str]:
    """The fields of a case's text, V[1], V[2], ... in order; ValueError for a layout that is neither one line of
    comma-separated fields nor one field per line (nor, without commas, one line of blank-separated ones)."""
    lines = [line for line in text.splitlines() if line.strip()]
    if "," not in text:
        words = text.split()
        if len(lines) > 1 and len(words) != len(lines):
            raise ValueError(f"holds {len(words)} numbers on {len(lines)} lines; V is one line of comma-separated "
                             "numbers or one number per line")
        return words
    if len(lines) != 1:
        raise ValueError(f"holds {len(lines)} lines with commas (a matrix, which TPCAP's readers read otherwise); "
                         "V is one line of comma-separated numbers")
    fields = [f.strip() for f in lines[0].split(",")]
    if len(fields) > 1 and not fields[-1]:
        fields.pop()  # one trailing comma
    for i, field in enumerate(fields, 1):
        if not field:
            raise ValueError(f"has an empty field V[{i}] (two commas in a row, or a leading comma); give a number "
                             "between every two commas")
    return fields


def _case(v: list[float]) -> TpcapCase:
    """The poses and polygons of the finite numbers ``v`` of a TPCAP case; ValueError saying what is wrong."""
    if len(v) < 7 or v[6] != int(v[6]) or v[6] < 0:
        raise ValueError("is too short or its obstacle count V[7] is not a count")
    n = int(v[6])
    counts = v[7:7 + n]
    if len(counts) < n or any(c != int(c) or c < 3 for c in counts) or len(v) != 7 + n + 2 * int(sum(counts)):
        raise ValueError("does not hold the vertices its counts announce")
    for i, x in enumerate(v):
        yaw = i in (2, 5)
        if i < 6 or i >= 7 + n:
            try:
                if yaw:
                    _bounded(x, f"V[{i + 1}]", -math.tau, math.tau, unit="radians")
                else:
                    _bounded(x, f"V[{i + 1}]", -MAX_CASE_COORD, MAX_CASE_COORD)
            except ValueError as exc:
                raise ValueError(f"holds a number out of range: {exc}") from None
    x0, y0 = v[0], v[1]
    for i in [3, *range(7 + n, len(v), 2)]:
        far = max(abs(v[i] - x0), abs(v[i + 1] - y0))
        if far > MAX_COORD:
            raise ValueError(f"holds the point V[{i + 1}], V[{i + 2}] = ({v[i]!r}, {v[i + 1]!r}), {far:.6g} m from "
                             f"the start (V[1], V[2]) in x or y; a case spans at most {MAX_COORD:g} m")
    polys, at = [], 7 + n
    for k, c in enumerate(map(int, counts)):
        poly = [(v[at + 2 * j], v[at + 2 * j + 1]) for j in range(c)]
        if _area(tuple(poly)) == 0:
            raise ValueError(f"holds obstacle {k + 1}, a polygon of zero area (its vertices V[{at + 1}] to "
                             f"V[{at + 2 * c}] lie on a line)")
        polys.append(poly)
        at += 2 * c
    return (v[0], v[1], v[2]), (v[3], v[4], v[5]), polys
