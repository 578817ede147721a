"""A parking car's own sensors, beyond the front camera: a rear camera, ultrasonic rangefinders and a slot detector.

Each is an entry of the drive env's observation table (:mod:`~garage_mj.driving.sim.observations`), opt-in through
:class:`SensorConfig` (``GarageDriveEnv(sensors=...)``), so an env that asks for none has the observations, the
compiled model and the results it had before them:

- **rear camera** (``rear_depth``, ``rear_segmentation``): the car model's ``rear`` camera, the front camera's twin
  looking back (same resolution, planes and tilt), rendered through the front camera's GL context
  (:class:`~garage_mj.driving.sim.sensors.Camera` ``share=``).
- **ultrasonic** (``ultrasonic``): the car model's 12 MuJoCo ``rangefinder`` sensors
  (:data:`~garage_mj.scene.car.ULTRASONIC_SENSORS`), 6 per bumper at bumper height, looking outward and level.
  A rangefinder leaves out its site's own body (the chassis: the car never sees itself) and transparent geoms
  (empty stalls' parked cars, unused actor slots); level at 0.5 m it never meets the floor. Readings are
  [:data:`ULTRASONIC_MIN`, :data:`ULTRASONIC_MAX`] m: no echo (MuJoCo's -1) or one beyond reads the maximum, a
  nearer one the minimum. The drive env's model keeps the sensor sites but not the rangefinder sensors, which
  MuJoCo would compute at every physics step (12 ray casts each, more than doubling a step's time in a garage);
  :class:`Ultrasonic` casts their rays once per observation, the values MuJoCo's rangefinders give (a test
  compares them), at the state the camera renders.
- **slot detector** (``slot``): the target stall as a slot detector reports it, in the car frame: its centre
  (x forward, y left) [m], the direction it opens to relative to the car's heading [rad], its width (across its
  opening; a parallel slot's length along the aisle) and depth [m]. Optional Gaussian noise on the position and
  the yaw, drawn per observation from a generator of its own (:func:`slot_rng`, seeded by the test's seed), so
  every other draw of a test stays what it was.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from garage_mj.core.config import load_config
from garage_mj.scene.car import ULTRASONIC_SENSORS

if TYPE_CHECKING:
    from garage_mj.scene.stalls import Stall

ULTRASONIC_MIN = 0.2  # [m] nearest an ultrasonic sensor reads (nearer echoes read this)
ULTRASONIC_MAX = 5.0  # [m] farthest it reads; no echo reads this too
SLOT_STREAM = 0x5107DE  # the slot detector's noise generator: seeded by (this, the test's seed)
MAX_SLOT_SIZE = 20.0  # [m] bound of the slot detector's width and depth observation


@dataclass(frozen=True)
class SensorConfig:
    """Which of the parking sensors a drive env observes (all off by default), and the slot detector's noise."""

    rear_camera: bool = False  # rear_depth and rear_segmentation: the rear camera, configured as the front one
    ultrasonic: bool = False  # the 12 bumper rangefinders
    slot: bool = False  # the target stall's pose and size, as a slot detector reports it
    slot_position_sigma: float = 0.0  # [m] standard deviation of the slot detector's x and y (each)
    slot_yaw_sigma: float = 0.0  # [rad] standard deviation of its yaw

    def __post_init__(self) -> None:
        for name in ("slot_position_sigma", "slot_yaw_sigma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"sensors: {name} must be a finite number >= 0, got {v!r}")

    @property
    def any(self) -> bool:
        """Whether any parking sensor is on."""
        return self.rear_camera or self.ultrasonic or self.slot

    @property
    def noisy_slot(self) -> bool:
        """Whether the slot detector adds noise (and so draws from its generator)."""
        return self.slot and (self.slot_position_sigma > 0.0 or self.slot_yaw_sigma > 0.0)


NO_SENSORS = SensorConfig()
ALL_SENSORS = SensorConfig(rear_camera=True, ultrasonic=True, slot=True)


def sensor_config(value: SensorConfig | dict | str | list | tuple | None) -> SensorConfig:
    """A :class:`SensorConfig` from an instance, a dict of its fields (unknown keys are an error), sensor names
    (``"rear_camera,ultrasonic"``, a list of them; ``"all"``) or None (none)."""
    if value is None:
        return NO_SENSORS
    if isinstance(value, SensorConfig):
        return value
    if isinstance(value, dict):
        return load_config(SensorConfig, value)
    names = [n.strip() for n in (value.split(",") if isinstance(value, str) else value) if n.strip()]
    if names == ["all"]:
        return ALL_SENSORS
    known = ("rear_camera", "ultrasonic", "slot")
    bad = [n for n in names if n not in known]
    if bad:
        raise ValueError(f"unknown sensor {bad[0]!r}; sensors: {', '.join(known)} (or all)")
    return SensorConfig(**dict.fromkeys(names, True))


class Ultrasonic:
    """The car's :data:`~garage_mj.scene.car.ULTRASONIC_SENSORS` in a compiled model: what its MuJoCo rangefinders read.

    Each reading is MuJoCo's rangefinder on that site, cast when asked (:meth:`read`): ``mj_ray`` from the site along
    its z axis, leaving out the site's body, static geoms included, every geom group, transparent geoms left out;
    -1 without an echo. A model that carries the rangefinder sensors themselves (``attach_car(..., ultrasonic=True)``)
    computes them at every physics step; casting the same rays once per observation gives the same values at a
    twentieth of the cost at the drive env's 20 physics steps per control step (``eval/bench_park_sensors.py``).
    """

    def __init__(self, model: mujoco.MjModel, prefix: str = "ego/"):
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, prefix + n) for n in ULTRASONIC_SENSORS]
        if min(ids) < 0:
            missing = [prefix + n for n, i in zip(ULTRASONIC_SENSORS, ids, strict=True) if i < 0]
            raise ValueError(f"the model has no ultrasonic sensor site {missing[0]!r} (models/car has them)")
        self.model = model
        self._rays = [(i, int(model.site_bodyid[i])) for i in ids]
        self._geom = np.zeros(1, dtype=np.int32)
        self._raw = np.empty(len(ids), dtype=np.float64)

    def raw(self, data: mujoco.MjData) -> np.ndarray:
        """(12,) float64: what MuJoCo's rangefinders read at ``data``'s kinematics [m], -1 where nothing echoes."""
        m, geom, out = self.model, self._geom, self._raw
        for k, (site, body) in enumerate(self._rays):
            axis = np.ascontiguousarray(data.site_xmat[site, 2::3])  # the site's z axis: the rangefinder's ray
            out[k] = mujoco.mj_ray(m, data, data.site_xpos[site], axis, None, 1, body, geom)
        return out.copy()

    def read(self, data: mujoco.MjData) -> np.ndarray:
        """(12,) float32 ranges [m] in [:data:`ULTRASONIC_MIN`, :data:`ULTRASONIC_MAX`] (no echo: the maximum)."""
        raw = self.raw(data)
        return np.clip(np.where(raw < 0.0, ULTRASONIC_MAX, raw), ULTRASONIC_MIN, ULTRASONIC_MAX).astype(np.float32)


def slot_rng(seed: int) -> np.random.Generator:
    """The generator of a test's slot detector noise: seeded by the test's seed, apart from its other draws."""
    return np.random.default_rng([SLOT_STREAM, int(seed)])


def slot_pose(stall: Stall, x: float, y: float, yaw: float, config: SensorConfig = NO_SENSORS,
              rng: np.random.Generator | None = None) -> np.ndarray:
    """(5,) float32: ``stall`` as a slot detector on the car at (x, y, yaw) reports it (module docstring):
    centre x, y [m] in the car frame, yaw [rad] in [-pi, pi] relative to the car's, width, depth [m]. With the
    config's noise on, ``rng`` draws three normals per call (x, y, yaw, in this order)."""
    dx, dy = stall.x - x, stall.y - y
    c, s = math.cos(yaw), math.sin(yaw)
    sx, sy, syaw = c * dx + s * dy, -s * dx + c * dy, stall.yaw - yaw
    if config.noisy_slot:
        if rng is None:
            raise ValueError("a noisy slot detector needs its generator (slot_rng)")
        nx, ny, nyaw = rng.standard_normal(3)
        sx += config.slot_position_sigma * nx
        sy += config.slot_position_sigma * ny
        syaw += config.slot_yaw_sigma * nyaw
    return np.array([sx, sy, math.remainder(syaw, math.tau), stall.width, stall.length], dtype=np.float32)
