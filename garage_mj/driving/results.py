"""A cruise run's folder: ``run.json``, ``tests.csv`` read back and repaired, ``summary.csv`` and ``summary.json``.

``tests.csv`` holds one row per test (:data:`TEST_COLUMNS`), appended by the runner as each test
ends; :func:`read_tests` reads it back and repairs what a crash or a careless edit leaves, so a
re-run skips what is there. ``run.json`` holds the settings (:func:`check_settings` refuses a
re-run with other ones) and where the action type came from. :func:`write_outputs` summarizes the
rows per garage (``summary.csv``, the paper's table columns and ``route_difficulty`` beside
``difficulty``) and over the run (``summary.json``: counts, timing, Pearson r and the regression of
success rate on the paper's difficulty (``r``, ``slope``, ``intercept``, ``n``) and on the route
difficulty (``route_r``, ``route_slope``, ``route_intercept``, ``route_n``, under ``route_model``),
:mod:`garage_mj.driving.difficulty.regression`). A garage's route difficulty is empty in ``summary.csv`` when it
has no feasible stall or was not computed (a run without a route model, a run of an older garage-mj).

A park or AVP run (``CruiseSettings.task``) writes the same files; its ``tests.csv`` rows fill the park
columns (:data:`PARK_COLUMNS`, :data:`HAZARD_COLUMNS` and :data:`ROOM_COLUMNS`, empty but ``task`` in a cruise row),
and its ``summary.csv`` and ``summary.json`` add :data:`PARK_SUMMARY_COLUMNS` (a cruise run's keep their columns);
its ``summary.json`` also breaks success down by level, maneuver and stall angle (:func:`park_breakdown`,
docs/spec.md section 9).

Failures are counted per failure kind of :data:`garage_mj.driving.sim.outcomes.OUTCOMES`
(:data:`FAILURE_KINDS`, each with its column of :data:`COUNT_COLUMNS`), and folded into the paper's three
classes (:data:`garage_mj.driving.sim.outcomes.PAPER_CLASS`): ``summary.json`` gives both.
:func:`failed_tests` and :func:`failure_counts` are the one listing and count of failures the hunt,
the reports and a driver's tests read. Rows of older runs (from before a kind had a class of its own:
it was counted in its paper class) load as they are.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.config import refuse_other_settings
from garage_mj.core.fsutil import atomic_write, write_json
from garage_mj.driving.difficulty.regression import PAPER_R, regression
from garage_mj.driving.sim.outcomes import FAILURES, HIT_KINDS, NOT_DRIVEN, OUTCOMES, PAPER_CLASS, OutcomeKind
from garage_mj.driving.sources import (
    DEFAULT_TEST_TIMEOUT,
    CruiseError,
    CruiseSettings,
    CruiseSource,
    cruise_seed,
)
from garage_mj.scene.park_levels import LEVELS

#: The columns of ``tests.csv`` before park tests (a file with these alone is repaired to :data:`TEST_COLUMNS`).
LEGACY_TEST_COLUMNS = ("garage", "garage_hash", "test", "seed", "driver", "target_stall", "feasible", "outcome",
                       "hit", "hit_geom", "reason", "time", "path_length", "route_length", "difficulty",
                       "mean_road_length", "mean_intersection_degree", "pedestrians", "moving_cars", "clutter",
                       "wall_s")
#: A test's task and the parking metrics of docs/spec.md sections 8 and 9 (empty in a cruise test's row, but ``task``):
#: the car's final pose against the stall pose, the cusps driven, the parking time [s] (an AVP test's from the
#: end of its cruise route; the dwell at rest included), the footprint's least clearance along the driven path to the
#: solid bodies (parked cars as they stand, pillars, walls, obstacle blocks), the reference plan's length, cusps and
#: clearance; the test's level (every park or AVP test, driven or not), the final footprint's smallest margin inside
#: the stall's painted inner edges (negative: over a line), the least clearance along the driven path to the stall
#: outlines of the occupied stalls and the rest (what the planner measures; section 8's figure), the stall's angle;
#: the new plans the park guide showed the driven test (:mod:`~garage_mj.driving.sim.park_guide`).
PARK_COLUMNS = ("task", "maneuver", "position_error_m", "heading_error_deg", "lateral_offset_m", "direction_changes",
                "park_time_s", "min_clearance_m", "plan_length_m", "plan_cusps", "plan_clearance_m", "park_level",
                "inner_margin_m", "outline_clearance_m", "stall_angle_deg", "guide_replans")
#: The vehicles of a test (docs/spec.md section 9): the car under test's class, the parked fleet (``uniform`` or
#: ``mixed``) and the parked cars' jitter bound [m]; a row from before them holds the defaults (:data:`VEHICLE_DEFAULTS`).
VEHICLE_COLUMNS = ("vehicle", "parked_fleet", "parked_jitter_m")
VEHICLE_DEFAULTS = {"vehicle": "sedan", "parked_fleet": "uniform", "parked_jitter_m": "0"}
#: What a park or AVP test's row says before its drive of the room it leaves (empty in a cruise row): the stall's
#: width less the car's (a parallel slot: its length less the car's), the aisle's width, the start's straight-line
#: distance to the stall's centre [m] (:func:`~garage_mj.driving.sim.park_task.test_room`); and the test's park
#: difficulty, its failure probability under the run's park model (:mod:`garage_mj.scene.park_difficulty`; empty
#: for a test that is not driven, or a run without a park model).
ROOM_COLUMNS = ("bay_margin_m", "aisle_width_m", "start_distance_m", "park_difficulty")
#: A park or AVP test's pedestrians by behaviour (docs/spec.md section 8's hazards; empty in a cruise row and in a row
#: from before them): crossing behind the target stall as the car reverses (``behind_stall``), and walking along
#: the aisle past it (``beside_stall``). ``pedestrians`` counts both.
HAZARD_COLUMNS = ("pedestrians_behind", "pedestrians_beside")
TEST_COLUMNS = (*LEGACY_TEST_COLUMNS, *PARK_COLUMNS, *VEHICLE_COLUMNS, *HAZARD_COLUMNS, *ROOM_COLUMNS)
#: What a collision can hit (``hit`` column): the summary counts collisions per class.
HIT_CLASSES = ("parked_car", "wall", "pillar", "obstacle", "pedestrian", "moving_car", "clutter")
#: The failure outcomes, as ``tests.csv`` writes them, in display order.
FAILURE_KINDS = tuple(k.value for k in FAILURES)
#: Each failure outcome's count column in ``summary.csv`` (and the other tables of failures), in display order.
COUNT_COLUMNS = {s.kind: s.column for s in OUTCOMES if s.failure}
#: ``success_pct`` is over feasible tests; ``infeasible`` tests (never driven) are counted apart, and so are a park
#: run's ``unproven`` ones (:data:`PARK_SUMMARY_COLUMNS`): ``feasible`` is the tests less both.
SUMMARY_COLUMNS = ("garage", "difficulty", "route_difficulty", "E[X]", "E[Y]", "tests", "infeasible", "feasible", "successes",
                   *COUNT_COLUMNS.values(), "success_pct", *(f"hit_{c}" for c in HIT_CLASSES))
#: ``summary.csv``'s columns added for a park or AVP run (a cruise run's keep :data:`SUMMARY_COLUMNS` alone): the
#: tests whose verdict before the drive is ``unproven`` (no plan within the planner's escalated budget and no proof
#: that none exists: never driven, neither feasible nor infeasible) and their share of all tests, printed beside
#: every rate; collision and timeout rates over feasible tests, mean final position and heading errors over the driven
#: tests, mean parking time and direction changes over the successes.
PARK_SUMMARY_COLUMNS = ("unproven", "unproven_pct", "collision_pct", "timeout_pct", "mean_position_error_m", "mean_heading_error_deg",
                        "mean_park_time_s", "mean_direction_changes")
#: The task settings ``run.json`` holds only where they differ from these (a cruise run's is as before park tests).
TASK_DEFAULTS = {"task": "cruise", "maneuver": "reverse", "stall": None}
#: Settings beside the compared ones in ``run.json``: how they were chosen, not what the tests are.
PROVENANCE_KEYS = ("action_type_from",)


def vehicle_cells(env: dict[str, Any]) -> dict[str, str]:
    """The :data:`VEHICLE_COLUMNS` cells of a run whose ``GarageDriveEnv`` keyword arguments are ``env``."""
    jitter, vehicle = env.get("parked_jitter", 0), env.get("vehicle")
    return {"vehicle": getattr(vehicle, "name", vehicle) or VEHICLE_DEFAULTS["vehicle"],
            "parked_fleet": env.get("parked_fleet", VEHICLE_DEFAULTS["parked_fleet"]),
            "parked_jitter_m": f"{float(jitter):g}"}


def _is_header(fields: Sequence[str]) -> bool:
    return "garage_hash" in fields and "outcome" in fields


def _complete(row: dict[str, str]) -> bool:
    """A row a test wrote in full: every field present, an outcome, a wall time and a test index."""
    if any(v is None for v in row.values()) or row.get("outcome", "") == "" or row.get("wall_s", "") == "":
        return False
    return row.get("garage_hash", "") != "" and row.get("test", "").isdigit()


@dataclass(frozen=True)
class ParsedTests:
    """What :func:`parse_tests` read of a ``tests.csv``: the complete rows, the line each starts on, and whether the
    file needs writing back (:func:`repair_tests`) to hold just those under the :data:`TEST_COLUMNS` header."""

    rows: list[dict[str, str]]
    lines: list[int]  # the file's line (1: the first) each row starts on
    repair: bool


def parse_tests(path: Path) -> ParsedTests:
    """:func:`read_tests` without the repair: nothing is written."""
    if not path.is_file():
        return ParsedTests([], [], False)
    text = path.read_bytes().decode("utf-8", errors="replace")
    parts = text.split("\n")  # not splitlines(): it also breaks at \r, \x0b, \u2028... inside fields
    lines = [p + "\n" for p in parts[:-1]] + ([parts[-1]] if parts[-1] else [])
    first = next(csv.reader(lines[:1]), [])
    has_header = bool(lines) and lines[0].endswith("\n") and _is_header(first)
    columns = first if has_header else list(TEST_COLUMNS)
    body = lines[1:] if has_header else lines
    torn = bool(body) and not body[-1].endswith("\n")
    if torn:
        body = body[:-1]
    good: list[dict[str, str]] = []
    starts: list[int] = []
    seen: set[tuple[str, str]] = set()
    dropped = 0
    reader = csv.reader(body)
    ended = 0  # the body lines read so far
    for fields in reader:
        start, ended = ended + 1 + has_header, reader.line_num
        row = dict(zip(columns, fields)) if len(fields) == len(columns) else None
        if row is None and not has_header and len(fields) == len(LEGACY_TEST_COLUMNS):
            row = dict(zip(LEGACY_TEST_COLUMNS, fields))
        if row is not None and "task" not in row:  # a row from before park tests: a cruise test
            row = {**row, **dict.fromkeys(PARK_COLUMNS, ""), "task": "cruise"}
        if row is not None and "vehicle" not in row:  # a row from before vehicle classes: the default vehicles
            row = {**row, **VEHICLE_DEFAULTS}
        if row is not None and len(row) < len(TEST_COLUMNS):  # a header without a later column: it is empty
            row = {**dict.fromkeys(TEST_COLUMNS, ""), **row}
        if row is None or not _complete(row) or (row["garage_hash"], row["test"]) in seen:
            dropped += 1
            continue
        seen.add((row["garage_hash"], row["test"]))
        good.append(row)
        starts.append(start)
    return ParsedTests(good, starts, bool(torn or dropped or not has_header or tuple(columns) != TEST_COLUMNS))


def repair_tests(path: Path, parsed: ParsedTests) -> list[dict[str, str]]:
    """Write ``path`` back as :func:`parse_tests` found it should be (when it should); its rows."""
    if parsed.repair:
        write_csv(path, TEST_COLUMNS, parsed.rows)
    return parsed.rows


def read_tests(path: Path) -> list[dict[str, str]]:
    """The complete rows of ``tests.csv``, each (garage_hash, test) once; the file is repaired in place.

    Repairs what a crash, a second run or a careless edit can leave, never dropping a complete
    row: an empty file or a missing header (the header is written back), a torn last line (a
    ``kill -9`` mid-write: dropped), a header of other columns (rewritten with
    :data:`TEST_COLUMNS`), and duplicate (garage_hash, test) rows (the first one is kept). A file from
    before park tests (:data:`LEGACY_TEST_COLUMNS`, with or without its header) is a cruise run's: its
    rows get task ``cruise`` and empty park columns. The values are not checked: a run that resumes
    checks them against its settings (:func:`check_rows`).
    """
    return repair_tests(path, parse_tests(path))


#: Cells that hold a whole number >= 0 where not empty, and cells that hold a finite number where not empty.
_COUNT_CELLS = ("target_stall", "pedestrians", "moving_cars", "clutter", "direction_changes", "plan_cusps",
                "guide_replans", *HAZARD_COLUMNS)
_NUMBER_CELLS = ("time", "path_length", "route_length", "difficulty", "mean_road_length", "mean_intersection_degree",
                 "wall_s", "position_error_m", "heading_error_deg", "lateral_offset_m", "park_time_s",
                 "min_clearance_m", "plan_length_m", "plan_clearance_m", "inner_margin_m", "outline_clearance_m",
                 "stall_angle_deg", "bay_margin_m", "aisle_width_m", "start_distance_m", "park_difficulty")
#: Cells every row of a test holds (the rest are empty where a test was not driven or its process died).
_REQUIRED_CELLS = ("garage", "garage_hash", "test", "seed", "driver", "outcome", "difficulty", "mean_road_length",
                   "mean_intersection_degree", "wall_s", "task")
_OUTCOME_NAMES = tuple(s.kind for s in OUTCOMES)


def _finite(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def row_problem(row: dict[str, str], settings: CruiseSettings) -> tuple[str, str] | None:
    """Why ``row`` (read back from ``tests.csv``) is not a row a run with ``settings`` writes: ``(column, what is
    wrong)``, or None for a good row."""
    for col in _REQUIRED_CELLS:
        if row[col] == "":
            return col, "is empty; every test's row holds it"
    if row["outcome"] not in _OUTCOME_NAMES:
        return "outcome", f"is not a test outcome (one of {', '.join(_OUTCOME_NAMES)})"
    if row["task"] != settings.task:
        return "task", f"is not this run's task ({settings.task})"
    if row["driver"] != settings.driver:
        return "driver", f"is not this run's driver ({settings.driver!r})"
    for col in ("test", "seed"):
        if not (row[col].isascii() and row[col].isdigit()):
            return col, "is not a whole number >= 0"
    if int(row["seed"]) != cruise_seed(settings.seed, row["garage_hash"], int(row["test"])):
        return "seed", f"is not the seed of test {row['test']} of this garage under the run's seed {settings.seed}"
    for col in _COUNT_CELLS:
        cell = row.get(col, "")  # .get: a row built by hand may lack the newer columns
        if cell != "" and not (cell.isascii() and cell.isdigit()):
            return col, "is not a whole number >= 0"
    for col in _NUMBER_CELLS:
        if row.get(col, "") != "" and not _finite(row[col]):  # .get: a row built by hand may lack the newer columns
            return col, "is not a finite number"
    if row["feasible"] not in ("", "0", "1"):
        return "feasible", "is not 0, 1 or empty"
    if row["feasible"] != "" and (row["feasible"] == "0") != (row["outcome"] in NOT_DRIVEN):
        return "feasible", f"does not go with outcome {row['outcome']!r} (0 for {' and '.join(NOT_DRIVEN)} tests alone)"
    if settings.task == "cruise" and row["outcome"] == OutcomeKind.UNPROVEN.value:
        return "outcome", "is a park test's verdict; a cruise test is never unproven"
    if settings.stall is not None and row["target_stall"] not in ("", str(settings.stall)):
        return "target_stall", f"is not this run's stall ({settings.stall})"
    if settings.task == "cruise":
        extra = next((c for c in (*PARK_COLUMNS, *HAZARD_COLUMNS, *ROOM_COLUMNS) if c != "task" and row.get(c, "") != ""),
                     None)
        if extra is not None:
            return extra, "is filled in a cruise test's row (park columns are empty there)"
    elif row["maneuver"] not in ("", "reverse", "forward") or (
            settings.maneuver != "any" and row["maneuver"] not in ("", settings.maneuver)):
        return "maneuver", f"is not this run's maneuver ({settings.maneuver})"
    else:
        return _park_row_problem(row)
    return None


def _park_row_problem(row: dict[str, str]) -> tuple[str, str] | None:
    """:func:`row_problem` of a park or AVP test's row: its level (section 9), and a success as section 9 judges one."""
    if row["park_level"] == "":
        return "park_level", ("is empty; every park or AVP test's row holds its level (a row written before "
                              "docs/spec.md section 9's levels and success rule was judged by section 8's)")
    if row["park_level"] not in LEVELS:
        return "park_level", f"is not a level (one of {', '.join(LEVELS)})"
    if row["outcome"] == OutcomeKind.SUCCESS.value:
        if row["inner_margin_m"] != "" and float(row["inner_margin_m"]) < 0:
            return "inner_margin_m", "is negative in a success (a successful car stands inside the lines)"
        if row["min_clearance_m"] != "" and float(row["min_clearance_m"]) < 0:  # 0.0: closer than half a mm
            return "min_clearance_m", "is negative in a success (a successful car touched nothing)"
    return None


def check_rows(path: Path, parsed: ParsedTests, settings: CruiseSettings) -> None:
    """Refuse a resumed ``tests.csv`` row that a run with ``settings`` does not write (:func:`row_problem`): a
    :class:`CruiseError` line naming the file, the line, the cell and the fix. Counting such a row would change
    the run's results, and dropping it would too."""
    for row, line in zip(parsed.rows, parsed.lines):
        problem = row_problem(row, settings)
        if problem is not None:
            col, why = problem
            raise CruiseError(f"{path} line {line}: {col} {_shown_cell(row[col])} {why}; delete that line to run its "
                              f"test again (or restore the file), or use another --out")


def _shown_cell(text: str) -> str:
    return repr(text if len(text) <= 40 else text[:37] + "...")


def _csv_text(columns: Sequence[str], rows: Iterable[dict[str, Any]]) -> str:
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", restval="")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    atomic_write(path, _csv_text(columns, rows))


def _shown(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 40 else text[:37] + "..."


def check_settings(out: Path, settings: CruiseSettings, action_from: str = "--action-type",
                   write: bool = True) -> None:
    """Store the settings in ``run.json`` (atomically), or refuse a run whose settings differ.

    ``action_from`` (``"driver"`` or ``"--action-type"``) is recorded beside them, not compared: the same
    action type chosen another way runs the same tests, so the run resumes. ``write=False``: only refuse,
    writing nothing.
    """
    path = out / "run.json"
    mine = json.loads(json.dumps(asdict(settings)))
    # a cruise run's run.json stays as it was before park tests: the task settings only where not the defaults
    record = {**{k: v for k, v in mine.items() if k not in TASK_DEFAULTS or v != TASK_DEFAULTS[k]},
              "action_type_from": action_from}
    if path.is_file():
        try:
            theirs = json.loads(path.read_bytes().decode("utf-8"))
            if not isinstance(theirs, dict):
                raise ValueError("not an object")
        except (ValueError, UnicodeDecodeError, RecursionError) as exc:
            if parse_tests(out / "tests.csv").rows:
                raise CruiseError(f"{path} is damaged ({type(exc).__name__}: {exc}); it holds the settings "
                                  f"of the tests in {out / 'tests.csv'}: restore it, or use another --out") from None
            theirs = record  # no test was recorded under it: nothing to lose, write it afresh
            if write:
                write_json(path, record)
        theirs = {k: v for k, v in theirs.items() if k not in PROVENANCE_KEYS}
        theirs.setdefault("test_timeout", DEFAULT_TEST_TIMEOUT)  # a run.json from before the setting: the default
        for key, default in TASK_DEFAULTS.items():  # left out (a cruise run's), or from before park tests
            theirs.setdefault(key, default)

        def refuse(diff: list[str]) -> CruiseError:
            shown = ", ".join(f"{k} {_shown(theirs.get(k))} there, {_shown(mine.get(k))} now" for k in diff)
            hint = f" (--action-type {theirs['action_type']})" if diff == ["action_type"] else ""
            return CruiseError(f"{out} holds a run with other settings ({shown}); "
                               f"use another --out or the same settings to resume it{hint}")

        refuse_other_settings(theirs, mine, refuse)
    elif write:
        write_json(path, record)


def summarize(rows: Sequence[dict[str, Any]], sources: Sequence[CruiseSource],
              route: dict[str, float] | None = None) -> list[dict[str, Any]]:
    """One row per garage with tests: the paper's table columns, and the garage's route difficulty from
    ``route`` (garage hash -> value; None where there is none: not given, or NaN for no feasible stall)."""
    route = route or {}
    out = []
    for s in sources:
        mine = [r for r in rows if r["garage_hash"] == s.hash]
        if not mine:
            continue
        kinds = [r["outcome"] for r in mine]
        feasible = len(mine) - sum(kinds.count(k) for k in NOT_DRIVEN)
        hits = _hits(mine)
        out.append({
            "garage": s.name, "difficulty": round(s.difficulty, 4),
            "route_difficulty": rounded(route.get(s.hash)), "E[X]": round(s.mean_road_length, 3),
            "E[Y]": round(s.mean_intersection_degree, 3), "tests": len(mine),
            "infeasible": kinds.count("infeasible"), "feasible": feasible,
            "successes": kinds.count("success"), **{c: kinds.count(k) for k, c in COUNT_COLUMNS.items()},
            "success_pct": round(100.0 * kinds.count("success") / feasible, 2) if feasible else None,
            **{f"hit_{c}": hits.get(c, 0) for c in HIT_CLASSES},
        })
    return out


def _tested(sources: Sequence[CruiseSource], rows: Sequence[dict[str, Any]]) -> list[CruiseSource]:
    """The sources with a row, in order (the garages :func:`summarize` gives a row)."""
    hashes = {r["garage_hash"] for r in rows}
    return [s for s in sources if s.hash in hashes]


def _mean(rows: Sequence[dict[str, Any]], column: str) -> float | None:
    values = [float(r[column]) for r in rows if r.get(column, "") not in ("", None)]
    return rounded(float(np.mean(values))) if values else None


def park_summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """:data:`PARK_SUMMARY_COLUMNS` over the rows of park or AVP tests (docs/cruise.md, "Park and AVP tests")."""
    driven = driven_tests(rows)
    unproven = sum(r["outcome"] == OutcomeKind.UNPROVEN.value for r in rows)
    kinds = [r["outcome"] for r in driven]
    successes = [r for r in driven if r["outcome"] == OutcomeKind.SUCCESS.value]

    def pct(kind: str) -> float | None:
        return round(100.0 * kinds.count(kind) / len(driven), 2) if driven else None

    return {"unproven": unproven, "unproven_pct": round(100.0 * unproven / len(rows), 2) if rows else None,
            "collision_pct": pct(OutcomeKind.COLLISION.value), "timeout_pct": pct(OutcomeKind.TIMEOUT.value),
            "mean_position_error_m": _mean(driven, "position_error_m"),
            "mean_heading_error_deg": _mean(driven, "heading_error_deg"),
            "mean_park_time_s": _mean(successes, "park_time_s"),
            "mean_direction_changes": _mean(successes, "direction_changes")}


#: The breakdowns of a park or AVP run's success (docs/spec.md section 9): summary.json key -> the tests.csv column
#: whose value groups the tests.
BREAKDOWNS = {"by_level": "park_level", "by_maneuver": "maneuver", "by_stall_angle": "stall_angle_deg",
              "by_park_difficulty": "park_difficulty"}
PARK_DIFFICULTY_BAND = 0.2  # width of the park difficulty bands of ``by_park_difficulty`` ("0.2-0.4")


def _group_key(column: str, value: str) -> str:
    """The group a cell puts its test in: a stall angle as a plain number (``90``), a park difficulty as its band of
    :data:`PARK_DIFFICULTY_BAND` (``0.2-0.4``; the top band holds 1), anything else as written."""
    if column == "stall_angle_deg" and _finite(value):
        return f"{float(value):g}"
    if column == "park_difficulty" and _finite(value):
        n = round(1 / PARK_DIFFICULTY_BAND)
        k = min(int(float(value) * n), n - 1)
        return f"{k / n:.1f}-{(k + 1) / n:.1f}"
    return value


def _group_order(column: str, keys: Iterable[str]) -> list[str]:
    """``keys`` in display order: levels easiest first, maneuvers as the planner lists them, angles by size."""
    known = {"park_level": LEVELS, "maneuver": ("reverse", "forward")}.get(column)
    if known is not None:
        return [k for k in known if k in keys] + sorted(k for k in keys if k not in known)
    return sorted(keys, key=lambda k: (not _finite(k), float(k) if _finite(k) else 0.0, k))


def park_breakdown(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    """Success of a park or AVP run's tests per level, per maneuver, per stall angle and per park difficulty band
    (:data:`BREAKDOWNS`): for each
    group its ``tests``, ``infeasible``, ``unproven``, ``feasible`` (driven), ``successes`` and ``success_pct`` (over the
    feasible ones; None without any). A test whose cell is empty (not drawn: an infeasible test's maneuver is still
    written) is grouped under ``""``, except in the park difficulty bands, which leave it out (a run without a park
    model has none)."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for key, column in BREAKDOWNS.items():
        groups: dict[str, list[dict[str, Any]]] = {}
        for r in rows:
            groups.setdefault(_group_key(column, str(r.get(column, ""))), []).append(r)
        if column == "park_difficulty":  # tests without one (no park model, or not drawn) are in no band
            groups.pop("", None)
        out[key] = {}
        for name in _group_order(column, groups):
            mine = groups[name]
            kinds = [r["outcome"] for r in mine]
            driven = len(driven_tests(mine))
            wins = kinds.count(OutcomeKind.SUCCESS.value)
            out[key][name] = {"tests": len(mine), "infeasible": kinds.count(OutcomeKind.INFEASIBLE.value),
                              "unproven": kinds.count(OutcomeKind.UNPROVEN.value), "feasible": driven,
                              "successes": wins, "success_pct": round(100.0 * wins / driven, 2) if driven else None}
    return out


def breakdown_lines(breakdown: dict[str, dict[str, dict[str, Any]]]) -> list[str]:
    """One line per breakdown of :func:`park_breakdown`, e.g. ``by level: normal 9/10 (90.0%), complex ...``: what a
    park run's closing lines and the report print."""
    lines = []
    for key, groups in breakdown.items():
        parts = [f"{name or 'n/a'} {g['successes']}/{g['feasible']}"
                 + (f" ({g['success_pct']}%)" if g["success_pct"] is not None else "")
                 + (f", {g['unproven']} unproven" if g["unproven"] else "") for name, g in groups.items()]
        what = key.removeprefix("by_").replace("_", " ")
        lines.append(f"success by {what}{' [deg]' if what == 'stall angle' else ''}: {'; '.join(parts) or 'no tests'}")
    return lines


def rounded(value: float | None, digits: int = 4) -> float | None:
    """``value`` rounded for a CSV or JSON file; None (empty) for None, NaN or an infinity."""
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def driven_tests(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of tests that were driven (an infeasible or unproven test is decided before the drive, never driven)."""
    return [r for r in rows if r["outcome"] not in NOT_DRIVEN]


def failed_tests(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of tests that failed (outcome one of :data:`FAILURE_KINDS`), in their order."""
    return [r for r in rows if r["outcome"] in FAILURE_KINDS]


def failure_counts(rows: Sequence[dict[str, Any]]) -> dict[str, int]:
    """Failure kind -> its tests among ``rows``, every kind of :data:`FAILURE_KINDS` (0 too), in display order."""
    kinds = [r["outcome"] for r in rows]
    return {k: kinds.count(k) for k in FAILURE_KINDS}


def _hits(rows: Sequence[dict[str, Any]]) -> dict[str, int]:
    """Collisions by the class of what was hit."""
    out: dict[str, int] = {}
    for r in rows:
        if r["outcome"] in HIT_KINDS:
            out[r["hit"] or "?"] = out.get(r["hit"] or "?", 0) + 1
    return dict(sorted(out.items()))


def paper_failures(failures: dict[str, int]) -> dict[str, int]:
    """Failure counts by outcome folded into the paper's three classes (:data:`PAPER_CLASS`)."""
    out = {c: 0 for c in dict.fromkeys(PAPER_CLASS.values())}
    for kind, n in failures.items():
        out[PAPER_CLASS[kind]] += n
    return out


def write_outputs(out: Path, rows: Sequence[dict[str, Any]], sources: Sequence[CruiseSource],
                  settings: CruiseSettings, action_from: str = "--action-type",
                  route: dict[str, float] | None = None, route_model: str | None = None,
                  route_info: dict[str, Any] | None = None) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``summary.csv`` and ``summary.json`` from the test rows (``regression.png`` is drawn from them by
    :func:`garage_mj.reporting.cruise.cruise_figure`); ``action_from``: where the action type came from;
    ``route``: garage hash -> route difficulty under the model with key ``route_model``; ``route_info``: what
    summary.json says of that model (:meth:`~garage_mj.driving.difficulty.rating.RouteModelChoice.record`:
    its name, the drivers and action types it was fitted for, or why there is none)."""
    summary = summarize(rows, sources, route)
    parking = settings.task != "cruise"
    if parking:
        for s, row in zip(_tested(sources, rows), summary, strict=True):
            row.update(park_summary([r for r in rows if r["garage_hash"] == s.hash]))
    write_csv(out / "summary.csv", (*SUMMARY_COLUMNS, *PARK_SUMMARY_COLUMNS) if parking else SUMMARY_COLUMNS, summary)
    rated = [r for r in summary if r["success_pct"] is not None]  # garages with a feasible test
    fit = regression([r["difficulty"] for r in rated], [r["success_pct"] for r in rated])
    on_route = [r for r in rated if r["route_difficulty"] is not None]
    route_fit = regression([r["route_difficulty"] for r in on_route], [r["success_pct"] for r in on_route])
    driven = driven_tests(rows)
    timed = [r for r in driven if r["time"] != ""]  # not the tests whose driver crashed or hung: nothing was timed
    walls = [float(r["wall_s"]) for r in timed]
    sims = [float(r["time"]) for r in timed]
    kinds = [r["outcome"] for r in rows]
    failures = failure_counts(rows)
    stats = {**fit.as_reported(), "paper_r": PAPER_R,
             **{f"route_{k}": v for k, v in route_fit.as_reported().items()}, "route_model": route_model if route else None,
             **(route_info or {}),
             "garages": len(summary), "tests": len(rows),
             "infeasible": kinds.count("infeasible"), "feasible": len(driven),
             "driver": settings.driver, "seed": settings.seed,
             "action_type": settings.action_type, "action_type_from": action_from,
             "success_pct": round(100.0 * kinds.count("success") / len(driven), 2) if driven else None,
             "failures": failures,
             "paper_failures": paper_failures(failures),  # the paper's three classes
             "hits": _hits(driven),
             "seconds_per_test": round(float(np.mean(walls)), 4) if walls else None,
             "sim_seconds_per_wall_second": round(sum(sims) / sum(walls), 2) if walls and sum(walls) else None}
    if parking:  # judged by docs/spec.md section 9: the run's own r stays, the paper's cruise r is no reference for it
        del stats["paper_r"]
        stats.update(task=settings.task, maneuver=settings.maneuver, **park_summary(rows), **park_breakdown(rows))
    write_json(out / "summary.json", stats)
    return summary, stats
