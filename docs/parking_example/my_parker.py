"""A parking stack of your own (docs/own-parking-stack.md): reverse-in by pure pursuit on the stall's axis.

Test it with the pytest plugin (test_my_parker.py beside it: pytest test_my_parker.py) or from the CLI:
    garage-mj cruise --library garages.sqlite --task park --maneuver reverse --tests 3 --driver my_parker.py:MyParker --out runs/park
"""

from __future__ import annotations

import math

import numpy as np


class MyParker:
    """Reverse into the stall in two moves, as a driver does: forward along the lane until the stall lies
    ``setup`` metres behind the rear axle, stop, then back in, steering by pure pursuit on the stall's axis.
    It reads only ``stall`` (the stall pose in the car frame), ``speed`` and the car's geometry: no map, no
    privileged pose, no plan."""

    action_type = "continuous"  # act() returns [pedal, steer, gear], each in [-1, 1]; gear < 0 asks for R
    tasks = ("park",)           # the tasks it is made for: park tests (a cruise or AVP run refuses or warns)

    def __init__(self, speed: float = 0.8, setup: float = 4.5, lookahead: float = 2.0, near: float = 0.8) -> None:
        self.speed = speed            # [m/s] top speed of both moves
        self.setup = setup            # [m] how far past the stall the rear axle stops before backing in
        self.lookahead = lookahead    # [m] pure pursuit's look-ahead along the axis ...
        self.near = near              # [m] ... shrinking to this near the end, to settle on the axis

    def reset(self, info: dict) -> None:
        if info["maneuver"] != "reverse":
            raise ValueError(f"MyParker parks reverse-in only, not {info['maneuver']!r}")
        self.car = info["car"]        # CarGeometry: wheelbase [m], rear_axle (its x in the car frame), max_steer [rad]
        self.backing = False

    def act(self, obs: dict) -> np.ndarray:
        sx, sy, c, s = (float(v) for v in obs["stall"][:4])  # the stall pose, car frame: x ahead, y left [m]
        speed = abs(float(obs["speed"][0]))
        rear = self.car.rear_axle
        gx, gy = sx + rear * c, sy + rear * s              # where the rear axle ends in the stall, car frame
        left = (rear - gx) * c - gy * s                    # [m] the rear axle's way left along the stall's axis
        if not self.backing:                               # 1: forward along the stall row, past the stall, stop
            if rear - gx < self.setup:
                yaw = math.atan2(s, c)                     # the stall's yaw relative to the car's heading
                square = math.copysign(math.pi / 2, yaw)   # ... when the car is parallel to the stall row
                return self._drive(1, 1.5 * (yaw - square), self.speed, speed)
            if speed > 0.05:
                return np.array([-1.0, 0.0, 1.0], dtype=np.float32)
            self.backing = True
        if left < 0.05:                                    # 3: parked; hold the brake
            return np.array([-1.0, 0.0, -1.0], dtype=np.float32)
        ahead = min(self.lookahead, max(self.near, 0.5 * left))  # 2: back in, aiming at a point on the axis
        tx, ty = gx + (left - ahead) * c - rear, gy + (left - ahead) * s  # that point, from the rear axle
        curvature = 2.0 * ty / max(tx * tx + ty * ty, 1e-6)  # the arc from the rear axle through it [1/m]
        steer = math.atan(self.car.wheelbase * curvature) / self.car.max_steer
        return self._drive(-1, steer, min(self.speed, math.sqrt(left)), speed)  # slowing at 0.5 m/s^2 to the end

    @staticmethod
    def _drive(gear: int, steer: float, target: float, speed: float) -> np.ndarray:
        """[pedal, steer, gear] holding ``gear`` and speeding up or slowing towards ``target`` [m/s]."""
        return np.clip([(target - speed) / 0.5, steer, gear], -1.0, 1.0).astype(np.float32)
