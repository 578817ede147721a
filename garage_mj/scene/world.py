"""3D conventions (docs/spec.md section 6): world frame, block size and the sizes of roads, stalls, pillars.

World frame: x east, y north, z up, origin at the grid's south-west corner. Cell (row r, col c)
of an H-row grid has its centre at x = B c + B/2, y = B (H - 1 - r) + B/2 with B the block edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from garage_mj.core.geometry import EAST, NORTH, SOUTH, WEST


@dataclass(frozen=True)
class WorldConfig:
    block: float = 9.0  # [m] edge of one grid cell
    lane_width: float = 3.5  # [m] two lanes per road, one per direction, right-hand traffic
    stall_width: float = 2.5  # [m]
    stall_length: float = 4.5  # [m]
    pillar_size: float = 0.6  # [m] square pillars
    ceiling_height: float = 3.0  # [m]
    wall_thickness: float = 0.3  # [m] outer walls
    marking_width: float = 0.15  # [m] painted lines
    # park geometry (docs/spec.md section 9): the drivable width of a road block serving stalls, and the stalls'
    # angle to their aisle [deg] (90 perpendicular; 60, 45 angled; 0 parallel slots along the aisle)
    aisle_width: float = 9.0  # [m]
    stall_angle: float = 90.0  # [deg]

    @property
    def road_width(self) -> float:
        return 2 * self.lane_width


DEFAULT_WORLD = WorldConfig()

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
