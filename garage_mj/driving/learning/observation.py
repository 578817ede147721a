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
