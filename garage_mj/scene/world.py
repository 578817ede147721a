"""3D conventions (docs/spec.md section 6): world frame, block size and the sizes of roads, stalls, pillars.

World frame: x east, y north, z up, origin at the grid's south-west corner. Cell (row r, col c)
of an H-row grid has its centre at x = B c + B/2, y = B (H - 1 - r) + B/2 with B the block edge.

The park geometry (docs/spec.md section 9: stall width, depth and angle, aisle width, parallel slot
length) is part of :class:`WorldConfig`: bounded fields, checked whenever one is built, so a bad value
is one :class:`GeometryError` line naming the field and the fix. :data:`GEOMETRY_KEYS` names them as a
pack's manifest, a ``--layout`` file and the command line spell them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

from garage_mj.core.config import ConfigError, bounded, checked_value, read_toml
from garage_mj.core.geometry import EAST, NORTH, SOUTH, WEST

#: Stall angles to the aisle [deg] a garage can be built with: perpendicular, angled, parallel (0).
STALL_ANGLES = (90.0, 60.0, 45.0, 0.0)
#: [m per m] a lane narrows by this much for every metre an aisle is narrower than its block: the lanes of a
#: narrow aisle draw together toward its middle (a 5.5 m aisle: 0.875 m lanes, a car drives down the middle), so a
#: car turning into it keeps its swing clear of the kerb.
LANE_NARROWING = 0.75
#: [m] a parallel slot is the vehicle's length plus this (SPEC section 9).
SLOT_SPARE = 1.0
#: [m] bumper to bumper of the default vehicle (the sedan of models/car, section 6; ``FLEET["sedan"].length`` in
#: :mod:`garage_mj.scene.vehicles`, which reads the car's model: a test keeps the two equal).
DEFAULT_VEHICLE_LENGTH = 4.6


class GeometryError(ConfigError):
    """A park geometry the garage cannot be built with; the message names the field and the fix."""


@dataclass(frozen=True)
class WorldConfig:
    block: float = 9.0  # [m] edge of one grid cell
    lane_width: float = 3.5  # [m] two lanes per road, one per direction, right-hand traffic (nominal: see drive_lane_width)
    stall_width: float = bounded(2.5, ge=2.2, le=3.0, why="a bay from a compact car's doors to a van's")  # [m]
    stall_length: float = bounded(4.5, ge=4.0, le=6.0, why="the stall's depth, a compact car's length to a van's "
                                                             "plus room")  # [m]
    pillar_size: float = 0.6  # [m] square pillars
    ceiling_height: float = 3.0  # [m]
    wall_thickness: float = 0.3  # [m] outer walls
    marking_width: float = 0.15  # [m] painted lines
    # park geometry (docs/spec.md section 9): the drivable width of a road block serving stalls, and the stalls'
    # angle to their aisle [deg] (90 perpendicular; 60, 45 angled; 0 parallel slots along the aisle)
    aisle_width: float = bounded(9.0, ge=5.5, le=9.0, why="two lanes of a narrow garage to the whole 9 m block")  # [m]
    stall_angle: float = bounded(90.0, ge=0.0, le=90.0, why="one of 90, 60, 45 or 0 (parallel)")  # [deg]
    slot_length: float = bounded(DEFAULT_VEHICLE_LENGTH + SLOT_SPARE, ge=4.5, le=8.0,
                                 why="a parallel slot along the aisle: the vehicle's length + 1 m by default")  # [m]

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name in GEOMETRY_FIELDS.values():
                try:
                    checked_value(type(self), f.name, getattr(self, f.name), "park geometry")
                except ConfigError as exc:
                    raise GeometryError(_fix(f.name, str(exc))) from None
        if float(self.stall_angle) not in STALL_ANGLES:
            raise GeometryError(f"stall angle {self.stall_angle:g} degrees: a block holds stalls at 90 "
                                "(perpendicular), 60 or 45 (angled) or 0 (parallel); give --stall-angle 90, 60, 45 or 0")
        if self.aisle_width > self.block:
            raise GeometryError(f"aisle width {self.aisle_width:g} m is wider than the {self.block:g} m block; give "
                                f"--aisle-width {self.block:g} or less")

    @property
    def drive_lane_width(self) -> float:
        """[m] the lane width the roads are built with: ``lane_width``, narrowed by :data:`LANE_NARROWING` per metre
        of an aisle narrower than the block (``lane_width`` itself for the full block)."""
        return self.lane_width - LANE_NARROWING * (self.block - self.aisle_width)

    @property
    def road_width(self) -> float:
        return 2 * self.drive_lane_width

    @property
    def aisle_setback(self) -> float:
        """[m] the strip of a road block on each side of its aisle (0 for the full 9 m aisle): kerb, or stalls
        moved toward the road."""
        return (self.block - self.aisle_width) / 2

    @property
    def is_default_geometry(self) -> bool:
        """Whether the park geometry is today's (2.5 m x 4.5 m perpendicular stalls, 9 m aisles)."""
        return geometry(self) == geometry(DEFAULT_WORLD)


#: The park geometry as a manifest, a ``--layout`` file and the command line name it -> the WorldConfig field.
GEOMETRY_FIELDS: dict[str, str] = {
    "stall_width": "stall_width",
    "stall_depth": "stall_length",
    "aisle_width": "aisle_width",
    "stall_angle": "stall_angle",
    "slot_length": "slot_length",
}
GEOMETRY_KEYS = tuple(GEOMETRY_FIELDS)


def _fix(field: str, message: str) -> str:
    """A bounds error on ``field`` in the words of the command line: the key and its ``--option``."""
    key = next(k for k, f in GEOMETRY_FIELDS.items() if f == field)
    return message.replace(f"{field} = ", f"{key} = ", 1).replace(f": {field} must", f": {key} (--{key.replace('_', '-')}) "
                                                                   "must", 1)


DEFAULT_WORLD = WorldConfig()


def geometry(world: WorldConfig) -> dict[str, float]:
    """The park geometry of ``world`` as a manifest records it (keys :data:`GEOMETRY_KEYS`, [m] and [deg])."""
    return {key: float(getattr(world, f)) for key, f in GEOMETRY_FIELDS.items()}


def world_with(geometry_values: dict[str, object] | None, where: str = "park geometry",
               base: WorldConfig | None = None) -> WorldConfig:
    """``base`` (default: :data:`DEFAULT_WORLD`) with the park geometry ``geometry_values`` (keys
    :data:`GEOMETRY_KEYS`; missing ones keep ``base``'s). An unknown key or a bad value is one
    :class:`GeometryError` line naming ``where``, the key and the fix."""
    base = base or DEFAULT_WORLD
    values = dict(geometry_values or {})
    unknown = sorted(set(values) - set(GEOMETRY_FIELDS))
    if unknown:
        raise GeometryError(f"{where}: unknown key(s) {', '.join(map(str, unknown))}; known keys: "
                            f"{', '.join(GEOMETRY_KEYS)}")
    kwargs = {}
    for key, value in values.items():
        f = GEOMETRY_FIELDS[key]
        try:
            kwargs[f] = checked_value(WorldConfig, f, value, where)
        except ConfigError as exc:
            raise GeometryError(_fix(f, str(exc))) from None
    if not kwargs:
        return base
    try:
        return replace(base, **kwargs)
    except GeometryError as exc:
        raise GeometryError(f"{where}: {exc}") from None


def load_layout(path: str) -> dict[str, float]:
    """The park geometry of a ``--layout FILE.toml``: top-level keys of :data:`GEOMETRY_KEYS` (or one
    ``[layout]`` table of them); an unknown key, a bad value or a broken file is one :class:`GeometryError` line."""
    try:
        data = read_toml(path, "layout file")
    except ConfigError as exc:
        raise GeometryError(f"--layout: {exc}") from None
    if set(data) == {"layout"} and isinstance(data["layout"], dict):
        data = data["layout"]
    world = world_with(data, where=f"--layout {path}")
    return {k: v for k, v in geometry(world).items() if k in data}


#: Unit vector (x, y) in the world of each grid direction (0 W, 1 E, 2 N, 3 S).
WORLD_DIR: dict[int, tuple[float, float]] = {
    WEST: (-1.0, 0.0),
    EAST: (1.0, 0.0),
    NORTH: (0.0, 1.0),
    SOUTH: (0.0, -1.0),
}
#: Yaw [rad] of each grid direction (counter-clockwise from +x, east).
DIR_YAW: dict[int, float] = {EAST: 0.0, NORTH: math.pi / 2, WEST: math.pi, SOUTH: -math.pi / 2}


def cell_center(r: int, c: int, rows: int, world: WorldConfig = DEFAULT_WORLD) -> tuple[float, float]:
    """World (x, y) [m] of the centre of cell (r, c) in a grid of ``rows`` rows."""
    b = world.block
    return b * c + b / 2, b * (rows - 1 - r) + b / 2


def world_to_cell(x: float, y: float, rows: int, world: WorldConfig = DEFAULT_WORLD) -> tuple[int, int]:
    """Grid (row, col) containing world point (x, y) (may be outside the grid)."""
    b = world.block
    return rows - 1 - math.floor(y / b), math.floor(x / b)
