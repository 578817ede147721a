"""A park or AVP run (docs/spec.md sections 8 and 9) as a report shows it: the park table and a top-down picture of
each failure shown.

- :func:`park_table`: per garage of ``summary.csv`` (and over the run, ``summary.json``) the tests, the
  infeasible ones, success of the feasible ones and the columns of
  :data:`~garage_mj.driving.results.PARK_SUMMARY_COLUMNS` (their headers made from the column names, so
  a new summary column shows up without an edit here), with :data:`SUCCESS_NOTE` and the run's success by level,
  maneuver and stall angle (``summary.json``'s breakdowns, docs/spec.md section 9). A cruise run's
  ``summary.csv`` has none of those columns: no table.
- :func:`park_picture`: one test driven again as the run drove it (its seed, settings and driver, as the
  failure videos are), drawn from above with matplotlib: the stall outlines, and the walls, pillars, obstacle
  blocks and parked cars around the test as their outlines (the parked cars where they stand, as the planner
  and the simulation see them), with a legend; the reference plan of the reset info (``park_plan``: forward
  solid, reverse dashed), the driven path (the car centre each control step; an AVP test's shown from near
  the stall), the stall pose and the final footprint; a collision's contact point, and an ``outside_stall``
  test's limit that its reason names (:func:`~garage_mj.scene.park_planning.stall_limits`).
  :func:`record_park_pictures` writes them into ``OUT/pictures/<garage>_<test>_<outcome>.png``: for the
  first failures (the ones the report shows, as :func:`garage_mj.reporting.failures.run_failures` picks), or
  with ``which="all"`` for every driven test, successes too (``cruise --pictures``).
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from garage_mj.core.fsutil import FolderLock, atomic_write  # noqa: E402
from garage_mj.driving.results import BREAKDOWNS, PARK_SUMMARY_COLUMNS, breakdown_lines  # noqa: E402
from garage_mj.driving.sim.outcomes import NOT_DRIVEN  # noqa: E402
from garage_mj.driving.sources import CruiseSettings, CruiseSource, cruise_seed  # noqa: E402
from garage_mj.reporting.plots import DPI  # noqa: E402
from garage_mj.reporting.report import PICTURE_CHOICES, ParkTable, fmt_percent  # noqa: E402
from garage_mj.scene.car import CarGeometry  # noqa: E402
from garage_mj.scene.clearance import Obstacles, footprint  # noqa: E402
from garage_mj.scene.park_planning import (  # noqa: E402
    FAR_END_SLACK,
    HEADING_TOLERANCE,
    centre_to_rear,
    stall_limits,
)
from garage_mj.scene.parked_fleet import body_obstacles  # noqa: E402

PICTURES = "pictures"  # a run folder's top-down pictures of park and AVP failures
#: The CARLA end-to-end parking benchmark's success box, for comparison (SPEC 8).
CARLA_BOX = {"lateral_m": 0.6, "longitudinal_m": 1.0, "heading_deg": 10.0}
SUCCESS_NOTE = (
    "Success (docs/spec.md section 9): no contact at any time; at rest for the dwell (1 s by default); the footprint "
    "inside the paint's inner edges (a car longer than the stall's room may stand past its open end by the stall "
    f"pose's own overhang + {FAR_END_SLACK} m: 0.3 m for the default car); heading within {HEADING_TOLERANCE:g} deg of "
    "the stall axis. Levels after the HOPE planner's: extreme, complex, normal (docs/spec.md section 9); the CARLA parking "
    f"benchmark's: within {CARLA_BOX['lateral_m']} m lateral, {CARLA_BOX['longitudinal_m']} m longitudinal, "
    f"{CARLA_BOX['heading_deg']:g} deg. Unproven tests (no reference plan within the planner's escalated budget, "
    "and no proof that none exists: docs/spec.md section 9) are neither feasible nor infeasible: never driven, "
    "counted apart, their share of all tests beside the rates. Rates are over feasible tests, errors over driven tests, park time and "
    "direction changes over successes.")
#: A summary column's unit suffix and how its header writes it.
UNITS = {"_pct": "%", "_m": "[m]", "_deg": "[deg]", "_s": "[s]"}
VIEW_MARGIN = 4.0  # [m] around the plan, the driven path and the stall
NEAR_STALL = 15.0  # [m] driven poses farther from the stall centre widen the view only as the final pose
PICTURE_SIZE = (6.4, 5.6)  # [in] at plots' DPI
#: Each obstacle class of a picture: its fill and its legend label (a class not here is drawn grey, named as it is).
OBSTACLE_STYLES = {"parked_car": ("#93c5fd", "parked car"), "pillar": ("#9ca3af", "pillar"),
                   "wall": ("#374151", "wall"), "obstacle": ("#92400e", "obstacle block")}
CONTACT_SEARCH = 1.0  # [m] how far from the car a collision's contact point is looked for (it touched: ~0)


def column_label(column: str) -> str:
    """A summary column's header: ``mean_position_error_m`` -> ``mean position error [m]``."""
    for suffix, unit in UNITS.items():
        if column.endswith(suffix):
            return f"{column[: -len(suffix)].replace('_', ' ')} {unit}"
    return column.replace("_", " ")


def _cell(column: str, value: Any) -> object:
    """A park summary value as the table writes it: a rate in percent, a mean with 2 decimals, n/a for none."""
    if value is None or value == "":
        return "n/a"
    if not column.endswith(tuple(UNITS)):  # a count
        return int(float(value))
    return fmt_percent(float(value)) if column.endswith("_pct") else f"{float(value):.2f}"


def _row(name: str, r: dict[str, Any]) -> list[object]:
    return [name, int(r["tests"]), int(r["infeasible"]),
            fmt_percent(None if r["success_pct"] in (None, "") else float(r["success_pct"])),
            *(_cell(c, r.get(c)) for c in PARK_SUMMARY_COLUMNS)]


def park_table(run_dir: str | Path, label: str | None = None) -> ParkTable | None:
    """The park table of the run in ``run_dir`` (a row per garage of ``summary.csv``, a last one over the run
    from ``summary.json``); None for a cruise run (its summary has no park columns)."""
    run = Path(run_dir)
    with open(run / "summary.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
        if not set(PARK_SUMMARY_COLUMNS) <= set(reader.fieldnames or ()):
            return None
    stats = json.loads((run / "summary.json").read_text())
    columns = ["garage", "tests", "infeasible", "success of feasible", *map(column_label, PARK_SUMMARY_COLUMNS)]
    table = [_row(r["garage"], r) for r in rows] + [_row("all garages", stats)]
    what = f"{stats.get('driver', '?')}, {stats.get('task', 'park')} tests ({stats.get('maneuver', 'reverse')})"
    breakdown = breakdown_lines({k: stats[k] for k in BREAKDOWNS}) if all(k in stats for k in BREAKDOWNS) else []
    return ParkTable(label or what, columns, table, SUCCESS_NOTE, breakdown)


@dataclass(frozen=True)
class ParkDrive:
    """One park or AVP test driven again: what its picture draws."""

    title: str
    stall: Any  # the target Stall
    obstacles: Obstacles  # walls, pillars, obstacle blocks and the parked cars of the test as they stand
    stall_corners: list[np.ndarray]  # every stall's outline, (4, 2) each
    plan: dict[str, Any]  # the reset info's park_plan: poses (N, 3), directions (N,), stall_pose
    driven: np.ndarray  # (M, 3) the car centre at the reset and after every control step
    car: CarGeometry
    contact: np.ndarray | None = None  # (2,) where a collision touched (x, y) [m]
    hit: str = ""  # the class a collision hit
    limit: tuple[str, np.ndarray, str] | None = None  # an outside_stall test's limit: name, (2, 2) segment, label
    outcome: str = ""  # the test's outcome (a success's final footprint is drawn green, a failure's red)


def collision_point(env: Any, geom: str) -> np.ndarray | None:
    """(x, y) [m] where the car touches geom ``geom`` at the end of a collision: the middle of the nearest points of
    the car's collidable geoms and it (``mj_geomDistance``); None for a geom without a name, or none within
    :data:`CONTACT_SEARCH`."""
    import mujoco

    model, data = env.model, env.data
    other = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
    if other < 0:
        return None
    best, point = CONTACT_SEARCH, None
    fromto = np.zeros(6)
    for g in np.flatnonzero(env.car.geom_mask):
        if not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        dist = mujoco.mj_geomDistance(model, data, int(g), other, CONTACT_SEARCH, fromto)
        if dist < best:
            best, point = dist, (fromto[:2] + fromto[3:5]) / 2
    return point


def _limit(env: Any, outcome: str) -> tuple[str, np.ndarray, str] | None:
    """The limit of the target stall an ``outside_stall`` test's reason names (the nearest at its final pose), with
    how far over or inside it the footprint stands; None for another outcome."""
    fit = getattr(env.monitor, "fit", None)
    if outcome != "outside_stall" or fit is None or not fit.line:
        return None
    segment = stall_limits(env.stalls[env.target], env.car_geometry, env.scene.world.marking_width)[fit.line]
    label = f"{fit.line}: {fit.overhang:.2f} m over" if not fit.inside else f"{fit.line}: {fit.margin:.2f} m inside"
    return fit.line, segment, label


def drive_park_test(source: CruiseSource, settings: CruiseSettings, test: int) -> ParkDrive:
    """Test ``test`` of ``source`` driven again with the run's ``settings`` (same seed: the same test and
    outcome), the car's pose recorded each step."""
    from garage_mj.driving.drivers import choose_action_type, load_driver
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    choice = choose_action_type(settings.driver, settings.action_type, warn=False)
    drv = load_driver(settings.driver, **(settings.driver_kwargs or {}))
    env = GarageDriveEnv(garage=source.garage, action_type=choice.action_type, occupancy=settings.occupancy,
                         infeasible="report", **settings.task_kwargs(), **(settings.env or {}))
    try:
        seed = cruise_seed(settings.seed, source.hash, test)
        obs, info = env.reset(seed=seed)
        plan = info.get("park_plan") or {"poses": np.zeros((0, 3)), "directions": np.zeros(0)}
        poses = [env.car.pose(env.data)]
        if info.get("outcome") not in NOT_DRIVEN:
            drv.reset(env.driver_info(seed))
            while True:
                obs, _, term, trunc, info = env.step(drv.act(obs))
                poses.append(env.car.pose(env.data))
                if term or trunc:
                    break
        obstacles = body_obstacles(env.park_planner.obstacles(), env.target, env.parked_bodies)  # cars as they stand
        hit = f" ({info['hit']})" if info.get("hit") else ""
        contact = collision_point(env, info["hit_geom"]) if info.get("outcome") == "collision" and info.get(
            "hit_geom") else None
        return ParkDrive(f"{source.name} {settings.task} test {test}: {info['outcome'].replace('_', ' ')}{hit}",
                         env.stalls[env.target], obstacles, [np.array(s.corners) for s in env.stalls], plan,
                         np.array(poses, dtype=float), env.car_geometry, contact, info.get("hit") or "",
                         _limit(env, info["outcome"]), info["outcome"])
    finally:
        env.close()


def _body(car: CarGeometry, pose: Sequence[float]) -> np.ndarray:
    """(4, 2) corners of the car's body at ``pose`` (car centre)."""
    rear = centre_to_rear(np.asarray(pose, dtype=float), car)
    return footprint(car, rear[None, :2], np.array([rear[2]]))[0]


def _view(drive: ParkDrive) -> tuple[float, float, float, float]:
    """The box the picture shows, with :data:`VIEW_MARGIN`: the plan, the stall, the final footprint and the
    driven path within :data:`NEAR_STALL` of the stall (an AVP test's cruise from the entrance is cut off)."""
    stall = np.array([drive.stall.x, drive.stall.y])
    near = drive.driven[np.hypot(*(drive.driven[:, :2] - stall).T) <= NEAR_STALL, :2]
    pts = [near, np.array(drive.stall.corners), _body(drive.car, drive.driven[-1])]
    if len(drive.plan["poses"]):
        pts.append(np.asarray(drive.plan["poses"])[:, :2])
    if drive.limit is not None:
        pts.append(drive.limit[1])
    xy = np.vstack(pts)
    (x0, y0), (x1, y1) = xy.min(axis=0) - VIEW_MARGIN, xy.max(axis=0) + VIEW_MARGIN
    return float(x0), float(y0), float(x1), float(y1)


def _draw_plan(ax, plan: dict[str, Any]) -> None:
    """The reference plan, one line per run of one gear: forward solid, reverse dashed."""
    poses, dirs = np.asarray(plan["poses"]), np.asarray(plan["directions"])
    cuts = [0, *(k for k in range(1, len(poses) - 1) if dirs[k] != dirs[k - 1]), len(poses) - 1]
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        ax.plot(poses[a:b + 1, 0], poses[a:b + 1, 1], color="#2563eb", lw=1.6, ls="-" if dirs[a] >= 0 else "--",
                label="plan (reverse dashed)" if a == 0 else None)


def draw_park_picture(drive: ParkDrive, path: str | Path) -> Path:
    """The top-down PNG of ``drive`` at ``path`` (written atomically)."""
    fig = park_axes(drive).figure
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return atomic_write(Path(path), buf.getvalue())


def park_axes(drive: ParkDrive):
    """The matplotlib axes of ``drive``'s top-down picture, legend included (the caller closes its figure)."""
    from matplotlib.patches import Polygon

    x0, y0, x1, y1 = _view(drive)
    fig, ax = plt.subplots(figsize=PICTURE_SIZE)
    for corners in drive.stall_corners:
        ax.add_patch(Polygon(corners, closed=True, fill=False, ec="#9ca3af", lw=0.8))
    shown = set()
    for (bx0, by0, bx1, by1), outline, cls in zip(drive.obstacles.boxes, drive.obstacles.outlines,
                                                  drive.obstacles.classes, strict=True):
        if bx1 >= x0 and bx0 <= x1 and by1 >= y0 and by0 <= y1:
            colour, label = OBSTACLE_STYLES.get(cls, ("#9ca3af", cls.replace("_", " ")))
            ax.add_patch(Polygon(outline, closed=True, fc=colour, ec="#1f2937", lw=0.5, alpha=0.85,
                                 label=None if cls in shown else label))
            shown.add(cls)
    ax.add_patch(Polygon(drive.stall.corners, closed=True, fill=False, ec="#16a34a", lw=2.0, label="target stall"))
    goal = drive.plan.get("stall_pose")
    if goal is not None and np.all(np.isfinite(goal)):
        ax.add_patch(Polygon(_body(drive.car, goal), closed=True, fill=False, ec="#16a34a", ls=":", lw=1.5,
                             label="stall pose"))
    if len(drive.plan["poses"]) > 1:
        _draw_plan(ax, drive.plan)
    ax.plot(drive.driven[:, 0], drive.driven[:, 1], color="#f97316", lw=1.6, label="driven")
    ax.add_patch(Polygon(_body(drive.car, drive.driven[0]), closed=True, fill=False, ec="#6b7280", lw=1.0,
                         label="start"))
    final = "#16a34a" if drive.outcome == "success" else "#dc2626"
    ax.add_patch(Polygon(_body(drive.car, drive.driven[-1]), closed=True, fc=final, alpha=0.45, ec=final, lw=1.2,
                         label="final footprint" + (" (parked)" if drive.outcome == "success" else "")))
    if drive.limit is not None:  # the line an outside_stall reason names
        _, segment, label = drive.limit
        ax.plot(segment[:, 0], segment[:, 1], color="#c026d3", lw=2.6, ls=(0, (4, 2)), label=label, zorder=5)
    if drive.contact is not None:
        ax.plot(*drive.contact, marker="X", ms=13, mfc="#facc15", mec="#111827", mew=1.2, ls="none", zorder=6,
                label=f"collision point{f' ({drive.hit})' if drive.hit else ''}")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(drive.title, fontsize=9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
    return ax


def picture_name(row: dict[str, Any]) -> str:
    """File name of a test's top-down picture: its video's name (``<garage>_<test>_<outcome>``) as a PNG."""
    from garage_mj.reporting.cruise import video_name

    return video_name(row)[: -len(".mp4")] + ".png"


def park_picture(source: CruiseSource, path: str | Path, settings: CruiseSettings, test: int) -> Path:
    """Drive test ``test`` again (:func:`drive_park_test`) and draw it into ``path`` (:func:`draw_park_picture`)."""
    return draw_park_picture(drive_park_test(source, settings, test), path)


def record_park_pictures(run_dir: str | Path, rows: Sequence[dict[str, Any]], sources: Sequence[CruiseSource],
                         n: int, which: str = "failures") -> dict[tuple[str, int], Path]:
    """The top-down pictures of the park or AVP run in ``run_dir`` in ``OUT/pictures/``: ``which="failures"`` (the
    default) the first ``n`` failures (garage and test order, the ones the report shows), ``"all"`` every driven
    test, successes too (:data:`PICTURE_CHOICES`); a test whose driver crashed or hung is left out, one already
    drawn is kept. Returns (garage hash, test) -> path; a cruise run gets none."""
    from garage_mj.reporting.cruise import UNWATCHABLE
    from garage_mj.reporting.failures import first_failures

    if which not in PICTURE_CHOICES:
        raise ValueError(f"which must be one of {', '.join(PICTURE_CHOICES)}, got {which!r}")
    run = Path(run_dir)
    settings = CruiseSettings.from_stored(json.loads((run / "run.json").read_text()))
    if settings.task == "cruise":
        return {}
    by_hash = {s.hash: s for s in sources}
    if which == "all":
        order = {s.hash: k for k, s in enumerate(sources)}
        chosen = sorted((r for r in rows if r["garage_hash"] in order),
                        key=lambda r: (order[r["garage_hash"]], int(r["test"])))
    else:
        chosen = first_failures(rows, sources, n)
    made = {}
    with FolderLock(run, "garage-mj cruise", remove=True):
        for row in chosen:
            if row["outcome"] in UNWATCHABLE:
                continue
            path = run / PICTURES / picture_name(row)
            if not path.is_file():
                path.parent.mkdir(parents=True, exist_ok=True)
                park_picture(by_hash[row["garage_hash"]], path, settings, int(row["test"]))
            made[row["garage_hash"], int(row["test"])] = path
    return made
