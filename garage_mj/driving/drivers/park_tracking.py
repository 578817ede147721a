"""Tracking a park plan forward and in reverse: the privileged oracle's park controller (SPEC 8).

:class:`ParkTracker` is a pure controller: it takes a plan (car-centre poses ``(N, 3)`` and the gear
``directions`` ``(N,)`` of :class:`~garage_mj.scene.park_planning.ParkPlan`) and, per control step,
the car's pose, signed speed and (when known) gear and road-wheel angle, and answers
``(pedal, steer, gear)``: the continuous park command of :meth:`~garage_mj.driving.sim.vehicle.Car.park_control`.
It needs no env, so it is tested against the car's dynamics alone.

- **Segments.** The plan is split at its cusps (:meth:`ParkPlan.segments`). Each segment is
  followed in its own gear on the rear-axle path, in the *travel* frame (the direction the car
  moves): the rear axle's kinematics are then the same in both gears (it moves along the travel
  heading, which turns at the path curvature), so one tracker serves both. Only the steering
  geometry is mirrored: forward ``tan(delta) = L * kappa``, in reverse ``tan(delta) = -L * kappa``.
- **Steering.** The path's curvature a short preview ahead plus feedback on lateral and heading
  error in the travel frame (as the cruise oracle).
- **Speed.** A profile per segment, computed once: capped on curves and where the (rate-limited)
  steering must turn, braking at ``stop_decel`` to zero at the segment's end (a cusp or the stall);
  never below ``creep`` before the stop, so the car does not stall short of it.
- **Cusps.** Within ``stop_within`` (plus the braking distance) of a segment's end the car brakes to
  rest, already turning the road wheels towards the next segment's starting curvature, then requests
  the next segment's gear and finishes turning the wheels at rest before it moves; after the last
  segment it holds the brake. Every cusp is driven, the short shuffles of a sampled plan too (0.1 to
  0.2 m: skipping them, ``min_segment``, measured worse: up to 0.19 m off the path instead of 0.02 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from garage_mj.driving.actors.park_placement import park_corridor
from garage_mj.driving.actors.scenario import actor_poses, sample_times
from garage_mj.driving.sim.vehicle import Gear, clip
from garage_mj.scene.actor_spec import ActorSpec
from garage_mj.scene.car import CarGeometry
from garage_mj.scene.park_planning import centre_to_rear, rear_to_centre

#: What a park tracker yields to (:attr:`ParkTrackConfig.actor_foresight`).
ACTOR_FORESIGHT = ("trajectory", "present")


@dataclass(frozen=True)
class ParkTrackConfig:
    """Speeds and gains of the park tracker (units in the comments)."""

    speed: float = 1.0  # [m/s] top speed along a park plan (either gear)
    creep: float = 0.15  # [m/s] least target speed before a stop
    lateral_accel: float = 0.5  # [m/s^2] v <= sqrt(a_lat / |curvature|) on curves
    steer_ramp: float = 0.5  # [m] a road-wheel change must be steerable within this distance
    smooth: float = 0.2  # [m] curvature is the heading change over +- this (plans hold short blips)
    stop_decel: float = 0.6  # [m/s^2] planned braking to cusps and to the stall pose
    k_lateral: float = 1.0  # [1/m^2] curvature command per metre of lateral error
    k_heading: float = 2.0  # [1/m] curvature command per radian of heading error
    k_speed: float = 2.0  # pedal gain on the speed error (1: the cruise drivers' gain)
    preview: float = 0.25  # [m] curvature preview (the steering lags by its rate limit)
    stop_within: float = 0.0  # [m] this close to a segment's end, plus the braking distance: brake
    brake_time: float = 0.27  # [s] braking distance = speed x this (the car's brakes at parking speeds)
    steer_settle: float = 0.08  # [rad] at rest, turn the wheels to within this before moving off
    at_rest: float = 0.08  # [m/s] below this the car is at rest at a cusp
    min_segment: float = 0.0  # [m] a shorter stretch in one gear between two cusps is skipped (0: none)
    handover: float = 6.0  # [m] AVP (oracle): the tracker takes over this far before the cruise goal
    gear_change_speed: float = 0.1  # [m/s] the car's (CarConfig): below it a gear request is honoured
    # fractions of full lock a driver can command (the learned parking driver's STEER_LEVELS), or () for any: the
    # wheel target is the nearest of them, so the tracker moves off at rest once the wheels reach a target that
    # driver can give, and its commands are that driver's to imitate
    steer_levels: tuple[float, ...] = ()
    # [m] at rest this close to a cusp (or past it), the car has reached it (the stop there begins this far out)
    cusp_within: float = 0.0
    # [m] at rest farther than this short of where a segment's stop begins, with the stop begun (it braked early):
    # creep on instead of holding there (inf: hold). The oracle stops where it means to; a learner it labels for may not
    resume: float = math.inf
    # what it yields to (watch): "trajectory", every pose an actor's trajectory will still take (the privileged
    # oracle, which knows where a pedestrian is going), or "present", only where each actor is now (what a camera
    # or an ultrasonic sensor can show: an expert a camera-driven learner can imitate)
    actor_foresight: str = "trajectory"

    def __post_init__(self) -> None:
        if self.actor_foresight not in ACTOR_FORESIGHT:
            raise ValueError(f"actor_foresight {self.actor_foresight!r}: give one of {', '.join(ACTOR_FORESIGHT)}")


@dataclass(frozen=True)
class Segment:
    """One gear's stretch of a plan, on the rear-axle path in the travel frame."""

    gear: Gear
    points: np.ndarray  # (n, 2) rear-axle midpoint
    yaw: np.ndarray  # (n,) car heading
    travel: np.ndarray  # (n,) travel heading: yaw (D) or yaw + pi (R)
    s: np.ndarray  # (n,) [m] travelled distance from the segment's start
    kappa: np.ndarray  # (n,) [1/m] travel-frame curvature (d travel heading / ds)
    v_limit: np.ndarray  # (n,) [m/s] speed profile, 0 at the end

    @property
    def length(self) -> float:
        return float(self.s[-1])


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def plan_segments(poses, directions, car: CarGeometry, config: ParkTrackConfig) -> list[Segment]:
    """The plan's gear segments (split at cusps, each cusp pose in both neighbours) with their speed profiles."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    d = np.asarray(directions).reshape(-1)
    if len(poses) < 2:
        raise ValueError("a park plan needs at least two poses")
    cut = [0, *(np.flatnonzero(d[1:-1] != d[:-2]) + 1).tolist(), len(d) - 1]
    rear = centre_to_rear(poses, car)
    step = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(rear[:, :2], axis=0), axis=1))])
    ranges = [(a, b, int(d[a])) for a, b in zip(cut[:-1], cut[1:], strict=True) if b > a]
    # a stretch shorter than min_segment (a sampled plan's shuffle) is skipped: its neighbours share a gear
    ranges = [r for i, r in enumerate(ranges)
              if step[r[1]] - step[r[0]] >= config.min_segment or i == len(ranges) - 1]
    groups: list[tuple[int, list[np.ndarray]]] = []
    for a, b, g in ranges:
        if groups and groups[-1][0] == g:
            groups[-1][1].append(np.arange(a, b + 1))
        else:
            groups.append((g, [np.arange(a, b + 1)]))
    out = []
    for g, parts in groups:
        gear = Gear.R if g < 0 else Gear.D
        idx = np.concatenate(parts)
        pts, yaw = rear[idx, :2], rear[idx, 2]
        ds = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(ds)])
        kappa = _curvature(s, np.unwrap(yaw), config.smooth)
        travel = yaw if gear is Gear.D else _wrap(yaw + math.pi)
        out.append(Segment(gear, pts, yaw, travel, s, kappa, _profile(s, kappa, car, config)))
    return out


def _curvature(s: np.ndarray, yaw: np.ndarray, half: float) -> np.ndarray:
    """[1/m] the heading change over the stretch ``s +- half`` (at least to the neighbouring points; clipped to
    the segment), per metre."""
    i = np.arange(len(s))
    lo = np.minimum(np.searchsorted(s, s - half, side="left"), np.maximum(i - 1, 0))  # a neighbour at least
    hi = np.maximum(np.searchsorted(s, s + half, side="right") - 1, np.minimum(i + 1, len(s) - 1))
    ds = s[hi] - s[lo]
    return np.where(ds > 1e-6, (yaw[hi] - yaw[lo]) / np.maximum(ds, 1e-6), 0.0)


def _profile(s: np.ndarray, kappa: np.ndarray, car: CarGeometry, cfg: ParkTrackConfig) -> np.ndarray:
    """[m/s] the fastest speed per point that still stops at the segment's end at ``stop_decel``."""
    k = np.abs(kappa)
    v = np.full(len(k), cfg.speed)
    curved = k > 1e-6
    v[curved] = np.minimum(v[curved], np.sqrt(cfg.lateral_accel / k[curved]))
    wheel = np.arctan(car.wheelbase * kappa)  # [rad] the road-wheel angle the path asks for
    lo = np.searchsorted(s, s - cfg.steer_ramp / 2, side="left")
    hi = np.searchsorted(s, s + cfg.steer_ramp / 2, side="right")
    change = np.array([np.ptp(wheel[a:b]) for a, b in zip(lo, hi, strict=True)])  # [rad] around each point
    v = np.minimum(v, np.where(change > 1e-3, car.steer_rate * cfg.steer_ramp / np.maximum(change, 1e-3), np.inf))
    v[-1] = 0.0
    for i in range(len(v) - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * cfg.stop_decel * (s[i + 1] - s[i])))
    return v


class ParkTracker:
    """Follows a park plan's segments in their gears; :meth:`command` per control step."""

    def __init__(self, poses, directions, car: CarGeometry, config: ParkTrackConfig | None = None,
                 dt: float = 0.1) -> None:
        self.car = car
        self.config = config or ParkTrackConfig()
        self.dt = float(dt)
        self.segments = plan_segments(poses, directions, car, self.config)
        self.k = 0  # current segment
        self.index = 0  # projection index within it
        self.stopping = False  # braking to rest at the current segment's end
        self.gear = Gear.D  # the car's gear as far as the tracker knows (obs["gear"] wins)
        self.steer_angle = 0.0  # [rad] road-wheel angle as far as the tracker knows (obs["steer"] wins)
        self.done = False  # at rest at the plan's end
        self._speed = 0.0  # [m/s] the speed of the current step
        self.blocks: list[list[tuple[int, np.ndarray, np.ndarray]]] = [[] for _ in self.segments]
        self._yield = (0.4, 0.5, 2.0)  # actor margin [m], gap [m], braking [m/s^2] (set by watch)

    def watch(self, actors: list, margin: float, gap: float, decel: float) -> None:
        """Yield to moving ``actors`` (:class:`~garage_mj.scene.actor_spec.ActorSpec` or their dicts), as the cruise
        oracle does: per segment and per moment of each actor's trajectory, the poses of the segment the rest of
        the trajectory comes within ``margin`` of; :meth:`command` then stops ``gap`` before the first such pose
        ahead (braking at ``decel``) while a triggered actor still reaches it. With ``actor_foresight`` "present"
        only the poses the actor's body is near now block (it goes on as soon as the actor is off its path)."""
        self._yield = (float(margin), float(gap), float(decel))
        self.blocks = [[] for _ in self.segments]
        specs = [a if isinstance(a, ActorSpec) else ActorSpec.from_dict(a) for a in actors]
        present = self.config.actor_foresight == "present"
        for seg, blocks in zip(self.segments, self.blocks, strict=True):
            corr = park_corridor(rear_to_centre(np.column_stack([seg.points, seg.yaw]), self.car), self.car)
            for k, a in enumerate(specs):
                if a.static:
                    continue
                times = sample_times(a)
                hit = corr.conflicts(a.shape, actor_poses(a, times), margin)  # (T, n)
                if hit.any():
                    blocks.append((k, times, hit if present else np.logical_or.accumulate(hit[::-1], axis=0)[::-1]))

    def _actor_stop(self, actors) -> float:
        """[m] station of the current segment to stop at for the triggered actors (inf when none blocks ahead)."""
        blocks = self.blocks[self.k]
        if not blocks or actors is None:
            return math.inf
        state = np.asarray(actors, dtype=float).reshape(-1, 4)
        seg, stop = self.segment, math.inf
        for k, times, rest in blocks:
            tau = float(state[k, 3]) if k < len(state) else -1.0
            if tau < 0:  # not triggered: placement left the stopping distance once it is
                continue
            t = int(np.searchsorted(times, tau - 0.2))
            if t >= len(times):  # its trajectory has run out
                continue
            cols = np.flatnonzero(rest[t])
            cols = cols[cols >= self.index]
            if len(cols):
                stop = min(stop, float(seg.s[int(cols[0])]) - self._yield[1])
        return stop

    @property
    def segment(self) -> Segment:
        return self.segments[self.k]

    def _project(self, seg: Segment, rx: float, ry: float) -> int:
        lo, hi = max(0, self.index - 10), min(len(seg.s), self.index + 40)
        d = np.sum((seg.points[lo:hi] - (rx, ry)) ** 2, axis=1)
        self.index = lo + int(np.argmin(d))
        return self.index

    def errors(self, pose) -> tuple[float, float, float, float]:
        """On the current segment: (travelled s [m], lateral error [m] left of travel, heading error [rad],
        remaining [m]) of the car at ``pose`` (car centre)."""
        x, y, yaw = (float(v) for v in pose)
        b = self.car.rear_axle
        rx, ry = x + b * math.cos(yaw), y + b * math.sin(yaw)
        seg = self.segment
        i = self._project(seg, rx, ry)
        th = float(seg.travel[i])
        px, py = seg.points[i]
        lateral = -math.sin(th) * (rx - px) + math.cos(th) * (ry - py)
        along = math.cos(th) * (rx - px) + math.sin(th) * (ry - py)
        s_now = float(seg.s[i]) + along
        heading = math.remainder(yaw - float(seg.yaw[i]), math.tau)
        return s_now, lateral, heading, seg.length - s_now

    def _steer(self, seg: Segment, s_now: float, lateral: float, heading: float) -> float:
        cfg = self.config
        j = min(int(np.searchsorted(seg.s, s_now + cfg.preview)), len(seg.s) - 1)
        kappa = float(seg.kappa[j]) - cfg.k_lateral * lateral - cfg.k_heading * math.sin(heading)
        return self._steer_for(seg.gear.sign * kappa)

    def _steer_for(self, curvature: float) -> float:
        wheel = clip(math.atan(self.car.wheelbase * curvature) / self.car.max_steer, -1.0, 1.0)
        levels = self.config.steer_levels
        return min(levels, key=lambda level: abs(level - wheel)) if levels else wheel

    def _answer(self, pedal: float, steer: float, gear: Gear) -> tuple[float, float, Gear]:
        """The command, with the tracker's copy of the car's gear and steering moved as the car will."""
        if gear is not self.gear and abs(self._speed) < self.config.gear_change_speed:
            self.gear = gear  # the car engages a requested gear at rest, at this control
        step = self.car.steer_rate * self.dt
        self.steer_angle += clip(steer * self.car.max_steer - self.steer_angle, -step, step)
        return pedal, steer, gear

    def stop_state(self, remaining: float, speed: float) -> bool:
        """Whether the car, ``remaining`` metres short of its segment's end at signed ``speed``, is stopping there: it
        begins once the end is within ``stop_within`` (a cusp: ``cusp_within``, if more) plus the braking distance,
        and holds, unless the car is at rest more than ``resume`` short of that. At rest while stopping,
        :meth:`take_next` takes the next segment."""
        cfg = self.config
        v = self.segment.gear.sign * speed  # along the gear's direction
        reach = cfg.stop_within if self.k == len(self.segments) - 1 else max(cfg.stop_within, cfg.cusp_within)
        if not self.stopping and remaining <= reach + max(v, 0.0) * cfg.brake_time:
            self.stopping = True
        if self.stopping and abs(speed) < cfg.at_rest and remaining > reach + cfg.resume:
            self.stopping = False  # at rest short of the end: creep on to it
        return self.stopping

    def take_next(self, remaining: float, speed: float) -> bool:
        """:meth:`stop_state`, and at rest while stopping at a cusp (not the plan's end), move on to the next segment:
        whether it did. The one rule by which :meth:`command` and
        :class:`~garage_mj.driving.sim.park_guide.ParkGuide` go from one segment to the next."""
        if self.stop_state(remaining, speed) and abs(speed) < self.config.at_rest and self.k < len(self.segments) - 1:
            self.next_segment()
            return True
        return False

    def next_segment(self) -> None:
        """Move on to the next segment, from its start."""
        self.k, self.index, self.stopping = self.k + 1, 0, False

    def command(self, pose, speed: float, gear: Gear | None = None,
                steer: float | None = None, actors=None) -> tuple[float, float, Gear]:
        """``(pedal, steer, gear request)`` for the car at ``pose`` (centre x, y, yaw) with signed ``speed``;
        ``gear`` (the car's) and ``steer`` (its road-wheel angle, fraction of full lock) when observed; ``actors``
        the observation's actor states (x, y, yaw, seconds since the trigger or -1) when it yields (:meth:`watch`)."""
        cfg = self.config
        if gear is not None:
            self.gear = gear
        self._speed = speed
        if steer is not None:
            self.steer_angle = float(steer) * self.car.max_steer
        s_now, lateral, heading, remaining = self.errors(pose)
        seg = self.segment
        if self.take_next(remaining, speed):  # at rest at a cusp: the next segment
            s_now, lateral, heading, remaining = self.errors(pose)
            seg = self.segment
        elif self.stopping:
            last = self.k == len(self.segments) - 1
            # braking to a cusp (the car moves a centimetre or two): already turn the wheels for the next segment
            wheel = self._steer(seg, min(s_now, seg.length), lateral, heading) if last else \
                self._steer(self.segments[self.k + 1], 0.0, 0.0, 0.0)
            self.done = last and abs(speed) < cfg.at_rest
            return self._answer(-1.0, wheel, seg.gear)
        wheel = self._steer(seg, s_now, lateral, heading)
        if self.gear is not seg.gear or abs(wheel * self.car.max_steer - self.steer_angle) > cfg.steer_settle and \
                abs(speed) < cfg.at_rest:
            return self._answer(-1.0, wheel, seg.gear)  # change gear and turn the wheels at rest
        target = float(np.interp(s_now, seg.s, seg.v_limit))
        target = max(target, min(cfg.creep, math.sqrt(2.0 * cfg.stop_decel * max(remaining, 0.0))))
        stop = self._actor_stop(actors)
        if stop < math.inf:  # an actor ahead on this segment: stop short of it, go on once it has passed
            room = stop - s_now
            if room <= 0.05:
                return self._answer(-1.0, wheel, seg.gear)
            target = min(target, math.sqrt(2.0 * self._yield[2] * room))
        return self._answer(self._pedal(target, seg.gear.sign * speed), wheel, seg.gear)

    def _pedal(self, target: float, speed: float) -> float:
        err = target - speed
        if err >= 0:
            return clip(self.config.k_speed * err / (self.car.max_accel * self.dt * 2), 0.0, 1.0)
        return clip(self.config.k_speed * err / (self.car.max_decel * self.dt * 2), -1.0, 0.0)
