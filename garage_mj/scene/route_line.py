"""A route as a 2D polyline in world coordinates: length, projection of the car, lookahead points.

Pure geometry (no MuJoCo): the drive env builds a :class:`Route` from a test's planned path, the
outcome monitor measures progress and deviation on it, and the env gives drivers the lookahead point.
"""

from __future__ import annotations

import math

import numpy as np


class Route:
    """Polyline through ``points`` (N >= 2, metres, world frame x east / y north)."""

    def __init__(self, points) -> None:
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        keep = np.ones(len(pts), dtype=bool)
        keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9  # drop repeated points
        pts = pts[keep]
        if len(pts) < 2:
            raise ValueError("a route needs at least two distinct points")
        self.points = pts
        seg = np.diff(pts, axis=0)
        self._seg = seg
        self._seg_len = np.linalg.norm(seg, axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self._starts, self._ends = self._cum[:-1], self._cum[1:]  # [m] each segment's arc-length range
        self._seg_len2 = self._seg_len**2

    @property
    def length(self) -> float:
        """Total length [m]."""
        return float(self._cum[-1])

    @property
    def goal(self) -> np.ndarray:
        """The last point."""
        return self.points[-1]

    def project(self, point, s_min: float = 0.0, s_max: float | None = None) -> tuple[float, float]:
        """(arc length s [m] of the nearest route point, distance [m] to it), searching s in [s_min, s_max].

        A window keeps tracking monotonic where the route passes close to itself.
        """
        p = np.asarray(point, dtype=float)[:2]
        s_max = self.length if s_max is None else s_max
        # the segments that overlap [s_min, s_max] (arc length rises: one run of them); none: every segment
        lo = int(self._ends.searchsorted(s_min, side="left"))
        hi = int(self._starts.searchsorted(s_max, side="right"))
        if lo >= hi:
            lo, hi = 0, len(self._seg)
        start, end, seg, seg_len = self._starts[lo:hi], self._ends[lo:hi], self._seg[lo:hi], self._seg_len[lo:hi]
        points = self.points[lo:hi]
        t = np.einsum("ij,ij->i", p - points, seg) / self._seg_len2[lo:hi]
        s = start + np.minimum(np.maximum(t, 0.0), 1.0) * seg_len
        s = np.minimum(np.maximum(s, s_min), s_max)
        s = np.minimum(np.maximum(s, start), end)  # stay on each segment
        off = points + ((s - start) / seg_len)[:, None] * seg - p  # foot point - p
        dist = np.sqrt(np.add.reduce(off * off, axis=1))  # np.linalg.norm(axis=1), without its dispatch
        i = int(dist.argmin())
        return float(s[i]), float(dist[i])

    def point_at(self, s: float) -> np.ndarray:
        """The route point at arc length ``s`` (clamped to the route)."""
        s = min(max(s, 0.0), self.length)
        i = min(int(np.searchsorted(self._cum, s, side="right")) - 1, len(self._seg) - 1)
        return self.points[i] + (s - self._cum[i]) / self._seg_len[i] * self._seg[i]

    def heading_at(self, s: float) -> float:
        """Direction [rad] of the route at arc length ``s``."""
        s = min(max(s, 0.0), self.length)
        i = min(int(np.searchsorted(self._cum, s, side="right")) - 1, len(self._seg) - 1)
        return math.atan2(self._seg[i, 1], self._seg[i, 0])


def to_car_frame(point, x: float, y: float, yaw: float) -> np.ndarray:
    """A world point in the car frame (x forward, y left) of a car at (x, y, yaw)."""
    dx, dy = float(point[0]) - x, float(point[1]) - y
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([c * dx + s * dy, -s * dx + c * dy])
