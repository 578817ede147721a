"""``vision``: drives from the camera only, plus the next route waypoint and its own speed.

Each frame, every pixel becomes a 3D point in the car frame (depth along the optical axis and the
camera geometry). A pixel is an obstacle when segmentation says it is not drivable (anything but
floor, markings, entrance, exit; background and the ego car excluded) or depth puts it above the
floor. Candidate arcs (curvatures from full left to full right, plus the pure-pursuit arc to the
waypoint) are scored by the free distance along them for the car's width; the driver takes the
arc nearest the waypoint's that is free far enough, and its speed lets it stop before the first
obstacle on that arc. So what it does depends on what the camera sees: clutter, occlusion and
narrow passages all show up as failures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from garage_mj.driving.drivers.base import BaseDriver
from garage_mj.driving.sim.vehicle import clip
from garage_mj.scene.semantics import DRIVABLE, NUM_CLASSES, Semantic

_NOT_OBSTACLE = np.zeros(NUM_CLASSES, dtype=bool)
_NOT_OBSTACLE[[int(c) for c in DRIVABLE]] = True
_NOT_OBSTACLE[[int(Semantic.BACKGROUND), int(Semantic.EGO_CAR)]] = True
# per class, for obstacle_points: an obstacle whatever its height / one if it stands high enough
_ALWAYS = ~_NOT_OBSTACLE
_IF_HIGH = np.ones(NUM_CLASSES, dtype=bool)
_IF_HIGH[[int(Semantic.BACKGROUND), int(Semantic.EGO_CAR)]] = False
# the same per uint8 label (labels past the last class read as the last class), indexed without clipping
_ALWAYS_U8 = _ALWAYS[np.minimum(np.arange(256), NUM_CLASSES - 1)]
_IF_HIGH_U8 = _IF_HIGH[np.minimum(np.arange(256), NUM_CLASSES - 1)]


@dataclass(frozen=True)
class VisionConfig:
    """Perception and planning parameters of the vision driver."""

    cruise_speed: float = 2.5  # [m/s]
    min_speed: float = 0.8  # [m/s] slowest planned speed while the way is free
    lateral_accel: float = 1.5  # [m/s^2] v <= sqrt(a_lat / |curvature|)
    comfort_decel: float = 2.5  # [m/s^2] speed lets the car stop in the free distance at this rate
    stop_decel: float = 1.2  # [m/s^2] braking to stop at the goal
    margin: float = 0.3  # [m] clearance kept beside the car body
    stop_distance: float = 0.8  # [m] stop this far before an obstacle
    needed_free: float = 5.0  # [m] an arc this free is good enough; nearer the waypoint arc wins
    horizon: float = 15.0  # [m] ignore points farther than this
    blind_allowance: float = 1.5  # [m] free distance granted beyond where an arc leaves the view
    near_blind: float = 2.0  # [m] ahead of the camera: below its view anyway, not checked for leaving it
    obstacle_height: float = 0.15  # [m] a point this high above the floor is an obstacle
    max_height: float = 2.5  # [m] points higher than this (ceiling) are ignored
    candidates: int = 15  # arcs from full left to full right


class VisionDriver(BaseDriver):
    """Free-space arc selection from depth + segmentation, toward the route waypoint."""

    config_class = VisionConfig
    action_type = "continuous"  # made for [throttle, steer]; discrete actions round its commands

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # what depends on the camera, car and arcs only, kept across frames (the same numbers, computed once)
        self._rays: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._seen_to: dict[tuple, np.ndarray] = {}
        self._fan: tuple[float, np.ndarray] = (math.nan, np.zeros(0))

    def obstacle_points(self, depth: np.ndarray, segmentation: np.ndarray) -> np.ndarray:
        """(N, 2) obstacle points (x forward, y left, metres) in the car frame."""
        cam, cfg = self.camera, self.config
        h, w = depth.shape
        key = (cam, h, w)
        if key not in self._rays:  # per camera and image size: each pixel's ray terms, computed once
            tan_v = math.tan(math.radians(cam.fovy) / 2)
            tan_h = tan_v * w / h
            u = ((np.arange(w) + 0.5) / w * 2 - 1) * tan_h  # right positive
            v = (1 - (np.arange(h) + 0.5) / h * 2) * tan_v  # up positive (row 0 is the top)
            c, s = math.cos(cam.pitch), math.sin(cam.pitch)
            # per pixel, flat: forward and right terms (read only at the pixels kept); per row: up
            self._rays[key] = (np.repeat(c + v * s, w), np.tile(u, h), v[:, None] * c - s)
        forward, right, up = self._rays[key]
        d = depth.astype(np.float64)
        z = cam.z + d * up
        if segmentation.dtype == np.uint8:
            always, if_high = _ALWAYS_U8[segmentation], _IF_HIGH_U8[segmentation]
        else:  # other label types: clipped to the classes
            seg = np.clip(segmentation, 0, NUM_CLASSES - 1)
            always, if_high = _ALWAYS[seg], _IF_HIGH[seg]
        # not drivable, or high enough and not background; never the ego car or the ceiling ...
        hit = always | (z > cfg.obstacle_height) & if_high
        hit &= z < cfg.max_height
        # ... nor beyond the horizon: x and y only where z kept a pixel (the same numbers, fewer of them)
        kept = np.flatnonzero(hit)
        d = d.ravel()[kept]
        x = cam.x + d * forward[kept]
        near = x < cfg.horizon + cam.x
        y = -d * right[kept]
        return np.stack([x[near], y[near]], axis=1)

    def free_distance(self, points: np.ndarray, curvatures: np.ndarray, seen_only: bool = True) -> np.ndarray:
        """Free distance [m] ahead of the front bumper along each arc (driven by the rear axle).

        An obstacle blocks an arc when it lies in the band the car body sweeps (inner rear edge to
        outer front corner). With ``seen_only``, the part of an arc the camera cannot see counts as
        free for only ``blind_allowance`` metres, so the car creeps, not races, into the unseen.
        """
        arcs = self._first_obstacle(points, curvatures)
        return self._free(arcs) if seen_only else self._free_seen_or_not(arcs[0])

    @staticmethod
    def _arc_geometry(curvatures: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(straight, radius, |radius|)`` of each arc, as (n, 1) columns (radius 1 for a straight arc)."""
        k = curvatures[:, None]
        straight = np.abs(k) < 1e-4
        radius = 1.0 / np.where(straight, 1.0, k)
        return straight, radius, np.abs(radius)

    def _first_obstacle(self, points: np.ndarray, curvatures: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(first, curvatures)``: per arc, the rear-axle arc length [m] to the first obstacle in its
        swept band (inf: none)."""
        cfg, car = self.config, self.car
        front = car.front - car.rear_axle  # [m] bumper ahead of the rear axle
        half = car.half_width + cfg.margin
        if not len(points):
            return np.full(len(curvatures), np.inf), curvatures
        xr = points[:, 0] - car.rear_axle
        y = points[:, 1]
        if len(curvatures) == 1:  # one arc (the waypoint's, every frame): the same numbers on 1-D arrays
            k = float(curvatures[0])
            if abs(k) < 1e-4:  # straight: the band is |y| < half, ahead is x > 0
                blocked, along = (np.abs(y) < half) & (xr > 0), xr
            else:
                radius = 1.0 / k
                r_abs = abs(radius)
                r = np.hypot(xr, y - radius)
                theta = np.arctan2(xr, r_abs - (1.0 if radius > 0 else -1.0) * y)
                r_out = np.hypot(r_abs + half, front)
                blocked = (r > r_abs - half) & (r < r_out) & (theta > 0)
                along = r_abs * theta
            return np.where(blocked, along, np.inf).min(keepdims=True), curvatures
        straight, radius, r_abs = self._arc_geometry(curvatures)
        r = np.hypot(xr, y - radius)
        theta = np.arctan2(xr, r_abs - np.sign(radius) * y)
        r_out = np.hypot(r_abs + half, front)
        blocked = (r > r_abs - half) & (r < r_out) & (theta > 0)  # in the swept band, ahead
        along = r_abs * theta
        rows = straight[:, 0]
        if rows.any():  # straight arcs: the band is |y| < half, ahead is x > 0
            blocked[rows] = (np.abs(y) < half) & (xr > 0)
            along[rows] = xr
        return np.where(blocked, along, np.inf).min(axis=1), curvatures

    def _free_seen_or_not(self, first: np.ndarray) -> np.ndarray:
        """Free distance ahead of the bumper from the first obstacles, the unseen counted as free."""
        front = self.car.front - self.car.rear_axle
        return np.minimum(np.maximum(first - front, 0.0), self.config.horizon)

    def _free(self, arcs: tuple[np.ndarray, ...]) -> np.ndarray:
        """Free distance ahead of the bumper from :meth:`_first_obstacle`'s ``arcs``, bounded by the view."""
        return self._free_seen_or_not(np.minimum(arcs[0], self._seen(arcs)))

    def _seen(self, arcs: tuple[np.ndarray, ...]) -> np.ndarray:
        """Per arc of ``arcs``, how far along it counts as free unseen: where it leaves the view plus
        ``blind_allowance`` (rear-axle arc length [m]; kept per arc set)."""
        curvatures = arcs[1]
        key = (self.car, self.camera, curvatures.tobytes())
        if key not in self._seen_to:
            if len(self._seen_to) >= 4096:  # the waypoint arc's curvature varies: keep the cache small
                self._seen_to.clear()
            self._seen_to[key] = self._seen_until(curvatures) + self.config.blind_allowance
        return self._seen_to[key]

    def _free_one(self, first: float, seen: float = math.inf) -> float:
        """:meth:`_free_seen_or_not` (``seen`` inf) or :meth:`_free` for one arc, on floats: the same
        operations as on the arrays, without numpy's cost per call (the waypoint arc at every frame)."""
        front = self.car.front - self.car.rear_axle
        return min(max(min(first, seen) - front, 0.0), self.config.horizon)

    def _seen_until(self, curvatures: np.ndarray) -> np.ndarray:
        """Per arc, how far along it (rear-axle arc length [m]) its centre line stays in the camera's
        horizontal field of view (inf: to the horizon); depends on the arcs, car and camera only."""
        cfg, car = self.config, self.car
        front = car.front - car.rear_axle
        cam = self.camera
        half_fov = math.atan(math.tan(math.radians(cam.fovy) / 2))  # square images: h fov = v fov
        s = np.arange(cam.x - car.rear_axle + cfg.near_blind, cfg.horizon + front, 0.25)[None, :]
        if len(curvatures) == 1:  # one arc (the waypoint's, a new one every frame): the same numbers, 1-D
            k, s = float(curvatures[0]), s[0]
            if abs(k) < 1e-4:
                px, py, turned = s, np.zeros_like(s), np.zeros_like(s)
            else:
                radius = 1.0 / k
                turned = s / abs(radius)
                px = abs(radius) * np.sin(turned)
                py = radius * (1 - np.cos(turned))
            unseen = (np.abs(np.arctan2(py, px - (cam.x - car.rear_axle))) > half_fov) | (turned > math.pi / 2)
            i = int(unseen.argmax())
            return np.array([s[i] if unseen[i] else np.inf])
        straight, radius, r_abs = self._arc_geometry(curvatures)
        turned = s / r_abs  # [rad] heading change along each arc
        px = r_abs * np.sin(turned)
        py = radius * (1 - np.cos(turned))
        if straight.any():
            px, py, turned = np.where(straight, s, px), np.where(straight, 0.0, py), np.where(straight, 0.0, turned)
        bearing = np.abs(np.arctan2(py, px - (cam.x - car.rear_axle)))
        unseen = (bearing > half_fov) | (turned > math.pi / 2)
        return np.where(unseen.any(axis=1), s[0, np.argmax(unseen, axis=1)], np.inf)

    def command(self, obs: dict[str, Any]) -> tuple[float, float]:
        cfg, car = self.config, self.car
        speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
        k_goal = self.pursuit_curvature(np.asarray(obs["waypoint"], dtype=float))
        k_max = math.tan(car.max_steer) / car.wheelbase
        k_goal = clip(k_goal, -k_max, k_max)
        if self._fan[0] != k_max:  # the candidate arcs, from full left to full right (per car)
            self._fan = (k_max, np.linspace(-k_max, k_max, cfg.candidates))
        points = self.obstacle_points(obs["depth"], obs["segmentation"])
        # the waypoint arc first: free for needed_free, it is good whatever the others and the cheapest
        # (cost -1e-9 below), so the other arcs would not change the choice
        found = self._first_obstacle(points, np.array([k_goal]))
        if self._free_one(float(found[0][0])) < cfg.needed_free:
            arcs = np.append(self._fan[1], k_goal)
            found = self._first_obstacle(points, arcs)
            clear = self._free_seen_or_not(found[0])  # blocked by what is seen
            good = clear >= min(cfg.needed_free, clear.max())
            cost = np.abs(arcs - k_goal) + np.where(good, 0.0, np.inf)
            cost[-1] -= 1e-9  # ties go to the waypoint arc itself
            best = int(np.argmin(cost))
            found = tuple(a[best : best + 1] for a in found)
        kappa = float(found[1][0])
        room = self._free_one(float(found[0][0]), float(self._seen(found)[0]))  # also bounded by the view
        v = self.curve_speed(kappa, cfg.cruise_speed, cfg.min_speed, cfg.lateral_accel)
        v = min(v, math.sqrt(2 * cfg.comfort_decel * max(room - cfg.stop_distance, 0.0)))
        v = min(v, self.approach_speed(obs, cfg.stop_decel))
        return self.drive_at(v, speed, kappa)
