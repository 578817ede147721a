"""garage-mj's pytest plugin: tiny garages, a drive env and cruise tests of your own driver in your test suite.

Installed with garage-mj (entry point ``pytest11``), so pytest loads it in every run. It imports only
pytest: garage-mj (numpy, gymnasium, MuJoCo) is imported inside the fixtures, so a suite that uses none
of them starts and runs as before. ``-p no:pytest_garage_mj`` turns it off. The machinery lives in
:mod:`garage_mj.testing`.

Fixtures:

- ``tiny_7x11`` (session): the ``tiny_7x11`` map painted by the scripted painter (seed 1), a usable ``Garage``.
- ``garage_drive_env``: ``GarageDrive-v0`` on ``tiny_7x11``, closed after the test; its keyword arguments
  by indirect parametrization (``@pytest.mark.parametrize("garage_drive_env", [{"action_type":
  "continuous"}], indirect=True)``).
- ``garage_library``: the path of an SQLite scenario library in the test's ``tmp_path`` holding 3 painted
  ``tiny_7x11`` garages.
- ``garage_packs`` (session): a folder of the asset packs of those 3 garages (shared: copy it to change it).
- ``garage_cruise``: ``garage_cruise(MyDriver)`` runs cruise tests (``task="park"`` or ``"avp"``: park or
  AVP tests, with ``maneuver`` and ``stall``; ``vehicle``: the car under test's class; ``sensors``: the parking
  sensors its driver observes too, ``"rear_camera,ultrasonic,slot"`` or ``"all"``) of a driver class and returns
  :class:`garage_mj.testing.DriverTests` (the results table; ``.assert_success()`` fails listing each
  failed test with how it failed, its MP4 and its ``.xosc``). Output in the test's ``tmp_path``.

What ``garage_cruise`` tests, from the command line (``pytest --garage-tests 20``), else the marker
``@pytest.mark.garage_mj(maps=[...], per_map=N, tests=N, workers=N, test_timeout=SECONDS, task=..., maneuver=...,
stall=ID, vehicle=..., sensors=...)``, else the
defaults; an argument given to ``garage_cruise(...)`` in the test itself wins over both. A test that runs
past ``test_timeout`` (default 120 s) fails as ``driver_timeout`` and the others still run.
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

MARKER = "garage_mj"
#: What the options and the marker choose, with the defaults: maps to paint garages of, garages per map,
#: cruise tests per garage, worker processes, wall time a test may take [s] (garage_mj's DEFAULT_TEST_TIMEOUT),
#: the task (cruise, park, avp), the park maneuver (reverse, forward, any), the target stall (None: drawn), the
#: car under test's class (docs/spec.md section 9) and the parking sensors observed (None: none; docs/observations.md).
DEFAULTS: dict[str, Any] = {"maps": ["tiny_7x11"], "per_map": 1, "tests": 3, "workers": 1, "test_timeout": 120.0,
                            "task": "cruise", "maneuver": "reverse", "stall": None, "vehicle": "sedan", "sensors": None}
TASKS = ("cruise", "park", "avp")  # garage_mj's TASKS, MANEUVER_CHOICES and FLEET (not imported: see above)
MANEUVERS = ("reverse", "forward", "any")
VEHICLES = ("compact", "sedan", "suv", "van")
SENSORS = ("rear_camera", "ultrasonic", "slot")  # garage_mj.driving.sim.park_sensors.SensorConfig's switches
_CLI_HINT = " (put --debug before the command for its traceback)"  # the command line's advice; the traceback follows here
_OPTIONS = {"maps": "garage_maps", "per_map": "garage_per_map", "tests": "garage_tests", "workers": "garage_workers",
            "test_timeout": "garage_test_timeout", "task": "garage_task", "maneuver": "garage_maneuver",
            "stall": "garage_stall", "vehicle": "garage_vehicle", "sensors": "garage_sensors"}


def _number(text: str, convert: Callable[[str], Any], valid: Callable[[Any], bool], hint: str):
    """``text`` as ``convert`` reads it; an option error saying ``hint`` where it does not read or is not ``valid``."""
    try:
        value = convert(text)
    except ValueError:
        value = None
    if value is None or not valid(value):
        raise argparse.ArgumentTypeError(f"{text!r}: {hint}")
    return value


def _positive(text: str) -> int:
    return _number(text, int, lambda v: v >= 1, "give a whole number >= 1")


def _seconds(text: str) -> float:
    return _number(text, float, lambda v: 0 < v < float("inf"), "give a number of seconds > 0")


def _stall(text: str) -> int:
    return _number(text, int, lambda v: v >= 0, "give a stall id, a whole number >= 0")


def _maps(text: str) -> list[str]:
    maps = [m.strip() for m in text.split(",") if m.strip()]
    if not maps:
        raise argparse.ArgumentTypeError(f"{text!r}: give map names or map files, comma-separated "
                                         "(e.g. tiny_7x11,m5_13x13_aligned)")
    return maps


def _sensors(text: str) -> str:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names or (names != ["all"] and not set(names) <= set(SENSORS)):
        raise argparse.ArgumentTypeError(f"{text!r}: give sensor names, comma-separated ({', '.join(SENSORS)}), "
                                         "or all")
    return ",".join(names)


def _sensor_env(sensors: str | list[str] | tuple[str, ...]) -> dict[str, bool]:
    """The drive env's ``sensors`` (a dict of switches, as ``garage-mj cruise --sensors`` stores it) of names."""
    names = [n.strip() for n in (sensors.split(",") if isinstance(sensors, str) else sensors) if n.strip()]
    return dict.fromkeys(SENSORS if names == ["all"] else names, True)


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("garage-mj", "garage-mj cruise tests (the garage_cruise fixture)")
    group.addoption("--garage-maps", type=_maps, metavar="MAPS",
                    help="comma-separated map names or map files to paint garages of (default tiny_7x11)")
    group.addoption("--garage-per-map", type=_positive, metavar="N", help="painted garages per map (default 1)")
    group.addoption("--garage-tests", type=_positive, metavar="N", help="cruise tests per garage (default 3)")
    group.addoption("--garage-workers", type=_positive, metavar="N", help="worker processes (default 1)")
    group.addoption("--garage-test-timeout", type=_seconds, metavar="SECONDS",
                    help="wall time a cruise test may take before it fails as driver_timeout (default 120)")
    group.addoption("--garage-task", choices=TASKS, help="cruise, park or avp tests (default cruise)")
    group.addoption("--garage-maneuver", choices=MANEUVERS,
                    help="park and AVP tests: reverse-in, nose-in (forward) or drawn per test (any; default reverse)")
    group.addoption("--garage-stall", type=_stall, metavar="ID",
                    help="the stall every test targets (default: drawn per test)")
    group.addoption("--garage-vehicle", choices=VEHICLES, help="the car under test's class (default sedan)")
    group.addoption("--garage-sensors", type=_sensors, metavar="NAMES",
                    help="parking sensors the driver observes too: rear_camera, ultrasonic, slot, comma-separated, "
                         "or all (default none)")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{MARKER}(maps=[...], per_map=N, tests=N, workers=N, test_timeout=SECONDS, task=..., "
                                       "maneuver=..., stall=ID, vehicle=..., sensors=...): what the "
                                       "garage_cruise fixture tests by default (--garage-* options override it)")


def pytest_report_header(config: pytest.Config) -> str | None:
    given = {k: config.getoption(o) for k, o in _OPTIONS.items() if config.getoption(o) is not None}
    if not given:
        return None  # a suite that does not ask for garage-mj sees no change
    return "garage-mj: " + ", ".join(f"{k} {','.join(v) if k == 'maps' else v}" for k, v in given.items())


def _chosen(request: pytest.FixtureRequest) -> dict[str, Any]:
    """The defaults of ``garage_cruise`` for this test: command line, then marker, then :data:`DEFAULTS`."""
    marker = request.node.get_closest_marker(MARKER)
    marked: dict[str, Any] = {}
    if marker is not None:
        unknown = sorted(set(marker.kwargs) - set(DEFAULTS))
        if marker.args or unknown:
            pytest.fail(f"@pytest.mark.{MARKER}: takes keyword arguments {', '.join(DEFAULTS)} only; "
                        f"got {', '.join(map(repr, [*marker.args, *unknown]))}", pytrace=False)
        marked = dict(marker.kwargs)
        if isinstance(marked.get("maps"), (str, Path)):
            marked["maps"] = [marked["maps"]]
    out = {}
    for key, option in _OPTIONS.items():
        given = request.config.getoption(option)
        out[key] = given if given is not None else marked.get(key, DEFAULTS[key])
    return out


@pytest.fixture(scope="session")
def tiny_7x11():
    """The ``tiny_7x11`` map painted by the scripted painter (seed 1): a usable ``Garage``, the same every run."""
    from garage_mj.testing.garages import tiny_garage

    return tiny_garage()


@pytest.fixture
def garage_drive_env(request: pytest.FixtureRequest, tiny_7x11):
    """``GarageDrive-v0`` on ``tiny_7x11`` (keyword arguments from indirect parametrization), closed after."""
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    env = GarageDriveEnv(**{"garage": tiny_7x11, **(getattr(request, "param", None) or {})})
    yield env
    env.close()


@pytest.fixture
def garage_library(tmp_path: Path) -> Path:
    """The path of an SQLite scenario library in ``tmp_path`` with 3 painted ``tiny_7x11`` garages."""
    from garage_mj.testing.garages import painted_garages, write_library

    return write_library(tmp_path / "library.sqlite", painted_garages())


@pytest.fixture(scope="session")
def garage_packs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of the asset packs of the library's 3 garages (shared by the session: copy it to change it)."""
    from garage_mj.testing.garages import painted_garages, write_packs

    return write_packs(painted_garages(), tmp_path_factory.mktemp("garage_packs"))


@pytest.fixture
def garage_cruise(request: pytest.FixtureRequest, tmp_path: Path):
    """``garage_cruise(driver, garages=None, *, tests=None, task=None, ...)``: cruise (park, AVP) tests of
    ``driver`` (a class with ``reset(info)`` and ``act(obs)``, or a spec); returns ``garage_mj.testing.DriverTests``."""
    chosen = _chosen(request)
    runs = itertools.count()

    def garage_cruise(driver, garages=None, *, tests: int | None = None, workers: int | None = None,
                      test_timeout: float | None = None,
                      per_map: int | None = None, seed: int = 0, action_type: str | None = None,
                      occupancy: float = 0.5, driver_kwargs: dict[str, Any] | None = None,
                      env: dict[str, Any] | None = None, task: str | None = None, maneuver: str | None = None,
                      stall: int | None = None, vehicle: str | None = None, sensors: str | None = None):
        from garage_mj.core.backends import Compute
        from garage_mj.core.errors import GarageMJError
        from garage_mj.driving.sources import CruiseSettings
        from garage_mj.testing import run_driver_tests

        __tracebackhide__ = True
        k = next(runs)
        given = {"maps": garages, "tests": tests, "workers": workers, "test_timeout": test_timeout,
                 "per_map": per_map, "task": task, "maneuver": maneuver, "stall": stall, "vehicle": vehicle,
                 "sensors": sensors}
        use = {key: chosen[key] if value is None else value for key, value in given.items()}  # the call's, else chosen
        env = dict(env or {})
        if use["vehicle"] != DEFAULTS["vehicle"]:  # the default car: run.json as without the option
            env.setdefault("vehicle", use["vehicle"])
        if use["sensors"]:  # none: run.json as without the option
            env.setdefault("sensors", _sensor_env(use["sensors"]))
        try:
            settings = CruiseSettings(seed=seed, action_type=action_type, occupancy=occupancy, env=env,
                                      driver_kwargs=dict(driver_kwargs or {}),  # the driver: run_driver_tests sets it
                                      task=use["task"], maneuver=use["maneuver"], stall=use["stall"])
            compute = Compute(workers=use["workers"], progress=False)
            return run_driver_tests(
                driver, use["maps"], use["tests"],
                out_dir=tmp_path / ("cruise" if k == 0 else f"cruise_{k}"), settings=settings, compute=compute,
                per_map=use["per_map"], test_timeout=use["test_timeout"])
        except GarageMJError as exc:  # a bad map, driver or garage list, or a driver that raised: one message
            message = str(exc).replace(_CLI_HINT, "")
            if exc.details:  # the driver's own traceback, from whichever process ran it
                message += f"\n{exc.details}"
        pytest.fail(f"garage_cruise: {message}", pytrace=False)  # outside the except: no chained traceback

    return garage_cruise
