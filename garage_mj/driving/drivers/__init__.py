"""Drivers: the algorithms a cruise test drives with. Built-ins by name, user drivers as ``module:Class``.

Usage: ``driver = load_driver("waypoint", noise={"steer_std": 0.05})``, then per test
``driver.reset({"seed": 0, "action_type": "continuous"})`` and per step ``driver.act(obs)``.
"""

from __future__ import annotations

import importlib
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

#: Built-in drivers: name -> "module:Class".
DRIVERS: dict[str, str] = {
    "oracle": "garage_mj.driving.drivers.oracle:OracleDriver",
    "waypoint": "garage_mj.driving.drivers.waypoint:WaypointDriver",
    "vision": "garage_mj.driving.drivers.vision:VisionDriver",
}

__all__ = [
    "DRIVERS",
    "BaseDriver",
    "CameraGeometry",
    "CarGeometry",
    "Driver",
    "DriverError",
    "DriverNoiseConfig",
    "discretize",
    "load_driver",
    "resolve_driver",
]


class DriverError(GarageMJError, ValueError):
    """A driver name or ``module:Class`` spec that cannot be loaded; the message says why."""


def resolve_driver(spec: str) -> type:
    """The driver class for a built-in name or a ``module:Class`` spec."""
    target = DRIVERS.get(spec, spec)
    module_name, sep, class_name = target.partition(":")
    if not sep or not module_name or not class_name:
        raise DriverError(
            f"unknown driver {spec!r}: use a built-in ({', '.join(DRIVERS)}) or module:Class for your own"
        )
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise DriverError(f"driver {spec!r}: cannot import module {module_name!r} ({exc})") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        raise DriverError(f"driver {spec!r}: module {module_name!r} has no attribute {class_name!r}")
    if not isinstance(cls, type) or not all(callable(getattr(cls, m, None)) for m in ("reset", "act")):
        raise DriverError(f"driver {spec!r}: {class_name} must be a class with reset(info) and act(obs)")
    return cls


def load_driver(spec: str, **kwargs: Any) -> Driver:
    """An instance of driver ``spec`` (built-in name or ``module:Class``), built with ``kwargs``."""
    cls = resolve_driver(spec)
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise DriverError(f"driver {spec!r}: cannot construct {cls.__name__} ({exc})") from None
