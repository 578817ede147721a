"""The ego car's model file and its geometry, as the planner, the drivers and the exporters see it.

One source for the car's physical quantities: :class:`CarConfig` holds its limits,
:func:`car_geometry` reads its outline and axles from ``models/car/car.xml`` and
:func:`car_camera` the pose and field of view of its cameras. The MuJoCo actuation of the car
lives in :mod:`garage_mj.driving.sim.vehicle`.
"""

from __future__ import annotations

import functools
import importlib.resources
import math
from dataclasses import dataclass
from pathlib import Path

import mujoco

CAR_MODEL = "car"  # folder under garage_mj.models
FRONT_CAMERA = "front"  # the car model's forward camera (``ego/front`` once attached to a scene)
# The MJCF gives a camera's orientation as axes written to 6 digits: xyaxes="0 -1 0 0.173648 0 0.984808"
# is a 10 degree tilt to within 2e-7 rad. The pitch is read to this many decimals of a degree, so it comes
# out as the tilt the file means (exactly math.radians(10.0)), not as its 6-digit rounding.
PITCH_DECIMALS = 4


@dataclass(frozen=True)
class CarConfig:
    """Limits of the ego car in a garage (docs/spec.md section 7 cruise tests; reverse: section 8 park tests)."""

    max_speed: float = 4.0  # [m/s] garage speed limit (~15 km/h)
    max_accel: float = 2.0  # [m/s^2] full throttle
    max_decel: float = 5.0  # [m/s^2] full brake
    max_steer: float = 0.7  # [rad] bicycle-model road-wheel angle at full lock (~40 deg)
    steer_rate: float = 0.8  # [rad/s] how fast the road wheels turn
    speed_lead: float = 1.0  # [m/s] most the cruise speed may run ahead of the real speed (no windup)
    brake_gain: float = 1.0  # wheel brake ctrl at full brake, 0..1 (the damper actuators)
    max_reverse_speed: float = 1.5  # [m/s] top speed in reverse (park and AVP tests only)
    gear_change_speed: float = 0.1  # [m/s] below this |speed| the car is at rest: drive <-> reverse allowed


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


def car_camera(camera: str = FRONT_CAMERA, path: str | Path | None = None) -> dict[str, float]:
    """Where camera ``camera`` of the car model sits and looks, read from its compiled model.

    ``x`` [m] forward of the car centre, ``z`` [m] above the ground, ``pitch`` [rad] downward tilt
    of the optical axis (to :data:`PITCH_DECIMALS` decimals of a degree), ``fovy`` [deg] vertical
    field of view. ``path``: another car MJCF than ``models/car/car.xml``. The camera must sit on
    the car's centre line and look straight ahead (what a driver's camera geometry assumes).
    """
    return dict(_car_camera(camera, None if path is None else str(path)))


@functools.lru_cache(maxsize=8)
def _car_camera(camera: str, path: str | None) -> tuple[tuple[str, float], ...]:
    if path is None:
        with importlib.resources.as_file(car_xml_path()) as default:
            model = mujoco.MjModel.from_xml_path(str(default))
    else:
        model = mujoco.MjModel.from_xml_path(path)
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if cam < 0:
        names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)]
        raise ValueError(f"the car model has no camera {camera!r}; cameras: {', '.join(map(str, names))}")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # the car at rest on the ground (qpos0): its frame is the world's
    x, y, z = (float(v) for v in data.cam_xpos[cam])
    axis = -data.cam_xmat[cam].reshape(3, 3)[:, 2]  # a camera looks along its -z axis
    if abs(y) > 1e-9 or abs(float(axis[1])) > 1e-9:
        raise ValueError(f"car camera {camera!r} must sit on the car's centre line and look straight ahead "
                         f"(y {y:g} m, optical axis {axis.round(6).tolist()})")
    pitch = math.atan2(-float(axis[2]), math.hypot(float(axis[0]), float(axis[1])))
    pitch = math.radians(round(math.degrees(pitch), PITCH_DECIMALS))
    return ("x", x), ("z", z), ("pitch", pitch), ("fovy", float(model.cam_fovy[cam]))


def car_xml_path():
    """Path (importlib resource) of ``models/car/car.xml``."""
    return importlib.resources.files("garage_mj.models") / CAR_MODEL / "car.xml"
