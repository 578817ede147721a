"""The actors of a cruise test against the ego car's swept path: :class:`Scenario` and :class:`Corridor`.

A :class:`~garage_mj.driving.actors.config.ScenarioConfig` says how many actors of each kind a
test gets; :func:`~garage_mj.driving.actors.placement.draw_scenario` places them from the test's
random stream, around the test's planned route (:class:`~garage_mj.scene.drivable.TestPlan`),
and :func:`~garage_mj.driving.actors.judging.judge` decides from the scene and the trigger rule
alone whether every event stays avoidable. What an actor is (kinds, behaviours, shapes, the
trigger) is :mod:`garage_mj.scene.actor_spec`. Nothing here runs MuJoCo: the drive env moves the
actors (kinematic mocap bodies, :mod:`garage_mj.scene.actor_bodies`) along their
:class:`~garage_mj.scene.actor_spec.ActorSpec` trajectories, and the OpenSCENARIO writer
(:mod:`garage_mj.export.xosc`) exports the same specs.

This module holds what placement, judging and the ``oracle`` driver share: the drawn
:class:`Scenario`, the car's swept path (:class:`Corridor`), each body shape as circles, and the
sampling of an actor's trajectory in time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from garage_mj.scene.actor_spec import ROUND, SHAPE_SIZE, ActorSpec
from garage_mj.scene.drivable import START_OFFSET, TestPlan

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry

SAMPLE_DT = 0.1  # [s] trajectories are checked against the swept path at this time step
CONTROL_LAG = 0.1  # [s] a trigger is checked once per control step: it may fire this late


@dataclass
class Scenario:
    """The actors of one test and whether every event stays avoidable."""

    actors: list[ActorSpec] = field(default_factory=list)
    feasible: bool = True
    reason: str = ""
    missing: dict[str, int] = field(default_factory=dict)  # kind -> actors asked for but not placed
    free_stalls: set[int] = field(default_factory=set)  # stalls the actors take (no parked car)

    def count(self, kind: str) -> int:
        return sum(a.kind == kind for a in self.actors)

    @property
    def duration(self) -> float:
        """[s] summed over moving actors: how long a driver may have to wait for them."""
        return float(sum(a.duration for a in self.actors if not a.static))


# -- shapes as circles ---------------------------------------------------------------------------------
def shape_circles(shape: str) -> tuple[np.ndarray, float]:
    """Circle centres along the body's length (local x) and their radius, covering the body's outline."""
    hx, hy, _ = SHAPE_SIZE[shape]
    if shape in ROUND:
        return np.array([0.0]), hx
    n = max(2, int(math.ceil(hx / hy)))
    step = 2 * hx / n
    xs = -hx + step / 2 + step * np.arange(n)
    return xs, math.hypot(step / 2, hy)


def circle_points(shape: str, poses: np.ndarray) -> tuple[np.ndarray, float]:
    """(P, C, 2) circle centres of ``shape`` at each of P poses (x, y, yaw), and the radius."""
    xs, r = shape_circles(shape)
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    return np.stack([poses[:, 0:1] + c * xs, poses[:, 1:2] + s * xs], axis=-1), r


class Corridor:
    """The ego car's swept path of a feasible test: body footprints along the planned route."""

    def __init__(self, plan: TestPlan, car: CarGeometry, start: float = START_OFFSET) -> None:
        """``start`` [m]: the station the car starts at (a cruise test's :data:`START_OFFSET`; a park plan's 0)."""
        self.car = car
        self.rear = np.asarray(plan.rear, dtype=float)
        self.heading = np.asarray(plan.heading, dtype=float)
        self.centre = np.asarray(plan.centre, dtype=float)
        seg = np.linalg.norm(np.diff(self.centre, axis=0), axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])  # [m] centre-path stations
        self.i0 = int(min(np.searchsorted(self.s, start), len(self.s) - 1))  # where the car starts
        self._cos, self._sin = np.cos(self.heading), np.sin(self.heading)

    def distance(self, points: np.ndarray, first: int = 0) -> np.ndarray:
        """(N', M) distance [m] of each of M points to the car body at path poses ``first``..N-1."""
        car = self.car
        x0, x1 = car.rear - car.rear_axle, car.front - car.rear_axle  # body along x from the rear axle
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        dx = pts[None, :, 0] - self.rear[first:, None, 0]
        dy = pts[None, :, 1] - self.rear[first:, None, 1]
        c, s = self._cos[first:, None], self._sin[first:, None]
        lx = c * dx + s * dy
        ly = -s * dx + c * dy
        ex = np.maximum(np.maximum(x0 - lx, lx - x1), 0.0)
        ey = np.maximum(np.abs(ly) - car.half_width, 0.0)
        return np.hypot(ex, ey)

    def conflicts(self, shape: str, poses: np.ndarray, margin: float) -> np.ndarray:
        """(P, N) whether the body at each pose comes within ``margin`` of the car body at each path pose."""
        pts, r = circle_points(shape, np.asarray(poses, dtype=float).reshape(-1, 3))
        p, c = pts.shape[:2]
        d = self.distance(pts.reshape(-1, 2))  # (N, P * C)
        near = (d < r + margin).reshape(len(self.s), p, c).any(axis=2)
        return near.T

    def clearance(self, shape: str, poses: np.ndarray) -> float:
        """[m] smallest distance of the body at any of ``poses`` to the car body anywhere on the drive."""
        pts, r = circle_points(shape, np.asarray(poses, dtype=float).reshape(-1, 3))
        return float(self.distance(pts.reshape(-1, 2), self.i0).min()) - r

    def pose(self, i: int) -> tuple[np.ndarray, float]:
        """Centre-path point and heading at path index ``i``."""
        return self.centre[i], float(self.heading[i])

    def index_at(self, station: float) -> int:
        return int(min(max(np.searchsorted(self.s, station), 0), len(self.s) - 1))


def sample_times(actor: ActorSpec) -> np.ndarray:
    """Times after the trigger at which an actor's trajectory is checked (its waypoints included)."""
    if actor.static:
        return np.zeros(1)
    t = np.arange(0.0, actor.duration, SAMPLE_DT)
    return np.unique(np.concatenate([t, actor.waypoints[:, 0]]))


def actor_poses(actor: ActorSpec, times: np.ndarray) -> np.ndarray:
    return np.array([actor.pose_at(float(t)) for t in times], dtype=float).reshape(-1, 3)
