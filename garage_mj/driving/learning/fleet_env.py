"""FleetDriveEnv: cruise tests over a set of garages, one garage per episode, for training a driver.

Each ``reset`` draws, from the env's seeded generator, a garage of the set (uniformly, or by
:meth:`FleetDriveEnv.set_weights`, which a curriculum or an adversary moves during training) and a
test seed, and resets that garage's :class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv` to it
(the paper's discrete actions; a test whose target stall cannot be reached is drawn again). The same seed gives the
same sequence of garages and tests. Scenes are kept in a cache of ``cache_size`` envs (least
recently used closed first), so a reset compiles a MuJoCo model only when it meets a garage not
in the cache; a garage without a drivable test in :data:`DRAWS` draws is dropped with a warning.

The observation is the unprivileged one (:func:`~garage_mj.driving.learning.observation.learned_observation`):
camera depth and segmentation, the next route waypoint, speed, the route left and the road-wheel
angle. With ``expert=True`` each ``info`` also carries ``expert_action``: what the privileged
``oracle`` (:class:`~garage_mj.driving.drivers.oracle.OracleDriver`, with the paper's actions) would
do in the state just observed, the label that imitation learning (DAgger) trains on. The expert
reads the privileged state, the learner never does.

Park tests (``env_kwargs`` with ``task`` "park"): one of the 90 park commands of
:mod:`~garage_mj.driving.learning.park_actions` (the label: the one nearest the oracle's continuous command), the
parking sensors on
(:data:`~garage_mj.driving.learning.observation.PARK_SENSORS`) and the parking driver's observation
(:func:`~garage_mj.driving.learning.observation.park_observation`). ``variants`` gives garages their own env
settings (a park geometry, a parked fleet): garage ``k`` is built with ``variants[k % len(variants)]`` over
``env_kwargs``.
"""

from __future__ import annotations

import collections
import dataclasses
import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from garage_mj.driving.learning.observation import (
    PARK_SENSORS,
    learned_observation,
    learned_space,
    park_observation,
    park_space,
)
from garage_mj.driving.learning.park_actions import PARK_COMMANDS, STEER_LEVELS, nearest_park_action
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.park_guide import GUIDE_TRACKING
from garage_mj.driving.sim.sensors import CameraConfig
from garage_mj.driving.sim.vehicle import DiscreteAction
from garage_mj.driving.sources import CruiseSource

DRAWS = 20  # test draws per reset before a garage is taken as one without a drivable test
REPLAN_DISTANCE = 0.5  # [m] park expert (replan): the car this far from every pose of the plan has left it ...
REPLAN_HEADING = 0.35  # [rad] ... or this far off the heading of the nearest one
REPLAN_EVERY = 1.0  # [s] and it plans again at most this often
#: the park expert's tracker: its wheel targets are the learner's steering levels, and at rest it waits only for a
#: wheel change of more than 0.3 rad (the oracle's own 0.08: a learner whose wheel was a little off was told to brake
#: until it matched, and learned to stand still). It ends a stretch as the park guide does (GUIDE_TRACKING: a cusp within
#: 0.1 m at rest; farther short, it creeps on): with the oracle's own rule, a learner at rest 2 cm short of a cusp was
#: told to go on, and 12 cm short of the stall, once its stop had begun, to hold there. Driven by its own labels it
#: parks 15 of 16 validation tests (with the oracle's stop rule: 16 of 16)
PARK_EXPERT = dataclasses.replace(GUIDE_TRACKING, steer_levels=STEER_LEVELS, steer_settle=0.3)


class FleetDriveEnv(gym.Env):
    """Drive one test of a garage drawn per episode from ``garages`` (module docstring).

    Args:
        garages: the garages (:class:`~garage_mj.driving.sources.CruiseSource`, e.g. a
            :class:`~garage_mj.driving.garage_set.GarageSet`).
        weights: draw probabilities per garage (normalised); None: uniform.
        cache_size: how many garages' scenes are kept compiled.
        expert: put the oracle's action for each observed state in ``info["expert_action"]``.
        env_kwargs: more :class:`GarageDriveEnv` keyword arguments (``occupancy``, ``camera``,
            ``scenario``, ``task``, ...); the env's ``action_type`` is discrete in cruise tests and continuous in
            park tests (this env's own actions are discrete in both), ``image_obs`` off.
        variants: env settings per garage (garage ``k``: ``variants[k % len(variants)]`` over ``env_kwargs``).
        park_route: park tests: observe the park route too (:func:`park_observation`'s ``route``).
        park_guide: park tests: observe the park route stretch by stretch too (:func:`park_observation`'s ``guide``);
            the expert then drives the stretch the guide shows (they keep the same rule; this keeps them in step).
        replan: park tests: the expert plans again (the test's reference planner, from the car's pose, around the
            same parked cars) when the car has left its plan (:data:`REPLAN_DISTANCE`, :data:`REPLAN_HEADING`), at
            most every :data:`REPLAN_EVERY` seconds, and labels by the new plan: off the plan, tracking the old one
            would only brake. In park tests the expert tracks with :data:`PARK_EXPERT`: wheel targets on the
            learner's steering levels (with any other target it waited at rest for a wheel angle no command gives,
            and its labels there, brakes, taught the learner to stand still).
        actor_foresight: park tests with actors: what the expert yields to (:class:`ParkTrackConfig`'s
            ``actor_foresight``): "trajectory" (where each actor will go) or "present" (where each actor is now,
            which the learner's cameras can show).
    """

    metadata = {"render_modes": []}

    def __init__(self, garages: Sequence[CruiseSource], weights: Sequence[float] | None = None,
                 cache_size: int = 8, expert: bool = False, env_kwargs: dict[str, Any] | None = None,
                 variants: Sequence[dict[str, Any]] | None = None, park_route: bool = False,
                 replan: bool = False, park_guide: bool = False, actor_foresight: str = "trajectory") -> None:
        self.sources = list(garages)
        if not self.sources:
            raise ValueError("FleetDriveEnv needs at least one garage")
        if cache_size < 1:
            raise ValueError(f"cache_size must be >= 1, got {cache_size}")
        self.env_kwargs = dict(env_kwargs or {})
        for key in ("action_type", "image_obs", "infeasible", "garage"):
            if key in self.env_kwargs:
                raise ValueError(f"FleetDriveEnv sets {key!r} itself; leave it out of env_kwargs")
        self.variants = [dict(v) for v in variants] if variants else [{}]
        self.park_route = bool(park_route)
        self.park_guide = bool(park_guide)
        if self.park_guide and replan:
            raise ValueError("park_guide and replan: the guide shows the test's plan, a replanning expert drives "
                             "another; give one")
        self.replan = bool(replan)
        self.park_expert = dataclasses.replace(PARK_EXPERT, actor_foresight=actor_foresight)
        self._plan_poses: np.ndarray | None = None  # the poses of the plan the expert tracks
        self._replanned_at = -np.inf
        self.task = str(self.env_kwargs.get("task", "cruise"))
        camera = self.env_kwargs.get("camera")
        cam = camera if isinstance(camera, CameraConfig) else CameraConfig(**(camera or {}))
        if self.task == "cruise":
            self.action_type = "discrete"
            self.observation_space = learned_space(cam.height, cam.width)
            self.action_space = spaces.Discrete(len(DiscreteAction))
        else:
            self.action_type = "continuous"
            self.env_kwargs.setdefault("sensors", {name: True for name in PARK_SENSORS})
            self.observation_space = park_space(cam.height, cam.width, self.park_route, self.park_guide)
            self.action_space = spaces.Discrete(len(PARK_COMMANDS))
        self.cache_size = int(cache_size)
        self.expert = bool(expert)
        self._envs: collections.OrderedDict[int, GarageDriveEnv] = collections.OrderedDict()
        self._dead: set[int] = set()
        self._weights = np.ones(len(self.sources)) / len(self.sources)
        if weights is not None:
            self.set_weights(weights)
        self._oracle = None
        self.env: GarageDriveEnv | None = None
        self.index = -1
        self.test_seed = 0

    def set_weights(self, weights: Sequence[float]) -> None:
        """Draw garage ``k`` with probability ``weights[k] / sum(weights)`` from the next reset on."""
        w = np.asarray(weights, dtype=float)
        if w.shape != (len(self.sources),) or not np.all(np.isfinite(w)) or (w < 0).any() or w.sum() <= 0:
            raise ValueError(f"weights must be {len(self.sources)} non-negative numbers with a positive sum")
        self._weights = w / w.sum()

    def _env_for(self, k: int) -> GarageDriveEnv | None:
        """Garage ``k``'s env from the cache (built when missing); None when no stall of it can be reached."""
        if k in self._envs:
            self._envs.move_to_end(k)
            return self._envs[k]
        src = self.sources[k]
        try:
            # "report": stalls are planned when drawn, not all at build (a 200-stall garage: 0.2 s, not 9 s)
            env = GarageDriveEnv(garage=src.garage, action_type=self.action_type, infeasible="report",
                                 **{**self.env_kwargs, **self.variants[k % len(self.variants)]})
        except ValueError as exc:
            warnings.warn(f"{src.name}: left out of the draw ({exc})", stacklevel=3)
            self._dead.add(k)
            return None
        self._envs[k] = env
        while len(self._envs) > self.cache_size:
            self._envs.popitem(last=False)[1].close()
        return env

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Draw a garage and a test; ``options`` may fix ``garage`` (index) and ``test_seed``."""
        super().reset(seed=seed)
        options = options or {}
        while True:
            w = self._weights.copy()
            if self._dead:
                w[list(self._dead)] = 0.0
                if w.sum() <= 0:
                    raise ValueError("no garage of the set has a reachable stall")
                w /= w.sum()
            k = int(options["garage"]) if "garage" in options else int(self.np_random.choice(len(w), p=w))
            env = self._env_for(k)
            if env is not None:
                for _ in range(DRAWS):  # a test whose target stall cannot be reached is drawn again
                    test_seed = int(options.get("test_seed", self.np_random.integers(2**31 - 1)))
                    obs, info = env.reset(seed=test_seed)
                    if info["feasible"]:
                        break
                else:
                    warnings.warn(f"{self.sources[k].name}: left out of the draw (no feasible test in {DRAWS} draws)",
                                  stacklevel=2)
                    self._dead.add(k)
                    env = None
            if env is not None:
                break
            if "garage" in options:
                raise ValueError(f"garage {k} ({self.sources[k].name}) has no test that can be driven")
        self.env, self.index, self.test_seed = env, k, test_seed
        if self.expert:
            from garage_mj.driving.drivers.oracle import OracleDriver

            if self._oracle is None:
                self._oracle = OracleDriver()
                if self.task != "cruise":
                    self._oracle.park_config = self.park_expert
            driver_info = env.driver_info(test_seed)
            self._oracle.reset(driver_info)
            plan = driver_info.get("park_plan")
            self._plan_poses = None if plan is None else np.asarray(plan["poses"], dtype=float)
            self._replanned_at = -np.inf
            self._guide_plan = None  # the plan the park guide showed at the last step (the expert drives it)
        return self._out(obs, info)

    def _follow(self, obs: dict[str, Any], info: dict[str, Any]) -> None:
        """Park tests with ``replan``: a new plan for the expert when the car has left its plan (class docstring)."""
        if self._plan_poses is None or "outcome" in info or self._oracle.tracker is None:
            return
        x, y, yaw = (float(v) for v in np.asarray(obs["pose"]).reshape(-1)[:3])
        d = np.hypot(self._plan_poses[:, 0] - x, self._plan_poses[:, 1] - y)
        i = int(np.argmin(d))
        dyaw = abs((yaw - self._plan_poses[i, 2] + np.pi) % (2 * np.pi) - np.pi)
        now = float(info.get("time", 0.0))
        if (d[i] <= REPLAN_DISTANCE and dyaw <= REPLAN_HEADING) or now - self._replanned_at < REPLAN_EVERY:
            return
        self._replanned_at = now
        plan = self.env.plan_from((x, y, yaw))
        if plan.found:
            self._oracle.follow(plan.poses, plan.directions)
            self._plan_poses = np.asarray(plan.poses, dtype=float)

    def _out(self, obs: dict[str, Any], info: dict[str, Any]):
        info = dict(info, garage=self.sources[self.index].name, garage_index=self.index, test_seed=self.test_seed)
        if self.task == "cruise":
            if self.expert:
                info["expert_action"] = int(self._oracle.act(obs))
            return learned_observation(obs), info
        if self.expert:
            if self.replan:
                self._follow(obs, info)
            guide, tracker = self.env.park_guide, self._oracle.tracker
            if self.park_guide and self.task == "park" and guide is not None and tracker is not None:
                if guide.poses is not self._guide_plan:  # the guide shows a new plan: the expert drives it too
                    if self._guide_plan is not None:
                        self._oracle.follow(guide.poses, guide.directions)
                        tracker = self._oracle.tracker
                    self._guide_plan = guide.poses
                if tracker.k != guide.stretch:
                    tracker.k, tracker.index, tracker.stopping = guide.stretch, 0, False  # the stretch the learner sees
            info["expert_action"] = nearest_park_action(self._oracle.act(obs))
        return park_observation(obs, self.park_route, self.park_guide), info

    def step(self, action):
        if self.env is None:
            raise RuntimeError("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(
            int(action) if self.task == "cruise" else PARK_COMMANDS[int(action)])
        out, info = self._out(obs, info)
        return out, reward, terminated, truncated, info

    def driver_info(self) -> dict[str, Any]:
        """The current test's driver info (:meth:`GarageDriveEnv.driver_info`)."""
        if self.env is None:
            raise RuntimeError("call reset() before driver_info()")
        return self.env.driver_info(self.test_seed)

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
        self.env = None
