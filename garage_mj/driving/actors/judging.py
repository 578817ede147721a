"""Whether every adverse event of a cruise test stays avoidable: :func:`judge`, decided before the drive.

Feasibility is never decided from a drive's outcome: a test with actors is infeasible when an
actor starts or ends in the car's swept path (no room to pass, nothing to wait for), or when an
actor's motion reaches the car's path less than the stopping distance
``v t_react + v^2 / (2 a_brake)`` (``v`` the car's top speed) beyond the place where the trigger
fires (at the latest: one control step, :data:`~garage_mj.driving.actors.scenario.CONTROL_LAG`, late).
"""

from __future__ import annotations

import numpy as np

from garage_mj.driving.actors.config import ScenarioConfig
from garage_mj.driving.actors.scenario import CONTROL_LAG, Corridor, actor_poses, sample_times
from garage_mj.scene.actor_spec import ActorSpec
from garage_mj.scene.drivable import DrivePlanner, TestPlan


def judge(actors: list[ActorSpec], plan: TestPlan, planner: DrivePlanner, config: ScenarioConfig,
          margin: float | None = None) -> tuple[bool, str]:
    """Whether a driver of this car can avoid every actor (and why not), from the scene and the trigger rule.

    Used by :func:`~garage_mj.driving.actors.placement.draw_scenario` and on a replayed scenario (a
    ``.xosc``), whose actors were not drawn here.
    """
    if not actors or not plan.feasible:
        return True, ""
    margin = planner.config.clearance_margin if margin is None else float(margin)
    return judge_path(actors, Corridor(plan, planner.car), config, margin, planner.car.max_speed)


def judge_path(actors: list[ActorSpec], corr: Corridor, config: ScenarioConfig, margin: float, v: float,
               rest_start: bool = False) -> tuple[bool, str]:
    """:func:`judge` on the car's swept path ``corr`` driven at up to ``v`` [m/s] (a park plan's: ``park_speed``).

    ``rest_start``: the car starts at rest (a park test), so an actor it starts within reach of needs no stopping
    distance, only to keep off the car where it stands.
    """
    car = corr.car
    for a in actors:
        noun = a.name.replace("_", " ")
        if a.static:
            gap = corr.clearance(a.shape, a.waypoints[:1, 1:])
            if gap < margin:
                return False, f"{noun} ({a.behaviour}) stands {max(gap, 0.0):.2f} m from the car's path (margin {margin:.2f} m)"
            continue
        times = sample_times(a)
        hit = corr.conflicts(a.shape, actor_poses(a, times), margin)
        hit[:, : corr.i0] = False
        if hit[0].any():
            return False, f"{noun} ({a.behaviour}) waits in the car's path"
        if hit[-1].any():
            return False, f"{noun} ({a.behaviour}) stops in the car's path: no room to pass"
        # where the trigger fires at the latest: at the trigger point (or at the start, if already inside)
        trig = np.asarray(a.trigger, dtype=float)
        d = np.linalg.norm(corr.centre - trig, axis=1)
        inside = np.flatnonzero(d <= a.trigger_radius)
        if not len(inside) or corr.s[corr.i0] >= corr.s[inside[-1]]:
            fire = corr.s[corr.i0]  # the car starts within reach of the trigger
        else:
            fire = corr.s[int(np.argmin(d))]
        d_stop = 0.0 if rest_start and fire <= corr.s[corr.i0] else config.stopping_distance(v)
        fire = max(fire, corr.s[corr.i0]) + v * CONTROL_LAG  # one control step late
        cols = np.flatnonzero(hit.any(axis=0))
        body = car.front - car.rear + a.trigger_radius
        bad = cols[(corr.s[cols] >= fire - body) & (corr.s[cols] < fire + d_stop)]
        if len(bad):
            gap = corr.s[bad[0]] - fire
            return False, (f"{noun} ({a.behaviour}) reaches the car's path {gap:.1f} m after its trigger; "
                           f"stopping from {v:.1f} m/s needs {d_stop:.1f} m")
    return True, ""
