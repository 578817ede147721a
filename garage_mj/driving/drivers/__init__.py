"""Drivers: the algorithms a cruise test drives with. Built-ins by name, user drivers as ``module:Class``
(a module on the Python path or in the current folder) or ``path/to/file.py:Class``.

Usage: ``driver = load_driver("waypoint", noise={"steer_std": 0.05})``, then per test
``driver.reset({"seed": 0, "action_type": "continuous"})`` and per step ``driver.act(obs)``.

The hand-written built-ins are in :data:`DRIVERS` (``oracle``, ``waypoint``, ``vision``, and
``park_assist``, a parking baseline for park and AVP tests only); the learned
one is ``learned`` (the shipped deep-RL model, :mod:`garage_mj.driving.drivers.learned`) or
``learned:PATH`` (a model zip of ``garage-mj train-driver``). The ``learned:`` prefix wins over
``module:Class``, so a spec string (what cruise settings store) names model and driver alike.

Each driver class declares the action type it is made for in a class attribute ``action_type``
(``"continuous"``: ``[throttle, steer]``, or ``"discrete"``: the paper's 4 actions). The hand-written
built-ins steer continuously (:class:`BaseDriver`'s default), ``learned`` uses the paper's actions;
a user class without the attribute is taken as ``"discrete"``, the paper's actions. Cruise and hunt run a driver with its own type unless told
otherwise (:func:`choose_action_type`), and warn when told otherwise.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from garage_mj.core.errors import GarageMJError
from garage_mj.driving.drivers.base import (
    BaseDriver,
    CameraGeometry,
    CarGeometry,
    Driver,
    DriverNoiseConfig,
    discretize,
)
from garage_mj.driving.learning.saved_model import learned_kind

#: Hand-written built-in drivers: name -> "module:Class".
DRIVERS: dict[str, str] = {
    "oracle": "garage_mj.driving.drivers.oracle:OracleDriver",
    "waypoint": "garage_mj.driving.drivers.waypoint:WaypointDriver",
    "vision": "garage_mj.driving.drivers.vision:VisionDriver",
    "park_assist": "garage_mj.driving.drivers.park_assist:ParkAssistDriver",
}
#: The name prefix of a module imported from a ``path/to/file.py:Class`` spec (its ``__file__`` is the path).
USER_FILE_MODULE = "garage_mj_user_driver_"
#: The learned built-in: ``learned`` (the shipped model) or ``learned:PATH`` (a model zip).
LEARNED = "learned"
LEARNED_DRIVER = "garage_mj.driving.drivers.learned:LearnedDriver"
#: The learned parking driver (park tests): ``learned:park`` or a parking model's path; the learned AVP driver
#: (AVP tests: the cruise and parking models together): ``learned:avp``.
LEARNED_PARK_DRIVER = "garage_mj.driving.drivers.learned:LearnedParkDriver"
LEARNED_AVP_DRIVER = "garage_mj.driving.drivers.learned:LearnedAVPDriver"

__all__ = [
    "DRIVERS",
    "LEARNED",
    "BaseDriver",
    "CameraGeometry",
    "CarGeometry",
    "Driver",
    "DriverError",
    "ACTION_TYPES",
    "ActionChoice",
    "ActionTypeWarning",
    "DriverNoiseConfig",
    "UNDECLARED_ACTION_TYPE",
    "USER_FILE_MODULE",
    "action_type_of",
    "choose_action_type",
    "discretize",
    "learned_model",
    "load_driver",
    "resolve_driver",
    "sensors_of",
    "tasks_of",
]

#: The action types a driver can be made for: ``[throttle, steer]`` in [-1, 1], or the paper's 4 actions.
ACTION_TYPES = ("continuous", "discrete")
#: The action type of a driver class that does not declare one: the paper's actions.
UNDECLARED_ACTION_TYPE = "discrete"


class DriverError(GarageMJError, ValueError):
    """A driver name or ``module:Class`` spec that cannot be loaded; the message says why."""


def learned_model(spec: str) -> str | None:
    """The model path of a ``learned:PATH`` spec; ``""`` for ``learned`` (the shipped model); None for
    any other spec. Raises :class:`DriverError` for ``learned:`` with no path."""
    if spec == LEARNED:
        return ""
    prefix = LEARNED + ":"
    if not spec.startswith(prefix):
        return None
    path = spec[len(prefix):]
    if not path.strip():
        raise DriverError(f"driver {spec!r}: give the model after the colon, learned:PATH (or just learned "
                          "for the shipped model)")
    return path


def _is_file_spec(module: str) -> bool:
    """Whether the part before the colon of ``path/to/file.py:Class`` names a file, not a module."""
    return module.endswith(".py") or "/" in module or os.sep in module


def _import_file(spec: str, path: str) -> ModuleType:
    """The module in file ``path`` (relative to the current folder), imported once under a name made from
    its absolute path, so a spawned worker that loads the same spec gets the same classes."""
    file = Path(path).expanduser().resolve()
    if not file.is_file():
        raise DriverError(f"driver {spec!r}: no file {path!r} (from the current folder {os.getcwd()})")
    name = USER_FILE_MODULE + hashlib.sha1(str(file).encode()).hexdigest()[:12]
    if name in sys.modules:
        return sys.modules[name]
    module_spec = importlib.util.spec_from_file_location(name, file)
    if module_spec is None or module_spec.loader is None:
        raise DriverError(f"driver {spec!r}: {path!r} is not a Python file")
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[name] = module
    try:
        module_spec.loader.exec_module(module)
    except Exception as exc:  # the user's code: say what failed in one line
        del sys.modules[name]
        raise DriverError(f"driver {spec!r}: running {path} failed: {type(exc).__name__}: {exc}") from None
    return module


def _import_module(spec: str, name: str) -> ModuleType:
    """Module ``name``, found on the Python path or in the current folder (as ``python`` finds a script's
    neighbours), without setting PYTHONPATH; the folder goes last so it shadows no installed package."""
    here = os.getcwd()
    if here not in sys.path:
        sys.path.append(here)
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name and (name == exc.name or name.startswith(exc.name + ".")):  # the driver's module itself, not one it imports
            raise DriverError(f"driver {spec!r}: cannot import module {name!r}: no such module in the current "
                              "folder or on the Python path (or give a file: path/to/file.py:Class)") from None
        raise DriverError(f"driver {spec!r}: cannot import module {name!r} ({exc})") from None
    except Exception as exc:  # the user's code: say what failed in one line
        raise DriverError(f"driver {spec!r}: importing {name} failed: {type(exc).__name__}: {exc}") from None


def resolve_driver(spec: str) -> type:
    """The driver class for a built-in name, ``learned[:PATH]``, ``module:Class`` (a module on the Python
    path or in the current folder) or ``path/to/file.py:Class``; ``learned:park`` and a parking model's
    ``learned:PATH`` give the learned parking driver's class, ``learned:avp`` the learned AVP driver's."""
    model = learned_model(spec)
    if model is not None:
        target = {"cruise": LEARNED_DRIVER, "park": LEARNED_PARK_DRIVER, "avp": LEARNED_AVP_DRIVER}[learned_kind(model)]
    else:
        target = DRIVERS.get(spec, spec)
    module_name, sep, class_name = target.rpartition(":")
    if not sep or not module_name or not class_name:
        raise DriverError(
            f"unknown driver {spec!r}: use a built-in ({', '.join(DRIVERS)}, {LEARNED} or {LEARNED}:PATH) "
            "or module:Class (or path/to/file.py:Class) for your own"
        )
    is_file = _is_file_spec(module_name)
    module = _import_file(spec, module_name) if is_file else _import_module(spec, module_name)
    cls = getattr(module, class_name, None)
    if cls is None:
        where = f"file {module_name!r}" if is_file else f"module {module_name!r}"
        raise DriverError(f"driver {spec!r}: {where} has no attribute {class_name!r}")
    if not isinstance(cls, type) or not all(callable(getattr(cls, m, None)) for m in ("reset", "act")):
        raise DriverError(f"driver {spec!r}: {class_name} must be a class with reset(info) and act(obs)")
    return cls


def load_driver(spec: str, **kwargs: Any) -> Driver:
    """An instance of driver ``spec`` (built-in name, ``learned[:PATH]`` or ``module:Class``), built
    with ``kwargs``; ``learned:PATH`` passes ``model=PATH``."""
    cls = resolve_driver(spec)
    path = learned_model(spec)
    if path:
        if "model" in kwargs:
            raise DriverError(f"driver {spec!r} names its model; give learned (and model=...) or learned:PATH, "
                              "not both")
        kwargs = {**kwargs, "model": path}
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise DriverError(f"driver {spec!r}: cannot construct {cls.__name__} ({exc})") from None


def sensors_of(spec: str) -> tuple[str, ...]:
    """The parking sensors driver ``spec`` observes besides the front camera: its class's ``sensors`` attribute
    (:class:`~garage_mj.driving.sim.park_sensors.SensorConfig` field names; none when it has none). A run turns
    them on for it (:meth:`~garage_mj.driving.sources.CruiseSettings.with_sensors`)."""
    return tuple(map(str, getattr(resolve_driver(spec), "sensors", ())))


#: The tasks of a driver class that does not declare ``tasks``: a cruise driver (docs/own-driver.md).
UNDECLARED_TASKS = ("cruise",)


def tasks_of(spec: str) -> tuple[str, ...]:
    """The tasks driver ``spec`` is made for: its class's ``tasks`` attribute (a string names one), ``("cruise",)``
    when it has none."""
    declared = getattr(resolve_driver(spec), "tasks", UNDECLARED_TASKS)
    return (declared,) if isinstance(declared, str) else tuple(map(str, declared))


class ActionTypeWarning(UserWarning):
    """A driver runs with another action type than the one it declares (it will likely drive badly)."""


def action_type_of(spec: str) -> str:
    """The action type driver ``spec`` (built-in name, ``learned[:PATH]`` or ``module:Class``) is made for: its class's
    ``action_type`` attribute, ``"discrete"`` (the paper's actions) when it has none."""
    cls = resolve_driver(spec)
    kind = getattr(cls, "action_type", UNDECLARED_ACTION_TYPE)
    if kind not in ACTION_TYPES:
        raise DriverError(f"driver {spec!r}: {cls.__name__}.action_type is {kind!r}; "
                          f"declare one of {', '.join(map(repr, ACTION_TYPES))}")
    return kind


@dataclass(frozen=True)
class ActionChoice:
    """The action type a run uses, where it came from, and the one the driver declares."""

    driver: str
    action_type: str  # the one used
    source: str  # "driver" (its own) or "--action-type" (given by the caller)
    declared: str  # the driver's own

    @property
    def label(self) -> str:
        """What a closing line says, e.g. "continuous actions, the driver's own"."""
        if self.source == "driver":
            return f"{self.action_type} actions, the driver's own"
        if self.action_type == self.declared:
            return f"{self.action_type} actions from --action-type, the driver's own too"
        return f"{self.action_type} actions from --action-type; the driver's own: {self.declared}"

    @property
    def mismatch(self) -> str | None:
        """One line naming the driver, both types and the consequence; None when the driver runs its own."""
        if self.action_type == self.declared:
            return None
        if self.declared == "continuous":
            why = ("its [throttle, steer] commands are rounded to the paper's 4 actions, which costs precision "
                   "(the waypoint driver succeeds in 24% of feasible tests that way, 99% with its own)")
        else:
            why = ("the env tells it to send [throttle, steer] commands, which a driver made for the paper's 4 "
                   "actions may not do")
        return (f"driver {self.driver!r} is made for {self.declared} actions but runs with {self.action_type} ones: "
                f"{why}; leave out --action-type to use its own")


def choose_action_type(spec: str, action_type: str | None = None, warn: bool = True) -> ActionChoice:
    """The action type to run driver ``spec`` with: ``action_type`` when given, else the driver's own
    (:func:`action_type_of`). With ``warn``, a type other than the driver's own is an
    :class:`ActionTypeWarning` (``garage-mj`` prints it as one line), never silent."""
    declared = action_type_of(spec)
    if action_type is None:
        return ActionChoice(spec, declared, "driver", declared)
    if action_type not in ACTION_TYPES:
        raise DriverError(f"action type {action_type!r}: use one of {', '.join(map(repr, ACTION_TYPES))} "
                          "(or none: the driver's own)")
    choice = ActionChoice(spec, action_type, "--action-type", declared)
    if warn and choice.mismatch:
        warnings.warn(choice.mismatch, ActionTypeWarning, stacklevel=3)
    return choice
