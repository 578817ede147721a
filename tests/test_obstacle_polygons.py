"""Obstacles that are not axis-aligned boxes (angled stalls, parked cars standing askew, cases from elsewhere):
every exact test uses the polygon, never its bounding box, and an axis-aligned polygon is its box."""

from __future__ import annotations

import math

import numpy as np
import pytest

from garage_mj.scene.car import car_geometry
from garage_mj.scene.clearance import Obstacles, footprint, nearest_obstacle, polygon_distance
from garage_mj.scene.park_planning import _Checker

CAR = car_geometry()
MARGIN = 0.1
REGION = (-50.0, -50.0, 50.0, 50.0)


def _diamond(cx: float, cy: float, r: float) -> np.ndarray:
    """A square turned 45 degrees: its bounding box is twice its area."""
    return np.array([[cx + r, cy], [cx, cy + r], [cx - r, cy], [cx, cy - r]])


def _dense(poly: np.ndarray, n: int = 120) -> np.ndarray:
    """Points along a closed outline."""
    a, b = poly, np.roll(poly, -1, axis=0)
    t = np.linspace(0, 1, n, endpoint=False)[:, None, None]
    return (a[None] + t * (b - a)[None]).reshape(-1, 2)


def _brute(body: np.ndarray, poly: np.ndarray) -> float:
    """Distance of two convex outlines from dense samples of both (0 when one holds a point of the other)."""
    p, q = _dense(body), _dense(poly)
    if (polygon_distance(p, poly) == 0).any() or (polygon_distance(q, body) == 0).any():
        return 0.0
    return float(np.min(np.linalg.norm(p[:, None] - q[None], axis=-1)))


def test_polygon_distance_is_zero_inside_and_exact_outside():
    sq = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    pts = np.array([[1.0, 0.5], [3.0, 0.5], [3.0, 2.0], [1.0, -0.25], [0.0, 0.0]])
    assert polygon_distance(pts, sq) == pytest.approx([0.0, 1.0, math.sqrt(2.0), 0.25, 0.0])
    assert polygon_distance(pts, sq[::-1]) == pytest.approx([0.0, 1.0, math.sqrt(2.0), 0.25, 0.0])  # either way round


def test_a_turned_obstacle_is_measured_by_its_outline_not_its_box():
    poly = _diamond(0.0, 0.0, 1.0)
    obs = Obstacles.from_polygons([poly], ["wall"])
    assert obs.rotated.tolist() == [True]
    rng = np.random.default_rng(0)
    rear = rng.uniform(-4.5, 4.5, size=(60, 2))
    yaw = rng.uniform(-math.pi, math.pi, size=60)
    dist, near = nearest_obstacle(obs, CAR, rear, yaw)
    body = footprint(CAR, rear, yaw)
    truth = np.array([_brute(b, poly) for b in body])
    exact = truth < 1.9  # farther than EXACT_BELOW the distance is a lower bound
    assert np.abs(dist - truth)[exact].max() < 0.03  # the samples' spacing
    assert (dist[~exact] <= truth[~exact] + 1e-9).all() and exact.sum() > 20
    # poses where the box overlaps the car and the diamond does not: the box alone would say touching
    box_only = Obstacles(obs.boxes, ["wall"], np.array([-1]))
    boxed, _ = nearest_obstacle(box_only, CAR, rear, yaw)
    assert ((boxed == 0) & (truth > 0.05)).any()


def test_the_planner_s_checker_sees_the_outline():
    poly = _diamond(0.0, 0.0, 1.0)
    obs = Obstacles.from_polygons([poly], ["wall"])
    checker = _Checker(obs, CAR, MARGIN, REGION)
    rng = np.random.default_rng(1)
    rear = np.column_stack([rng.uniform(-5, 5, 300), rng.uniform(-5, 5, 300), rng.uniform(-math.pi, math.pi, 300)])
    truth, _ = nearest_obstacle(obs, CAR, rear[:, :2], rear[:, 2])  # exact below 2 m (the test above)
    clear = checker.clear(rear)
    one = np.array([checker.pose_clear(*p) for p in rear])
    assert (clear == one).all()
    # the grown rectangle has square corners: the checker may be stricter than the margin at the car's
    # corners (up to margin x (sqrt 2 - 1) more), never looser
    assert not (clear & (truth < MARGIN - 1e-9)).any()
    assert (clear | (truth < MARGIN * math.sqrt(2) + 1e-9)).all()
    assert clear.sum() > 100 and (~clear).sum() > 50


def test_an_axis_aligned_polygon_is_its_box():
    boxes = np.array([[0.0, 0.0, 2.0, 1.0], [3.0, -1.0, 3.5, 4.0]])
    plain = Obstacles(boxes, ["wall", "pillar"], np.array([-1, -1]))
    polys = Obstacles.from_polygons([[(0, 0), (2, 0), (2, 1), (0, 1)], [(3.5, 4.0), (3.0, 4.0), (3.0, -1.0), (3.5, -1.0)]],
                                    ["wall", "pillar"])
    assert polys.rotated.tolist() == [False, False]
    np.testing.assert_array_equal(polys.boxes, boxes)
    rng = np.random.default_rng(2)
    rear = np.column_stack([rng.uniform(-4, 7, 300), rng.uniform(-4, 6, 300), rng.uniform(-math.pi, math.pi, 300)])
    for a, b in zip(nearest_obstacle(plain, CAR, rear[:, :2], rear[:, 2]),
                    nearest_obstacle(polys, CAR, rear[:, :2], rear[:, 2]), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(_Checker(plain, CAR, MARGIN, REGION).clear(rear),
                                  _Checker(polys, CAR, MARGIN, REGION).clear(rear))


def test_obstacles_join_and_select_with_their_outlines():
    a = Obstacles(np.array([[0.0, 0.0, 1.0, 1.0]]), ["wall"], np.array([-1]))
    b = Obstacles.from_polygons([[(5, 5), (6, 5), (5.5, 6)]], ["obstacle"])  # a triangle
    both = a.plus(b)
    assert both.classes == ["wall", "obstacle"] and both.polygons.shape == (2, 4, 2)
    assert both.rotated.tolist() == [False, True]
    assert both.take([1]).classes == ["obstacle"]
    np.testing.assert_array_equal(both.take([1]).polygons[0, :3], [(5, 5), (6, 5), (5.5, 6)])
    with pytest.raises(ValueError, match="polygons must be"):
        Obstacles(np.zeros((2, 4)), ["a", "b"], np.array([-1, -1]), np.zeros((1, 4, 2)))
