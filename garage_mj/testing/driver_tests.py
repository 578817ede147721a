"""Cruise, park and AVP tests of a driver class from a user's own test suite: run them, read the table,
assert on it.

:func:`run_driver_tests` runs ``tests`` cruise tests (or park or AVP tests: ``task``) of a driver on
each garage through the cruise runner (:func:`garage_mj.driving.cruise.run_cruise`: the same seeds, outcomes and ``tests.csv`` as
``garage-mj cruise``) and returns :class:`DriverTests`, the results table.
:meth:`DriverTests.assert_success` fails with a message a person can act on: how many feasible tests
failed and how (reasons grouped per class, :mod:`garage_mj.reporting.failures`), then each failed test
with its outcome and reason (a park or AVP test's also with its position and heading error at the
end), the MP4 of the first few (:func:`garage_mj.reporting.cruise.record_cruise_videos`,
as ``garage-mj cruise --videos``) and its ``.xosc`` (the runner's ``xosc=True``, as ``garage-mj cruise
--xosc``). Both are made only once a test has failed, so a passing suite pays for neither.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from garage_mj.core.backends import Compute
from garage_mj.core.errors import GarageMJError
from garage_mj.driving.cruise import CruiseResult, run_cruise
from garage_mj.driving.drivers import USER_FILE_MODULE
from garage_mj.driving.results import COUNT_COLUMNS, driven_tests, failed_tests
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.reporting.failures import run_failures
from garage_mj.testing.garages import TINY_MAP, cruise_sources

DEFAULT_TESTS = 3  # cruise tests per garage
DEFAULT_VIDEOS = 5  # failed tests recorded as MP4 when an assertion fails
LISTED = 20  # failed tests listed one by one in a message (the rest are in tests.csv)
QUIET = Compute(progress=False)  # one worker, no progress bar: a test suite's output stays its own
TABLE_COLUMNS = ("garage", "difficulty", "tests", "infeasible", "successes", *COUNT_COLUMNS.values(), "success_pct")


class DriverTestError(GarageMJError):
    """A driver that cruise tests cannot run (not a class importable by name); the message says the fix."""


def driver_spec(driver: type | str) -> str:
    """The ``module:Class`` spec the cruise runner loads ``driver`` by (a string is returned as it is).

    Worker processes and the ``.xosc`` replay import the class by that name, so it must be defined at
    the top level of its module (a test file is fine: pytest imports it as a module).
    """
    if isinstance(driver, str):
        return driver
    if not isinstance(driver, type):
        raise DriverTestError(f"driver {driver!r}: give the driver class (or a 'module:Class' string), not an "
                              "instance; the runner builds one per worker with driver_kwargs")
    module, name = driver.__module__, driver.__qualname__
    if "." in name:  # defined in a function (<locals>) or nested in a class
        raise DriverTestError(f"driver {name}: define the class at the top level of its module, not inside a "
                              "function or class; workers and the .xosc replay import it as module:Class")
    if getattr(sys.modules.get(module), name, None) is not driver:
        raise DriverTestError(f"driver {name}: {module}.{name} is not this class; define it at the top level of "
                              "an importable module")
    if module.startswith(USER_FILE_MODULE):  # loaded from path/to/file.py:Class: workers load the file too
        return f"{sys.modules[module].__file__}:{name}"
    return f"{module}:{name}"


def run_driver_tests(
    driver: type | str,
    garages: Any = TINY_MAP,
    tests: int = DEFAULT_TESTS,
    *,
    out_dir: str | Path,
    settings: CruiseSettings | None = None,
    compute: Compute = QUIET,
    per_map: int = 1,
    test_timeout: float | None = None,
    task: str | None = None,
    maneuver: str | None = None,
    stall: int | None = None,
) -> DriverTests:
    """Run ``tests`` cruise tests of ``driver`` on every garage of ``garages``; the results table.

    ``driver``: a class with ``reset(info)`` and ``act(obs)`` (README "Your own driver"), or a spec
    (``waypoint``, ``module:Class``); built with ``settings.driver_kwargs``. ``settings``: the seed,
    action type, occupancy, env and driver kwargs of the tests (:class:`CruiseSettings`; its driver is
    ``driver``). ``garages``: map names or map files (``per_map`` painted garages each, from
    ``settings.seed``), pack folders, a library file, ``Garage`` objects or library
    records (:func:`garage_mj.testing.garages.cruise_sources`). ``out_dir`` receives what ``garage-mj
    cruise --out`` does; a second call into it resumes (same settings) or is refused (other settings).
    ``compute``: the workers (default one, no progress bar). Test seeds derive from (seed, garage, test
    index), so results do not depend on the workers. ``test_timeout`` [s]: the wall time a test may take
    (default ``settings.test_timeout``, :data:`~garage_mj.driving.sources.DEFAULT_TEST_TIMEOUT`); a test past it
    is a ``driver_timeout`` failure and the others still run. ``task`` (``cruise``, ``park``, ``avp``),
    ``maneuver`` (``reverse``, ``forward``, ``any``) and ``stall`` (a stall id every test targets), when
    given, replace the ones of ``settings`` (docs/spec.md section 8; ``garage-mj cruise --task``).
    """
    settings = settings if settings is not None else CruiseSettings()
    timeout = settings.test_timeout if test_timeout is None else test_timeout
    chosen = {k: v for k, v in (("task", task), ("maneuver", maneuver), ("stall", stall)) if v is not None}
    settings = dataclasses.replace(settings, driver=driver_spec(driver), test_timeout=timeout, **chosen)
    sources = cruise_sources(garages, per_map, settings.seed)
    call = {"sources": sources, "tests": tests, "settings": settings, "out_dir": out_dir, "compute": compute}
    return DriverTests(run_cruise(**call), tuple(sources), call)


def _replay_command(spec: str) -> str:
    """The command that drives a test's ``.xosc`` again with driver ``spec`` (which it records)."""
    module = sys.modules.get(spec.partition(":")[0]) if ":" in spec else None
    where = getattr(module, "__file__", None)
    if where is None or spec.partition(":")[0].startswith("garage_mj."):
        return "garage-mj cruise --scenario-file FILE.xosc --out DIR"
    root = Path(where).resolve().parents[spec.partition(":")[0].count(".")]  # where the module is importable from
    return f"PYTHONPATH={root} garage-mj cruise --scenario-file FILE.xosc --out DIR"


def _park_errors(row: dict[str, str]) -> str:
    """A park or AVP test's errors at the end (`` (position error 1.2 m, heading error 14.0 deg)``); empty for a
    cruise test's row, whose park columns are empty."""
    pos, head = row.get("position_error_m", ""), row.get("heading_error_deg", "")
    if not pos or not head:
        return ""
    return f" (position error {float(pos):.2f} m, heading error {float(head):.1f} deg)"


def _pct(x: float | None) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:g}%"


@dataclass(frozen=True)
class DriverTests:
    """The cruise tests of one driver: every test's row (``rows``, as ``tests.csv``), the per-garage table
    (``summary``, as ``summary.csv``) and the run's figures (``stats``, as ``summary.json``)."""

    result: CruiseResult
    sources: tuple[CruiseSource, ...]
    _call: dict[str, Any] = field(repr=False, compare=False)

    @property
    def out_dir(self) -> Path:
        return self.result.out_dir

    @property
    def driver(self) -> str:
        return self._call["settings"].driver

    @property
    def task(self) -> str:
        """What the tests were: ``cruise``, ``park`` or ``avp`` (:attr:`CruiseSettings.task`)."""
        return self._call["settings"].task

    @property
    def rows(self) -> list[dict[str, str]]:
        return self.result.rows

    @property
    def summary(self) -> list[dict[str, Any]]:
        return self.result.summary

    @property
    def stats(self) -> dict[str, Any]:
        return self.result.stats

    @property
    def feasible(self) -> list[dict[str, str]]:
        """The tests that were driven (an infeasible or unproven test is decided before the drive, never driven)."""
        return driven_tests(self.rows)

    @property
    def failures(self) -> list[dict[str, str]]:
        """The driven tests that failed (:func:`garage_mj.driving.results.failed_tests`)."""
        return failed_tests(self.rows)

    @property
    def success_rate(self) -> float | None:
        """Successes over feasible tests, in [0, 1]; None when no test was feasible."""
        driven = self.feasible
        return sum(r["outcome"] == "success" for r in driven) / len(driven) if driven else None

    def table(self) -> str:
        """The per-garage table as text (columns of :data:`TABLE_COLUMNS`)."""
        lines = [[c if c != "success_pct" else "success" for c in TABLE_COLUMNS]]
        for r in self.summary:
            lines.append([_pct(r[c]) if c == "success_pct" else str(r[c]) for c in TABLE_COLUMNS])
        widths = [max(len(row[i]) for row in lines) for i in range(len(TABLE_COLUMNS))]
        return "\n".join("  ".join(v.ljust(w) if i == 0 else v.rjust(w) for i, (v, w) in enumerate(zip(row, widths)))
                         for row in lines)

    def __str__(self) -> str:
        return f"{self.task} tests of {self.driver} ({self.out_dir / 'tests.csv'}):\n{self.table()}"

    def _record_failures(self, videos: int) -> None:
        """The ``.xosc`` of every test and the MP4 of the first ``videos`` failures, into ``out_dir``."""
        from garage_mj.driving.drivers import ActionTypeWarning
        from garage_mj.reporting.cruise import record_cruise_videos  # matplotlib, cv2

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ActionTypeWarning)  # the first run warned already
            run_cruise(**{**self._call, "xosc": True})  # the tests are done: this only writes their .xosc
        if videos > 0:
            record_cruise_videos(self.result, self.sources, min(videos, len(self.failures)))

    def failure_report(self, min_success: float = 1.0, videos: int = DEFAULT_VIDEOS) -> str | None:
        """Why these tests miss ``min_success`` (successes over feasible tests), or None when they meet it.

        When they miss it, writes the ``.xosc`` of every test and the MP4s of the first ``videos``
        failed tests into ``out_dir`` first, and names them in the message.
        """
        if not 0.0 <= min_success <= 1.0:
            raise ValueError(f"min_success must be in [0, 1] (a share of feasible tests), got {min_success}")
        rate, n, failed = self.success_rate, len(self.feasible), self.failures
        unproven = sum(r["outcome"] == "unproven" for r in self.rows)  # park tests: no plan and no proof, never driven
        infeasible = len(self.rows) - n - unproven
        apart = f"{infeasible} infeasible" + (f", {unproven} unproven ({unproven / len(self.rows):.1%})" if unproven else "")
        garages = len({r["garage_hash"] for r in self.rows})
        head = f"{self.task} tests of {self.driver} on {garages} garage(s), {len(self.rows)} test(s)"
        if rate is None:
            why = "no forward route to the target stall clears the car" if self.task == "cruise" else \
                "no park plan into the target stall clears the car"
            return (f"{head}: none was feasible ({apart}: {why}), so nothing was driven; test more garages or more tests per garage "
                    f"(rows in {self.out_dir / 'tests.csv'})")
        if rate >= min_success - 1e-12:
            return None
        self._record_failures(videos)
        report = run_failures(self.driver, self.out_dir, self.rows, self.sources, shown=min(len(failed), LISTED))
        lines = [f"{head}: {len(failed)} of {n} feasible test(s) failed, success {rate:.1%} "
                 f"(required {min_success:.0%}; {apart}, excluded)"]
        for kind, count in report.counts.items():
            lines.append(f"  {kind} {count}: " + "; ".join(f"{g.text} (x{g.count})" for g in report.reasons[kind]))
        hits = {(r["garage"], int(r["test"])): r["hit"] for r in failed}
        errors = {(r["garage"], int(r["test"])): _park_errors(r) for r in failed}
        lines.append(f"failed tests (the first {min(videos, len(failed))} with an MP4; replay one with "
                     f"{_replay_command(self.driver)}):")
        for item in report.shown:
            hit = hits.get((item.garage, item.test))
            lines.append(f"  {item.garage} test {item.test}: {item.outcome}{f' ({hit})' if hit else ''}: "
                         f"{item.reason}{errors.get((item.garage, item.test), '')}")
            if item.video is not None:
                lines.append(f"    video: {item.video}")
            if item.xosc is not None:
                lines.append(f"    xosc:  {item.xosc}")
        if len(failed) > len(report.shown):
            lines.append(f"  ... and {len(failed) - len(report.shown)} more")
        lines.append(f"every test: {self.out_dir / 'tests.csv'}")
        return "\n".join(lines)

    def assert_success(self, min_success: float = 1.0, videos: int = DEFAULT_VIDEOS) -> DriverTests:
        """Fail (``AssertionError``) unless at least ``min_success`` of the feasible tests succeeded (all by
        default); the message is :meth:`failure_report`. Returns ``self``, to chain."""
        __tracebackhide__ = True  # pytest shows the caller's line, not this one
        message = self.failure_report(min_success, videos)
        if message is not None:
            raise AssertionError(message)
        return self
