"""A cruise run's own HTML report (``garage-mj cruise --report``): ``OUT/report.html`` beside the run's files.

Its success and regression figures, the failures' reasons per class and the first failures with their files
(the MP4s :func:`garage_mj.reporting.cruise.record_cruise_videos` recorded, the ``.xosc`` files of ``--xosc``)
and, for a park or AVP run, the park table and a top-down picture of each failure shown
(:mod:`garage_mj.reporting.park`). A cruise run's report has neither.
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
from garage_mj.reporting.report import ReportData, count_noun, fmt_percent, write_report

REPORT_FAILURES = 3  # failures a run's report shows, each with its files


def cruise_report(out_dir: str | Path, sources: Sequence[CruiseSource | Garage], shown: int = REPORT_FAILURES) -> Path:
    """``OUT/report.html`` of the cruise run in ``out_dir``: its success and regression figures, its failures
    (the first ``shown``, with the MP4s :func:`~garage_mj.reporting.cruise.record_cruise_videos` recorded) and, for a park or AVP run, the
    park table and a top-down picture of each failure shown (drawn now; one already there is kept)."""
    out = Path(out_dir)
    srcs = [s if isinstance(s, CruiseSource) else CruiseSource.from_garage(s) for s in sources]
    rows = read_tests(out / "tests.csv")
    stats = json.loads((out / "summary.json").read_text())
    pictures = record_park_pictures(out, rows, srcs, shown)
    park = park_table(out)
    figures = {m: out / name for m, (name, _) in FIGURES.items()}
    unproven = f", {fmt_percent(stats['unproven_pct'])} unproven" if stats.get("unproven") else ""
    success = (f"{fmt_percent(stats['success_pct'])} of {stats['feasible']} feasible{unproven}"
               if stats["success_pct"] is not None else f"no feasible test{unproven}")
    data = ReportData(
        title=f"garage-mj cruise: {stats['driver']}",
        subtitle=f"{count_noun(stats['tests'], 'test')} on {count_noun(stats['garages'], 'garage')}, "
                 f"{stats['action_type']} actions",
        kpis={"success": success, "infeasible tests": str(stats["infeasible"]),
              **({"unproven tests": f"{stats['unproven']} ({fmt_percent(stats['unproven_pct'])})"}
                 if "unproven" in stats else {})},
        park_tables=[park] if park is not None else [],
        failures=[run_failures(stats["driver"], out, rows, srcs, shown=shown, pictures=pictures)],
        regression_png=figures["paper"] if figures["paper"].is_file() else None,
        regression_route_png=figures["route"] if figures["route"].is_file() else None,
        notes=["every test, its outcome and reason: tests.csv; per garage: summary.csv; over the run: summary.json"],
    )
    return write_report(data, out)
