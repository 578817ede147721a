"""A cruise run as the command runs it: the tests (:func:`garage_mj.driving.cruise.run_cruise`), then
what a person reads and watches of it: the regression figures (``regression.png`` on the paper's
difficulty, ``regression_route.png`` on the route difficulty; a park or AVP run has neither, but
``park_success.png``, :mod:`garage_mj.reporting.park_figure`) and, if asked, MP4s of chosen tests
(``videos/``).

The driving stage writes the run's numbers (``tests.csv``, ``summary.csv``, ``summary.json`` with
Pearson r); :func:`cruise_figure` draws the figures from those files, so they can also be
drawn for a run folder another job filled (the hunt's ``OUT/cruise``). :func:`record_cruise_videos`
drives chosen tests again with the run's settings and seeds (the same test, the same outcome) into
``OUT/videos/<garage>_<test>_<outcome>.mp4``, failures first (a run's ``report.html``:
:mod:`garage_mj.reporting.run_report`).
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from garage_mj.core.fsutil import FolderLock
from garage_mj.driving import cruise as driving_cruise
from garage_mj.driving.cruise import CruiseResult
from garage_mj.driving.sim.outcomes import FAILURES, NOT_DRIVEN, RUNNER_KINDS
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.grid.garage import Garage
from garage_mj.reporting.analysis import regression_plot

_FAILED = {k.value for k in FAILURES}
UNWATCHABLE = {*NOT_DRIVEN, *(k.value for k in RUNNER_KINDS)}  # never driven, or its driver would crash or hang again


#: The figure of each metric in a cruise run's folder, and the summary.csv column it reads.
FIGURES = {"paper": ("regression.png", "difficulty"), "route": ("regression_route.png", "route_difficulty")}


def cruise_figure(out_dir: str | Path, metric: str = "paper") -> Path | None:
    """The regression figure of the cruise run in ``out_dir``: success % against the difficulty of each
    garage with a feasible test (``summary.csv``), titled with the run's driver (``run.json``).

    ``metric="paper"``: the paper's difficulty, ``regression.png``; ``"route"``: the route difficulty,
    ``regression_route.png``, or None (nothing drawn) when ``summary.csv`` has no route difficulty (a run
    of an older garage-mj, or one without a route model). A park or AVP run gets neither (None): it is judged by
    docs/spec.md section 9, not by the paper's cruise regression (:func:`run_figures` draws its figure).
    """
    if metric not in FIGURES:
        raise ValueError(f"metric must be one of {', '.join(FIGURES)}, got {metric!r}")
    name, column = FIGURES[metric]
    out = Path(out_dir)
    if run_task(out) != "cruise":  # judged by docs/spec.md section 9, not the paper's regression: run_figures
        return None
    with open(out / "summary.csv", newline="") as f:
        # garages with a feasible test (and a route difficulty: one with a feasible test has one when computed)
        rated = [r for r in csv.DictReader(f) if r["success_pct"] != "" and r.get(column, "") != ""]
    if metric == "route" and not rated:
        return None
    driver = json.loads((out / "run.json").read_text())["driver"]
    what = "difficulty" if metric == "paper" else "route difficulty"
    return regression_plot([float(r[column]) for r in rated], [float(r["success_pct"]) for r in rated],
                           out / name, title=f"Cruise success vs. {what} ({driver})", metric=metric)


def run_task(out_dir: str | Path) -> str:
    """The task of the run in ``out_dir`` (``run.json``; a run from before tasks: ``cruise``)."""
    return json.loads((Path(out_dir) / "run.json").read_text()).get("task", "cruise")


def run_figures(out_dir: str | Path) -> list[Path]:
    """The figures of the run in ``out_dir``, by its task: a cruise run's regressions (:func:`cruise_figure`, each
    metric), a park or AVP run's success by level and maneuver (:func:`~garage_mj.reporting.park_figure.park_figure`:
    ``park_success.png``; it is not judged by the paper's cruise regression). Returns the files drawn."""
    from garage_mj.reporting.park_figure import park_figure

    if run_task(out_dir) == "cruise":
        drawn = [cruise_figure(out_dir, metric) for metric in FIGURES]
    else:
        drawn = [park_figure(out_dir)]
    return [p for p in drawn if p is not None]


def video_name(row: dict[str, Any]) -> str:
    """File name of a test's MP4: ``<garage>_<test>_<outcome>.mp4`` (the garage name made filesystem-safe)."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", str(row["garage"]))[:64].strip("-.") or "garage"
    return f"{safe}_{int(row['test']):05d}_{row['outcome']}.mp4"


def pick_tests(rows: Sequence[dict[str, Any]], sources: Sequence[CruiseSource], n: int) -> list[dict[str, Any]]:
    """Up to ``n`` driven tests to watch: the failures first, then the successes, each in garage and test
    order (infeasible tests were never driven: nothing to watch; a test whose driver crashed or hung would
    again)."""
    order = {s.hash: k for k, s in enumerate(sources)}
    driven = sorted((r for r in rows if r["outcome"] not in UNWATCHABLE and r["garage_hash"] in order),
                    key=lambda r: (r["outcome"] not in _FAILED, order[r["garage_hash"]], int(r["test"])))
    return driven[:n]


def record_cruise_videos(result: CruiseResult, sources: Sequence[CruiseSource | Garage], n: int
                         ) -> list[tuple[Path, dict[str, Any]]]:
    """MP4s of up to ``n`` tests of ``result`` (:func:`pick_tests`) in ``OUT/videos/`` (:func:`video_name`),
    each driven again with the run's settings (``run.json``); a video already there is kept. Returns
    (path, tests.csv row) pairs."""
    from garage_mj.reporting.video import record_video

    srcs = [s if isinstance(s, CruiseSource) else CruiseSource.from_garage(s) for s in sources]
    by_hash = {s.hash: s for s in srcs}
    settings = CruiseSettings.from_stored(json.loads((result.out_dir / "run.json").read_text()))
    made = []
    with FolderLock(result.out_dir, "garage-mj cruise", remove=True):
        for row in pick_tests(result.rows, srcs, n):
            path = result.out_dir / "videos" / video_name(row)
            if not path.is_file():
                record_video(by_hash[row["garage_hash"]], path, settings, test=int(row["test"]))
            made.append((path, row))
    return made


def run_cruise(*args: Any, **kwargs: Any) -> CruiseResult:
    """:func:`garage_mj.driving.cruise.run_cruise` (same arguments), then the figures of its folder (:func:`run_figures`:
    a cruise run's regressions, a park or AVP run's success by level and maneuver)."""
    result = driving_cruise.run_cruise(*args, **kwargs)
    run_figures(result.out_dir)
    return result

