"""What a cruise test asks of a driver, from its planned route alone (before any drive).

:func:`plan_features` reads one feasible :class:`~garage_mj.scene.drivable.TestPlan` (the route the
planner of :mod:`garage_mj.scene.drivable` gives to a stall) and returns :data:`FEATURES`, each
oriented so that a larger value is a harder drive:

``length``
    [m] route from the start pose to the goal.
``turns``, ``left_turns``, ``right_turns``
    90-degree turns on the route (the planner's fillets), and of them to the left and right.
``heading_change``
    [rad] total absolute heading change, the integral of ``|curvature|``.
``tightness``
    the route's largest ``|curvature|`` as a share of the car's own limit (1 = full lock).
``squeeze``
    ``CLEAR_CAP`` minus the smallest swept clearance [m] of the car's body to walls, pillars,
    obstacles and stall outlines (every stall may hold a parked car), capped at ``CLEAR_CAP``.
``turn_squeeze``
    the same over the poses in a turn or within ``TURN_REACH`` of one (where drivers cut corners).
``tight_length``
    [m] of the route where the swept clearance is below ``TIGHT`` m.
``stalls_passed``
    other stalls whose outline comes within ``PASS_REACH`` m of the car's body along the route
    (where a parked car can be hit).
``junctions``
    road cells with three or more openings that the route crosses (the goal's cell included).
``goal_left``, ``goal_ahead``
    1 when the stall lies across the lane (on the driver's left) or ahead (a dead end facing
    stalls); 0 when it lies on the car's own side (the planner's preference).
``pullback``
    [m] how far the goal moved back from the stall because its pose was not clear.
``short_roads``, ``few_way``
    the whole garage's two terms of the paper's difficulty (:func:`garage_mj.grid.metrics.difficulty`),
    the same for every test of a garage: ``1 - n_X`` (short road segments, E[X] of 2 cells -> 1,
    6 -> 0) and ``1 - n_Y`` (junctions where few roads meet, E[Y] of 2 -> 1, 4 -> 0). Some drivers
    fail by the garage as a whole rather than by their route (the learned driver, on the fresh held-out set).

:func:`garage_features` gives the features of every stall of a garage; cruise draws the target
stall uniformly and counts success over the feasible ones, so the expectation of a per-test
quantity over a garage's tests is the mean over its feasible stalls.
"""

from __future__ import annotations

import math
import weakref
from typing import TYPE_CHECKING

import numpy as np

from garage_mj.grid.metrics import DEFAULT_DIFFICULTY, evaluate
from garage_mj.scene.drivable import DrivePlanner, drive_planner

if TYPE_CHECKING:
    from garage_mj.scene.drivable import TestPlan
    from garage_mj.scene.garage_scene import GarageScene

FEATURES = ("length", "turns", "left_turns", "right_turns", "heading_change", "tightness", "squeeze",
            "turn_squeeze", "tight_length", "stalls_passed", "junctions", "goal_left", "goal_ahead", "pullback",
            "short_roads", "few_way")
CLEAR_CAP = 2.0  # [m] clearances above this count as open (the planner measures them exactly below 2 m)
TIGHT = 0.75  # [m] swept clearance below which a stretch of route is tight
TURN_REACH = 3.0  # [m] poses this close (along the route) to a turn belong to it for turn_squeeze
PASS_REACH = 1.0  # [m] a stall outline this close to the car's body is passed
#: per planner (one per garage and car), per pose (:func:`~garage_mj.scene.drivable.pose_keys`): the stalls in reach
_PASSED: weakref.WeakKeyDictionary[DrivePlanner, dict[bytes, frozenset[int]]] = weakref.WeakKeyDictionary()
#: per planner: its garage's grid-level features (``short_roads``, ``few_way``)
_GARAGE: weakref.WeakKeyDictionary[DrivePlanner, dict[str, float]] = weakref.WeakKeyDictionary()


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges of the True runs of ``mask``."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def plan_features(planner: DrivePlanner, plan: TestPlan) -> dict[str, float]:
    """The :data:`FEATURES` of one feasible test plan (raises ``ValueError`` for an infeasible one)."""
    if not plan.feasible or plan.centre is None or plan.clearances is None:
        raise ValueError(f"stall {plan.stall}: no feasible route ({plan.reason}); route features need one")
    i0 = plan.drive_from
    centre, rear, hdg = plan.centre[i0:], plan.rear[i0:], plan.heading[i0:]
    kap = plan.curvature[i0:]
    clear = np.minimum(plan.clearances, CLEAR_CAP)
    seg = np.linalg.norm(np.diff(rear, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    ds = np.concatenate([seg, [0.0]])  # length of route each pose stands for
    curved = np.abs(kap) > 1e-9
    turns = _runs(curved)
    left = sum(1 for a, _ in turns if kap[a] > 0)
    near_turn = np.zeros(len(s), dtype=bool)
    for a, b in turns:
        near_turn |= (s >= s[a] - TURN_REACH) & (s <= s[b - 1] + TURN_REACH)
    # junction cells crossed
    net, rows = planner.net, planner.rows
    b = planner.world.block
    r_, c_ = (rows - 1 - np.floor(centre[:, 1] / b)).astype(int), np.floor(centre[:, 0] / b).astype(int)
    cells = {divmod(int(code), 1 << 16) for code in np.unique((r_ << 16) + (c_ & 0xFFFF))}  # world_to_cell, once each
    junctions = sum(1 for c in cells if c in net.cells and len(net.cells[c].openings) >= 3)
    return {
        "length": float(np.linalg.norm(np.diff(centre, axis=0), axis=1).sum()),
        "turns": float(len(turns)),
        "left_turns": float(left),
        "right_turns": float(len(turns) - left),
        "heading_change": float(np.sum(np.abs(kap) * ds)),
        "tightness": float(np.abs(kap).max() / planner.car.max_curvature),
        "squeeze": float(CLEAR_CAP - clear.min()),
        "turn_squeeze": float(CLEAR_CAP - clear[near_turn].min()) if near_turn.any() else 0.0,
        "tight_length": float(ds[clear < TIGHT].sum()),
        "stalls_passed": float(_stalls_passed(planner, rear, hdg, plan.stall, planner.plan_keys(plan)[i0:])),
        "junctions": float(junctions),
        "goal_left": float(plan.stall_side == "left"),
        "goal_ahead": float(plan.stall_side == "ahead"),
        "pullback": float(plan.pullback),
        **_garage_terms(planner),
    }


def _garage_terms(planner: DrivePlanner) -> dict[str, float]:
    """The paper's two difficulty terms of the planner's garage, as ``short_roads`` and ``few_way`` (kept per planner)."""
    terms = _GARAGE.get(planner)
    if terms is None:
        m = evaluate(planner.scene.garage)
        c = DEFAULT_DIFFICULTY
        terms = {"short_roads": 1.0 - (m.mean_road_length - c.road_length_min) / (c.road_length_max - c.road_length_min),
                 "few_way": 1.0 - (m.mean_intersection_degree - c.intersection_min) / (c.intersection_max - c.intersection_min)}
        _GARAGE[planner] = terms
    return terms


def _stalls_passed(planner: DrivePlanner, rear: np.ndarray, hdg: np.ndarray, target: int, keys: list[bytes]) -> int:
    """Stalls other than ``target`` whose outline comes within ``PASS_REACH`` of the car's body at the poses
    ``rear``, ``hdg`` (their :func:`~garage_mj.scene.drivable.pose_keys` ``keys``).

    Routes to a garage's stalls share most poses, so each pose's stalls in reach are kept on the planner.
    """
    cache = _PASSED.setdefault(planner, {})
    miss = [i for i, k in enumerate(keys) if k not in cache]
    if miss:
        obs = planner.obstacles()
        is_stall = obs.stall >= 0
        boxes, ids = obs.boxes[is_stall], obs.stall[is_stall]
        body = planner.footprint(rear[miss], hdg[miss])  # (N, 4, 2)
        lo, hi = body.min(axis=1), body.max(axis=1)  # the body's axis-aligned bounds per pose
        # gap between the body's bounds and each box (a lower bound of their distance; exact for axis-aligned poses)
        gx = np.maximum(np.maximum(boxes[None, :, 0] - hi[:, None, 0], lo[:, None, 0] - boxes[None, :, 2]), 0.0)
        gy = np.maximum(np.maximum(boxes[None, :, 1] - hi[:, None, 1], lo[:, None, 1] - boxes[None, :, 3]), 0.0)
        near = np.hypot(gx, gy) <= PASS_REACH
        for row, i in enumerate(miss):
            cache[keys[i]] = frozenset(ids[near[row]].tolist())
    passed = frozenset().union(*filter(None, map(cache.__getitem__, keys)))
    return len(passed - {target})


def garage_features(scene: GarageScene, car=None) -> dict[int, dict[str, float] | None]:
    """Per stall id, the :data:`FEATURES` of its test, or None when no feasible route reaches it."""
    planner = drive_planner(scene, car)
    out: dict[int, dict[str, float] | None] = {}
    for plan in planner.plans():
        out[plan.stall] = plan_features(planner, plan) if plan.feasible else None
    return out


def mean_features(features: dict[int, dict[str, float] | None]) -> dict[str, float]:
    """The expectation of each feature over a garage's tests: the mean over its feasible stalls (NaN if none)."""
    rows = [f for f in features.values() if f is not None]
    if not rows:
        return {k: math.nan for k in FEATURES}
    return {k: float(np.mean([r[k] for r in rows])) for k in FEATURES}
