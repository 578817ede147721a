"""Plan one garage-mj park problem with OMPL (Reeds-Shepp curves, RRT-Connect), check the path against the
problem's obstacles with its margin, and score it against the problem's reference plan.

Usage: python park_problem_example.py PROBLEM.json   (a file of garage-mj export --park-problems)

Only ompl, json and math: the problem file is all a planner needs (docs/park-problems.md).
"""

from __future__ import annotations

import json
import math
import sys

from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

STEP = 0.1  # [m] spacing of the poses checked along the path
PLAN_TIME = 5.0  # [s] RRT-Connect's budget


def footprint(car: dict, pose: list[float], grow: float) -> list[tuple[float, float]]:
    """The car's body at a rear-axle pose [x, y, yaw], grown by ``grow`` metres on every side: 4 corners, CCW."""
    x, y, yaw = pose
    back, front = -car["rear_overhang"] - grow, car["wheelbase"] + car["front_overhang"] + grow
    side = car["width"] / 2 + grow
    c, s = math.cos(yaw), math.sin(yaw)
    return [(x + a * c - b * s, y + a * s + b * c) for a, b in ((back, -side), (front, -side), (front, side),
                                                                (back, side))]


def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _segments_meet(p1, p2, q1, q2) -> bool:
    d1, d2, d3, d4 = _cross(q1, q2, p1), _cross(q1, q2, p2), _cross(p1, p2, q1), _cross(p1, p2, q2)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and 0 not in (d1, d2, d3, d4):
        return True
    return any(d == 0 and min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])
               for d, a, b, c in ((d1, q1, q2, p1), (d2, q1, q2, p2), (d3, p1, p2, q1), (d4, p1, p2, q2)))


def _inside(point, polygon) -> bool:
    x, y, inside = point[0], point[1], False
    for (x1, y1), (x2, y2) in zip(polygon, polygon[1:] + polygon[:1]):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def polygons_touch(a: list, b: list) -> bool:
    """Do two simple polygons overlap (an edge crossing, or one inside the other)?"""
    edges_a, edges_b = list(zip(a, a[1:] + a[:1])), list(zip(b, b[1:] + b[:1]))
    if any(_segments_meet(p, q, r, s) for p, q in edges_a for r, s in edges_b):
        return True
    return _inside(a[0], b) or _inside(b[0], a)


class Problem:
    """A park problem file and the collision check it implies."""

    def __init__(self, path: str) -> None:
        with open(path) as f:
            self.data = json.load(f)
        self.car, self.margin = self.data["car"], self.data["planner"]["margin"]
        self.obstacles = []
        for o in self.data["obstacles"]:
            pts = [tuple(v) for v in o["vertices"]]
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
            self.obstacles.append((min(xs), min(ys), max(xs), max(ys), pts))

    def clear(self, pose: list[float]) -> bool:
        """Is the rear axle inside the region, and the body grown by the margin clear of every obstacle?"""
        xmin, ymin, xmax, ymax = self.data["region"]
        if not (xmin <= pose[0] <= xmax and ymin <= pose[1] <= ymax):
            return False
        body = footprint(self.car, pose, self.margin)
        bx, by = [p[0] for p in body], [p[1] for p in body]
        return not any(max(bx) >= x0 and min(bx) <= x1 and max(by) >= y0 and min(by) <= y1 and polygons_touch(body, pts)
                       for x0, y0, x1, y1, pts in self.obstacles)


def plan(problem: Problem, seed: int = 1) -> list[list[float]] | None:
    """Rear-axle poses [x, y, yaw] every STEP metres from start to goal, or None: Reeds-Shepp + RRT-Connect."""
    ou.setLogLevel(ou.LOG_WARN)
    ou.RNG.setSeed(seed)  # before OMPL draws its first random number: the same seed, the same path
    space = ob.ReedsSheppStateSpace(problem.data["planner"]["turning_radius"])
    bounds = ob.RealVectorBounds(2)
    xmin, ymin, xmax, ymax = problem.data["region"]
    bounds.setLow(0, xmin)
    bounds.setLow(1, ymin)
    bounds.setHigh(0, xmax)
    bounds.setHigh(1, ymax)
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(lambda st: problem.clear([st.getX(), st.getY(), st.getYaw()]))
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(STEP / space.getMaximumExtent())
    ends = []
    for key in ("start", "goal"):
        st = space.allocState()
        x, y, yaw = problem.data[key]  # yaws lie in [-pi, pi), the bounds of OMPL's SO2
        st.setX(x)
        st.setY(y)
        st.setYaw(yaw)
        ends.append(st)
    ss.setStartAndGoalStates(ends[0], ends[1], 1e-3)
    ss.setPlanner(og.RRTConnect(si))
    if not ss.solve(PLAN_TIME) or not ss.haveExactSolutionPath():
        return None
    ss.simplifySolution()
    path = ss.getSolutionPath()
    path.interpolate(max(2, math.ceil(path.length() / STEP) + 1))
    return [[st.getX(), st.getY(), st.getYaw()] for st in path.getStates()]


def gears(poses: list[list[float]]) -> list[int]:
    """+1 (forward) or -1 (reverse) for each step: the motion's direction against the heading."""
    out = []
    for (x0, y0, yaw), (x1, y1, _) in zip(poses, poses[1:]):
        if math.hypot(x1 - x0, y1 - y0) > 1e-6:  # a step of no length (at a cusp) has no direction
            out.append(1 if (x1 - x0) * math.cos(yaw) + (y1 - y0) * math.sin(yaw) >= 0 else -1)
    return out


def score(problem: Problem, poses: list[list[float]]) -> dict:
    """The path's length and cusps next to the reference plan's, and whether every pose is clear."""
    length = sum(math.dist(a[:2], b[:2]) for a, b in zip(poses, poses[1:]))
    g = gears(poses)
    cusps = sum(a != b for a, b in zip(g, g[1:]))
    ref = problem.data.get("reference") or {}
    out = {"clear": all(problem.clear(p) for p in poses), "length": round(length, 2), "cusps": cusps}
    if ref.get("found"):
        out |= {"reference_length": round(ref["length"], 2), "length_ratio": round(length / ref["length"], 3),
                "reference_cusps": ref["cusps"]}
    return out


def main(path: str) -> dict:
    problem = Problem(path)
    poses = plan(problem)
    result = {"found": poses is not None} | (score(problem, poses) if poses else {})
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main(sys.argv[1])
