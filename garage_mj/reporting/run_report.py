"""A run's own HTML report (``garage-mj cruise --report``): ``OUT/report.html`` beside the run's files, titled with
its task (``garage-mj park tests: oracle``).

Its success, the failures' reasons per class and the first failures with their files (the MP4s
:func:`garage_mj.reporting.cruise.record_cruise_videos` recorded, the ``.xosc`` files of ``--xosc``); a cruise run's
regression figures on difficulty; a park or AVP run's park table, success by level and maneuver
(:mod:`garage_mj.reporting.park_figure`) and top-down pictures (:mod:`garage_mj.reporting.park`), never the paper's
cruise regression. A cruise run's report has no park table and no pictures.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from garage_mj.driving.results import read_tests
from garage_mj.driving.sources import CruiseSource
from garage_mj.grid.garage import Garage
from garage_mj.reporting.cruise import FIGURES
from garage_mj.reporting.failures import run_failures
from garage_mj.reporting.park import park_table, record_park_pictures
from garage_mj.reporting.park_figure import PARK_FIGURE, park_figure
from garage_mj.reporting.report import (
    FailureItem,
    ReportData,
    count_noun,
    fmt_percent,
    task_noun,
    write_report,
)

REPORT_FAILURES = 3  # failures a run's report shows, each with its files


def cruise_report(out_dir: str | Path, sources: Sequence[CruiseSource | Garage], shown: int = REPORT_FAILURES,
                  pictures: str = "failures") -> Path:
    """``OUT/report.html`` of the run in ``out_dir``, titled with its task: its success, its failures (the first
    ``shown``, with the MP4s :func:`~garage_mj.reporting.cruise.record_cruise_videos` recorded) and its figures: a
    cruise run's regressions on difficulty; a park or AVP run's park table, its success by level and maneuver
    (``park_success.png``, never the paper's cruise regression) and top-down pictures (drawn now; one already there
    is kept): of each failure shown, and with ``pictures="all"`` of every driven test, the successes listed apart."""
    out = Path(out_dir)
    srcs = [s if isinstance(s, CruiseSource) else CruiseSource.from_garage(s) for s in sources]
    rows = read_tests(out / "tests.csv")
    stats = json.loads((out / "summary.json").read_text())
    task = stats.get("task", "cruise")
    noun = task_noun(task)
    drawn = record_park_pictures(out, rows, srcs, shown, pictures)
    park = park_table(out)
    unproven = f", {fmt_percent(stats['unproven_pct'])} unproven" if stats.get("unproven") else ""
    success = (f"{fmt_percent(stats['success_pct'])} of {stats['feasible']} feasible{unproven}"
               if stats["success_pct"] is not None else f"no feasible test{unproven}")
    if task == "cruise":
        figures = {m: out / name for m, (name, _) in FIGURES.items()}
        regression = {"regression_png": figures["paper"] if figures["paper"].is_file() else None,
                      "regression_route_png": figures["route"] if figures["route"].is_file() else None}
        park_png = None
    else:  # judged by docs/spec.md section 9: its own figure (drawn for a folder from before it), no regression
        regression = {}
        park_png = out / PARK_FIGURE if (out / PARK_FIGURE).is_file() else park_figure(out)
    maneuver = f" ({stats.get('maneuver', 'reverse')})" if task != "cruise" else ""
    parked = [FailureItem(r["garage"], int(r["test"]), r["outcome"], r["reason"], picture=drawn[key])
              for r in rows if r["outcome"] == "success" and (key := (r["garage_hash"], int(r["test"]))) in drawn]
    data = ReportData(
        title=f"garage-mj {noun} tests: {stats['driver']}",
        subtitle=f"{count_noun(stats['tests'], f'{noun} test')}{maneuver} on {count_noun(stats['garages'], 'garage')}, "
                 f"{stats['action_type']} actions",
        kpis={"success": success, "infeasible tests": str(stats["infeasible"]),
              **({"unproven tests": f"{stats['unproven']} ({fmt_percent(stats['unproven_pct'])})"}
                 if "unproven" in stats else {})},
        park_tables=[park] if park is not None else [],
        park_figure_png=park_png,
        parked=parked,
        failures=[run_failures(stats["driver"], out, rows, srcs, shown=shown, pictures=drawn)],
        **regression,
        notes=["every test, its outcome and reason: tests.csv; per garage: summary.csv; over the run: summary.json"],
    )
    return write_report(data, out)
