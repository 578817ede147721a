"""The demo's parking part: park tests (each maneuver) and AVP tests on the demo's garages with the parking drivers.

Each run is a park or AVP run of :func:`garage_mj.reporting.cruise.run_cruise` into ``OUT/park/<driver>_<task>_<maneuver>/``
(its ``tests.csv``, ``summary.csv``, ``summary.json`` and ``park_success.png``, docs/spec.md section 9), resumed
like the cruise runs. What the report shows is read back from those files: a table of success by driver and
task (``summary.json``), each run's park table (:func:`garage_mj.reporting.park.park_table`) with its success by
level and maneuver (``park_success.png``, :mod:`garage_mj.reporting.park_figure`), and its first failures with a
top-down picture each (:func:`garage_mj.reporting.park.record_park_pictures`).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from garage_mj.core.backends import Compute
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.reporting.failures import run_failures
from garage_mj.reporting.park import park_table, record_park_pictures
from garage_mj.reporting.park_figure import PARK_FIGURE, park_figure
from garage_mj.reporting.report import ParkTable, RunFailures, count_noun, fmt_percent, task_noun

PARK_RUNS = "park"  # the demo's park and AVP runs, under its output folder
#: The columns of the report's table of success by driver and task (``summary.json`` of each run).
SUMMARY_COLUMNS = ["driver", "task", "maneuver", "tests", "infeasible", "unproven", "feasible", "successes",
                   "success of feasible"]


@dataclass
class ParkPart:
    """What the parking part adds to the report and to the demo's closing lines."""

    summary: ParkTable | None = None  # success by driver and task, a row per run
    tables: list[ParkTable] = field(default_factory=list)  # each run's park table with its park_success.png
    failures: list[RunFailures] = field(default_factory=list)  # each run's failures, the shown ones with a picture
    kpis: dict[str, str] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)  # a line per driver: its park and AVP results
    notes: list[str] = field(default_factory=list)  # the report's notes: where the runs' files are


def park_label(driver: str, task: str, maneuver: str) -> str:
    """A run as the report names it: ``oracle, park tests (reverse)``, ``park_assist, AVP tests (any maneuver)``."""
    return f"{driver}, {task_noun(task)} tests ({'any maneuver' if maneuver == 'any' else maneuver})"


def park_runs(drivers: Sequence[str], maneuvers: Sequence[str], avp_maneuver: str) -> list[tuple[str, str, str]]:
    """(driver, task, maneuver) of each run: per driver a park run per maneuver, then an AVP run (none when
    ``avp_maneuver`` is empty), each only where the driver is made for the task (``learned:park`` parks,
    ``learned:avp`` drives AVP tests)."""
    from garage_mj.driving.drivers import tasks_of  # the drivers' classes: deferred

    tasks = [("park", m) for m in maneuvers] + ([("avp", avp_maneuver)] if avp_maneuver else [])
    return [(d, t, m) for d in drivers for t, m in tasks if t in tasks_of(d) or "cruise" in tasks_of(d)]


def run_park_part(runs: Sequence[tuple[str, str, str]], sources: Sequence[CruiseSource], tests: int, out: Path,
                  seed: int, workers: int, shown: int, say: Callable[[str], None]) -> ParkPart:
    """Run each of ``runs`` on ``sources`` (``tests`` per garage) into ``out/park/``; returns what the report shows."""
    from garage_mj.driving.drivers import choose_action_type  # MuJoCo (the car): deferred
    from garage_mj.reporting.cruise import run_cruise

    part = ParkPart()
    rows: list[list[object]] = []
    per_driver: dict[str, list[str]] = {}
    for driver, task, maneuver in runs:
        label = park_label(driver, task, maneuver)
        choice = choose_action_type(driver)
        say(f"{task_noun(task)} tests: driver {driver} ({maneuver}), {count_noun(tests, 'test')} x "
            f"{count_noun(len(sources), 'garage')}")
        folder = out / PARK_RUNS / f"{driver}_{task}_{maneuver}"
        result = run_cruise(sources, tests, CruiseSettings(driver, seed, task=task, maneuver=maneuver), folder,
                            compute=Compute(workers=workers, progress=False), choice=choice, xosc=True)
        stats = json.loads((folder / "summary.json").read_text())  # what the report shows: the run's own files
        figure = folder / PARK_FIGURE if (folder / PARK_FIGURE).is_file() else park_figure(folder)
        table = park_table(folder, label)
        if table is not None:
            table.figure_png = figure
            if part.tables:  # what success means is the same for every run: under the first table only
                table.note = ""
            part.tables.append(table)
        drawn = record_park_pictures(folder, result.rows, sources, shown)
        part.failures.append(run_failures(label, folder, result.rows, sources, shown=shown, pictures=drawn))
        rate = fmt_percent(stats["success_pct"])
        wins = _successes(result.rows)  # tests.csv's rows, as the run wrote them
        rows.append([driver, task_noun(task), maneuver, stats["tests"], stats["infeasible"], stats.get("unproven", 0),
                     stats["feasible"], wins, rate])
        per_driver.setdefault(driver, []).append(f"{task_noun(task)} {maneuver} {wins}/{stats['feasible']}")
        say(f"{label}: {rate} of {stats['feasible']} feasible")
    if rows:
        part.summary = ParkTable("success by driver and task", SUMMARY_COLUMNS, rows,
                                 "Success of the feasible tests of each park and AVP run (its summary.json and "
                                 "tests.csv); a park test starts on the lane beside the stall, an AVP test at the "
                                 "entrance (docs/spec.md section 9).")
    part.notes.append(f"park and AVP runs: {PARK_RUNS}/<driver>_<task>_<maneuver>/ (tests.csv, summary.csv, "
                      f"summary.json, {PARK_FIGURE}, xosc/ with every test as OpenSCENARIO, pictures/ with the "
                      "failures shown above)")
    for driver, results in per_driver.items():
        part.kpis[f"{driver} park and AVP successes"] = ", ".join(results)
        part.lines.append(f"{driver}: {', '.join(results)} (successes/feasible)")
    return part


def _successes(rows: Sequence[dict[str, str]]) -> int:
    return sum(r["outcome"] == "success" for r in rows)
