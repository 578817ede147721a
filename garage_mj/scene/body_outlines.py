"""The floor outlines of the solid bodies around a test, and how far the car's footprint stays from them (SPEC 9).

Section 9 judges a park test against the *actual* bodies (parked cars as they stand, pillars, walls, obstacle
blocks), never against stall outlines. :class:`BodyOutlines` holds each body's outline on the floor as a
convex quadrilateral of any orientation (a parked car standing askew, an angled stall's car), with its class;
the drive env reads them off its compiled MuJoCo model (:func:`garage_mj.driving.sim.solid_bodies.solid_bodies`).

- :func:`body_clearance`: per pose of the car (rear-axle midpoint and heading, as
  :func:`~garage_mj.scene.clearance.footprint` takes), the footprint's distance to the nearest body (0 when
  they overlap) and which one: exact where a bounding-circle bound is below
  :data:`~garage_mj.scene.clearance.EXACT_BELOW`, that bound above it.
- :func:`segment_crosses`: the bodies a straight segment crosses (touching counts).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from garage_mj.scene.clearance import EXACT_BELOW, footprint

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry


@dataclass(frozen=True)
class BodyOutlines:
    """Solid bodies on the floor: ``corners`` (M, 4, 2) each outline in order round it [m], their ``classes``
    (``wall``, ``pillar``, ``obstacle``, ``parked_car``, ...) and ``names`` (the geoms they came from)."""

    corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 2)))
    classes: tuple[str, ...] = ()
    names: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.corners)

    @classmethod
    def from_boxes(cls, boxes, classes, names=None) -> BodyOutlines:
        """Axis-aligned boxes (M, 4) ``[xmin, ymin, xmax, ymax]`` as outlines."""
        b = np.asarray(boxes, dtype=float).reshape(-1, 4)
        corners = np.stack([b[:, [0, 1]], b[:, [2, 1]], b[:, [2, 3]], b[:, [0, 3]]], axis=1)
        return cls(corners, tuple(classes), tuple(names or (f"box_{k}" for k in range(len(b)))))

    def plus(self, other: BodyOutlines) -> BodyOutlines:
        return BodyOutlines(np.concatenate([self.corners, other.corners]), (*self.classes, *other.classes),
                            (*self.names, *other.names))


def _projections(polys: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of polygons (..., V, 2) projected on axes (..., A, 2): each (..., A)."""
    p = np.einsum("...vd,...ad->...av", polys, axes)
    return p.min(-1), p.max(-1)


def _normals(polys: np.ndarray) -> np.ndarray:
    """(..., V, 2) the edge normals (not unit) of polygons (..., V, 2)."""
    e = np.roll(polys, -1, axis=-2) - polys
    return np.stack([-e[..., 1], e[..., 0]], axis=-1)


def _overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K,) whether convex polygons ``a`` (K, V, 2) and ``b`` (K, W, 2) overlap (touching counts): no edge normal
    of either separates them."""
    axes = np.concatenate([_normals(a), _normals(b)], axis=-2)  # (K, V + W, 2)
    alo, ahi = _projections(a, axes)
    blo, bhi = _projections(b, axes)
    return ~((ahi < blo) | (bhi < alo)).any(axis=-1)


def _points_to_edges(points: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """(K,) the smallest distance of any of ``points`` (K, P, 2) to any edge of ``polys`` (K, V, 2)."""
    a = polys[:, None]  # (K, 1, V, 2)
    ab = np.roll(polys, -1, axis=-2)[:, None] - a
    ap = points[:, :, None] - a  # (K, P, V, 2)
    t = np.clip((ap * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1).min(axis=(1, 2))


def polygon_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K,) the distance [m] between convex polygons ``a`` (K, V, 2) and ``b`` (K, W, 2): 0 where they overlap."""
    gap = np.minimum(_points_to_edges(a, b), _points_to_edges(b, a))
    return np.where(_overlap(a, b), 0.0, gap)


def body_clearance(bodies: BodyOutlines, car: CarGeometry, rear: np.ndarray, heading: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Per pose (rear-axle midpoints (N, 2), headings (N,)): the car footprint's distance [m] to the nearest body
    and that body's index (inf and -1 without bodies)."""
    n = len(rear)
    if not len(bodies) or not n:
        return np.full(n, np.inf), np.full(n, -1)
    body = footprint(car, np.asarray(rear, dtype=float), np.asarray(heading, dtype=float))  # (N, 4, 2)
    mid, centre = body.mean(axis=1), bodies.corners.mean(axis=1)  # (N, 2), (M, 2)
    r_car = np.linalg.norm(body - mid[:, None], axis=-1).max(axis=1)  # (N,)
    r_body = np.linalg.norm(bodies.corners - centre[:, None], axis=-1).max(axis=1)  # (M,)
    dist = np.maximum(np.linalg.norm(mid[:, None] - centre[None], axis=-1) - r_car[:, None] - r_body[None], 0.0)
    i, j = np.nonzero(dist < EXACT_BELOW)
    if len(i):
        dist[i, j] = polygon_gap(body[i], bodies.corners[j])
    k = np.argmin(dist, axis=1)
    return dist[np.arange(n), k], k


def segment_crosses(bodies: BodyOutlines, a, b) -> list[int]:
    """The indices of the bodies the straight segment from ``a`` to ``b`` (x, y) crosses or touches."""
    if not len(bodies):
        return []
    seg = np.repeat(np.array([[a[:2], b[:2], b[:2], a[:2]]], dtype=float), len(bodies), axis=0)  # a flat polygon
    return [int(k) for k in np.flatnonzero(_overlap(seg, bodies.corners))]


__all__ = ["BodyOutlines", "body_clearance", "polygon_gap", "segment_crosses"]
