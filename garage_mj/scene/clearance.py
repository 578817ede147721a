"""How far the ego car's body stays from what it may not touch, along a path (docs/spec.md section 7).

The obstacles of a scene are axis-aligned rectangles: walls, obstacle blocks, pillars and every
stall's outline (parked cars lie wholly inside stall outlines, so any occupancy is covered). An obstacle may
also be a convex polygon of any orientation (an angled stall, a parked car standing askew, a case's obstacle
from elsewhere: :meth:`Obstacles.from_polygons`); ``boxes`` then holds its bounding box, for look-ups and bounds,
and ``polygons`` its outline, which every exact test uses.
The car's body is a rectangle around its rear-axle midpoint (:func:`footprint`); the swept
clearance (:func:`clearance`) is, per pose, the distance of that rectangle to the nearest
obstacle: a bounding-circle lower bound first, exact polygon distances only where the bound
is below ``EXACT_BELOW``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.semantics import Semantic

if TYPE_CHECKING:
    from garage_mj.scene.car import CarGeometry

NEAR_OBSTACLE = 6.0  # [m] obstacles farther than this from every path point are not tested
EXACT_BELOW = 2.0  # [m] clearances above this are reported as the bounding-circle lower bound


@dataclass
class Obstacles:
    """Obstacles with their class and stall id (or -1): ``boxes`` (M, 4) ``[xmin, ymin, xmax, ymax]``, and where some
    are not axis-aligned rectangles, ``polygons`` (M, K, 2): every obstacle's convex outline (K >= 3 corners, in
    order; a shorter outline repeats its last corner), ``boxes`` then their bounding boxes."""

    boxes: np.ndarray
    classes: list[str]
    stall: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    polygons: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.polygons is not None:
            self.polygons = np.asarray(self.polygons, dtype=float)
            if self.polygons.ndim != 3 or self.polygons.shape[1] < 3 or self.polygons.shape[2] != 2 \
                    or len(self.polygons) != len(self.boxes):
                raise ValueError(f"Obstacles.polygons must be (M, K >= 3, 2) for M = {len(self.boxes)} boxes, "
                                 f"got {self.polygons.shape}")

    @classmethod
    def from_polygons(cls, polygons, classes: list[str], stall=None) -> Obstacles:
        """Obstacles from convex outlines ``polygons`` (M, K, 2) (or a list of (K_i, 2) outlines, padded here)."""
        polys = list(polygons)
        k = max((len(p) for p in polys), default=4)
        out = np.zeros((len(polys), max(k, 3), 2))
        for i, p in enumerate(polys):
            p = np.asarray(p, dtype=float).reshape(-1, 2)
            out[i, :len(p)] = p
            out[i, len(p):] = p[-1]
        boxes = np.concatenate([out.min(axis=1), out.max(axis=1)], axis=1) if len(out) else np.zeros((0, 4))
        ids = np.full(len(out), -1, dtype=int) if stall is None else np.asarray(stall, dtype=int)
        return cls(boxes, list(classes), ids, out)

    @property
    def outlines(self) -> np.ndarray:
        """(M, K, 2) every obstacle's outline: its polygon, or its box's four corners (counter-clockwise)."""
        return _box_corners(self.boxes) if self.polygons is None else self.polygons

    @property
    def rotated(self) -> np.ndarray:
        """(M,) whether each obstacle is something other than its box (its polygon differs from the box's corners)."""
        if self.polygons is None:
            return np.zeros(len(self.boxes), dtype=bool)
        if self.polygons.shape[1] != 4:
            return np.ones(len(self.boxes), dtype=bool)
        corners = _box_corners(self.boxes)
        same = np.zeros(len(self.boxes), dtype=bool)
        for shift in range(4):  # the same four corners from any first corner, either way round
            for poly in (self.polygons, self.polygons[:, ::-1]):
                same |= np.all(np.abs(np.roll(poly, shift, axis=1) - corners) < 1e-12, axis=(1, 2))
        return ~same

    def take(self, idx) -> Obstacles:
        """The obstacles at indices ``idx``, in that order."""
        idx = np.asarray(idx, dtype=int)
        return Obstacles(self.boxes[idx], [self.classes[i] for i in idx], self.stall[idx],
                         None if self.polygons is None else self.polygons[idx])

    def plus(self, other: Obstacles) -> Obstacles:
        """These obstacles followed by ``other``'s."""
        polys = None
        if self.polygons is not None or other.polygons is not None:
            a, b = self.outlines, other.outlines
            k = max(a.shape[1], b.shape[1])
            polys = np.concatenate([_pad(a, k), _pad(b, k)])
        return Obstacles(np.vstack([self.boxes.reshape(-1, 4), other.boxes.reshape(-1, 4)]),
                         [*self.classes, *other.classes], np.concatenate([self.stall, other.stall]).astype(int), polys)


def _pad(polys: np.ndarray, k: int) -> np.ndarray:
    """``polys`` (M, K', 2) with the last corner repeated up to ``k`` corners."""
    if polys.shape[1] >= k:
        return polys
    return np.concatenate([polys, np.repeat(polys[:, -1:], k - polys.shape[1], axis=1)], axis=1)


def polygon_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N,) distance [m] of each point (N, 2) to the convex polygon ``poly`` (K, 2): 0 inside or on it."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a  # (K, 2)
    ap = points[:, None, :] - a[None]  # (N, K, 2)
    denom = np.maximum((ab * ab).sum(-1), 1e-12)
    t = np.clip((ap * ab[None]).sum(-1) / denom, 0.0, 1.0)
    d = np.linalg.norm(ap - t[..., None] * ab[None], axis=-1).min(axis=1)
    cross = ab[None, :, 0] * ap[..., 1] - ab[None, :, 1] * ap[..., 0]  # (N, K), 0 on degenerate edges
    real = (ab * ab).sum(-1) > 1e-18
    cross = cross[:, real]
    inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    return np.where(inside, 0.0, d)


def polygon_axes(poly: np.ndarray) -> np.ndarray:
    """(K', 4) the separating axes of a convex polygon (K, 2): per edge of non-zero length its unit normal
    (nx, ny) and the polygon's projection on it (lo, hi)."""
    e = np.roll(poly, -1, axis=0) - poly
    n = np.linalg.norm(e, axis=1)
    e, n = e[n > 1e-9], n[n > 1e-9]
    normal = np.stack([-e[:, 1], e[:, 0]], axis=1) / n[:, None]
    proj = poly @ normal.T  # (K, K')
    return np.column_stack([normal, proj.min(axis=0), proj.max(axis=0)])


def scene_obstacles(scene: GarageScene) -> Obstacles:
    """Walls, obstacle blocks, pillars and stall outlines of ``scene`` as axis-aligned rectangles (angled stalls:
    every obstacle as its outline, :meth:`Obstacles.from_polygons`)."""
    boxes, classes, stall = [], [], []
    lay = scene.layout
    for box in lay.boxes:
        if box.collides and box.cls in (Semantic.WALL, Semantic.OBSTACLE):
            (cx, cy, _), (hx, hy, _) = box.center, box.half
            boxes.append((cx - hx, cy - hy, cx + hx, cy + hy))
            classes.append(box.cls.name.lower())
            stall.append(-1)
    h = scene.world.pillar_size / 2
    for p in lay.pillars:
        boxes.append((p.x - h, p.y - h, p.x + h, p.y + h))
        classes.append("pillar")
        stall.append(-1)
    for s in scene.stalls.stalls:
        xs, ys = zip(*s.corners)
        boxes.append((min(xs), min(ys), max(xs), max(ys)))
        classes.append("parked_car")
        stall.append(s.id)
    if any(s.angle not in (90.0, 0.0) for s in scene.stalls.stalls):  # angled stalls: their outlines, not boxes
        fixed = np.array(boxes[: len(boxes) - len(scene.stalls.stalls)], dtype=float).reshape(-1, 4)
        outlines = [*_box_corners(fixed), *(np.array(s.corners) for s in scene.stalls.stalls)]
        return Obstacles.from_polygons(outlines, classes, stall)
    return Obstacles(np.array(boxes, dtype=float).reshape(-1, 4), classes, np.array(stall, dtype=int))


def footprint(car: CarGeometry, rear: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """(N, 4, 2) corners of the car's body with its rear-axle midpoint at ``rear`` and ``heading``."""
    x0, x1 = car.rear - car.rear_axle, car.front - car.rear_axle
    w = car.half_width
    local = np.array([[x1, w], [x0, w], [x0, -w], [x1, -w]])
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    x = rear[:, 0:1] + c * local[:, 0] - s * local[:, 1]
    y = rear[:, 1:2] + s * local[:, 0] + c * local[:, 1]
    return np.stack([x, y], axis=-1)


def clearance(obs: Obstacles, car: CarGeometry, rear: np.ndarray, heading: np.ndarray,
              exclude_stall: int = -1) -> tuple[np.ndarray, list[str]]:
    """Per pose, the distance [m] of the car body to the nearest obstacle (0 when touching), and its class.

    The outline of stall ``exclude_stall`` (the test's target) is not an obstacle.
    """
    dist, nearest = nearest_obstacle(obs, car, rear, heading, exclude_stall)
    return dist, [obs.classes[k] if k >= 0 else "" for k in nearest]


def nearest_obstacle(obs: Obstacles, car: CarGeometry, rear: np.ndarray, heading: np.ndarray,
                     exclude_stall: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, the distance [m] of the car body to the nearest obstacle and that obstacle's index in ``obs``
    (-1 when none lies within ``NEAR_OBSTACLE`` of the poses: distance inf)."""
    keep = obs.stall != exclude_stall if exclude_stall >= 0 else np.ones(len(obs.boxes), dtype=bool)
    dist, idx = _distances(obs, car, rear, heading, keep)
    if not len(idx):
        return np.full(len(rear), np.inf), np.full(len(rear), -1)
    j = np.argmin(dist, axis=1)
    return dist[np.arange(len(rear)), j], idx[j]


def nearest_two(obs: Obstacles, car: CarGeometry, rear: np.ndarray, heading: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`nearest_obstacle` per pose, and the same without the nearest obstacle's stall (its own
    answer when that is no stall outline): what a test toward that stall measures (its own outline is
    no obstacle to it), from one pass over the obstacles near the poses."""
    keep = np.ones(len(obs.boxes), dtype=bool)
    dist, idx = _distances(obs, car, rear, heading, keep)
    n = len(rear)
    if not len(idx):
        none_d, none_j = np.full(n, np.inf), np.full(n, -1)
        return none_d, none_j, none_d.copy(), none_j.copy()
    rows = np.arange(n)
    j = np.argmin(dist, axis=1)
    stall_of = obs.stall[idx]
    own = stall_of[j]  # the nearest obstacle's stall (-1: not an outline)
    other = np.where((own[:, None] >= 0) & (stall_of[None, :] == own[:, None]), np.inf, dist)
    j2 = np.argmin(other, axis=1)
    d2 = other[rows, j2]
    return dist[rows, j], idx[j], d2, np.where(np.isinf(d2), -1, idx[j2])


def _distances(obs: Obstacles, car: CarGeometry, rear: np.ndarray, heading: np.ndarray,
               keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, M) distances of the car body at each pose to the ``keep`` obstacles near the poses, and those
    obstacles' indices (M,) in ``obs`` (exact below ``EXACT_BELOW``, else a lower bound)."""
    boxes = obs.boxes
    # only obstacles near the path
    lo, hi = rear.min(axis=0) - NEAR_OBSTACLE, rear.max(axis=0) + NEAR_OBSTACLE
    keep = keep & (boxes[:, 2] >= lo[0]) & (boxes[:, 0] <= hi[0]) & (boxes[:, 3] >= lo[1]) & (boxes[:, 1] <= hi[1])
    idx = np.flatnonzero(keep)
    if not len(idx):
        return np.zeros((len(rear), 0)), idx
    boxes = boxes[idx]
    outlines = None if obs.polygons is None else obs.polygons[idx]
    rotated = obs.rotated[idx]
    body = footprint(car, rear, heading)  # (N, 4, 2)
    # a cheap lower bound from the body's bounding circle; exact distances only where it is small
    mid = body.mean(axis=1)  # (N, 2) body centre
    radius = float(np.linalg.norm(body[0, 0] - mid[0]))
    dx = np.maximum(np.maximum(boxes[None, :, 0] - mid[:, None, 0], mid[:, None, 0] - boxes[None, :, 2]), 0.0)
    dy = np.maximum(np.maximum(boxes[None, :, 1] - mid[:, None, 1], mid[:, None, 1] - boxes[None, :, 3]), 0.0)
    bound = np.hypot(dx, dy) - radius  # (N, M) <= the true distance
    dist = np.maximum(bound, 0.0)
    n_i, m_i = np.nonzero(bound < EXACT_BELOW)
    if len(n_i):
        cars, bx = body[n_i], boxes[m_i]  # (K, 4, 2), (K, 4)
        bc = _box_corners(bx) if outlines is None else outlines[m_i]
        exact = np.minimum(_points_to_edges(cars, bc), _points_to_edges(bc, cars))
        overlap = _overlap_pairs(cars, bx, bc)
        turned = rotated[m_i]
        if turned.any():  # a polygon's own edges may separate it from the car where its box does not
            overlap[turned] &= ~_separated_by_edges(cars[turned], bc[turned])
        exact[overlap] = 0.0
        dist[n_i, m_i] = exact
    return dist, idx


def _points_to_edges(points: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Smallest distance from any of ``points`` (..., 4, 2) to any edge of ``polys`` (..., 4, 2)."""
    a = polys
    b = np.roll(polys, -1, axis=-2)
    ab = b - a  # (..., 4, 2) edges
    p = points[..., :, None, :]  # (..., 4 points, 1, 2)
    ap = p - a[..., None, :, :]
    denom = np.maximum((ab * ab).sum(-1), 1e-12)[..., None, :]
    t = np.clip((ap * ab[..., None, :, :]).sum(-1) / denom, 0.0, 1.0)
    closest = a[..., None, :, :] + t[..., None] * ab[..., None, :, :]
    d = np.linalg.norm(p - closest, axis=-1)
    return d.min(axis=(-1, -2))


def _separated_by_edges(car: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """(K,) whether an edge normal of each convex polygon (K, V, 2) separates it from its car rectangle (K, 4, 2)."""
    e = np.roll(polys, -1, axis=1) - polys  # (K, V, 2)
    normal = np.stack([-e[..., 1], e[..., 0]], axis=-1)  # (K, V, 2); zero on a repeated corner: never separates
    pc = np.einsum("kcd,kvd->kvc", car, normal)  # (K, V, 4)
    pp = np.einsum("kcd,kvd->kvc", polys, normal)  # (K, V, V)
    sep = (pc.max(-1) < pp.min(-1)) | (pc.min(-1) > pp.max(-1))
    return sep.any(axis=1)


def _box_corners(boxes: np.ndarray) -> np.ndarray:
    """(K, 4, 2) corners, counter-clockwise, of axis-aligned boxes (K, 4) [xmin, ymin, xmax, ymax]."""
    return np.stack([boxes[:, [0, 1]], boxes[:, [2, 1]], boxes[:, [2, 3]], boxes[:, [0, 3]]], axis=1)


def _overlap_pairs(car: np.ndarray, boxes: np.ndarray, bc: np.ndarray) -> np.ndarray:
    """(K,) whether each car rectangle (K, 4, 2) overlaps its axis-aligned box (K, 4), corners ``bc``."""
    sep = ((car[..., 0].max(-1) < boxes[:, 0]) | (car[..., 0].min(-1) > boxes[:, 2])
           | (car[..., 1].max(-1) < boxes[:, 1]) | (car[..., 1].min(-1) > boxes[:, 3]))
    for e in (0, 1):  # the car's two axes
        axis = car[:, e + 1] - car[:, e]
        axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        pc = np.einsum("kcd,kd->kc", car, axis)
        pb = np.einsum("kcd,kd->kc", bc, axis)
        sep |= (pc.max(-1) < pb.min(-1)) | (pc.min(-1) > pb.max(-1))
    return ~sep
