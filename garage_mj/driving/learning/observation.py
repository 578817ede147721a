"""What a learned driver sees: the unprivileged observation, one function for training and driving.

A learned driver acts from the front camera and what the car itself knows of its route in its own
frame, never from the world frame or the other road users' states: it reads only the entries of
:data:`~garage_mj.driving.sim.observations.OBSERVATIONS` not marked privileged (so no ``pose``, no
``actors``; :data:`UNPRIVILEGED`). From a drive env's observation
(:class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv`, depth in metres) :func:`learned_observation`
makes a dict for stable-baselines3's ``MultiInputPolicy``:

- ``image``: (2, H, W) uint8, channel first: depth clipped to :data:`DEPTH_RANGE` metres and scaled
  to 0..255, and the segmentation class ids spread over 0..255 (:data:`SEG_SCALE` per class);
- ``vector``: (8,) float32: the route waypoint :data:`~garage_mj.driving.sim.observations.LOOKAHEAD` metres
  ahead in the car frame (x, y over the lookahead), the speed over the car's top speed, the route
  left to the goal (metres over :data:`REMAINING_RANGE`, capped at 1), the road-wheel angle
  (fraction of full lock), the route left again over :data:`NEAR_RANGE` (capped at 1), and the goal
  (the route's last point) in the car frame over :data:`NEAR_RANGE`, clipped to [-1, 1]: the last
  metres at a finer scale, where the car must stop within a metre of the goal, and whether it has
  passed it (the route left reads 0 past the goal). Without these a DAgger-trained model's failures
  were mostly stops 1 m short of or past the goal. The goal is in the car frame, as the waypoint
  is; the world frame (``pose``, where the goal is in the garage) stays hidden.

The trainer (:mod:`garage_mj.driving.learning.train`) and the ``learned`` driver both call it, so a
model sees at test time exactly what it saw in training.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from garage_mj.driving.sim.observations import LOOKAHEAD, unprivileged
from garage_mj.scene.semantics import Semantic

DEPTH_RANGE = 20.0  # [m] depth beyond this reads as this (a garage's far wall rarely matters)
SEG_SCALE = 255 // max(Semantic)  # segmentation id -> pixel value
REMAINING_RANGE = 10.0  # [m] route left to the goal, read up to this (it matters for stopping)
NEAR_RANGE = 2.0  # [m] the route left read again at a finer scale, for the stop
SPEED_RANGE = 4.0  # [m/s] the car's top speed in a garage (CarConfig.max_speed)
UNPRIVILEGED = unprivileged()  # the drive env's entries a learned driver may read (the table's, not privileged)
VECTOR_KEYS = ("waypoint_x", "waypoint_y", "speed", "remaining", "steer", "near_goal", "goal_x", "goal_y")


def _unit(x: float) -> float:
    return min(max(x, -1.0), 1.0)


def learned_space(height: int, width: int) -> spaces.Dict:
    """The observation space of :func:`learned_observation` for an ``height`` x ``width`` camera."""
    return spaces.Dict({
        "image": spaces.Box(0, 255, (2, height, width), np.uint8),
        "vector": spaces.Box(-np.inf, np.inf, (len(VECTOR_KEYS),), np.float32),
    })


def learned_observation(obs: dict[str, Any]) -> dict[str, np.ndarray]:
    """The unprivileged observation from a drive env's (depth in metres, ``image_obs=False``)."""
    obs = {k: obs[k] for k in UNPRIVILEGED if k in obs}  # the privileged entries are out of reach
    depth = np.asarray(obs["depth"], dtype=np.float32)
    if depth.ndim != 2:
        raise ValueError(f"learned_observation needs depth as (H, W) metres (GarageDriveEnv(image_obs=False)), "
                         f"got shape {depth.shape}")
    image = np.empty((2, *depth.shape), dtype=np.uint8)
    image[0] = np.rint(np.clip(depth, 0.0, DEPTH_RANGE) * (255.0 / DEPTH_RANGE))  # a new array: obs untouched
    np.multiply(np.asarray(obs["segmentation"], dtype=np.uint8), SEG_SCALE, out=image[1])
    wx, wy = (float(v) for v in np.asarray(obs["waypoint"]).reshape(-1)[:2])
    speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
    remaining = float(np.asarray(obs["remaining"]).reshape(-1)[0])
    steer = float(np.asarray(obs["steer"]).reshape(-1)[0]) if "steer" in obs else 0.0
    gx, gy = (float(v) for v in np.asarray(obs["goal"]).reshape(-1)[:2])  # car frame
    vector = np.array([wx / LOOKAHEAD, wy / LOOKAHEAD, speed / SPEED_RANGE,
                       min(remaining / REMAINING_RANGE, 1.0), steer, min(remaining / NEAR_RANGE, 1.0),
                       _unit(gx / NEAR_RANGE), _unit(gy / NEAR_RANGE)], dtype=np.float32)
    return {"image": image, "vector": vector}


# -- the parking driver's observation (park and AVP tests) -----------------------------------------------------
#: The parking sensors a learned parking driver observes (:class:`~garage_mj.driving.sim.park_sensors.SensorConfig`
#: fields): both cameras, the 12 ultrasonic rangefinders and the slot detector.
PARK_SENSORS = ("rear_camera", "ultrasonic", "slot")
SLOT_RANGE = 10.0  # [m] the slot detector's position, read up to this ...
SLOT_NEAR = 2.0  # [m] ... and again at a finer scale, for the last metres into the stall
ULTRASONIC_RANGE = 5.0  # [m] the rangefinders' farthest reading (park_sensors.ULTRASONIC_MAX)
PARK_VECTOR_KEYS = ("slot_x", "slot_y", "slot_cos", "slot_sin", "slot_near_x", "slot_near_y", "slot_width",
                    "slot_depth", "facing_cos", "facing_sin", "speed", "steer", "gear", *(f"ultrasonic_{i}" for i in range(12)))
#: With ``route``: the park route's waypoint ahead (car frame, over the lookahead) and the route left (over
#: :data:`REMAINING_RANGE`, and again over :data:`NEAR_RANGE`).
PARK_ROUTE_KEYS = ("route_x", "route_y", "route_left", "route_near")
#: With ``guide``: the park route stretch by stretch (the drive env's ``park_guide``): the stretch's gear, the offset
#: from it (over 2 m, clipped), the cosine and sine of the heading off it, its curvature near and far (times 3 m, about a
#: wheelbase: the wheel's tangent), the stretch left (over 5 m and again over 1 m, clipped to [-1, 1]) and the stretches
#: after it (over 2, capped at 1).
PARK_GUIDE_KEYS = ("guide_gear", "guide_lateral", "guide_cos", "guide_sin", "guide_near", "guide_far", "guide_left",
                   "guide_left_near", "guide_after")
GUIDE_OFFSET = 2.0  # [m] the offset from the stretch, read up to this
GUIDE_LEFT = 5.0  # [m] the stretch left, read up to this ...
GUIDE_NEAR = 1.0  # [m] ... and again at a finer scale, for the stop at its end
GUIDE_RADIUS = 3.0  # [m] the curvature ahead is read times this (a plan's sharpest turn, about 0.3 /m, near 1)
GUIDE_AFTER = 2.0  # the stretches after this one, read up to this many
PARK_IMAGE_CHANNELS = 4  # front depth, front segmentation, rear depth, rear segmentation


def park_vector_size(route: bool = False, guide: bool = False) -> int:
    """The length of :func:`park_observation`'s vector with the park route's entries and the guide's or without."""
    return len(PARK_VECTOR_KEYS) + (len(PARK_ROUTE_KEYS) if route else 0) + (len(PARK_GUIDE_KEYS) if guide else 0)


def park_space(height: int, width: int, route: bool = False, guide: bool = False) -> spaces.Dict:
    """The observation space of :func:`park_observation` for ``height`` x ``width`` cameras (``route``: with the
    park route's entries; ``guide``: with the park guide's)."""
    size = park_vector_size(route, guide)
    return spaces.Dict({
        "image": spaces.Box(0, 255, (PARK_IMAGE_CHANNELS, height, width), np.uint8),
        "vector": spaces.Box(-np.inf, np.inf, (size,), np.float32),
    })


def _camera_planes(depth: Any, segmentation: Any, out: np.ndarray) -> None:
    """Depth (metres) and segmentation ids into two uint8 planes of ``out`` (as :func:`learned_observation`)."""
    out[0] = np.rint(np.clip(np.asarray(depth, dtype=np.float32), 0.0, DEPTH_RANGE) * (255.0 / DEPTH_RANGE))
    np.multiply(np.asarray(segmentation, dtype=np.uint8), SEG_SCALE, out=out[1])


def park_observation(obs: dict[str, Any], route: bool = False, guide: bool = False) -> dict[str, np.ndarray]:
    """What a learned parking driver sees, from a park or AVP test's drive env observation with the
    :data:`PARK_SENSORS` on (depth in metres, ``image_obs=False``):

    - ``image``: (4, H, W) uint8: the front and the rear camera, each as depth and segmentation (as
      :func:`learned_observation`'s two planes);
    - ``vector``: (25,) float32 (:data:`PARK_VECTOR_KEYS`): the slot detector's stall centre in the car frame
      (over :data:`SLOT_RANGE`, and again over :data:`SLOT_NEAR`, clipped to [-1, 1]), the cosine and sine of
      the direction it opens to, its width and depth (over 5 m and 6 m), the cosine and sine of the heading the
      car must end in, relative to its own (the test's instruction: reverse-in or nose-in, from the ``stall``
      entry; its position is not read), the speed, the road-wheel angle, the
      gear (+1 D, -1 R) and the 12 ultrasonic ranges over 5 m; with ``route``, then :data:`PARK_ROUTE_KEYS`: the
      route's waypoint ahead and the route left, as the cruise driver reads its route; with ``guide``, then
      :data:`PARK_GUIDE_KEYS`: the park route stretch by stretch (the ``park_guide`` entry), the gear it is driven in,
      the way it goes from the car and the stretch left.

    Nothing the observation table marks privileged: no pose, no plan's poses and gears, no other road user's state
    (:data:`UNPRIVILEGED` only). The route of a park test is the reference planner's path to the stall, planned
    around the parked cars as they stand: without ``route`` the driver finds its way from its sensors alone."""
    obs = {k: obs[k] for k in UNPRIVILEGED if k in obs}
    missing = [k for k in ("rear_depth", "ultrasonic", "slot", "gear", "stall") if k not in obs]
    if missing:
        raise ValueError(f"a learned parking driver observes {', '.join(missing)}: run park or AVP tests with the "
                         f"sensors {', '.join(PARK_SENSORS)} on (--sensors {','.join(PARK_SENSORS)})")
    depth = np.asarray(obs["depth"])
    if depth.ndim != 2:
        raise ValueError(f"park_observation needs depth as (H, W) metres (GarageDriveEnv(image_obs=False)), "
                         f"got shape {depth.shape}")
    image = np.empty((PARK_IMAGE_CHANNELS, *depth.shape), dtype=np.uint8)
    _camera_planes(depth, obs["segmentation"], image[0:2])
    _camera_planes(obs["rear_depth"], obs["rear_segmentation"], image[2:4])
    sx, sy, syaw, swidth, sdepth = (float(v) for v in np.asarray(obs["slot"]).reshape(-1)[:5])
    fcos, fsin = (float(v) for v in np.asarray(obs["stall"]).reshape(-1)[2:4])
    speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
    steer = float(np.asarray(obs["steer"]).reshape(-1)[0]) if "steer" in obs else 0.0
    gear = float(np.asarray(obs["gear"]).reshape(-1)[0])
    sonar = np.asarray(obs["ultrasonic"], dtype=np.float32).reshape(-1) / ULTRASONIC_RANGE
    way: list[float] = []
    if route:
        wx, wy = (float(v) for v in np.asarray(obs["waypoint"]).reshape(-1)[:2])
        left = float(np.asarray(obs["remaining"]).reshape(-1)[0])
        way = [wx / LOOKAHEAD, wy / LOOKAHEAD, min(left / REMAINING_RANGE, 1.0), min(left / NEAR_RANGE, 1.0)]
    if guide:
        if "park_guide" not in obs:
            raise ValueError("a learned parking driver trained with the park guide observes park_guide: drive it in "
                             "park or AVP tests")
        gear_s, lateral, heading, near, far, stretch, after = (float(v) for v in
                                                              np.asarray(obs["park_guide"]).reshape(-1)[:7])
        way += [gear_s, _unit(lateral / GUIDE_OFFSET), math.cos(heading), math.sin(heading), GUIDE_RADIUS * near,
                GUIDE_RADIUS * far, _unit(stretch / GUIDE_LEFT), _unit(stretch / GUIDE_NEAR), min(after / GUIDE_AFTER, 1.0)]
    vector = np.array([_unit(sx / SLOT_RANGE), _unit(sy / SLOT_RANGE), math.cos(syaw), math.sin(syaw),
                       _unit(sx / SLOT_NEAR), _unit(sy / SLOT_NEAR), swidth / 5.0, sdepth / 6.0, fcos, fsin,
                       speed / SPEED_RANGE, steer, gear, *sonar.tolist(), *way], dtype=np.float32)
    return {"image": image, "vector": vector}
