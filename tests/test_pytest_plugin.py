"""The pytest plugin (``pytest_garage_mj``) as a user meets it: the example they copy passes, a failing
driver's message names each failed test with its MP4 and ``.xosc``, the ``--garage-*`` options beat the
marker, and a suite that uses none of it imports nothing of garage-mj."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from garage_mj.generation.library import Library
from garage_mj.testing import DriverTestError, driver_spec
from garage_mj.testing.garages import LIBRARY_GARAGES, cruise_sources

pytest_plugins = ["pytester"]

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "pytest_example" / "test_my_driver.py"

FAILING = """
import numpy as np
import pytest


class FullLock:
    action_type = "continuous"

    def reset(self, info):
        pass

    def act(self, obs):
        return np.array([1.0, 1.0], dtype=np.float32)  # full throttle, full left lock


@pytest.mark.garage_mj(tests=2)
def test_full_lock(garage_cruise):
    garage_cruise(FullLock).assert_success()
"""


def test_the_plugin_is_installed_and_loads_nothing_but_pytest(pytestconfig):
    assert pytestconfig.pluginmanager.has_plugin("pytest_garage_mj")  # loaded through its pytest11 entry point
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    code = ("import os, sys, pytest_garage_mj; "
            "print(sorted(m for m in ('garage_mj', 'numpy', 'mujoco', 'gymnasium') if m in sys.modules), "
            "os.environ.get('MUJOCO_GL'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.split() == ["[]", "None"], out.stdout + out.stderr


def test_a_suite_that_does_not_use_it_runs_as_before(pytester):
    pytester.makepyfile(test_plain="""
        import sys

        def test_plain():
            assert "garage_mj" not in sys.modules
    """)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)
    assert "garage-mj:" not in result.stdout.str()  # no report header line of its own either
    bad = pytester.runpytest_subprocess("--garage-tests", "0")
    assert bad.ret == pytest.ExitCode.USAGE_ERROR
    assert "give a whole number >= 1" in bad.stderr.str()


def test_the_readme_example_passes(pytester):
    pytester.makepyfile(test_my_driver=EXAMPLE.read_text())
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)


def test_a_failing_driver_names_each_failure_with_its_video_and_xosc(pytester):
    pytester.makepyfile(test_full_lock=FAILING)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--garage-tests", "1")
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "--garage-tests 1" not in text and "garage-mj: tests 1" in text  # the report header says it
    # the option beats the marker's tests=2: one test on the one tiny_7x11 garage
    assert "cruise tests of test_full_lock:FullLock on 1 garage(s), 1 test(s): 1 of 1 feasible" in text
    assert re.search(r"tiny_7x11-\S+ test 0: (collision|deadlock|timeout|missed_goal)", text), text
    # under CI=1 pytest prints the whole message again in the short summary: count distinct paths
    videos = sorted(set(re.findall(r"video: (\S+\.mp4)", text)))
    xoscs = sorted(set(re.findall(r"xosc: +(\S+\.xosc)", text)))
    assert len(videos) == len(xoscs) == 1, text
    assert Path(videos[0]).stat().st_size > 1000 and Path(xoscs[0]).is_file()
    assert "garage-mj cruise --scenario-file FILE.xosc" in text


def test_the_library_and_packs_fixtures_are_what_a_cruise_takes(garage_library, garage_packs):
    with Library(garage_library, create=False) as lib:
        assert lib.count() == LIBRARY_GARAGES
    from_library = cruise_sources(garage_library)
    from_packs = cruise_sources(garage_packs)
    assert [s.hash for s in from_library] and {s.hash for s in from_library} == {s.hash for s in from_packs}
    assert all(s.pack for s in from_packs)


def test_a_driver_class_must_be_importable_by_name():
    class Local:
        def reset(self, info): ...

        def act(self, obs): ...

    with pytest.raises(DriverTestError, match="top level of its module"):
        driver_spec(Local)
    assert driver_spec("waypoint") == "waypoint"


SLEEPING = """
import time

import numpy as np


class Sleepy:
    action_type = "continuous"

    def reset(self, info):
        pass

    def act(self, obs):
        time.sleep(3600)  # never returns


def test_sleepy(garage_cruise):
    garage_cruise(Sleepy, tests=1).assert_success()
"""


def test_a_driver_that_never_returns_fails_as_driver_timeout(pytester):
    """--garage-test-timeout: the test that hangs fails with driver_timeout named, within the limit."""
    pytester.makepyfile(test_sleepy=SLEEPING)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--garage-test-timeout", "1")
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "driver_timeout 1: driver test_sleepy:Sleepy: ran past the time limit of 1 s of wall time" in text, text
    assert "video:" not in text  # driven again it would hang again: no MP4 of it


def test_run_driver_tests_takes_a_time_limit(tmp_path):
    from garage_mj.testing import run_driver_tests

    res = run_driver_tests("tests._crashing:SleepDriver", tests=1, out_dir=tmp_path, test_timeout=0.5)
    assert [r["outcome"] for r in res.rows] == ["driver_timeout"] and res.success_rate == 0.0
    assert "driver_timeout 1" in res.failure_report(videos=0)


PARKING = """
import numpy as np
import pytest


class StandStill:
    action_type = "continuous"

    def reset(self, info):
        pass

    def act(self, obs):
        return np.zeros(2, dtype=np.float32)  # no pedal, no steer: it never leaves the lane


@pytest.mark.garage_mj(tests=1, task="park")
def test_the_oracle_parks(garage_cruise):
    res = garage_cruise("oracle").assert_success()
    assert res.task == "park" and [r["task"] for r in res.rows] == ["park"]


def test_standing_still_does_not_park(garage_cruise):
    garage_cruise(StandStill, tests=1).assert_success()
"""


def test_park_tests_of_a_driver_pass_with_the_oracle_and_fail_readably_standing_still(pytester):
    """task="park" (marker) and --garage-task park: the oracle parks; a car that stands still fails (no
    progress), the message giving its position and heading error."""
    pytester.makepyfile(test_parking=PARKING)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--garage-maneuver", "reverse", "-k", "oracle")
    result.assert_outcomes(passed=1)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--garage-task", "park", "-k", "standing")
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "park tests of test_parking:StandStill on 1 garage(s), 1 test(s): 1 of 1 feasible" in text, text
    assert re.search(r"tiny_7x11-\S+ test 0: (outside_stall|deadlock): .*\(position error \d+\.\d\d m, heading error "
                     r"\d+\.\d deg\)", text), text
    assert re.search(r"video: \S+\.mp4", text) and re.search(r"xosc: +\S+\.xosc", text), text
