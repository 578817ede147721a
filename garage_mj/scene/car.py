"""The ego car's model file and its geometry, as the planner, the drivers and the exporters see it.

One source for the car's physical quantities: :class:`CarConfig` holds its limits, and
:func:`car_geometry` reads its outline and axles from ``models/car/car.xml``. The MuJoCo
actuation of the car lives in :mod:`garage_mj.driving.sim.vehicle`.
"""

from __future__ import annotations

import functools
import importlib.resources
import math
from dataclasses import dataclass

import mujoco

CAR_MODEL = "car"  # folder under garage_mj.models


@dataclass(frozen=True)
class CarConfig:
    """Limits of the ego car in a garage (SPEC section 7 cruise tests)."""

    max_speed: float = 4.0  # [m/s] garage speed limit (~15 km/h)
    max_accel: float = 2.0  # [m/s^2] full throttle
    max_decel: float = 5.0  # [m/s^2] full brake
    max_steer: float = 0.7  # [rad] bicycle-model road-wheel angle at full lock (~40 deg)
    steer_rate: float = 0.8  # [rad/s] how fast the road wheels turn
    speed_lead: float = 1.0  # [m/s] most the cruise speed may run ahead of the real speed (no windup)
    brake_gain: float = 1.0  # wheel brake ctrl at full brake, 0..1 (the damper actuators)


@dataclass(frozen=True)
class CarGeometry:
    """The car as planners and drivers see it: body outline, axles and limits.

    One source: :func:`car_geometry` reads the outline and axles from ``models/car/car.xml`` and
    the limits from :class:`CarConfig`; the drive env, the drivers and the drivability checks
    all use it. The car frame has its origin at the chassis centre, x forward, y left.
    """

    wheelbase: float = 2.7  # [m] front to rear axle
    rear_axle: float = -1.35  # [m] rear axle x in the car frame
    half_width: float = 0.95  # [m] half the body width
    front: float = 2.3  # [m] front bumper x in the car frame
    rear: float = -2.3  # [m] rear bumper x in the car frame
    max_steer: float = 0.7  # [rad] road-wheel angle at steer = 1
    steer_rate: float = 0.8  # [rad/s] how fast the road wheels turn
    max_speed: float = 4.0  # [m/s]
    max_accel: float = 2.0  # [m/s^2]
    max_decel: float = 5.0  # [m/s^2]

    @property
    def max_curvature(self) -> float:
        """[1/m] tightest path curvature of the rear-axle midpoint at full lock (bicycle model)."""
        return math.tan(self.max_steer) / self.wheelbase

    @property
    def min_radius(self) -> float:
        """[m] smallest turning radius of the rear-axle midpoint."""
        return 1.0 / self.max_curvature


def car_geometry(config: CarConfig | None = None) -> CarGeometry:
    """The :class:`CarGeometry` of ``models/car`` under ``config`` (body and axles read from the model)."""
    cfg = config or CarConfig()
    return CarGeometry(**_car_body(), max_steer=cfg.max_steer, steer_rate=cfg.steer_rate, max_speed=cfg.max_speed,
                       max_accel=cfg.max_accel, max_decel=cfg.max_decel)


@functools.lru_cache(maxsize=1)
def _car_body() -> dict[str, float]:
    """Outline and axles of ``models/car`` from its compiled model (the collision box ``body_col``)."""
    with importlib.resources.as_file(car_xml_path()) as path:
        model = mujoco.MjModel.from_xml_path(str(path))

    def ident(kind, name):
        return mujoco.mj_name2id(model, kind, name)

    B, G = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_GEOM
    box = ident(G, "body_col")
    half_len, half_w = (float(v) for v in model.geom_size[box, :2])
    cx = float(model.geom_pos[box, 0])
    front_axle = float(model.body_pos[ident(B, "steer_fl"), 0])
    rear_axle = float(model.body_pos[ident(B, "wheel_rl"), 0])
    return {"wheelbase": front_axle - rear_axle, "rear_axle": rear_axle, "half_width": half_w,
            "front": cx + half_len, "rear": cx - half_len}


def car_xml_path():
    """Path (importlib resource) of ``models/car/car.xml``."""
    return importlib.resources.files("garage_mj.models") / CAR_MODEL / "car.xml"
