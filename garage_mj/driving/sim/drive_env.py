"""GarageDriveEnv: one cruise test (docs/spec.md section 7) in a MuJoCo garage with the camera car.

The scene (garage + every stall's parked car + the ego car) is built and compiled ONCE per env.
``reset(seed)`` then draws, from the seed alone: the target stall, which other stalls hold a
parked car (each with probability ``occupancy``; the target stall itself is always empty, its
neighbours are not kept free, as in a real garage), and the start pose noise. Parked cars of
empty stalls neither collide nor render (:func:`~garage_mj.scene.mjcf_scene.set_parked`), so a
reset never recompiles. The scene is compiled with its static bodies fused into the world body
(``build_scene(fuse_static=True)``): the same geoms, a physics step in about 0.6 of the time. The
car rolls on an invisible plane at the floor's top (:func:`_plane_floor`: a fifth off each physics
step), and three MuJoCo contact sensors tell whether it touches anything but the floor
(:func:`_add_hit_sensors`), so the contact list is read only when it does.

The route and the goal come from the garage's :class:`~garage_mj.scene.GarageScene` planner
(:mod:`garage_mj.scene.drivable`): right-hand lane centre lines with turns the car can steer, the
goal a pose on the lane beside the target stall, the car's swept footprint checked clear of
every obstacle and stall outline. A target that no driver of this car could reach is
``infeasible``: with ``infeasible="skip"`` (default) such stalls are never drawn; with
``"report"`` (the cruise runner) they are drawn like any other and the test ends at reset with
outcome ``infeasible`` and its reason, never driven. The car starts :data:`START_OFFSET` metres
along the route, so it is wholly inside the garage.

Outcomes are the environment's (:class:`~garage_mj.driving.sim.outcomes.OutcomeMonitor`): each one
terminates the episode, but a kind that :data:`~garage_mj.driving.sim.outcomes.OUTCOMES` marks as truncating
(the time limit) truncates it. The reward is route progress [m] per step, plus :data:`SUCCESS_REWARD` or
:data:`COLLISION_PENALTY` at the end.

The observation is declared once, in :data:`~garage_mj.driving.sim.observations.OBSERVATIONS`
(``docs/observations.md`` is rendered from it): the front camera's ``depth`` and ``segmentation``
(and ``rgb``), the route ``waypoint`` and ``goal`` in the car frame, ``speed``, ``remaining`` and
``steer``: what the car itself knows; privileged, for reference drivers: ``pose`` (world frame)
and, with actors, ``actors``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from garage_mj.core.config import load_config
from garage_mj.driving.actors.config import NO_ACTORS, ScenarioConfig, load_scenario_config
from garage_mj.driving.actors.judging import judge
from garage_mj.driving.actors.park_placement import park_scenario
from garage_mj.driving.actors.placement import draw_scenario
from garage_mj.driving.actors.scenario import Scenario
from garage_mj.driving.sim.observations import (
    ObservationSetup,
    Snapshot,
    observation_spaces,
    observe,
    observed_entries,
)
from garage_mj.driving.sim.outcomes import (
    TRUNCATING,
    Outcome,
    OutcomeConfig,
    OutcomeKind,
    OutcomeMonitor,
    ego_contacts,
)
from garage_mj.driving.sim.park_guide import MAX_REPLANS, ParkGuide
from garage_mj.driving.sim.park_outcomes import ParkMonitor, ParkOutcomeConfig
from garage_mj.driving.sim.park_sensors import (
    NO_SENSORS,
    SensorConfig,
    Ultrasonic,
    sensor_config,
    slot_rng,
)
from garage_mj.driving.sim.park_task import (
    MANEUVER_CHOICES,
    MAX_HANDOVER_START,
    TASKS,
    ParkTest,
    draw_park_test,
    end_info,
    park_info,
    park_monitor,
    test_level,
    test_room,
)
from garage_mj.driving.sim.sensors import Camera, CameraConfig
from garage_mj.driving.sim.solid_bodies import solid_bodies
from garage_mj.driving.sim.vehicle import (
    EGO_NAME,
    Car,
    DiscreteAction,
    Gear,
    attach_car,
    command_from_action,
    compile_mjcf,
    park_action_space,
    park_command_from_action,
)
from garage_mj.grid.garage import Garage
from garage_mj.scene.actor_bodies import ActorBodies, add_actor_bodies
from garage_mj.scene.actor_spec import ActorSpec
from garage_mj.scene.car import FRONT_CAMERA, REAR_CAMERA, CarConfig, car_camera, car_geometry
from garage_mj.scene.clearance import Obstacles, nearest_obstacle
from garage_mj.scene.drivable import START_OFFSET, DriveConfig, TestPlan, drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.mjcf_scene import ParkedCars, build_scene
from garage_mj.scene.park_planning import ParkConfig, ParkPlan, ParkPlanner
from garage_mj.scene.parked_fleet import (
    ParkedBody,
    ParkedFleet,
    RouteLane,
    body_obstacles,
    draw_parked,
    fleet_rng,
)
from garage_mj.scene.route_line import Route
from garage_mj.scene.semantics import COLLIDABLE, Semantic, geom_classes
from garage_mj.scene.vehicles import VehicleClass, vehicle_class
from garage_mj.scene.world import WorldConfig, world_with

SUCCESS_REWARD = 10.0
COLLISION_PENALTY = -10.0
ACTION_TYPES = ("discrete", "continuous")
INFEASIBLE_MODES = ("skip", "report")


def _as(cls: type, value: Any) -> Any:
    """A config of ``cls`` from an instance, a dict (unknown keys rejected) or None (defaults)."""
    return value if isinstance(value, cls) else load_config(cls, value)


def _hittable(ego: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """(ngeom,) bool: the geoms whose contact with the car is a hit (collidable classes, not the car itself).

    Where the hit sensors cannot tell (:func:`_hit_sensors`), one lookup per physics step says
    whether :func:`~garage_mj.driving.sim.outcomes.ego_contacts` has anything to name (it still checks
    that the car is one side of the contact); calling it at every step cost as much as the step
    itself, the wheels being always on the floor.
    """
    return np.isin(classes, [int(c) for c in COLLIDABLE]) & ~ego


_HIT_SENSORS = ("ego_contacts", "ego_floor_contacts", "ego_self_contacts")  # contact sensors: found counts
FLOOR_PLANE = "floor_plane"  # what the car rolls on in the drive env (the slab "floor" is drawn only)


def _plane_floor(root) -> None:
    """Roll the car on an analytic plane at the top of the floor slab instead of on the slab.

    The wheels are ellipsoids: against the slab (a box) MuJoCo's general convex collider runs for
    each wheel at each physics step, against a plane a closed form does, which makes a step about
    a fifth cheaper. The plane is invisible (alpha 0: the scene update skips it) and the slab
    stays what every camera draws, now outside the collision pipeline. The plane is unbounded:
    past the slab's edge (out through a gate) the car no longer falls.
    """
    slab = root.find("geom", "floor")
    if slab is None:
        return
    (x, y, z), (hx, hy, hz) = slab.pos, slab.size
    root.worldbody.add("geom", name=FLOOR_PLANE, dclass=slab.dclass, type="plane", pos=[x, y, z + hz],
                       size=[hx, hy, 1.0], rgba=[0.0, 0.0, 0.0, 0.0])
    slab.contype = slab.conaffinity = 0


def _add_hit_sensors(root, car_frame) -> None:
    """Contact sensors counting the car's contacts: with anything, with the floor, with itself.

    The car hits something exactly when the first count exceeds the other two, provided the floor is
    the only non-collidable geom the car can touch (:func:`_hit_sensors` checks that once the model
    is compiled); MuJoCo counts them during the step, so the env reads three numbers per physics
    step instead of the contact list.
    """
    floor = root.find("geom", FLOOR_PLANE) or root.find("geom", "floor")
    if floor is None:
        return
    any_, floor_, self_ = _HIT_SENSORS
    root.sensor.add("contact", name=any_, subtree1=car_frame, data="found")
    root.sensor.add("contact", name=floor_, subtree1=car_frame, geom2=floor, data="found")
    root.sensor.add("contact", name=self_, subtree1=car_frame, subtree2=car_frame, data="found")


def _hit_sensors(model: mujoco.MjModel, ego: np.ndarray, hittable: np.ndarray) -> tuple[int, int, int] | None:
    """The sensordata addresses of :func:`_add_hit_sensors`' counts, or None when they cannot tell a hit
    (no such sensors, or the car can touch a non-collidable geom other than the floor)."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, n) for n in _HIT_SENSORS]
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, FLOOR_PLANE)
    if floor < 0:
        floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    if min(ids) < 0 or floor < 0:
        return None
    contype, conaffinity = model.geom_contype, model.geom_conaffinity
    touch = ((contype & np.bitwise_or.reduce(conaffinity[ego])) | (conaffinity & np.bitwise_or.reduce(contype[ego]))) != 0
    ego_ids = np.flatnonzero(ego)  # explicit <pair>s with the car touch it whatever their bits
    touch[model.pair_geom1[np.isin(model.pair_geom2, ego_ids)]] = True
    touch[model.pair_geom2[np.isin(model.pair_geom1, ego_ids)]] = True
    other = touch & ~ego & ~hittable
    other[floor] = False
    if other.any():
        return None
    a, f, s = (int(model.sensor_adr[i]) for i in ids)
    return a, f, s


class GarageDriveEnv(gym.Env):
    """Drive from the entrance to a target stall (registered as ``garage_mj/GarageDrive-v0``).

    Args:
        garage: the :class:`Garage` to drive in (for an asset pack: ``load_pack(folder).garage``).
        action_type: ``"discrete"`` (the paper's :class:`DiscreteAction`) or ``"continuous"``
            (``[throttle/brake, steer]`` in [-1, 1]).
        occupancy: probability that a non-target stall holds a parked car.
        start_noise: (position [m], yaw [rad]) half-widths of the uniform start pose noise;
            the position noise is lateral to the route.
        camera, car, outcome: :class:`CameraConfig`, :class:`CarConfig`, :class:`OutcomeConfig`
            or dicts of their fields. The camera rate sets the control period.
        rgb: also observe the colour image.
        infeasible: ``"skip"`` draws targets among feasible stalls only; ``"report"`` draws among
            all stalls and ends an infeasible test at reset (outcome ``infeasible``).
        drive: :class:`~garage_mj.scene.drivable.DriveConfig` (margins of the feasibility checks).
        image_obs: depth and segmentation as SB3 image spaces, ``(H, W, 1)`` uint8 in [0, 255]
            (depth scaled from [0, far] metres; segmentation the class ids), so that
            ``MultiInputPolicy`` hands them to its CNN. The built-in drivers expect the default
            (depth in metres as ``(H, W)`` float32).
        render_mode: ``"rgb_array"`` renders the ``ego/top`` camera (``render_size`` pixels).
        scenario: :class:`~garage_mj.driving.actors.config.ScenarioConfig` (or a dict of its fields, or a TOML
            file): pedestrians, moving cars and clutter drawn per test from the test seed (after
            the draws above, so the same seed gives the same target, parked cars and start with
            or without actors). A test whose events no driver could avoid is ``infeasible``.
            With actors the observation gains ``actors`` (privileged, like ``pose``): per actor
            (x, y, yaw, seconds since its trigger or -1), in the order of ``driver_info()["actors"]``.
        task: ``"cruise"`` (the default: everything above, exactly), ``"park"`` (start at rest on the cruise
            goal beside the target stall, park in it) or ``"avp"`` (cruise from the entrance, then park;
            one test); docs/spec.md section 8 and :mod:`~garage_mj.driving.sim.park_task`. Park and AVP
            tests act through :func:`~garage_mj.driving.sim.vehicle.park_action_space` (a cruise driver's
            action is taken too, and keeps the gear: it cannot reverse), end by
            :class:`~garage_mj.driving.sim.park_outcomes.ParkMonitor` (``park_outcome``: its
            :class:`~garage_mj.driving.sim.park_outcomes.ParkOutcomeConfig`), observe also ``stall`` and
            ``gear``, and give the reference plan in the reset info as ``park_plan`` (``poses`` (N, 3) car
            centre, ``directions`` (N,) +1/-1, ``stall_pose``), as :meth:`driver_info` does. With ``scenario`` their
            actors are the park behaviours, placed around the target stall and the park plan from a generator of
            their own (:mod:`~garage_mj.driving.actors.park_placement`).
        maneuver: ``"reverse"`` (reverse-in, the default), ``"forward"`` (nose-in) or ``"any"`` (drawn per test).
        stall: a stall id every reset tests (default: drawn per test).
        handover_start: [m] park tests only: the car starts up to this far before or after the park plan's start
            (drawn uniformly per test; before it: on the cruise route, after it: along its heading), where an AVP
            test's cruise may leave it for the parking (a car braked to rest where the park guide begins, within
            :data:`~garage_mj.driving.sim.park_guide.START_RADIUS` of the plan's start, stands up to that far short
            of it). The plan is the one from the noised cruise goal, as without it. 0 (the default): the car starts
            on the plan's start.
        guide_replans: park and AVP tests: how many new plans the park guide may show a test, each from where the car
            stands at rest outside the stall (:mod:`~garage_mj.driving.sim.park_guide`; 0 to 10, default
            :data:`~garage_mj.driving.sim.park_guide.MAX_REPLANS`); 0: the guide shows the test's plan only.
        scene_seed: park and AVP tests only: every reset draws its test (target stall, parked cars and their fleet,
            maneuver, start, slot noise) from this seed, as ``reset(seed=scene_seed)`` would, and only its actors
            from its own seed: one test's scene with its actors placed anew per seed (how a park hunt searches actor
            placements). None (the default): everything from the reset's seed.
        park_config: :class:`~garage_mj.scene.park_planning.ParkConfig` of the reference park planner.
        world: the park geometry the garage is built in (docs/spec.md section 9): a
            :class:`~garage_mj.scene.world.WorldConfig`, or a dict of its geometry keys (``stall_width``,
            ``stall_depth``, ``aisle_width``, ``stall_angle``, ``slot_length``; a pack's manifest ``geometry``);
            None (the default): today's 2.5 m x 4.5 m perpendicular stalls on 9 m aisles.
        vehicle: the car under test, a class of the fleet (:data:`~garage_mj.scene.vehicles.FLEET`: ``compact``,
            ``sedan``, ``suv``, ``van``) or a :class:`~garage_mj.scene.vehicles.VehicleClass`; None (the default):
            ``models/car``, the sedan, with ``car``'s full lock. A class brings its MuJoCo model
            (:func:`~garage_mj.scene.car.car_model`), its outline and axles, and its full lock, which every planner,
            monitor and observation of the env then uses (``car`` may not set another ``max_steer``).
        parked_fleet: ``"uniform"`` (the default: every parked car is ``models/parked_car``, centred in its stall) or
            ``"mixed"`` (each parked car's class drawn per test from the fleet); :mod:`~garage_mj.scene.parked_fleet`.
        parked_jitter: [m] each parked car's lateral offset bound (0 to 0.5; its heading's is proportional), drawn per
            test. A mixed fleet or a jitter draws from a generator of its own, seeded by the test's seed, and moves
            the parked cars' geoms in the compiled model (no recompiling): cameras, collisions and the park planner
            see them where they stand (``parked_bodies``). Park and AVP tests plan around the parked cars' bodies with
            any fleet; cruise tests' drivability checks keep the stall outlines.
        sensors: the parking sensors to observe besides the front camera, in any task
            (:mod:`~garage_mj.driving.sim.park_sensors`): a :class:`~garage_mj.driving.sim.park_sensors.SensorConfig`,
            a dict of its fields, or sensor names (``"rear_camera,ultrasonic,slot"``, ``"all"``); None (the default):
            none, and the observation, the model and every result stay what they are without them. ``rear_camera``
            adds ``rear_depth`` and ``rear_segmentation`` (the front camera's config, looking back), ``ultrasonic``
            the 12 bumper ranges, ``slot`` the target stall's pose and size in the car frame (its noise drawn from a
            generator of its own, seeded by the test's seed).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    # the parking sensors' defaults: none (a subclass that builds its own scene, CaseDriveEnv, has these)
    sensor_config: SensorConfig = NO_SENSORS
    rear_camera: Camera | None = None
    ultrasonic: Ultrasonic | None = None
    slot_rng: np.random.Generator | None = None
    handover_start: float = 0.0  # [m] park tests start on their plan's start (a subclass that builds its own scene)
    guide_replans: int = MAX_REPLANS  # new plans the park guide may show a test (a subclass: the same)
    scene_seed: int | None = None  # a park test's draws, but its actors', from the reset's seed (a subclass: the same)

    def __init__(
        self,
        garage: Garage | None = None,
        action_type: str = "discrete",
        occupancy: float = 0.5,
        start_noise: tuple[float, float] = (0.3, 0.05),
        camera: CameraConfig | dict[str, Any] | None = None,
        car: CarConfig | dict[str, Any] | None = None,
        outcome: OutcomeConfig | dict[str, Any] | None = None,
        rgb: bool = False,
        render_mode: str | None = None,
        render_size: tuple[int, int] = (320, 240),
        infeasible: str = "skip",
        drive: DriveConfig | dict[str, Any] | None = None,
        image_obs: bool = False,
        scenario: ScenarioConfig | dict[str, Any] | str | None = None,
        task: str = "cruise",
        maneuver: str = "reverse",
        stall: int | None = None,
        handover_start: float = 0.0,
        guide_replans: int = MAX_REPLANS,
        scene_seed: int | None = None,
        park_config: ParkConfig | dict[str, Any] | None = None,
        park_outcome: ParkOutcomeConfig | dict[str, Any] | None = None,
        vehicle: str | VehicleClass | None = None,
        world: WorldConfig | dict[str, Any] | None = None,
        parked_fleet: str = "uniform",
        parked_jitter: float = 0.0,
        sensors: SensorConfig | dict[str, Any] | str | None = None,
    ) -> None:
        if not isinstance(garage, Garage):
            raise ValueError("GarageDriveEnv needs garage= (a garage_mj.Garage; for a pack: load_pack(folder).garage)")
        if infeasible not in INFEASIBLE_MODES:
            raise ValueError(f"infeasible must be one of {INFEASIBLE_MODES}, got {infeasible!r}")
        if action_type not in ACTION_TYPES:
            raise ValueError(f"action_type must be one of {ACTION_TYPES}, got {action_type!r}")
        if not 0.0 <= occupancy <= 1.0:
            raise ValueError(f"occupancy must be in [0, 1], got {occupancy}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {task!r}")
        if maneuver not in MANEUVER_CHOICES:
            raise ValueError(f"maneuver must be one of {MANEUVER_CHOICES}, got {maneuver!r}")
        self.task = task
        self.maneuver = maneuver
        self.stall = None if stall is None else int(stall)
        if isinstance(handover_start, bool) or not 0.0 <= float(handover_start) <= MAX_HANDOVER_START:
            raise ValueError(f"handover_start must be in [0, {MAX_HANDOVER_START:g}] m, got {handover_start!r}")
        if handover_start and task != "park":
            raise ValueError("handover_start is for park tests (task='park'): an AVP test starts at the entrance")
        self.handover_start = float(handover_start)
        if isinstance(guide_replans, bool) or not isinstance(guide_replans, int) or not 0 <= guide_replans <= 10:
            raise ValueError(f"guide_replans must be an integer from 0 to 10 (new plans the park guide may show a "
                             f"test), got {guide_replans!r}")
        self.guide_replans = guide_replans
        if scene_seed is not None and (isinstance(scene_seed, bool) or not isinstance(scene_seed, int)
                                       or scene_seed < 0):
            raise ValueError(f"scene_seed must be a test seed, an integer >= 0, got {scene_seed!r}")
        if scene_seed is not None and task == "cruise":
            raise ValueError("scene_seed is for park and AVP tests (task='park' or 'avp')")
        self.scene_seed = scene_seed
        self.garage = garage
        self.world = world if isinstance(world, WorldConfig) else world_with(world)  # its park geometry
        self.infeasible = infeasible
        self.image_obs = bool(image_obs)
        self.action_type = action_type
        self.occupancy = float(occupancy)
        self.start_noise = (float(start_noise[0]), float(start_noise[1]))
        cam = _as(CameraConfig, camera)
        if rgb and not cam.rgb:
            cam = CameraConfig(**{**cam.__dict__, "rgb": True})
        self.camera_config = cam
        self.sensor_config = sensor_config(sensors)
        self.vehicle = None if vehicle is None else vehicle_class(vehicle)
        self.parked_fleet = ParkedFleet(parked_fleet, parked_jitter)
        self.car_config = _as(CarConfig, car)
        if self.vehicle is None:  # models/car as it is: the sedan, steered to the car config's full lock
            self.car_geometry = car_geometry(self.car_config)
        else:
            self.car_config = self.vehicle.car_config(self.car_config)
            self.car_geometry = self.vehicle.geometry(self.car_config)
        self.drive_config = _as(DriveConfig, drive)
        self.outcome_config = _as(OutcomeConfig, outcome)
        self.scenario_config = scenario if isinstance(scenario, ScenarioConfig) else load_scenario_config(scenario)
        self.park_config = _as(ParkConfig, park_config)
        self.park_outcome_config = _as(ParkOutcomeConfig, park_outcome)
        self.render_mode = render_mode
        self.render_size = render_size
        self.dt = cam.period  # [s] control period

        self._build()
        if self.stall is not None and not 0 <= self.stall < len(self.stalls):
            raise ValueError(f"stall {self.stall} does not exist; garage {garage.name!r} has stalls "
                             f"0..{len(self.stalls) - 1}")
        if infeasible == "skip":
            self.targets = [s.id for s in self.stalls if self.planner.plan(s.id).feasible]
        else:
            self.targets = [s.id for s in self.stalls]
        if not self.targets:
            raise ValueError(f"garage {garage.name!r}: no stall can be reached by a feasible route from the entrance")

        setup = ObservationSetup(cam, self.image_obs, self.scenario_config.count, task, self.sensor_config)
        self.observation_space = spaces.Dict(observation_spaces(setup))
        self._observed = observed_entries(setup)  # the observation table's entries this env has
        if task != "cruise":
            self.action_space: spaces.Space = park_action_space(action_type)
        elif action_type == "discrete":
            self.action_space = spaces.Discrete(len(DiscreteAction))
        else:
            self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.route: Route | None = None
        self.monitor: OutcomeMonitor | ParkMonitor | None = None
        self._park: ParkTest | None = None  # the park or AVP test of this reset (None: a cruise test)
        self.park_guide: ParkGuide | None = None  # its route stretch by stretch (None: a cruise test, or no plan)
        self._info_test: dict[str, Any] | None = None  # _info's entries fixed per test

    # -- scene -------------------------------------------------------------------------------------
    def _build(self) -> None:
        self.scene = GarageScene(self.garage, self.world)
        root = build_scene(self.scene, fuse_static=True)  # parked cars and pillars: geoms of the world body
        _plane_floor(root)
        self._entrance = self.scene.entrance_pose
        _add_hit_sensors(root, attach_car(root, *self._entrance, vehicle=self.vehicle))
        if self.scenario_config.count:
            add_actor_bodies(root, self.scenario_config)
        self.model = compile_mjcf(root)
        self.data = mujoco.MjData(self.model)
        self.actor_bodies = ActorBodies(self.model, self.scenario_config) if self.scenario_config.count else None
        self.car = Car(self.model, self.car_config)
        self.classes = geom_classes(self.model)
        self._hittable = _hittable(self.car.geom_mask, self.classes)
        self._hit_counts = _hit_sensors(self.model, self.car.geom_mask, self._hittable)
        self._sensor_values = memoryview(self.data.sensordata)  # the same buffer, read as floats
        self.camera = Camera(self.model, self.camera_config)
        self.rear_camera: Camera | None = None
        if self.sensor_config.rear_camera:  # the front camera's twin looking back, through the same GL context
            rear = CameraConfig(**{**self.camera_config.__dict__, "camera": f"{EGO_NAME}/{REAR_CAMERA}"})
            self.rear_camera = Camera(self.model, rear, share=self.camera)
        self.ultrasonic = Ultrasonic(self.model, f"{EGO_NAME}/") if self.sensor_config.ultrasonic else None
        self._top: Camera | None = None
        self.n_substeps = max(1, round(self.dt / self.model.opt.timestep))
        self.planner = drive_planner(self.scene, self.car_geometry, self.drive_config)
        self.park_planner = ParkPlanner(self.scene, self.car_geometry, self.park_config)
        self.stalls = self.scene.stalls.stalls
        self._parked_cars = ParkedCars(self.model)  # the parked cars' geoms, looked up once per scene
        self.parkable = sorted(self._parked_cars.geoms)

    def plan(self, stall_id: int) -> TestPlan:
        """The planned drive to a stall (route, goal, clearances), or why it is infeasible."""
        return self.planner.plan(stall_id)

    # -- gym API -----------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Draw target stall, parked cars and start pose from ``seed``.

        ``options`` may fix ``target`` (stall id), ``occupied`` (stall ids), ``start`` ((x, y, yaw))
        or ``actors`` (a list of :class:`~garage_mj.scene.actor_spec.ActorSpec` or their dicts, replacing the
        drawn ones; a replayed ``.xosc`` does this); their avoidability is judged the same way.
        """
        super().reset(seed=seed)
        rng = self.np_random
        options = options or {}
        actor_seed = seed
        if self.scene_seed is not None:  # a park test's draws from the scene seed, only its actors' from the reset's
            seed = self.scene_seed
            rng = np.random.default_rng(seed)  # the generator reset(seed=scene_seed) makes
        # the parked fleet's draws: a generator of their own (none for the scene's own cars)
        self._fleet_rng = None if self.parked_fleet.default else fleet_rng(seed) if seed is not None else rng
        self.parked_bodies: dict[int, ParkedBody] = {}
        # the slot detector's noise: a generator of its own, drawn from only when it adds noise
        self.slot_rng = None if not self.sensor_config.noisy_slot else slot_rng(seed) if seed is not None else rng
        if self.task != "cruise":
            return self._reset_park(rng, options, actor_seed)
        if "target" in options:
            target = int(options["target"])
        elif self.stall is not None:  # one stall for every test (no draw: the other draws as with none)
            target = self.stall
        else:
            target = int(rng.choice(self.targets))
        if target not in self.targets:
            raise ValueError(f"stall {target} cannot be reached; reachable stalls: {self.targets}")
        occupied, lateral, dyaw = self.draw_parked_and_noise(rng, target, options)

        self.target = target
        self.test_plan = plan = self.planner.plan(target)
        self.scenario = self._scenario(plan, rng, options.get("actors"))
        occupied = [s for s in occupied if s not in self.scenario.free_stalls]
        self.occupied = occupied
        if plan.feasible:
            self.route = Route(plan.centre)
            self.monitor = OutcomeMonitor(self.route, self.outcome_config, goal=plan.goal,
                                          extra_time=self.scenario.duration)
        else:  # never driven: the car waits at the start of the entrance lane
            x0, y0, h0 = self._entrance
            ahead = [(x0 + k * math.cos(h0), y0 + k * math.sin(h0)) for k in (0.0, START_OFFSET + 5.0)]
            self.route = Route(ahead)
            self.monitor = OutcomeMonitor(self.route, self.outcome_config)
        heading = self.route.heading_at(START_OFFSET)
        p = self.route.point_at(START_OFFSET)
        x = float(p[0]) - math.sin(heading) * lateral
        y = float(p[1]) + math.cos(heading) * lateral
        yaw = heading + dyaw
        if "start" in options:  # an explicit (x, y, yaw) start pose, for forced scenarios
            x, y, yaw = (float(v) for v in options["start"])
        self.start_pose = (x, y, yaw)  # exactly as set (the measured pose after mj_forward differs in the last bits)
        mujoco.mj_resetData(self.model, self.data)
        self._parked_cars.apply(self.model, None, occupied)
        if not self.parked_fleet.default:
            self.parked_bodies = self.draw_parked_bodies(target, occupied, plan)
            self._parked_cars.place(self.model, None, self.parked_bodies)
        self._place_actors()
        self.car.reset(self.data, x, y, yaw)  # runs mj_forward
        self.monitor.progress = START_OFFSET  # [m] the car starts this far along the route
        self.path_length = 0.0  # [m] driven
        self._last_xy = (x, y)
        self.outcome: Outcome | None = None
        self._info_test: dict[str, Any] | None = None
        if not plan.feasible:
            self.outcome = Outcome(OutcomeKind.INFEASIBLE, 0.0, plan.reason)
        elif not self.scenario.feasible:
            self.outcome = Outcome(OutcomeKind.INFEASIBLE, 0.0, self.scenario.reason)
        return self._observe(), self._info()

    def draw_parked_and_noise(self, rng: np.random.Generator, target: int,
                              options: dict[str, Any]) -> tuple[list[int], float, float]:
        """The parked cars and the start noise of a test on ``target``, as every task draws them.

        Returns (occupied stall ids, never ``target``; lateral offset [m]; yaw offset [rad]), drawn from
        ``rng`` in this order: one uniform per parkable stall, then lateral, then yaw. ``options["occupied"]``
        replaces the parked cars drawn (the draw still happens, so the later draws stay the same).
        """
        occupied_draw = rng.random(len(self.parkable)) < self.occupancy
        occupied = [sid for sid, o in zip(self.parkable, occupied_draw, strict=True) if o and sid != target]
        if "occupied" in options:
            occupied = [int(s) for s in options["occupied"] if int(s) != target]
        lateral = rng.uniform(-1.0, 1.0) * self.start_noise[0]
        dyaw = rng.uniform(-1.0, 1.0) * self.start_noise[1]
        return occupied, lateral, dyaw

    def draw_parked_bodies(self, target: int, occupied: list[int], route: TestPlan | None = None
                           ) -> dict[int, ParkedBody]:
        """The parked cars of this reset's test on ``target`` as they stand (:func:`~garage_mj.scene.parked_fleet.
        draw_parked` from the reset's fleet generator; the scene's own cars, centred, with the default fleet). With the
        cruise ``route`` the test drives (a cruise or an AVP test), they keep the drive planner's clearance margin from
        it as from the stall outlines (:class:`~garage_mj.scene.parked_fleet.RouteLane`)."""
        lane = None if route is None or not route.feasible else RouteLane(
            route.rear, route.heading, self.car_geometry, self.planner.config.clearance_margin)
        return draw_parked(self.stalls, occupied, target, self.parked_fleet, self._fleet_rng,
                           self.scene.world.marking_width, lane)

    def _reset_park(self, rng, options: dict[str, Any], seed: int | None = None):
        """:meth:`reset` of a park or AVP test (:mod:`~garage_mj.driving.sim.park_task`): the test drawn from ``rng``,
        its actors from ``seed`` (the reset's; None: from ``np_random``)."""
        given = options.get("actors")
        if given is not None and "occupied" in options:  # a replay: the stalls its actors take held parked cars
            took = {int(a.stall if isinstance(a, ActorSpec) else a.get("stall", -1)) for a in given} - {-1}
            options = {**options, "occupied": sorted({int(s) for s in options["occupied"]} | took)}
        test = self._draw_park_test(rng, options)
        # the actors: their own generator, after the test's draws (park_placement); the stalls they take are freed
        self.scenario, test = park_scenario(self, test, seed, self.np_random, given)
        self._park = test
        plan = test.plan
        self.park_guide = ParkGuide(plan.poses, plan.directions, self.car_geometry, self.guide_replans) \
            if plan is not None and plan.found and len(plan.poses) >= 2 else None
        self.target, self.occupied, self.test_plan = test.stall, test.occupied, test.cruise
        self.route = test.reference
        self.monitor = park_monitor(self, test)
        self.monitor.time_limit += self.scenario.duration  # waiting for the actors is not the driver's time
        self.start_pose = x, y, yaw = test.start
        mujoco.mj_resetData(self.model, self.data)
        self._parked_cars.apply(self.model, None, test.occupied)
        self.parked_bodies = test.bodies
        if not self.parked_fleet.default:
            self._parked_cars.place(self.model, None, test.bodies)
        self._place_actors()
        self.car.reset(self.data, x, y, yaw)  # runs mj_forward; in D, at rest
        # the solid bodies as they stand (clutter included; a walking or driving actor is nowhere for long)
        moving = np.isin(self.classes, [int(Semantic.PEDESTRIAN), int(Semantic.MOVING_CAR)])
        self._bodies = solid_bodies(self.model, self.data, self.car.geom_mask | moving, self.classes)
        self._park_level = test_level(self, test, self._bodies)
        self.path_length = 0.0  # [m] driven
        self._last_xy = (x, y)
        self._rest_since: float | None = None  # when the car came to rest (the guide's re-plan waits on it)
        self.outcome = None if test.feasible else Outcome(OutcomeKind(test.verdict), 0.0, test.reason)
        if self.outcome is None and not self.scenario.feasible:
            self.outcome = Outcome(OutcomeKind.INFEASIBLE, 0.0, self.scenario.reason)
        self._info_test = None
        self._end_info: dict[str, Any] | None = None
        return self._observe(), {**self._info(), "park_plan": test.plan_info()}

    def _draw_park_test(self, rng, options: dict[str, Any]) -> ParkTest:
        """The park or AVP test of this reset (:func:`~garage_mj.driving.sim.park_task.draw_park_test`); an env whose
        tests come from elsewhere (:class:`~garage_mj.driving.sim.case_env.CaseDriveEnv`) gives its own here."""
        return draw_park_test(self, rng, options)

    def _park_command(self, action) -> tuple[float, float, Gear | None]:
        """A park action as (pedal, steer, gear request); a cruise driver's ``[throttle, steer]`` keeps the gear."""
        if np.shape(action) == (2,):
            return (*command_from_action(action), None)
        return park_command_from_action(action)

    def _scenario(self, plan: TestPlan, rng, given) -> Scenario:
        """The test's actors: drawn from ``rng`` per the scenario config, or ``given`` (a replay)."""
        cfg = self.scenario_config
        if given is None:
            return draw_scenario(cfg, plan, self.planner, rng)
        actors = [a if isinstance(a, ActorSpec) else ActorSpec.from_dict(a) for a in given]
        if actors and self.actor_bodies is None:
            raise ValueError("this env has no actor bodies: build it with scenario= room for the replayed actors")
        ok, why = judge(actors, plan, self.planner, cfg if cfg.count else NO_ACTORS)
        return Scenario(actors, ok, why, {}, {a.stall for a in actors if a.stall >= 0})

    def _place_actors(self) -> None:
        """Put every actor at its first waypoint (untriggered), hide the unused slots."""
        self._actor_tau: list[float | None] = [None if not a.static else 0.0 for a in self.scenario.actors]
        self._actor_t0: list[float | None] = [None] * len(self.scenario.actors)
        if self.actor_bodies is None:
            return
        self._actor_ids = self.actor_bodies.place(self.data, self.scenario.actors)
        for a in self.scenario.actors:
            ActorBodies.set_pose(self.data, self._actor_ids[a.name], a.pose_at(None))

    def _move_actors(self, x: float, y: float) -> bool:
        """Fire the triggers the car reached, move the triggered actors to this time; True while one moves."""
        moving = False
        t = float(self.data.time)
        for k, a in enumerate(self.scenario.actors):
            if a.static:
                continue
            if self._actor_t0[k] is None and math.hypot(x - a.trigger[0], y - a.trigger[1]) <= a.trigger_radius:
                self._actor_t0[k] = t
            if self._actor_t0[k] is None:
                continue
            tau = t - self._actor_t0[k]
            self._actor_tau[k] = tau
            moving |= tau < a.duration
            ActorBodies.set_pose(self.data, self._actor_ids[a.name], a.pose_at(tau))
        return moving

    def step(self, action):
        """One control step; an action outside the action space (NaN or infinite included) is a ValueError
        naming it, raised before anything moves (a driver's bad action is its error, never an outcome)."""
        if self.monitor is None:
            raise RuntimeError("call reset() before step()")
        if self.outcome is not None:
            raise RuntimeError("the episode is over; call reset()")
        park = self._park is not None
        # a bad or non-finite action is refused before anything moves
        command = command_from_action(action) if not park else self._park_command(action)
        before = self.monitor.progress
        moving = False
        if self.scenario.actors:
            x0, y0, _ = self.car.pose(self.data)
            moving = self._move_actors(x0, y0)
        if park:
            self.car.park_control(self.data, *command, self.dt)
        else:
            self.car.control(self.data, *command, self.dt)
        contacts = []
        model, data, hittable = self.model, self.data, self._hittable
        if self._hit_counts is not None:  # the wheels touch the floor at every step: count the rest
            touched, floor, own = self._hit_counts
            counts = self._sensor_values  # Python floats per read, cheaper than numpy scalars
            for _ in range(self.n_substeps):
                mujoco.mj_step(model, data)
                if counts[touched] > counts[floor] + counts[own]:
                    contacts += ego_contacts(model, data, self.car.geom_mask, self.classes)
        else:
            for _ in range(self.n_substeps):
                mujoco.mj_step(model, data)
                # name contacts only when one may be a hit
                if data.ncon and np.count_nonzero(hittable[data.contact.geom]):
                    contacts += ego_contacts(model, data, self.car.geom_mask, self.classes)
        x, y, yaw = pose = self.car.pose(self.data)
        speed = self.car.speed(self.data)
        if self.park_guide is not None:
            self._guide(pose, speed)
        self.path_length += math.hypot(x - self._last_xy[0], y - self._last_xy[1])
        self._last_xy = (x, y)
        self.outcome = self.monitor.update(self.data.time, (x, y), speed, contacts, yaw=yaw,
                                           hold=moving)
        reward = self.monitor.progress - before
        terminated = truncated = False
        if self.outcome is not None:
            truncated = self.outcome.kind in TRUNCATING
            terminated = not truncated
            if self.outcome.kind is OutcomeKind.SUCCESS:
                reward += SUCCESS_REWARD
            elif self.outcome.kind is OutcomeKind.COLLISION:
                reward += COLLISION_PENALTY
        return self._observe(pose, speed), float(reward), terminated, truncated, self._info(pose)

    def plan_from(self, pose) -> ParkPlan:
        """The reference planner's plan from ``pose`` (car centre x, y, yaw) into this park test's stall with its
        maneuver, around its parked cars as they stand: the test's plan made again from where the car is. A car that
        stopped near the stall pose is shown a correction (:meth:`ParkPlanner.correct`: an arc onto the stall's heading
        and back) where one is clear, as a park assist straightens a car in its slot."""
        test, planner = self._park, self.park_planner
        obstacles = self._park_obstacles()
        plan = planner.correct(pose, test.stall, test.maneuver, obstacles=obstacles)
        return plan if plan.found else planner.plan(pose, test.stall, test.maneuver, obstacles=obstacles)

    def _park_obstacles(self) -> Obstacles:
        """The park test's obstacles: the garage's walls, pillars and blocks and its parked cars as they stand."""
        return body_obstacles(self.park_planner.obstacles(), self._park.stall, self._park.bodies)

    def _check_cusp(self, pose) -> None:
        """At a cusp just taken: where the next stretch, driven from the car's pose, would hit something, show a new
        plan from here (:meth:`plan_from`; :data:`~garage_mj.driving.sim.park_guide.MAX_CUSP_PLANS` tries a test)."""
        guide = self.park_guide
        rear, heading = guide.stretch_from(pose)
        clearance, _ = nearest_obstacle(self._park_obstacles(), self.car_geometry, rear, heading)
        if clearance.min() > 0.0:
            return
        guide.cusp_plans += 1
        plan = self.plan_from(pose)
        if plan.found and len(plan.poses) >= 2:
            guide.replace(plan.poses, plan.directions, at_cusp=True)
            self.monitor.follow(Route(plan.poses[:, :2]))

    def _guide(self, pose, speed: float) -> None:
        """Move the park guide on; where the car has rested, not parked, as long as the guide's rule says, plan
        again from its pose into the stall around the parked cars as they stand (the test's planner and obstacles;
        the judge's reference stays the test's), and where no plan is found, show it the next stretch if it stopped
        a little short of a cusp (:meth:`ParkGuide.skip_to_next`)."""
        guide = self.park_guide
        tracker, stretch = guide.tracker, guide.stretch
        guide.update(pose, speed)
        if guide.tracker is tracker and guide.stretch > stretch and guide.wants_cusp_check():
            self._check_cusp(pose)
        if abs(speed) >= self.park_outcome_config.rest_speed:
            self._rest_since = None
            return
        now = float(self.data.time)
        if self._rest_since is None:
            self._rest_since = now
        fit = self.monitor.fit
        if (fit is not None and fit.parked) or not guide.wants_plan(now - self._rest_since):
            return
        self._rest_since = now  # planned, moved on or not, the next try waits as long again
        plan = self.plan_from(pose)
        if plan.found and len(plan.poses) >= 2:
            guide.replace(plan.poses, plan.directions)
            self.monitor.follow(Route(plan.poses[:, :2]))  # driving it out and in again is progress, not a stop
        else:
            guide.tries += 1
            guide.skip_to_next()  # no plan: a car stopped a little short of a cusp is shown the next stretch

    def _observe(self, pose: tuple[float, float, float] | None = None, speed: float | None = None
                 ) -> dict[str, np.ndarray]:
        """The observation of the current state (``pose`` and ``speed``: the car's, when the caller has them)."""
        x, y, yaw = pose or self.car.pose(self.data)
        frame = self.camera.render(self.data)
        rear = None if self.rear_camera is None else self.rear_camera.render(self.data)
        speed = self.car.speed(self.data) if speed is None else speed
        return observe(self._observed, Snapshot(self, x, y, yaw, speed, frame, rear))

    def _info(self, pose: tuple[float, float, float] | None = None) -> dict[str, Any]:
        x, y, yaw = pose or self.car.pose(self.data)
        if self._info_test is None:  # what stays the same for the whole test, built once per reset
            self._info_test = {
                "target_stall": self.target,
                "route_length": self.route.length,
                "time_limit": self.monitor.time_limit,
                "parked": len(self.occupied),
                "goal": self.monitor.goal_pose,
                "feasible": self.test_plan.feasible and self.scenario.feasible,
                "actors": {k: self.scenario.count(k) for k in ("pedestrian", "moving_car", "clutter")},
            }
            if self.scenario.missing:
                self._info_test["actors_missing"] = dict(self.scenario.missing)
            if self._park is not None:
                stall = self.stalls[self._park.stall]
                walking = [a.behaviour for a in self.scenario.actors if a.kind == "pedestrian"]
                self._info_test.update(park_info(self._park, self._park_level, stall), **test_room(self, self._park),
                                       feasible=self._park.feasible and self.scenario.feasible,
                                       pedestrian_behaviours={b: walking.count(b) for b in set(walking)})
        info: dict[str, Any] = {"time": float(self.data.time), "path_length": self.path_length,
                                "progress": self.monitor.progress, "pose": (x, y, yaw), **self._info_test}
        info["actors"] = dict(info["actors"])  # fresh dicts: a caller may keep or change an info
        if "pedestrian_behaviours" in info:
            info["pedestrian_behaviours"] = dict(info["pedestrian_behaviours"])
        if "actors_missing" in info:
            info["actors_missing"] = dict(info["actors_missing"])
        if self.outcome is not None:
            info.update(outcome=self.outcome.kind.value, reason=self.outcome.reason,
                        hit=self.outcome.hit_class, hit_geom=self.outcome.hit_geom)
            if self._park is not None and self._park.feasible:  # the parking metrics, once the test is over
                if self._end_info is None:
                    self._end_info = end_info(self, self._park, self.monitor, self._bodies)
                info.update(self._end_info)
        return info

    def driver_info(self, seed: int = 0) -> dict[str, Any]:
        """What a :class:`~garage_mj.driving.drivers.Driver` gets at reset.

        Seed, action type, control period, the car's geometry, and the test's plan: ``route``
        (the centre path, (N, 2) m), ``rear_path`` and ``rear_heading`` (the rear-axle path the
        route was built from) and ``goal`` (x, y, yaw). Privileged drivers (``oracle``) use the
        plan; camera drivers should not. A park or AVP test adds ``task``, ``maneuver`` and ``park_plan``
        (as in the reset info); its ``route`` is the reference path (park: the park plan's centre
        path; AVP: the cruise route then the park plan), ``goal`` the stall pose, and ``rear_path``,
        ``rear_heading``, ``rear_curvature`` stay the cruise plan's to the stall (for a park test, the
        drive that ended at its start). An env of a vehicle class (``vehicle=``) observing through the front camera
        adds ``camera``: where that class's front camera sits (:func:`~garage_mj.scene.car.car_camera`).
        """
        plan = self.test_plan
        info = {"seed": int(seed), "action_type": self.action_type, "dt": self.dt,
                "target_stall": self.target, "route_length": self.route.length, "car": self.car_geometry,
                "route": self.route.points, "goal": self.monitor.goal_pose,
                "rear_path": plan.rear, "rear_heading": plan.heading, "rear_curvature": plan.curvature,
                "actors": [a.as_dict() for a in self.scenario.actors]}
        if self._park is not None:
            info.update(task=self.task, maneuver=self._park.maneuver, park_plan=self._park.plan_info())
        if self.vehicle is not None and self.camera_config.camera == f"{EGO_NAME}/{FRONT_CAMERA}":
            # a class's front camera sits where its body puts it (models/car's is what drivers assume by default)
            info["camera"] = car_camera(FRONT_CAMERA, vehicle=self.vehicle)
        return info

    def render(self) -> np.ndarray | None:
        """The ``ego/top`` camera in colour (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        if self._top is None:
            w, h = self.render_size
            self._top = Camera(self.model, CameraConfig(camera="ego/top", width=w, height=h, rgb=True,
                                                        depth=False, segmentation=False,
                                                        near=self.camera_config.near, far=self.camera_config.far))
        return self._top.render(self.data)["rgb"]

    def close(self) -> None:
        for cam in (self.rear_camera, self.camera, self._top):  # the rear camera borrows the front one's context
            if cam is not None:
                cam.close()
        self._top = None
