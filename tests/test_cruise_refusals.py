"""``garage-mj cruise`` and ``hunt`` refuse bad input before they write anything (docs/reliability.md): a stall a
garage lacks, a driver made for other tasks, a resumed ``tests.csv`` row that is not a row of the run; a driver
that exits its process is a ``driver_crash`` row with any worker count; a discrete action that is not an integer
is the driver's error; the pytest plugin says a bad stall in its one line."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from garage_mj.cli import main
from garage_mj.core.backends import Compute, LostJob, map_unordered
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.sim.vehicle import command_from_action, park_command_from_action
from garage_mj.driving.sources import CruiseError, CruiseSettings
from garage_mj.export.pack import export_pack
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.stalls import stall_layout
from tests import _crashing
from tests._cli import one_line_error, snapshot

pytest_plugins = ["pytester"]

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}
QUIET = Compute(progress=False)


@pytest.fixture(scope="module")
def tiny():
    return paint_garage("tiny_7x11", seed=1)


@pytest.fixture(scope="module")
def packs(tiny, tmp_path_factory) -> Path:
    """Packs of two garages: ``tiny`` and a larger one with more stalls."""
    out = tmp_path_factory.mktemp("packs")
    export_pack(tiny, out)
    export_pack(paint_garage("m5_13x13_aligned", seed=3), out)
    return out


@pytest.fixture(scope="module")
def finished(packs, tmp_path_factory) -> tuple[Path, list[str]]:
    """A finished cruise run of 2 tests on one garage (``tiny``'s pack), and the command that made it."""
    one = tmp_path_factory.mktemp("one")
    tiny_pack = next(d for d in packs.iterdir() if d.is_dir() and "tiny" in (d / "garage.json").read_text())
    shutil.copytree(tiny_pack, one / tiny_pack.name)
    out = tmp_path_factory.mktemp("runs") / "done"
    args = ["cruise", "--packs", str(one), "--tests", "2", "--driver", "waypoint", "--quiet"]
    assert main([*args, "--out", str(out)]) == 0
    return out, args


def test_a_stall_a_garage_lacks_is_refused_before_anything_is_written(packs, tiny, tmp_path, capsys):
    stalls = len(stall_layout(tiny).stalls)
    out = tmp_path / "new" / "D"
    base = ["cruise", "--packs", str(packs), "--tests", "1", "--driver", "oracle", "--task", "park", "--quiet"]
    line = one_line_error(capsys, [*base, "--stall", "999", "--out", str(out)])
    assert "stall 999 does not exist" in line and "--stall" in line, line
    assert not (tmp_path / "new").exists()  # not even --out
    # a stall the larger garage has and tiny lacks: refused before the larger garage's tests run
    line = one_line_error(capsys, [*base, "--stall", str(stalls + 5), "--out", str(out)])
    assert f"stall {stalls + 5} does not exist" in line and f"0..{stalls - 1}" in line, line
    assert not (tmp_path / "new").exists()
    with pytest.raises(CruiseError, match="stall 999 does not exist"):
        run_cruise([tiny], 1, CruiseSettings("oracle", task="park", stall=999), out, compute=QUIET,
                   route_model=False)
    assert not (tmp_path / "new").exists()


def test_a_driver_made_for_other_tasks_is_refused_before_anything_is_written(tmp_path, capsys, packs):
    out = tmp_path / "D"
    line = one_line_error(capsys, ["cruise", "--packs", str(packs), "--tests", "1", "--driver", "park_assist",
                                   "--task", "cruise", "--out", str(out), "--quiet"])
    assert "'park_assist'" in line and "cruise" in line and "--task park" in line, line
    assert not out.exists()
    line = one_line_error(capsys, ["hunt", "--map", "tiny_7x11", "--driver", "park_assist", "--budget", "4",
                                   "--population", "2", "--elites", "1", "--tests", "2",
                                   "--out", str(out), "--quiet", "--no-videos"])
    assert "'park_assist'" in line and "--task park" in line, line
    assert not out.exists()


def _edit_row(path: Path, line: int, **cells: str) -> None:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    for key, value in cells.items():
        rows[line - 1][header.index(key)] = value
    with open(path, "w", newline="") as f:
        csv.writer(f).writerows(rows)


@pytest.mark.parametrize(("cells", "named"), [
    ({"outcome": "banana"}, "outcome 'banana'"),
    ({"time": "nan"}, "time 'nan'"),
    ({"position_error_m": "nan"}, "position_error_m 'nan'"),
    ({"task": "park"}, "task 'park'"),
    ({"seed": "12"}, "seed '12'"),
    ({"feasible": "maybe"}, "feasible 'maybe'"),
])
def test_a_resumed_row_that_is_not_a_row_of_the_run_is_refused(finished, tmp_path, capsys, cells, named):
    done, args = finished
    out = tmp_path / "D"
    shutil.copytree(done, out)
    _edit_row(out / "tests.csv", 3, **cells)
    before = snapshot(out)
    line = one_line_error(capsys, [*args, "--tests", "3", "--out", str(out)])
    assert f"{out / 'tests.csv'} line 3" in line and named in line and "delete" in line, line
    assert snapshot(out) == before  # nothing repaired, summarized or run


def test_the_finished_run_resumes_as_before(finished, tmp_path, capsys):
    done, args = finished
    out = tmp_path / "D"
    shutil.copytree(done, out)
    assert main([*args, "--out", str(out)]) == 0
    assert "2 tests on 1 garages (0 new)" in capsys.readouterr().out


@pytest.mark.parametrize("workers", [1, 2])
def test_a_job_that_raises_system_exit_is_lost_as_a_crash(workers):
    got = list(map_unordered(_crashing.square_or_exit, range(4), compute=Compute(workers=workers, progress=False),
                             on_lost=lambda job, why: (job, why)))
    lost = [g for g in got if isinstance(g, tuple)]
    assert sorted(g for g in got if not isinstance(g, tuple)) == [0, 1, 9]
    assert [(job, why.kind, why.reason) for job, why in lost] == [(2, "crash", "it raised SystemExit(0)")]
    assert isinstance(lost[0][1], LostJob)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_driver_that_exits_is_a_driver_crash_row_with_any_worker_count(tiny, tmp_path, workers):
    res = run_cruise([tiny], 2, CruiseSettings("tests._crashing:ExitDriver", env=FAST), tmp_path / "c",
                     compute=Compute(workers=workers, progress=False), route_model=False)
    assert sorted((r["test"], r["outcome"], r["reason"]) for r in res.rows) == [
        (str(i), "driver_crash", "driver tests._crashing:ExitDriver: it raised SystemExit(0)") for i in (0, 1)]
    assert res.stats["failures"]["driver_crash"] == 2


def test_the_command_line_records_a_driver_that_exits(packs, tmp_path, capsys):
    one = tmp_path / "one"
    tiny_pack = next(d for d in packs.iterdir() if d.is_dir() and "tiny" in (d / "garage.json").read_text())
    shutil.copytree(tiny_pack, one / tiny_pack.name)
    assert main(["cruise", "--packs", str(one), "--tests", "1", "--driver", "tests._crashing:ExitDriver",
                 "--out", str(tmp_path / "c"), "--quiet", "--workers", "1"]) == 0
    assert "1 driver_crash: the driver's process died or hung" in capsys.readouterr().out
    with open(tmp_path / "c" / "tests.csv", newline="") as f:
        assert [r["outcome"] for r in csv.DictReader(f)] == ["driver_crash"]


def test_a_driver_that_raises_keyboard_interrupt_still_stops_the_run(tiny, tmp_path):
    with pytest.raises(KeyboardInterrupt):
        run_cruise([tiny], 2, CruiseSettings("tests._crashing:InterruptDriver", env=FAST), tmp_path / "c",
                   compute=QUIET, route_model=False)


@pytest.mark.parametrize("action", [2.7, -0.5, np.float32(1.5), True, np.bool_(False), "2", float("nan")])
def test_a_discrete_action_that_is_not_an_integer_is_refused(action):
    with pytest.raises(ValueError, match="is not one of 0..|is not finite"):
        park_command_from_action(action)
    with pytest.raises(ValueError, match="is not one of 0..|is not finite"):
        command_from_action(action)


@pytest.mark.parametrize("action", [2, np.int64(2), np.uint8(2), 2.0, np.float32(2.0), np.array(2)])
def test_a_discrete_action_that_is_an_integer_is_taken(action):
    assert park_command_from_action(action) == park_command_from_action(2)
    assert command_from_action(action) == command_from_action(2)


STALL = """
from garage_mj.driving.drivers.oracle import OracleDriver


def test_stall(garage_cruise):
    garage_cruise("oracle", tests=1, task="park").assert_success()
"""


def test_the_plugin_says_a_stall_the_garage_lacks_in_one_line(pytester):
    pytester.makepyfile(test_stall=STALL)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--garage-stall", "99999")
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "garage_cruise: stall 99999 does not exist" in text, text
    assert "Traceback" not in text and "drive_env.py" not in text and "backends.py" not in text, text


@pytest.mark.parametrize(("extra", "said"), [
    (["--tests", "99999999999999999999"], "from 1 to 1,000,000"),
    (["--workers", "5000"], "from 1 to 1,024"),
    (["--test-timeout", "1e308"], "at most 1,000,000 seconds"),
    (["--task", "park", "--stall", "999"], "stall 999 does not exist"),  # waypoint: no cruise-driver warning first
    (["--backend", "ray", "--address", "127.0.0.1:1"], "cannot reach the Ray cluster at 127.0.0.1:1"),
])
def test_cruise_refuses_a_bad_option_in_one_line_and_writes_nothing(packs, tmp_path, capsys, extra, said):
    line = one_line_error(capsys, ["cruise", "--packs", str(packs), "--driver", "waypoint", "--quiet", "--tests", "1",
                                   *extra, "--out", str(tmp_path / "new" / "D")])
    assert said in line, line
    assert not (tmp_path / "new").exists()


def test_run_cruise_refuses_a_number_of_tests_it_cannot_hold(tiny, tmp_path):
    with pytest.raises(CruiseError, match="tests must be an integer from 1 to 1,000,000"):
        run_cruise([tiny], 10**20, CruiseSettings("waypoint"), tmp_path / "D", compute=QUIET, route_model=False)
    with pytest.raises(CruiseError, match="test_timeout must be a number of seconds > 0 and at most 1,000,000"):
        CruiseSettings("waypoint", test_timeout=1e308)
    assert not (tmp_path / "D").exists()


@pytest.mark.parametrize(("extra", "said"), [
    (["--map", "no_such_map"], "no map named or at 'no_such_map'"),
    (["--map", "tiny_7x11", "--budget", "99999999999999999999"], "from 1 to 100,000,000"),
    (["--map", "tiny_7x11", "--population", "99999999999"], "from 1 to 100,000"),
    (["--map", "tiny_7x11", "--test-timeout", "1e308"], "at most 1,000,000 seconds"),
])
def test_hunt_refuses_a_bad_option_in_one_line_and_writes_nothing(tmp_path, capsys, extra, said):
    argv = ["hunt", "--quiet", "--no-videos", "--budget", "4", "--population", "2", "--elites", "1", "--tests", "2"]
    line = one_line_error(capsys, [*argv, *extra, "--out", str(tmp_path / "new" / "H")])
    assert said in line, line
    assert not (tmp_path / "new").exists()


def test_hunt_says_a_damaged_hunt_json_in_one_line(tmp_path, capsys):
    out = tmp_path / "H"
    out.mkdir()
    (out / "hunt.json").write_text("{broken")
    before = snapshot(out)
    line = one_line_error(capsys, ["hunt", "--quiet", "--no-videos", "--budget", "4", "--population", "2",
                                   "--elites", "1", "--tests", "2", "--map", "tiny_7x11", "--out", str(out)])
    assert f"{out / 'hunt.json'} is damaged" in line and "restore it" in line, line
    assert snapshot(out) == before


BAD_MARKERS = """
import pytest

MARKED = [{"tests": "3"}, {"tests": 0}, {"per_map": 0}, {"per_map": "2"}, {"maps": []}, {"maps": 5}, {"stall": 99999}]


@pytest.mark.parametrize("marked", [pytest.param(m, marks=pytest.mark.garage_mj(**m)) for m in MARKED])
def test_marked(garage_cruise, marked):
    garage_cruise("waypoint", **({"tests": 1} if "tests" not in marked else {}))
"""


def test_the_plugin_says_each_bad_choice_in_one_line(pytester):
    pytester.makepyfile(test_marked=BAD_MARKERS)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(failed=7)
    text = result.stdout.str()
    assert "Traceback" not in text and "TypeError" not in text and "ValueError" not in text, text
    for said in ("tests must be an integer from 1 to 1,000,000, got '3'", "tests must be an integer from 1 to "
                 "1,000,000, got 0", "per_map must be an integer from 1 to 1,000, got 0",
                 "per_map must be an integer from 1 to 1,000, got '2'",
                 "garages: the list is empty", "garages: cannot test int 5", "stall 99999 does not exist"):
        assert f"garage_cruise: {said}" in text, (said, text)
