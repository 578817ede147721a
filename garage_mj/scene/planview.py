"""Plan-view geometry of OpenDRIVE reference lines: lines and arcs, poses along them.

Pure 2D maths shared by the road model, the OpenDRIVE writer and the lane graph, so the
XML and the Python lane graph can never disagree. Headings are radians counter-clockwise
from +x (east); positive curvature turns left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

Pose = tuple[float, float, float]  # (x [m], y [m], heading [rad])

_EPS = 1e-9  # [m] lengths below this are dropped


@dataclass(frozen=True)
class Segment:
    """One ``<geometry>`` record: a line (curvature 0) or an arc, starting at ``s``."""

    s: float  # [m] start along the road
    x: float  # [m] start point
    y: float  # [m]
    hdg: float  # [rad] start heading
    length: float  # [m]
    curvature: float = 0.0  # [1/m], > 0 turns left

    def pose(self, ds: float) -> Pose:
        """Pose at distance ``ds`` from the segment start."""
        k = self.curvature
        h = self.hdg + k * ds
        if abs(k) < 1e-12:
            return self.x + ds * math.cos(self.hdg), self.y + ds * math.sin(self.hdg), h
        return (
            self.x + (math.sin(h) - math.sin(self.hdg)) / k,
            self.y - (math.cos(h) - math.cos(self.hdg)) / k,
            h,
        )

    def end(self) -> Pose:
        return self.pose(self.length)

    def project(self, x: float, y: float) -> tuple[float, float]:
        """(ds, t) of the point nearest (x, y) on this segment, ds clamped to [0, length].

        ``t`` is the signed lateral offset, positive to the left of the reference line.
        """
        k = self.curvature
        if abs(k) < 1e-12:
            c, s = math.cos(self.hdg), math.sin(self.hdg)
            dx, dy = x - self.x, y - self.y
            ds = min(max(dx * c + dy * s, 0.0), self.length)
            px, py, _ = self.pose(ds)
            return ds, (x - px) * -s + (y - py) * c
        r = 1.0 / k
        cx, cy = self.x - r * math.sin(self.hdg), self.y + r * math.cos(self.hdg)
        a0 = math.atan2(self.y - cy, self.x - cx)
        a = math.atan2(y - cy, x - cx)
        sweep = (a - a0) if k > 0 else (a0 - a)
        sweep = sweep % (2 * math.pi)
        ds = sweep * abs(r)
        if ds > self.length:  # past the end or before the start: clamp to the nearer end
            past = ds - self.length
            before = 2 * math.pi * abs(r) - ds
            ds = self.length if past < before else 0.0
        px, py, h = self.pose(ds)
        return ds, (x - px) * -math.sin(h) + (y - py) * math.cos(h)


def wrap(angle: float) -> float:
    """``angle`` wrapped to (-pi, pi]."""
    a = math.atan2(math.sin(angle), math.cos(angle))
    return math.pi if a == -math.pi else a


def connect(start: Pose, end: Pose, s0: float = 0.0) -> list[Segment]:
    """Lines and one arc from ``start`` to ``end`` whose headings are equal or a quarter turn apart.

    A quarter turn uses the largest circle that fits (radius = the shorter leg), with a line on
    the longer leg: a curve tile (legs B/2, B/2) becomes one quarter circle of radius B/2.
    """
    x0, y0, h0 = start
    x1, y1, h1 = end
    c, s = math.cos(h0), math.sin(h0)
    a = (x1 - x0) * c + (y1 - y0) * s  # forward leg
    b = -(x1 - x0) * s + (y1 - y0) * c  # left leg
    turn = wrap(h1 - h0)
    out: list[Segment] = []
    if abs(turn) < 1e-6:
        if abs(b) > 1e-6 or a <= 0:
            raise ValueError(f"cannot join {start} to {end} with a straight line")
        return [Segment(s0, x0, y0, h0, a)]
    if abs(abs(turn) - math.pi / 2) > 1e-6 or a <= 0 or b * turn <= 0:
        raise ValueError(f"cannot join {start} to {end} with a quarter turn")
    r = min(a, abs(b))
    pose = start
    s_at = s0
    if a - r > _EPS:
        out.append(Segment(s_at, *pose, a - r))
        pose, s_at = out[-1].end(), s_at + a - r
    arc = Segment(s_at, *pose, r * math.pi / 2, math.copysign(1.0 / r, turn))
    out.append(arc)
    pose, s_at = arc.end(), s_at + arc.length
    if abs(b) - r > _EPS:
        out.append(Segment(s_at, *pose, abs(b) - r))
    return out


def pose_at(segments: list[Segment], s: float) -> Pose:
    """Pose at ``s`` along a chain of segments (clamped to the chain)."""
    for seg in segments:
        if s <= seg.s + seg.length:
            return seg.pose(min(max(s - seg.s, 0.0), seg.length))
    return segments[-1].end()


def offset(pose: Pose, t: float) -> tuple[float, float]:
    """Point ``t`` metres to the left of ``pose`` (right for t < 0)."""
    x, y, h = pose
    return x - t * math.sin(h), y + t * math.cos(h)


def sample(segments: list[Segment], t: float, step: float) -> list[Pose]:
    """Poses of the curve at lateral offset ``t``, about every ``step`` metres, ends included.

    Headings are those of the reference line (parallel curves share them).
    """
    total = segments[-1].s + segments[-1].length - segments[0].s
    n = max(1, math.ceil(total / step - 1e-9))
    out = []
    for i in range(n + 1):
        p = pose_at(segments, segments[0].s + total * i / n)
        out.append((*offset(p, t), p[2]))
    return out


def merge_lines(segments: list[Segment]) -> list[Segment]:
    """Consecutive collinear lines joined into one (OpenDRIVE checkers flag redundant lines)."""
    out: list[Segment] = []
    for seg in segments:
        prev = out[-1] if out else None
        if (
            prev is not None
            and prev.curvature == 0.0
            and seg.curvature == 0.0
            and abs(wrap(prev.hdg - seg.hdg)) < 1e-9
        ):
            out[-1] = Segment(prev.s, prev.x, prev.y, prev.hdg, prev.length + seg.length)
        else:
            out.append(seg)
    return out
