"""CaseDriveEnv: the park test of one case from elsewhere (docs/spec.md section 9) in MuJoCo.

The park test of a :class:`~garage_mj.scene.case_scene.CaseScene` (a TPCAP case, or a park problem this project
exported), driven like a garage's park test: the same car model, actions, observations, outcome monitor
(:class:`~garage_mj.driving.sim.park_outcomes.ParkMonitor`) and parking metrics as
:class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv` with ``task="park"``, whose step, observation, info and
driver info this env inherits. What differs is where the test comes from: the scene is the case's obstacles
extruded (:func:`~garage_mj.scene.case_scene.build_case_scene`), the car is the case's vehicle class (its MuJoCo
model, geometry and full lock), the start is the case's start at rest in D with no noise (every reset is the
same test), the target is the stall drawn at the case's goal with the case's maneuver, and the reference plan is
the :class:`~garage_mj.scene.case_scene.CasePlanner`'s, planned once per env. A case without a plan is never
driven: its reset ends the test with outcome ``infeasible`` (a proof: the reason names it) or ``unproven``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from garage_mj.driving.actors.config import NO_ACTORS
from garage_mj.driving.sim.drive_env import (
    ACTION_TYPES,
    GarageDriveEnv,
    _add_hit_sensors,
    _as,
    _hit_sensors,
    _hittable,
    _plane_floor,
)
from garage_mj.driving.sim.observations import ObservationSetup, observation_spaces, observed_entries
from garage_mj.driving.sim.outcomes import OutcomeConfig
from garage_mj.driving.sim.park_outcomes import ParkOutcomeConfig
from garage_mj.driving.sim.park_task import ParkTest
from garage_mj.driving.sim.sensors import Camera, CameraConfig
from garage_mj.driving.sim.vehicle import Car, attach_car, compile_mjcf, park_action_space
from garage_mj.scene.car import CarConfig
from garage_mj.scene.case_scene import CaseScene, build_case_scene
from garage_mj.scene.drivable import TestPlan
from garage_mj.scene.mjcf_scene import ParkedCars
from garage_mj.scene.park_planning import ParkConfig, ParkPlan
from garage_mj.scene.parked_fleet import ParkedFleet
from garage_mj.scene.route_line import Route
from garage_mj.scene.semantics import geom_classes


class CaseDriveEnv(GarageDriveEnv):
    """The park test of one case (module docstring).

    Args:
        case: the :class:`~garage_mj.scene.case_scene.CaseScene` to drive.
        action_type, camera, car, outcome, rgb, render_mode, render_size, image_obs, park_config, park_outcome:
            as :class:`~garage_mj.driving.sim.drive_env.GarageDriveEnv`'s (``car``: the limits; its full lock is
            the case vehicle's; ``park_config``: default the case's own, :attr:`CaseScene.park_config
            <garage_mj.scene.case_scene.CaseScene.park_config>`).
        plan: the case's reference plan when planned already (:meth:`CasePlanner.plan_case
            <garage_mj.scene.case_scene.CasePlanner.plan_case>` with ``park_config``); None: planned on the first reset.
    """

    def __init__(
        self,
        case: CaseScene,
        action_type: str = "continuous",
        camera: CameraConfig | dict[str, Any] | None = None,
        car: CarConfig | dict[str, Any] | None = None,
        outcome: OutcomeConfig | dict[str, Any] | None = None,
        rgb: bool = False,
        render_mode: str | None = None,
        render_size: tuple[int, int] = (320, 240),
        image_obs: bool = False,
        park_config: ParkConfig | dict[str, Any] | None = None,
        park_outcome: ParkOutcomeConfig | dict[str, Any] | None = None,
        plan: ParkPlan | None = None,
    ) -> None:
        gym.Env.__init__(self)
        if not isinstance(case, CaseScene):
            raise ValueError("CaseDriveEnv needs case= (a garage_mj.scene.case_scene.CaseScene)")
        if action_type not in ACTION_TYPES:
            raise ValueError(f"action_type must be one of {ACTION_TYPES}, got {action_type!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.case = case
        self.task, self.maneuver, self.stall, self.garage = "park", case.maneuver, 0, None
        self.infeasible, self.occupancy, self.start_noise = "report", 0.0, (0.0, 0.0)
        self.action_type = action_type
        self.image_obs = bool(image_obs)
        cam = _as(CameraConfig, camera)
        if rgb and not cam.rgb:
            cam = CameraConfig(**{**cam.__dict__, "rgb": True})
        self.camera_config = cam
        self.vehicle = case.case.vehicle
        self.parked_fleet = ParkedFleet()  # none drawn: a case's parked cars are its obstacles
        self.car_config = self.vehicle.car_config(_as(CarConfig, car))
        self.car_geometry = self.vehicle.geometry(self.car_config)
        self.outcome_config = _as(OutcomeConfig, outcome)
        self.scenario_config = NO_ACTORS
        self.park_config = case.park_config if park_config is None else _as(ParkConfig, park_config)
        self.park_outcome_config = _as(ParkOutcomeConfig, park_outcome)
        self.render_mode, self.render_size = render_mode, render_size
        self.dt = cam.period  # [s] control period
        self._build()
        setup = ObservationSetup(cam, self.image_obs, 0, "park")
        self.observation_space = spaces.Dict(observation_spaces(setup))
        self._observed = observed_entries(setup)
        self.action_space = park_action_space(action_type)
        self.route, self.monitor, self._park, self._info_test = None, None, None, None
        self._plan: ParkPlan | None = plan

    def _build(self) -> None:
        case = self.case
        root = build_case_scene(case)
        _plane_floor(root)
        x, y, yaw = case.start_centre
        _add_hit_sensors(root, attach_car(root, x, y, yaw, vehicle=self.vehicle))
        self.model = compile_mjcf(root)
        self.data = mujoco.MjData(self.model)
        self.actor_bodies = None
        self.car = Car(self.model, self.car_config)
        self.classes = geom_classes(self.model)
        self._hittable = _hittable(self.car.geom_mask, self.classes)
        self._hit_counts = _hit_sensors(self.model, self.car.geom_mask, self._hittable)
        self._sensor_values = memoryview(self.data.sensordata)
        self.camera = Camera(self.model, self.camera_config)
        self._top: Camera | None = None
        self.n_substeps = max(1, round(self.dt / self.model.opt.timestep))
        self.park_planner = case.planner(self.park_config)
        self.stalls = case.stalls.stalls
        self.scene = case  # what the park task reads of a scene: its world (marking width, aisle)
        self.targets = [0]
        self.parkable: list[int] = []
        self._parked_cars = ParkedCars(self.model)  # none: a case's parked cars are obstacles

    @property
    def plan_of_case(self) -> ParkPlan:
        """The reference plan of the case (planned on first use, once per env)."""
        if self._plan is None:
            self._plan = self.park_planner.plan_case()
        return self._plan

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """The case's park test: always the same (``seed`` seeds only ``np_random``; no ``options``)."""
        if options:
            raise ValueError(f"CaseDriveEnv.reset takes no options (a case is one fixed test), got {sorted(options)}")
        return super().reset(seed=seed)

    def _draw_park_test(self, rng, options: dict[str, Any]) -> ParkTest:
        """The case's test: its start, its stall and maneuver, its reference plan (never drawn)."""
        plan = self.plan_of_case
        start = self.case.start_centre
        none = TestPlan(0, True, "")  # no cruise drive precedes a case's park test
        if plan.found:
            return ParkTest("park", 0, plan.maneuver, [], none, plan, start, "", Route(plan.poses[:, :2]), 0.0, 0.0)
        ahead = [start[:2], np.add(start[:2], (math.cos(start[2]), math.sin(start[2])))]
        return ParkTest("park", 0, plan.maneuver, [], none, plan, start, plan.reason, Route(ahead), 0.0, 0.0)


__all__ = ["CaseDriveEnv"]
