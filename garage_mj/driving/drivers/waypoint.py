"""``waypoint``: the baseline driver, pure pursuit on the route's lookahead point, blind to the camera.

It is privileged in that it trusts the route completely and ignores everything the camera sees,
so its failures come only from geometry the car cannot follow (tight curves, narrow passages).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from garage_mj.driving.drivers.base import BaseDriver


@dataclass(frozen=True)
class WaypointConfig:
    """Speed policy of the pure-pursuit driver."""

    cruise_speed: float = 3.0  # [m/s] on straight road
    min_speed: float = 1.0  # [m/s] never plan slower than this (except to stop)
    lateral_accel: float = 1.5  # [m/s^2] comfort limit: v <= sqrt(a_lat / |curvature|)
    stop_decel: float = 1.2  # [m/s^2] braking to stop at the goal


class WaypointDriver(BaseDriver):
    """Pure pursuit toward ``obs["waypoint"]`` with a curvature-limited speed."""

    config_class = WaypointConfig
    action_type = "continuous"  # made for [throttle, steer]; discrete actions round its commands

    def command(self, obs: dict[str, Any]) -> tuple[float, float]:
        cfg: WaypointConfig = self.config
        target = np.asarray(obs["waypoint"], dtype=float)
        speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
        kappa = self.pursuit_curvature(target)
        v = self.curve_speed(kappa, cfg.cruise_speed, cfg.min_speed, cfg.lateral_accel)
        v = min(v, self.approach_speed(obs, cfg.stop_decel))
        return self.drive_at(v, speed, kappa)
