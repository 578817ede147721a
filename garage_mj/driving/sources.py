"""What a cruise run tests: the garages (:class:`CruiseSource`), the settings that make two runs
comparable (:class:`CruiseSettings`), and each test's seed (:func:`cruise_seed`).

A source is a garage with the metrics the summary reports, from an asset pack, a library record,
a :class:`~garage_mj.grid.garage.Garage`, or painted by the scripted painter
(:func:`painted_sources`). :class:`CruiseError` is what a cruise run raises when it cannot go on.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError, control_character
from garage_mj.driving.sim.park_task import MANEUVER_CHOICES, TASKS
from garage_mj.grid.garage import Garage
from garage_mj.grid.metrics import evaluate


class CruiseError(GarageMJError):
    """A cruise run cannot go on (settings differ from the out dir's run, a driver raised)."""


@dataclass(frozen=True)
class CruiseSource:
    """One garage to test, with the metrics the summary reports."""

    name: str  # row key in the CSVs (pack folder, "map#id", or the garage's name)
    garage: Garage
    difficulty: float
    mean_road_length: float  # E[X]
    mean_intersection_degree: float  # E[Y]
    pack: str = ""  # its asset pack folder, when it came from one (the .xosc export refers to it)

    @property
    def hash(self) -> str:
        return self.garage.canonical_hash()

    @classmethod
    def from_garage(cls, garage: Garage, name: str | None = None) -> CruiseSource:
        m = evaluate(garage)
        name = name or f"{garage.name or 'garage'}-{garage.canonical_hash()[:8]}"
        return cls(name, garage, m.difficulty,
                   m.mean_road_length, m.mean_intersection_degree)

    @classmethod
    def from_pack(cls, path: str | Path) -> CruiseSource:
        from garage_mj.export.pack import load_pack

        pack = load_pack(path)
        name = Path(pack.path).name  # the row key of its tests, printed in every summary
        if control_character(name) is not None:
            raise CruiseError(f"pack {str(path)!r}: its folder name holds the control character "
                              f"{control_character(name)!r}; rename it as garage-mj export names packs "
                              "(<name>_<hash12>)")
        src = cls.from_garage(pack.garage, name)
        return dataclasses.replace(src, pack=str(Path(pack.path).resolve()))

    @classmethod
    def from_record(cls, record: Any) -> CruiseSource:
        """From a :class:`garage_mj.generation.library.GarageRecord`."""
        return cls(f"{record.map}#{record.id}", record.garage, record.difficulty, record.mean_road_length,
                   record.mean_intersection_degree)


#: [s] Wall time a test may take before it ends as ``driver_timeout`` (``--test-timeout``): far above any honest
#: test (the slowest, the learned driver on a 13x13 garage, takes a few seconds), so only a driver that hangs meets it.
DEFAULT_TEST_TIMEOUT = 120.0
#: [s] The most ``--test-timeout`` may be (11.6 days): beyond any test, and within what the timers take.
MAX_TEST_TIMEOUT = 1_000_000.0
#: The most tests per garage a run may ask for (``--tests``).
MAX_TESTS = 1_000_000


@dataclass(frozen=True)
class CruiseSettings:
    """What makes two runs comparable; stored in ``run.json`` (as :meth:`resolved` makes them).

    ``occupancy`` is a setting of its own, never a key of ``env``. ``test_timeout`` can change a test's
    outcome (``driver_timeout``), so it is stored and compared too; a ``run.json`` written before it
    existed holds the default. So do ``task``, ``maneuver`` and ``stall`` (docs/spec.md section 8): a
    ``run.json`` from before them is a cruise run's, with every stall drawn.
    """

    driver: str = "vision"  # built-in name or module:Class
    seed: int = 0
    action_type: str | None = None  # None: the driver's own; run_cruise stores the one it resolved
    occupancy: float = 0.5  # share of non-target stalls with a parked car
    env: dict[str, Any] = field(default_factory=dict)  # more GarageDriveEnv keyword arguments
    driver_kwargs: dict[str, Any] = field(default_factory=dict)
    test_timeout: float = DEFAULT_TEST_TIMEOUT  # [s] wall time per test; past it the test is a driver_timeout
    task: str = "cruise"  # "cruise", "park" or "avp" (GarageDriveEnv(task=))
    maneuver: str = "reverse"  # park and AVP tests: "reverse", "forward" or "any" (drawn per test)
    stall: int | None = None  # the stall every test targets (None: drawn per test)

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise CruiseError(f"task {self.task!r}: use one of {', '.join(TASKS)}")
        if self.maneuver not in MANEUVER_CHOICES:
            raise CruiseError(f"maneuver {self.maneuver!r}: use one of {', '.join(MANEUVER_CHOICES)}")
        if self.stall is not None and (isinstance(self.stall, bool) or not isinstance(self.stall, int)
                                       or self.stall < 0):
            raise CruiseError(f"stall {self.stall!r}: give a stall id, an integer >= 0")
        if "occupancy" in (self.env or {}):
            raise CruiseError("env: occupancy is a cruise setting of its own (CruiseSettings.occupancy), not an "
                              "env keyword; give it as occupancy=")
        t = self.test_timeout
        if (isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t)
                or not 0 < t <= MAX_TEST_TIMEOUT):
            raise CruiseError(f"test_timeout must be a number of seconds > 0 and at most {MAX_TEST_TIMEOUT:,.0f}, got "
                              f"{t!r}; give --test-timeout SECONDS (default {DEFAULT_TEST_TIMEOUT:g})")

    @classmethod
    def from_env_kwargs(cls, driver: str, env_kwargs: dict[str, Any] | None, **fields: Any) -> CruiseSettings:
        """Settings from GarageDriveEnv keyword arguments that may hold ``occupancy`` (a training run's):
        that becomes the setting, the rest ``env``."""
        env = dict(env_kwargs or {})
        return cls(driver, occupancy=env.pop("occupancy", cls.occupancy), env=env, **fields)

    @classmethod
    def from_stored(cls, data: dict[str, Any]) -> CruiseSettings:
        """The settings a run stored: ``run.json``, or the settings of a hunt's ``hunt.json`` (no driver kwargs)."""
        return cls(data["driver"], data["seed"], data["action_type"], data["occupancy"], data.get("env") or {},
                   data.get("driver_kwargs") or {}, data.get("test_timeout", DEFAULT_TEST_TIMEOUT),
                   data.get("task", "cruise"), data.get("maneuver", "reverse"), data.get("stall"))

    def task_kwargs(self) -> dict[str, Any]:
        """The ``GarageDriveEnv`` keyword arguments of the task settings (none for a cruise run with every stall drawn)."""
        kwargs: dict[str, Any] = {} if self.task == "cruise" else {"task": self.task, "maneuver": self.maneuver}
        if self.stall is not None:
            kwargs["stall"] = self.stall
        return kwargs

    def with_sensors(self, names: Sequence[str]) -> CruiseSettings:
        """These settings with the parking sensors ``names`` (:class:`~garage_mj.driving.sim.park_sensors.SensorConfig`
        fields) on as well as those ``env`` asks for (its slot noise kept): what a driver that declares ``sensors``
        observes (:func:`~garage_mj.driving.drivers.sensors_of`)."""
        if not names:
            return self
        env = dict(self.env or {})
        asked = env.get("sensors") or {}
        if isinstance(asked, str):  # "all" or comma-separated names, as GarageDriveEnv reads them
            from garage_mj.driving.sim.park_sensors import sensor_config

            asked = {k: v for k, v in vars(sensor_config(asked)).items() if v}
        env["sensors"] = {**dict(asked), **{name: True for name in names}}
        return dataclasses.replace(self, env=env)

    def resolved(self, action_type: str) -> CruiseSettings:
        """These settings as a run uses and stores them: ``action_type`` the one chosen, plain numbers and dicts, and
        the parking sensors the driver declares turned on (:meth:`with_sensors`)."""
        from garage_mj.driving.drivers import sensors_of

        return CruiseSettings(self.driver, int(self.seed), action_type, float(self.occupancy), dict(self.env or {}),
                              dict(self.driver_kwargs or {}), float(self.test_timeout), self.task, self.maneuver,
                              None if self.stall is None else int(self.stall)).with_sensors(sensors_of(self.driver))


def painted_sources(map: str, n: int, seed: int = 0, oversample: int = 4) -> list[CruiseSource]:
    """``n`` garages of ``map`` painted by the scripted painter, spread evenly over difficulty.

    Paints ``oversample * n`` candidates (distinct garages) and keeps the ones at evenly spaced
    difficulty ranks, standing in for a library's stratified sample when there is no library.
    """
    from garage_mj.grid.painters import paint_garage

    found: dict[str, CruiseSource] = {}
    for k in range(oversample * n * 3):
        if len(found) >= oversample * n:
            break
        g = paint_garage(map, seed=seed * 10_007 + k)
        found.setdefault(g.canonical_hash(), CruiseSource.from_garage(g, f"{map}-painted{k}"))
    ranked = sorted(found.values(), key=lambda s: (s.difficulty, s.name))
    if len(ranked) <= n:
        return ranked
    picks = np.linspace(0, len(ranked) - 1, n).round().astype(int)
    return [ranked[i] for i in picks]


def cruise_seed(seed: int, garage_hash: str, index: int) -> int:
    """The seed of test ``index`` on a garage: a function of (run seed, garage hash, index) only."""
    digest = hashlib.sha256(f"{seed}:{garage_hash}:{index}".encode()).digest()
    return int.from_bytes(digest[:4], "little")
