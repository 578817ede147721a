"""The drive env's observation, declared once: one :class:`ObservationEntry` per key of ``GarageDrive-v0``'s dict.

Each entry says how its gymnasium space is built from the env's options (:class:`ObservationSetup`),
whether it is privileged (the world frame and the other road users' states, for reference drivers;
a learned driver never reads it, :mod:`garage_mj.driving.learning.observation`), what it holds (one
line, with units), and how it is filled from the env's state at a step (:class:`Snapshot`).
:class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv` builds its observation space and each
step's observation dict from :data:`OBSERVATIONS`, in this order; :func:`observations_markdown`
renders ``docs/observations.md`` from it.

A new sensor is one entry in :data:`OBSERVATIONS` plus the function that fills it (the
:class:`Snapshot` carries the env, so the fill reads whatever the env knows).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from garage_mj.core.words import a_noun
from garage_mj.driving.sim.park_guide import (
    GUIDE_KEYS,
    MAX_CURVATURE,
    MAX_CUSP_PLANS,
    REPLAN_AT_END,
    REPLAN_STUCK,
    SHORT_FIRST,
    START_RADIUS,
    STUCK_CUSP_WITHIN,
)
from garage_mj.driving.sim.park_sensors import (
    ALL_SENSORS,
    MAX_SLOT_SIZE,
    NO_SENSORS,
    ULTRASONIC_MAX,
    ULTRASONIC_MIN,
    SensorConfig,
    slot_pose,
)
from garage_mj.driving.sim.sensors import CameraConfig
from garage_mj.scene.actor_bodies import states
from garage_mj.scene.car import ULTRASONIC_SENSORS
from garage_mj.scene.route_line import to_car_frame
from garage_mj.scene.semantics import Semantic

if TYPE_CHECKING:
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

LOOKAHEAD = 4.0  # [m] the observed waypoint lies this far ahead of the car's route progress
MAX_EXTENT = 1000.0  # [m] bound of the waypoint observation (far beyond any garage)
MAX_SPEED = 50.0  # [m/s] bound of the speed observation


@dataclass(frozen=True)
class ObservationSetup:
    """What the observation's spaces depend on: the camera, SB3 image spaces or not, the actor slots."""

    camera: CameraConfig = CameraConfig()
    image_obs: bool = False  # depth and segmentation as (H, W, 1) uint8 images (GarageDriveEnv(image_obs=True))
    actors: int = 0  # actor slots: the scenario's actor count
    task: str = "cruise"  # the drive env's task: "park" and "avp" tests observe the stall and the gear too
    sensors: SensorConfig = NO_SENSORS  # the parking sensors asked for (GarageDriveEnv(sensors=...)): all off


@dataclass(slots=True)  # not frozen: one is made per step, and a frozen init costs more
class Snapshot:
    """What one observation is made of: the env at this step, the car's pose and speed, the camera's images."""

    env: GarageDriveEnv
    x: float  # [m] world frame
    y: float  # [m]
    yaw: float  # [rad]
    speed: float  # [m/s] forward
    frame: dict[str, np.ndarray]  # the camera's images of this step (Camera.render: the ones it is set to render)
    rear: dict[str, np.ndarray] | None = None  # the rear camera's, when the env observes it


@dataclass(frozen=True)
class ObservationEntry:
    """One key of the drive env's observation dict.

    ``space`` builds its gymnasium space from the env's options, or returns None where the env has no
    such entry (``rgb`` without colour, ``actors`` without actors); ``fill`` computes its value at a
    step, or None where the camera did not render it (its image is then missing from the dict).
    """

    name: str
    space: Callable[[ObservationSetup], spaces.Box | None]
    privileged: bool  # True: a reference driver's (world frame, other road users); learned drivers never read it
    description: str  # one line, with units
    fill: Callable[[Snapshot], np.ndarray | None]


# -- camera images -----------------------------------------------------------------------------------
def _image(setup: ObservationSetup, channels: int | None, high, dtype) -> spaces.Box:
    h, w = setup.camera.height, setup.camera.width
    return spaces.Box(0, high, (h, w) if channels is None else (h, w, channels), dtype)


def _depth_space(setup: ObservationSetup) -> spaces.Box:
    if setup.image_obs:
        return _image(setup, 1, 255, np.uint8)
    return spaces.Box(0.0, setup.camera.far, (setup.camera.height, setup.camera.width), np.float32)


def _depth_of(frame: dict[str, np.ndarray] | None, s: Snapshot) -> np.ndarray | None:
    depth = None if frame is None else frame.get("depth")
    if depth is None or not s.env.image_obs:
        return depth
    far = s.env.camera_config.far
    return np.rint(np.clip(depth, 0.0, far) * (255.0 / far)).astype(np.uint8)[..., None]


def _depth(s: Snapshot) -> np.ndarray | None:
    return _depth_of(s.frame, s)


def _segmentation_space(setup: ObservationSetup) -> spaces.Box:
    return _image(setup, 1, 255, np.uint8) if setup.image_obs else _image(setup, None, max(Semantic), np.uint8)


def _segmentation_of(frame: dict[str, np.ndarray] | None, s: Snapshot) -> np.ndarray | None:
    seg = None if frame is None else frame.get("segmentation")
    return seg if seg is None or not s.env.image_obs else seg[..., None]


def _segmentation(s: Snapshot) -> np.ndarray | None:
    return _segmentation_of(s.frame, s)


# -- the car and its route ---------------------------------------------------------------------------
def _vector(n: int, low: float, high: float) -> Callable[[ObservationSetup], spaces.Box]:
    return lambda setup: spaces.Box(low, high, (n,), np.float32)


def _waypoint(s: Snapshot) -> np.ndarray:
    env = s.env
    target = env.route.point_at(env.monitor.progress + LOOKAHEAD)
    return to_car_frame(target, s.x, s.y, s.yaw).astype(np.float32)


def _goal(s: Snapshot) -> np.ndarray:
    return to_car_frame(s.env.monitor.goal, s.x, s.y, s.yaw).astype(np.float32)


def _remaining(s: Snapshot) -> np.ndarray:
    env = s.env
    return np.array([max(env.route.length - env.monitor.progress, 0.0)], dtype=np.float32)


def _steer(s: Snapshot) -> np.ndarray:
    return np.array([s.env.car.steer_angle / s.env.car_config.max_steer], dtype=np.float32)


def _pose_space(setup: ObservationSetup) -> spaces.Box:
    return spaces.Box(np.array([-MAX_EXTENT, -MAX_EXTENT, -np.pi], np.float32),
                      np.array([MAX_EXTENT, MAX_EXTENT, np.pi], np.float32), dtype=np.float32)


def _pose(s: Snapshot) -> np.ndarray:
    return np.array([s.x, s.y, math.remainder(s.yaw, math.tau)], dtype=np.float32)


# -- park and AVP tests -------------------------------------------------------------------------------
def _parking(space: spaces.Box) -> Callable[[ObservationSetup], spaces.Box | None]:
    """``space`` for park and AVP tests; a cruise test has no such entry."""
    return lambda setup: None if setup.task == "cruise" else space


def _stall(s: Snapshot) -> np.ndarray:
    gx, gy, gyaw = s.env.monitor.goal_pose
    x, y = to_car_frame((gx, gy), s.x, s.y, s.yaw)
    rel = gyaw - s.yaw
    return np.array([x, y, math.cos(rel), math.sin(rel)], dtype=np.float32)


def _gear(s: Snapshot) -> np.ndarray:
    return np.array([s.env.car.gear.value], dtype=np.float32)


def _park_guide(s: Snapshot) -> np.ndarray:
    guide = s.env.park_guide
    return np.zeros(len(GUIDE_KEYS), np.float32) if guide is None else guide.read((s.x, s.y, s.yaw))


_GUIDE_SPACE = spaces.Box(np.array([-1.0, -MAX_EXTENT, -np.pi, -MAX_CURVATURE, -MAX_CURVATURE, -MAX_EXTENT, 0.0],
                                   np.float32),
                          np.array([1.0, MAX_EXTENT, np.pi, MAX_CURVATURE, MAX_CURVATURE, MAX_EXTENT, MAX_EXTENT],
                                   np.float32), dtype=np.float32)


# -- the parking sensors (garage_mj.driving.sim.park_sensors; each on only when asked for) -------------------
def _sensor(on: Callable[[SensorConfig], bool], space: Callable[[ObservationSetup], spaces.Box | None]
            ) -> Callable[[ObservationSetup], spaces.Box | None]:
    """``space`` where the env's :class:`SensorConfig` has the sensor ``on``; no such entry otherwise."""
    return lambda setup: space(setup) if on(setup.sensors) else None


def _ultrasonic(s: Snapshot) -> np.ndarray:
    return s.env.ultrasonic.read(s.env.data)


def _slot(s: Snapshot) -> np.ndarray:
    env = s.env
    return slot_pose(env.stalls[env.target], s.x, s.y, s.yaw, env.sensor_config, env.slot_rng)


_SLOT_SPACE = spaces.Box(np.array([-MAX_EXTENT, -MAX_EXTENT, -np.pi, 0.0, 0.0], np.float32),
                         np.array([MAX_EXTENT, MAX_EXTENT, np.pi, MAX_SLOT_SIZE, MAX_SLOT_SIZE], np.float32),
                         dtype=np.float32)


# -- the other road users ----------------------------------------------------------------------------
def _actors_space(setup: ObservationSetup) -> spaces.Box | None:
    n = setup.actors
    if not n:
        return None
    return spaces.Box(np.tile(np.array([-MAX_EXTENT, -MAX_EXTENT, -np.pi, -1.0], np.float32), (n, 1)),
                      np.tile(np.array([MAX_EXTENT, MAX_EXTENT, np.pi, np.inf], np.float32), (n, 1)),
                      dtype=np.float32)


def _actors(s: Snapshot) -> np.ndarray:
    env = s.env
    rows = np.zeros((env.scenario_config.count, 4), dtype=np.float32)
    rows[:, 3] = -1.0
    rows[:, :2] = MAX_EXTENT  # slots without an actor: far away
    if env.scenario.actors:
        rows[: len(env.scenario.actors)] = states(env.scenario.actors, env._actor_tau)
    return rows


OBSERVATIONS: tuple[ObservationEntry, ...] = (
    ObservationEntry("rgb", lambda setup: _image(setup, 3, 255, np.uint8) if setup.camera.rgb else None, False,
                     "front camera colour image (only with colour on: `rgb=True`)", lambda s: s.frame.get("rgb")),
    ObservationEntry("depth", _depth_space, False,
                     "front camera depth along the optical axis [m], at most the far plane; "
                     "`image_obs`: 0..255 over [0, far] m", _depth),
    ObservationEntry("segmentation", _segmentation_space, False,
                     "front camera semantic class per pixel (`garage_mj.scene.semantics.Semantic` ids)",
                     _segmentation),
    ObservationEntry("waypoint", _vector(2, -MAX_EXTENT, MAX_EXTENT), False,
                     f"the route point {LOOKAHEAD:g} m ahead of the car's route progress, car frame "
                     "(x forward, y left) [m]", _waypoint),
    ObservationEntry("speed", _vector(1, -MAX_SPEED, MAX_SPEED), False, "forward speed [m/s]",
                     lambda s: np.array([s.speed], dtype=np.float32)),
    ObservationEntry("goal", _vector(2, -MAX_EXTENT, MAX_EXTENT), False,
                     "the goal, where the car must stop beside the target stall, car frame (x forward, y left) [m]",
                     _goal),
    ObservationEntry("remaining", _vector(1, 0.0, MAX_EXTENT), False,
                     "route left to the goal [m] (0 past it)", _remaining),
    ObservationEntry("steer", _vector(1, -1.0, 1.0), False,
                     "road-wheel angle over full lock, in [-1, 1] (positive: left)", _steer),
    ObservationEntry("stall", _parking(spaces.Box(np.array([-MAX_EXTENT, -MAX_EXTENT, -1.0, -1.0], np.float32),
                                                  np.array([MAX_EXTENT, MAX_EXTENT, 1.0, 1.0], np.float32),
                                                  dtype=np.float32)), False,
                     "the stall pose to park in (car centre), car frame: x forward, y left [m], cos and sin of its "
                     "yaw relative to the car's; park and AVP tests only", _stall),
    ObservationEntry("gear", _parking(spaces.Box(-1.0, 1.0, (1,), np.float32)), False,
                     "the gear: +1 drive, -1 reverse; park and AVP tests only", _gear),
    ObservationEntry("park_guide", _parking(_GUIDE_SPACE), False,
                     "the park route stretch by stretch, as a park assist shows it (`garage_mj.driving.sim.park_guide`): "
                     "the gear of the stretch the car is on (+1 D, -1 R), the rear axle's offset from it [m] (left of "
                     "travel), the heading off it [rad], its curvature 0.25 m and 1 m ahead [1/m] (signed as the wheels "
                     "turn), the stretch left [m] (negative past its end), the stretches after it; the next stretch "
                     "once the car is at rest at the end of this one; a new plan from where the car stands when it has rested "
                     f"outside the stall {REPLAN_AT_END:g} s where the plan ends or {REPLAN_STUCK:g} s elsewhere (the "
                     "env's `guide_replans`; near the stall pose a short correction; with no plan found, the next "
                     f"stretch for a car stopped up to {STUCK_CUSP_WITHIN:g} m short of a cusp) and, with those, a first "
                     f"stretch under {SHORT_FIRST:g} m shown as driven and, at a cusp, a new plan from where the car "
                     f"stands where the next stretch driven from there would hit something (up to {MAX_CUSP_PLANS} a test); "
                     "zeros without a plan and, in an AVP test, until the "
                     f"car is within {START_RADIUS:g} m of the park plan's start; park and AVP tests only",
                     _park_guide),
    ObservationEntry("rear_depth", _sensor(lambda c: c.rear_camera, _depth_space), False,
                     "rear camera depth, as the front camera's (same image, planes and tilt, looking back); "
                     "sensor `rear_camera` only", lambda s: _depth_of(s.rear, s)),
    ObservationEntry("rear_segmentation", _sensor(lambda c: c.rear_camera, _segmentation_space), False,
                     "rear camera semantic class per pixel; sensor `rear_camera` only", lambda s: _segmentation_of(s.rear, s)),
    ObservationEntry("ultrasonic", _sensor(lambda c: c.ultrasonic, _vector(len(ULTRASONIC_SENSORS), ULTRASONIC_MIN,
                                                                           ULTRASONIC_MAX)), False,
                     f"bumper ultrasonic ranges [m], front then rear, each left to right: side, outer, inner, inner, "
                     f"outer, side (`garage_mj.scene.car.ULTRASONIC_SENSORS`); no echo reads {ULTRASONIC_MAX:g}, "
                     f"nearer than {ULTRASONIC_MIN:g} reads {ULTRASONIC_MIN:g}; sensor `ultrasonic` only", _ultrasonic),
    ObservationEntry("slot", _sensor(lambda c: c.slot, lambda setup: _SLOT_SPACE), False,
                     "the target stall as a slot detector reports it, car frame: centre x forward, y left [m], the "
                     "direction it opens to relative to the car's heading [rad], width across its opening and depth "
                     "[m]; seeded noise on position and yaw if set; sensor `slot` only", _slot),
    ObservationEntry("pose", _pose_space, True, "the car's pose, world frame: x, y [m], yaw [rad] in [-pi, pi]",
                     _pose),
    ObservationEntry("actors", _actors_space, True,
                     "per actor slot, world frame: x, y [m], yaw [rad], seconds since its trigger (-1: not yet); "
                     "in the order of `driver_info()[\"actors\"]`, empty slots at (1000, 1000); only with actors",
                     _actors),
)


def unprivileged() -> tuple[str, ...]:
    """Names of the entries any driver may read (a learned driver reads only these)."""
    return tuple(e.name for e in OBSERVATIONS if not e.privileged)


def observed_entries(setup: ObservationSetup) -> tuple[ObservationEntry, ...]:
    """The entries of :data:`OBSERVATIONS` an env of ``setup`` has, in order."""
    return tuple(e for e in OBSERVATIONS if e.space(setup) is not None)


def observation_spaces(setup: ObservationSetup) -> dict[str, spaces.Box]:
    """The env's observation spaces by name, in :data:`OBSERVATIONS` order (entries the env has only)."""
    return {e.name: e.space(setup) for e in observed_entries(setup)}


def observe(entries: Iterable[ObservationEntry], snapshot: Snapshot) -> dict[str, np.ndarray]:
    """The observation dict of ``entries`` at ``snapshot`` (an image the camera did not render is left out)."""
    return {e.name: value for e in entries if (value := e.fill(snapshot)) is not None}


# -- the docs table ----------------------------------------------------------------------------------
# docs/observations.md: every entry on
DOC_SETUP = ObservationSetup(CameraConfig(rgb=True), image_obs=False, actors=2, task="park", sensors=ALL_SENSORS)


def _number(v: float) -> str:
    v = float(v)
    if math.isclose(abs(v), math.pi, rel_tol=1e-6):  # a float32 pi
        return "-pi" if v < 0 else "pi"
    return f"{v:g}"


def _bounds(a: np.ndarray) -> str:
    """A bound array as one number when uniform, else per component of its last axis."""
    a = np.asarray(a, dtype=np.float64)
    if (a == a.flat[0]).all():
        return _number(a.flat[0])
    per_column = a.reshape(-1, a.shape[-1])
    return "(" + ", ".join(_number(v) for v in per_column[0]) + ")"


def space_text(space: spaces.Box) -> str:
    """A Box as ``dtype shape in [low, high]`` (e.g. ``float32 (2,) in [-1000, 1000]``)."""
    return f"{space.dtype} {tuple(space.shape)} in [{_bounds(space.low)}, {_bounds(space.high)}]"


def observations_markdown(setup: ObservationSetup = DOC_SETUP) -> str:
    """``docs/observations.md``: the table of :data:`OBSERVATIONS` (name, space, privileged, description)."""
    images = observation_spaces(ObservationSetup(setup.camera, image_obs=True, actors=setup.actors,
                                                 sensors=setup.sensors))
    cam = setup.camera
    lines = [
        "# Observations of `GarageDrive-v0`",
        "",
        "Generated from `garage_mj/driving/sim/observations.py` (`OBSERVATIONS`) by",
        "`python -m garage_mj.driving.sim.observations > docs/observations.md`; a test checks that",
        "this file is what it renders. The observation is a dict with these keys, in this order.",
        f"Spaces as built for {a_noun(cam.width)} x {cam.height} camera with {a_noun(f'{cam.far:g}')} m far plane, colour "
        f"{'on' if cam.rgb else 'off'},",
        f"{setup.actors} actor slots{' and every parking sensor on' if setup.sensors == ALL_SENSORS else ''}; "
        "where `image_obs=True` changes a space, it is given after the default.",
        "A cruise test (`task=\"cruise\"`, the default) has no `stall` and no `gear`: they are a park or AVP test's.",
        "The parking sensors (`rear_depth`, `rear_segmentation`, `ultrasonic`, `slot`) are opt-in, in any task:",
        "`GarageDriveEnv(sensors=...)` (`garage_mj/driving/sim/park_sensors.py`, `SensorConfig`).",
        "Privileged entries are for reference drivers (the `oracle`); a learned driver never reads them",
        "(`garage_mj/driving/learning/observation.py`).",
        "",
        "| name | space | privileged | description |",
        "|---|---|---|---|",
    ]
    for e in OBSERVATIONS:
        space = e.space(setup)
        text = "(none with these options)" if space is None else space_text(space)
        if e.name in images and space_text(images[e.name]) != text:
            text += f"; `image_obs`: {space_text(images[e.name])}"
        lines.append(f"| `{e.name}` | {text} | {'yes' if e.privileged else 'no'} | {e.description} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(observations_markdown(), end="")
