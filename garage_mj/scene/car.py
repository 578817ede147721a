"""The ego car's model file and its geometry, as the planner, the drivers and the exporters see it.

One source for the car's physical quantities: :class:`CarConfig` holds its limits,
:func:`car_geometry` reads its outline and axles from ``models/car/car.xml`` and
:func:`car_camera` the pose and field of view of its cameras. :func:`car_model` is the MuJoCo model of
any vehicle class of the fleet (:mod:`garage_mj.scene.vehicles`): ``models/car`` resized to the class's
outline, axles and full lock. The MuJoCo actuation of the car lives in :mod:`garage_mj.driving.sim.vehicle`.
"""

from __future__ import annotations

import functools
import importlib.resources
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco

if TYPE_CHECKING:
    from dm_control import mjcf

    from garage_mj.scene.vehicles import VehicleClass

CAR_MODEL = "car"  # folder under garage_mj.models
FRONT_CAMERA = "front"  # the car model's forward camera (``ego/front`` once attached to a scene)
REAR_CAMERA = "rear"  # the car model's backward camera (``ego/rear``): the front one's twin, looking back
#: The ultrasonic park sensors of ``models/car`` (rangefinders on sites of the same names), front bumper then rear,
#: each left to right: a side sensor, the outer (corner) and inner pair across the bumper, the other side sensor.
ULTRASONIC_SENSORS = tuple(f"us_{end}_{where}" for end in "fr"
                           for where in ("side_l", "outer_l", "inner_l", "inner_r", "outer_r", "side_r"))
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
        return car_body(mujoco.MjModel.from_xml_path(str(path)))


def car_body(model: mujoco.MjModel, prefix: str = "") -> dict[str, float]:
    """Outline and axles (the :class:`CarGeometry` fields ``wheelbase``, ``rear_axle``, ``half_width``, ``front``,
    ``rear``) of the car in a compiled ``model`` whose names start with ``prefix`` (``"ego/"`` once attached)."""
    def ident(kind, name):
        i = mujoco.mj_name2id(model, kind, prefix + name)
        if i < 0:
            raise ValueError(f"the model has no car {kind.name[6:].lower()} named {prefix + name!r}")
        return i

    B, G = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_GEOM
    box = ident(G, "body_col")
    half_len, half_w = (float(v) for v in model.geom_size[box, :2])
    cx = float(model.geom_pos[box, 0])
    front_axle = float(model.body_pos[ident(B, "steer_fl"), 0])
    rear_axle = float(model.body_pos[ident(B, "wheel_rl"), 0])
    return {"wheelbase": front_axle - rear_axle, "rear_axle": rear_axle, "half_width": half_w,
            "front": cx + half_len, "rear": cx - half_len}


def car_camera(camera: str = FRONT_CAMERA, path: str | Path | None = None,
               vehicle: VehicleClass | None = None) -> dict[str, float]:
    """Where camera ``camera`` of the car model sits and looks, read from its compiled model.

    ``x`` [m] forward of the car centre, ``z`` [m] above the ground, ``pitch`` [rad] downward tilt
    of the optical axis (to :data:`PITCH_DECIMALS` decimals of a degree), ``fovy`` [deg] vertical
    field of view. ``path``: another car MJCF than ``models/car/car.xml``; ``vehicle``: the car of a fleet class
    (:func:`car_model`) instead. The camera must sit on the car's centre line and look straight ahead (what a
    driver's camera geometry assumes) or, as :data:`REAR_CAMERA` does, straight back (``x`` < 0 behind the centre;
    ``pitch`` its downward tilt all the same).
    """
    return dict(_car_camera(camera, None if path is None else str(path), vehicle))


@functools.lru_cache(maxsize=8)
def _car_camera(camera: str, path: str | None, vehicle: VehicleClass | None = None) -> tuple[tuple[str, float], ...]:
    if vehicle is not None:
        root = car_model(vehicle)
        model = mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())
    elif path is None:
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


#: Dimensions of ``models/car`` that :func:`car_model` keeps for every class (the chassis frame: origin at the
#: outline's centre at axle height, x forward, z up).
WHEEL_RADIUS = 0.33  # [m] every class rolls on the same wheels
WHEEL_INSET = 0.15  # [m] body side to the wheel's centre plane: track = width - 2 x this
BODY_TOP = 0.63  # [m] top of the lower body box above the chassis origin (the cabin stands on it)
CABIN_SHARE = 1.05 / 2.3  # cabin length / body length
CABIN_SHIFT = -0.15 / 4.6  # cabin centre behind the body centre / body length
CABIN_INSET = 0.1  # [m] body side to the cabin side
GLASS_INSET = 0.05  # [m] cabin edge to the window edge
LIGHT_INSET = 0.35  # [m] body side to a headlight's centre
CAMERA_SETBACK = 0.05  # [m] bumper to the camera looking out over it (front and rear)
ULTRASONIC_INNER_Y = 0.25  # [m] centre line to each of a bumper's inner pair of ultrasonic sensors
ULTRASONIC_CORNER_INSET = 0.2  # [m] body side to a bumper's outer (corner) ultrasonic sensor
ULTRASONIC_SIDE_SETBACK = 0.4  # [m] bumper to a side ultrasonic sensor, along the body side
STEER_RANGE = 0.9  # [rad] the steering joints' range in models/car; widened for a class whose inner wheel needs more
STEER_HEADROOM = 0.05  # [rad] beyond the inner wheel's angle at full lock, where a class needs a wider range


def _r(v: float) -> float:
    """A derived dimension to the nanometre: what the model file would write (so sedan's equal models/car's)."""
    return round(float(v), 9)


def inner_wheel_angle(wheelbase: float, track: float, max_steer: float) -> float:
    """[rad] the inner front wheel's angle when the bicycle-model angle is ``max_steer`` (Ackermann)."""
    t = math.tan(max_steer)
    return math.atan(wheelbase * t / (wheelbase - track / 2 * t))


def ultrasonic_positions(length: float, width: float) -> dict[str, tuple[float, float]]:
    """Where each of :data:`ULTRASONIC_SENSORS` sits on a car body ``length`` x ``width`` [m]: (x, y) [m] in the car
    frame, on the body's surface (bumpers at x = +-length / 2, sides at y = +-width / 2). The inner pair stands
    :data:`ULTRASONIC_INNER_Y` either side of the centre line, the outer pair :data:`ULTRASONIC_CORNER_INSET` in
    from the body sides, the side ones :data:`ULTRASONIC_SIDE_SETBACK` back from the bumper. Their height and the
    directions they look in are ``models/car``'s for every class."""
    half, hw = length / 2, width / 2
    across = {"side": (_r(half - ULTRASONIC_SIDE_SETBACK), _r(hw)), "outer": (_r(half), _r(hw - ULTRASONIC_CORNER_INSET)),
              "inner": (_r(half), ULTRASONIC_INNER_Y)}
    out = {}
    for n in ULTRASONIC_SENSORS:
        _, end, where, side = n.split("_")
        x, y = across[where]
        out[n] = (x if end == "f" else -x, y if side == "l" else -y)
    return out


def drop_rangefinders(root: mjcf.RootElement) -> None:
    """Remove the ultrasonic rangefinders (:data:`ULTRASONIC_SENSORS`) from a car's ``dm_control.mjcf`` model; their
    sites stay. A model that does not read them saves a ray cast per sensor and physics step."""
    for n in ULTRASONIC_SENSORS:
        sensor = root.find("sensor", n)
        if sensor is not None:
            sensor.remove()


def car_model(vehicle: VehicleClass | None = None, name: str = CAR_MODEL) -> mjcf.RootElement:
    """The MuJoCo car of ``vehicle`` (a :class:`~garage_mj.scene.vehicles.VehicleClass`; None: ``models/car`` as
    it is) as a ``dm_control.mjcf`` model named ``name``, with its free joint ``root``.

    ``models/car`` resized to the class: the collision and visual boxes to its length, width and height (the
    cabin on the lower body, up to the roof), the axles to its wheelbase and overhangs, the track to its
    width less :data:`WHEEL_INSET` on each side, the front and rear cameras :data:`CAMERA_SETBACK` inside their
    bumpers, the ultrasonic sensors on the bumpers and sides (:func:`ultrasonic_positions`), the
    steering joints' range wide enough for the inner wheel at the class's full lock. Wheels, masses,
    actuators and sensors stay the model's. The car frame's origin stays at the outline's centre (as
    :meth:`~garage_mj.scene.vehicles.VehicleClass.geometry` has it). Sedan gives ``models/car`` exactly.
    """
    from dm_control import mjcf

    with importlib.resources.as_file(car_xml_path()) as path:
        root = mjcf.from_path(str(path))
    root.model = name
    if vehicle is None:
        return root
    half, hw = vehicle.length / 2, vehicle.width / 2
    rear_axle = _r(-half + vehicle.rear_overhang)
    front_axle = _r(rear_axle + vehicle.wheelbase)
    track = _r(vehicle.width - 2 * WHEEL_INSET)
    cabin_hz = _r((vehicle.height - WHEEL_RADIUS - BODY_TOP) / 2)
    if cabin_hz <= GLASS_INSET:
        raise ValueError(f"vehicle {vehicle.name!r}: {vehicle.height:g} m is too low for the car model's cabin")
    cabin_z = _r(BODY_TOP + cabin_hz)
    cabin_hx, cabin_x, cabin_hy = _r(half * CABIN_SHARE), _r(vehicle.length * CABIN_SHIFT), _r(hw - CABIN_INSET)

    def geom(n: str):
        return root.find("geom", n)

    body_col = geom("body_col")
    body_col.size = [_r(half), _r(hw), body_col.size[2]]
    body_vis = geom("body_vis")
    body_vis.size = [_r(half), _r(hw), body_vis.size[2]]
    for n in ("cabin_col", "cabin_vis"):
        geom(n).size = [cabin_hx, cabin_hy, cabin_hz]
        geom(n).pos = [cabin_x, 0.0, cabin_z]
    glass = [geom("windshield").size[0], _r(cabin_hy - GLASS_INSET), _r(cabin_hz - GLASS_INSET)]
    for n, x in (("windshield", cabin_x + cabin_hx + 0.01), ("rear_window", cabin_x - cabin_hx - 0.01)):
        geom(n).size = glass
        geom(n).pos = [_r(x), 0.0, cabin_z]
    for n, side in (("headlight_l", 1), ("headlight_r", -1)):
        geom(n).pos = [_r(half), _r(side * (hw - LIGHT_INSET)), geom(n).pos[2]]
    for n, end in ((FRONT_CAMERA, 1), (REAR_CAMERA, -1)):
        cam = root.find("camera", n)
        cam.pos = [_r(end * (half - CAMERA_SETBACK)), 0.0, cam.pos[2]]
    for n, (x, y) in ultrasonic_positions(vehicle.length, vehicle.width).items():
        site = root.find("site", n)
        site.pos = [x, y, site.pos[2]]
    for n, x, side in (("steer_fl", front_axle, 1), ("steer_fr", front_axle, -1), ("wheel_rl", rear_axle, 1),
                       ("wheel_rr", rear_axle, -1)):
        root.find("body", n).pos = [x, _r(side * track / 2), 0.0]
    need = inner_wheel_angle(vehicle.wheelbase, track, vehicle.max_steer) + STEER_HEADROOM
    if need > STEER_RANGE:
        limit = _r(math.ceil(need * 100) / 100)
        for n in ("steer_fl", "steer_fr"):
            root.find("joint", n).range = [-limit, limit]
        for n in ("steer_left", "steer_right"):
            root.find("actuator", n).ctrlrange = [-limit, limit]
    return root


def car_xml_path():
    """Path (importlib resource) of ``models/car/car.xml``."""
    return importlib.resources.files("garage_mj.models") / CAR_MODEL / "car.xml"
