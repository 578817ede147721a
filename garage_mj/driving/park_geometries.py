"""Named park geometries: the garage geometry, parked fleet and jitter of a park or AVP test by one name.

A :class:`ParkGeometry` is the :class:`~garage_mj.scene.world.WorldConfig` fields of a geometry (docs/spec.md
section 9) with the parked fleet and its jitter; :meth:`ParkGeometry.env_kwargs` gives them as
:class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv` keyword arguments. :data:`PARK_GEOMETRIES` holds the ones
the park benchmarks (``eval/bench_park.py --geometries``) and ``garage-mj train-driver --geometries`` run on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class ParkGeometry:
    """One garage geometry of the grid: WorldConfig fields, the parked fleet and its jitter [m]."""

    name: str
    world: dict = field(default_factory=dict)
    parked_fleet: str = "uniform"
    parked_jitter: float = 0.0

    def env_kwargs(self) -> dict[str, Any]:
        """These settings as GarageDriveEnv keyword arguments (the default geometry's: none)."""
        kwargs: dict[str, Any] = {"world": dict(self.world)} if self.world else {}
        if self.parked_fleet != "uniform":
            kwargs["parked_fleet"] = self.parked_fleet
        if self.parked_jitter:
            kwargs["parked_jitter"] = self.parked_jitter
        return kwargs


#: The named park geometries (docs/spec.md section 9).
PARK_GEOMETRIES: dict[str, ParkGeometry] = {g.name: g for g in (
    ParkGeometry("default"),
    ParkGeometry("tight", {"stall_width": 2.3, "aisle_width": 6.5}, "mixed", 0.15),
    ParkGeometry("angled60", {"stall_angle": 60.0}),
    ParkGeometry("angled45", {"stall_angle": 45.0}),
    ParkGeometry("parallel", {"stall_angle": 0.0}),
    ParkGeometry("parallel_mixed", {"stall_angle": 0.0}, "mixed", 0.15),
    ParkGeometry("parallel_short", {"stall_angle": 0.0, "slot_length": 5.2}, "mixed", 0.15),  # extreme: < 4.6 + 0.9 m
)}


def park_geometry(name: str) -> ParkGeometry:
    """The geometry called ``name``; another name is a ``ValueError`` listing the names."""
    try:
        return PARK_GEOMETRIES[name]
    except KeyError:
        raise ValueError(f"park geometry {name!r}: use one of {', '.join(PARK_GEOMETRIES)}") from None


def geometry_names(names, option: str) -> tuple[str, ...]:
    """``names`` checked as the value of ``option`` (e.g. ``"hunt: --geometries"``): at least one, each a name of
    :data:`PARK_GEOMETRIES`, none twice; else a ``ValueError`` line naming the option and the fix."""
    names = tuple(names)
    unknown = [n for n in names if n not in PARK_GEOMETRIES]
    if unknown or not names:
        raise ValueError(f"{option} {','.join(unknown) or '(none)'}: give names from {', '.join(PARK_GEOMETRIES)}, "
                         "separated by commas")
    if len(set(names)) != len(names):
        raise ValueError(f"{option} {','.join(names)} names a geometry twice; give each once")
    return names
