"""A cruise run as the command runs it: the tests (:func:`garage_mj.driving.cruise.run_cruise`), then
the regression figure a person reads (``regression.png``).

The driving stage writes the run's numbers (``tests.csv``, ``summary.csv``, ``summary.json`` with
Pearson r); :func:`cruise_figure` draws ``regression.png`` from those files, so it can also be
drawn for a run folder another job filled (the hunt's ``OUT/cruise``).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from garage_mj.driving import cruise as driving_cruise
from garage_mj.driving.cruise import CruiseResult
from garage_mj.reporting.analysis import regression_plot


def cruise_figure(out_dir: str | Path) -> Path:
    """``regression.png`` of the cruise run in ``out_dir``: success % against difficulty per garage with a
    feasible test (``summary.csv``), titled with the run's driver (``run.json``)."""
    out = Path(out_dir)
    with open(out / "summary.csv", newline="") as f:
        rated = [r for r in csv.DictReader(f) if r["success_pct"] != ""]  # garages with a feasible test
    driver = json.loads((out / "run.json").read_text())["driver"]
    return regression_plot([float(r["difficulty"]) for r in rated], [float(r["success_pct"]) for r in rated],
                           out / "regression.png", title=f"Cruise success vs. difficulty ({driver})")


def run_cruise(*args: Any, **kwargs: Any) -> CruiseResult:
    """:func:`garage_mj.driving.cruise.run_cruise` (same arguments), then :func:`cruise_figure` of its folder."""
    result = driving_cruise.run_cruise(*args, **kwargs)
    cruise_figure(result.out_dir)
    return result
