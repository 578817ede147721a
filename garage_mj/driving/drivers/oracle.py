"""``oracle``: the privileged reference driver that proves each feasible test drivable.

It knows the car's exact pose (``obs["pose"]``) and the test's whole feasible route (the
rear-axle path, headings and curvature from :mod:`garage_mj.scene.drivable`, handed over in
``info`` at reset) and drives it with continuous control:

- steering: a kinematic path tracker on the rear-axle path: the path's curvature a short preview
  ahead (the steering lags by its rate limit) plus feedback on lateral and heading error;
- speed: a profile computed once per test, backwards from the goal (where it is zero): on curves
  no faster than ``lateral_accel`` allows and than the steering rate can follow, braking at
  ``stop_decel`` into curves and to the goal.

With actors (:mod:`garage_mj.driving.actors.scenario`) it is privileged too: it gets every actor's trajectory
(``info["actors"]``) and each actor's time since its trigger (``obs["actors"]``), and yields: at
reset it finds, per moving actor and per moment of its trajectory, which poses of its own path the
actor's body comes near (``actor_margin``); while any not-yet-run part of an actor's trajectory
still reaches the path ahead, it brakes to stop ``actor_gap`` before the first such pose, and
drives on when the actor has passed. A stop that would fall inside a turn moves back to the
straight before it (the tracker holds a curve worse from a standstill).

Park and AVP tests (docs/spec.md section 8): when the reset info has ``park_plan`` (the reference park
plan: car-centre ``poses`` and gear ``directions``), the oracle tracks it forward and in reverse with
:class:`~garage_mj.driving.drivers.park_tracking.ParkTracker` and answers the continuous park action
``[pedal, steer, gear]``. A park test (``task`` "park") is the plan alone; an AVP test (``task`` "avp")
first drives the cruise route exactly as a cruise test does (in D), until ``handover`` metres before its
goal; the tracker then follows that last stretch of the route and the plan after it, without stopping
at the goal when the plan begins forward (the cruise tracker can leave the car a few decimetres off the
goal after a turn, more than a short first park segment can take out). With discrete actions it answers
a :class:`~garage_mj.driving.sim.vehicle.ParkAction`: a gear selection while the wanted gear is not in,
else the closest cruise action (which costs precision).
Without ``park_plan`` nothing of this runs: a cruise test's commands are the same.

If the oracle fails a feasible test, the test or the testbed is wrong, not the driver under test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from garage_mj.driving.actors.scenario import Corridor, actor_poses, sample_times
from garage_mj.driving.drivers.base import BaseDriver
from garage_mj.driving.drivers.park_tracking import ParkTrackConfig, ParkTracker
from garage_mj.driving.sim.vehicle import Gear, ParkAction
from garage_mj.scene.actor_spec import ActorSpec
from garage_mj.scene.drivable import TestPlan
from garage_mj.scene.park_planning import rear_to_centre


@dataclass(frozen=True)
class OracleConfig:
    """Speeds and gains of the reference driver."""

    cruise_speed: float = 3.0  # [m/s] on straight road
    lateral_accel: float = 1.0  # [m/s^2] v <= sqrt(a_lat / |curvature|) on curves
    steer_ramp: float = 0.6  # [m] a curvature change must be steerable within this distance
    stop_decel: float = 1.2  # [m/s^2] planned braking into curves and to the goal
    k_lateral: float = 0.5  # [1/m^2] curvature command per metre of lateral error
    k_heading: float = 1.2  # [1/m] curvature command per radian of heading error
    preview: float = 0.3  # [m] curvature preview: half the steering ramp, so the ramp is centred
    stop_within: float = 0.15  # [m] closer than this to the goal: brake to a stop
    actor_margin: float = 0.4  # [m] an actor this close to the car body at a path pose blocks that pose
    actor_gap: float = 0.5  # [m] stop this far before the first blocked pose
    actor_decel: float = 2.0  # [m/s^2] braking for actors


class OracleDriver(BaseDriver):
    """Tracks the test's planned route with its exact pose; privileged, continuous control."""

    config_class = OracleConfig
    action_type = "continuous"  # made for [throttle, steer]; discrete actions round its commands
    tasks = ("cruise", "park", "avp")  # it reverses where a park plan asks (garage_mj.cli.cruise.task_warning)

    #: Gains and speeds of the park plan tracker (park and AVP tests).
    park_config = ParkTrackConfig()

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        self.tracker: ParkTracker | None = None
        self._actors = info.get("actors") or []  # the test's moving actors (the park tracker yields to them)
        self.phase = "cruise"  # "cruise" (no park plan, or an AVP test's route) or "park"
        plan = info.get("park_plan")
        avp = info.get("task", "park") == "avp"
        if plan is not None and len(plan["poses"]) >= 2 and not avp:
            self.tracker = ParkTracker(plan["poses"], plan["directions"], self.car, self.park_config, self.dt)
            self._park_yield(info)
            self.phase = "park"
            return
        rear = info.get("rear_path")
        if rear is None or info.get("rear_heading") is None:
            raise ValueError("the oracle driver needs the test's plan (rear_path, rear_heading, rear_curvature) "
                             "in its reset info: run it in GarageDrive-v0 (env.driver_info)")
        self.path = np.asarray(rear, dtype=float)
        self.heading = np.asarray(info["rear_heading"], dtype=float)
        self.kappa = np.asarray(info["rear_curvature"], dtype=float)
        seg = np.linalg.norm(np.diff(self.path, axis=0), axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(seg)])
        self.index = 0
        self.v_limit = self._speed_profile()
        self._actor_blocks(info.get("actors") or [])
        if plan is not None and len(plan["poses"]) >= 2:  # AVP: the route's last stretch, then the park plan
            self.tracker = self._handover(plan)
            self._park_yield(info)

    def follow(self, poses, directions) -> None:
        """Track a new park plan from here on (``poses`` (N, 3) car centre, ``directions`` (N,) +1/-1): a plan made
        again from the car's pose, as the park guide shows one; it yields to the test's actors as the first did."""
        self.tracker = ParkTracker(poses, directions, self.car, self.park_config, self.dt)
        self.phase = "park"
        self._park_yield({"actors": self._actors})

    def _park_yield(self, info: dict[str, Any]) -> None:
        """The park tracker yields to the test's moving actors as the cruise route does (``actor_margin``, ``_gap``,
        ``_decel``)."""
        actors = info.get("actors") or []
        if actors:
            cfg = self.config
            self.tracker.watch(actors, cfg.actor_margin, cfg.actor_gap, cfg.actor_decel)

    def _handover(self, plan: dict[str, Any]) -> ParkTracker:
        """An AVP test's tracker: the last ``handover`` metres of the cruise route (forward), then the park
        plan, so the car is on the plan's start line when the parking begins, not where the cruise left it."""
        tail = np.flatnonzero(self.s >= self.s[-1] - self.park_config.handover)
        rear = np.column_stack([self.path[tail], self.heading[tail]])
        poses = np.vstack([rear_to_centre(rear, self.car), np.asarray(plan["poses"], dtype=float)])
        directions = np.concatenate([np.ones(len(tail), dtype=np.int8), np.asarray(plan["directions"])])
        return ParkTracker(poses, directions, self.car, self.park_config, self.dt)

    def to_discrete(self, throttle: float, steer: float, obs: dict[str, Any]) -> int:
        """With the paper's actions it knows the car's answer to each (:meth:`track_discrete`)."""
        return self.track_discrete(throttle, steer, obs)

    def _actor_blocks(self, actors: list) -> None:
        """Per moving actor that comes near the path: its sample times and, per time, which path poses
        the rest of its trajectory from then on blocks (computed once here, read each step)."""
        self.blocks: list[tuple[int, np.ndarray, np.ndarray, int]] = []  # (actor, times, blocked (T, N), trigger index)
        if not actors:
            return
        centre = self.path + (-self.car.rear_axle) * np.stack([np.cos(self.heading), np.sin(self.heading)], axis=1)
        corr = Corridor(TestPlan(0, True, "", centre=centre, rear=self.path, heading=self.heading,
                                 curvature=self.kappa), self.car)
        for k, d in enumerate(actors):
            a = d if isinstance(d, ActorSpec) else ActorSpec.from_dict(d)
            if a.static:
                continue
            times = sample_times(a)
            hit = corr.conflicts(a.shape, actor_poses(a, times), self.config.actor_margin)  # (T, N)
            if hit.any():
                rest = np.logical_or.accumulate(hit[::-1], axis=0)[::-1]  # rest[t]: blocked at time t or later
                trig = int(np.argmin(np.linalg.norm(centre - np.asarray(a.trigger), axis=1)))
                self.blocks.append((k, times, rest, trig))

    def _actor_stop(self, obs: dict[str, Any], i: int) -> float:
        """[m] path station to stop at for the actors (inf when none blocks the path ahead)."""
        if not self.blocks or "actors" not in obs:
            return math.inf
        state = np.asarray(obs["actors"], dtype=float)
        stop = math.inf
        for k, times, rest, trig in self.blocks:
            tau = float(state[k, 3]) if k < len(state) else -1.0
            t = int(np.searchsorted(times, tau - 0.2)) if tau >= 0 else 0
            if t >= len(times):  # its trajectory has run out
                continue
            cols = np.flatnonzero(rest[t])
            # not started yet: it moves once the car reaches its trigger, so only the path beyond counts
            cols = cols[cols >= (i if tau >= 0 else max(i, trig))]
            if len(cols):
                j = int(cols[0])
                # wait on the straight before a turn, not in it: the tracker holds a curve worse
                # from a standstill (measured: 0.5 m off after stopping mid-turn)
                m = j
                while m > i and abs(self.kappa[m]) > 1e-6:
                    m -= 1
                if tau < 0 and m < trig:  # it only starts once the car reaches its trigger: go there
                    m = min(j, trig)
                stop = min(stop, self.s[m] - self.config.actor_gap)
        return stop

    def _speed_profile(self) -> np.ndarray:
        """[m/s] the fastest speed at each path point that still brakes in time for what follows."""
        cfg, car = self.config, self.car
        k = np.abs(self.kappa)
        v = np.full(len(k), min(cfg.cruise_speed, car.max_speed))
        curved = k > 1e-6
        v[curved] = np.minimum(v[curved], np.sqrt(cfg.lateral_accel / k[curved]))
        # where curvature changes, the steering (rate-limited) must turn within steer_ramp metres
        dk = np.abs(np.diff(self.kappa, prepend=self.kappa[0], append=self.kappa[-1]))
        jump = np.maximum(dk[:-1], dk[1:])
        steer_change = np.arctan(car.wheelbase * jump)  # [rad] about the road-wheel change needed
        rate = car.steer_rate
        with np.errstate(divide="ignore"):
            v = np.minimum(v, np.where(steer_change > 1e-3, rate * cfg.steer_ramp / np.maximum(steer_change, 1e-3), np.inf))
        v[-1] = 0.0  # stop at the goal
        for i in range(len(v) - 2, -1, -1):  # brake in time for every later limit
            ds = self.s[i + 1] - self.s[i]
            v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * cfg.stop_decel * ds))
        return v

    def _project(self, x: float, y: float) -> int:
        lo = max(0, self.index - 8)
        hi = min(len(self.path), self.index + 60)
        d = np.sum((self.path[lo:hi] - (x, y)) ** 2, axis=1)
        self.index = lo + int(np.argmin(d))
        return self.index

    def command(self, obs: dict[str, Any]) -> tuple[float, float]:
        cfg, car = self.config, self.car
        x, y, yaw = (float(v) for v in np.asarray(obs["pose"]).reshape(-1)[:3])
        speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
        rx, ry = x + car.rear_axle * math.cos(yaw), y + car.rear_axle * math.sin(yaw)
        i = self._project(rx, ry)
        h = self.heading[i]
        px, py = self.path[i]
        lateral = -math.sin(h) * (rx - px) + math.cos(h) * (ry - py)  # > 0: left of the path
        along = math.cos(h) * (rx - px) + math.sin(h) * (ry - py)
        s_now = self.s[i] + along
        ahead = s_now + cfg.preview
        j = min(int(np.searchsorted(self.s, ahead)), len(self.s) - 1)
        heading_err = math.remainder(yaw - h, math.tau)
        kappa = float(self.kappa[j]) - cfg.k_lateral * lateral - cfg.k_heading * math.sin(heading_err)
        remaining = self.remaining = self.s[-1] - s_now
        if remaining <= cfg.stop_within:
            return -1.0, self.steer_for(kappa)
        v = float(np.interp(s_now, self.s, self.v_limit))
        v = max(v, min(0.3, math.sqrt(2.0 * cfg.stop_decel * max(remaining, 0.0))))  # creep to the goal
        stop = self._actor_stop(obs, i)
        if stop < math.inf:
            room = stop - s_now
            if room <= 0.05:
                return -1.0, self.steer_for(kappa)
            v = min(v, math.sqrt(2.0 * cfg.actor_decel * room))
        return self.throttle_for(v, speed), self.steer_for(kappa)

    # -- park and AVP tests ------------------------------------------------------------------------
    def act(self, obs: dict[str, Any]):
        """The cruise action (no park plan: :meth:`BaseDriver.act`, unchanged), else the park action."""
        if self.tracker is None:
            return super().act(obs)
        speed = float(np.asarray(obs["speed"]).reshape(-1)[0])
        gear = Gear.D
        if self.phase == "cruise":  # an AVP test's route, driven as in a cruise test
            throttle, steer = self.command(obs)
            if self.remaining <= self.park_config.handover:
                self.phase = "park"
        if self.phase == "park":
            seen = obs.get("gear")
            wheel = obs.get("steer")
            throttle, steer, gear = self.tracker.command(
                np.asarray(obs["pose"]).reshape(-1)[:3], speed,
                None if seen is None else (Gear.R if float(np.asarray(seen).reshape(-1)[0]) < 0 else Gear.D),
                None if wheel is None else float(np.asarray(wheel).reshape(-1)[0]), obs.get("actors"))
        throttle, steer = self.delayed(throttle, steer)
        if self.discrete:
            return self._park_discrete(throttle, steer, gear, obs)
        return np.array([throttle, steer, gear.sign], dtype=np.float32)

    def _park_discrete(self, throttle: float, steer: float, gear: Gear, obs: dict[str, Any]) -> int:
        """The :class:`ParkAction` for a park command: a gear selection while the wanted gear is not in, else
        the cruise action closest to ``(throttle, steer)`` (:meth:`track_discrete`)."""
        seen = obs.get("gear")
        current = self.tracker.gear if seen is None else (Gear.R if float(np.asarray(seen).reshape(-1)[0]) < 0
                                                          else Gear.D)
        if gear is not current:
            return int(ParkAction.SELECT_REVERSE if gear is Gear.R else ParkAction.SELECT_DRIVE)
        return self.track_discrete(throttle, steer, obs)
