"""The ego car: attach ``models/car`` to an arena and turn high-level commands into actuator controls.

Commands are a throttle/brake pedal ``throttle`` in [-1, 1] and a steering request ``steer`` in
[-1, 1] (positive = left). The pedal is an acceleration request: +1 raises the cruise speed at
``max_accel``, -1 lowers it at ``max_decel`` and also applies the wheel brakes, 0 holds the current
speed. Steering moves toward ``steer * max_steer`` at ``steer_rate`` and is split into Ackermann
angles for the two front wheels; the rear wheels get per-side speeds (an electronic differential).

Gears (docs/spec.md section 8). The car is in drive (:attr:`Gear.D`) or reverse (:attr:`Gear.R`) and starts
every test in D. The pedal means the same in both: the cruise speed is a speed along the gear's
direction, so in R +1 accelerates backwards (up to ``max_reverse_speed``), -1 brakes, 0 holds the
speed. Steering is the same in both, as in a real car: steering left while reversing swings the
rear to the left (the heading turns clockwise). :meth:`Car.speed` is signed, negative in reverse.
A gear change is honoured only at rest (``|speed| < gear_change_speed``); a request for the other
gear while moving brakes in full (the pedal is overridden to -1, the steering still applies) until
the car is at rest, then the gear changes and the pedal acts in the new gear from that control
period on. The cruise speed restarts from 0 at a change.

Action spaces. Cruise tests (the paper's): :class:`DiscreteAction` (4 actions) or continuous
``[throttle, steer]``, through :func:`command_from_action` and :meth:`Car.act`; they have no gear,
so a cruise test always drives in D, exactly as before reverse existed. Park and AVP tests only:
:func:`park_action_space` and :func:`park_command_from_action`, used by :meth:`Car.park_act`:

- discrete, :class:`ParkAction`: ``ACCELERATE``, ``TURN_LEFT``, ``TURN_RIGHT``, ``BRAKE`` are the
  cruise actions with the same numbers and keep the gear (in R, ``ACCELERATE`` speeds up backwards
  and ``TURN_LEFT`` turns the front wheels left); ``SELECT_REVERSE`` (4) and ``SELECT_DRIVE`` (5)
  brake in full with the wheels straightening, and request R or D (the gear changes once at rest;
  a request for the gear already in is just ``BRAKE``);
- continuous: ``[pedal, steer, gear]`` in [-1, 1]; ``gear < 0`` requests R, ``gear >= 0`` requests D,
  at every step (so an agent holds a gear by holding its sign).
"""

from __future__ import annotations

import enum
import math
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from garage_mj.scene.car import CarConfig, car_model, drop_rangefinders

if TYPE_CHECKING:
    from garage_mj.scene.vehicles import VehicleClass

EGO_NAME = "ego"  # attachment name: every ego geom becomes "ego/..." (semantics: EGO_CAR)


class Gear(enum.Enum):
    """The car's gear: ``D`` drives forward, ``R`` backward (park and AVP tests only)."""

    D = 1
    R = -1

    @property
    def sign(self) -> float:
        """+1.0 in D, -1.0 in R: the direction of travel along the car's x axis."""
        return float(self.value)


class DiscreteAction(enum.IntEnum):
    """The paper's cruise actions (Sec. "Garage Difficulty Verification")."""

    ACCELERATE = 0
    TURN_LEFT = 1
    TURN_RIGHT = 2
    BRAKE = 3


#: (throttle, steer) per discrete action: turning keeps the speed, accelerating straightens up.
DISCRETE_COMMANDS: dict[DiscreteAction, tuple[float, float]] = {
    DiscreteAction.ACCELERATE: (1.0, 0.0),
    DiscreteAction.TURN_LEFT: (0.0, 1.0),
    DiscreteAction.TURN_RIGHT: (0.0, -1.0),
    DiscreteAction.BRAKE: (-1.0, 0.0),
}


class ParkAction(enum.IntEnum):
    """Discrete actions of park and AVP tests: the cruise actions (same numbers) and two gear selections."""

    ACCELERATE = 0
    TURN_LEFT = 1
    TURN_RIGHT = 2
    BRAKE = 3
    SELECT_REVERSE = 4
    SELECT_DRIVE = 5


#: (throttle, steer, gear request) per park action: ``None`` keeps the gear; a selection brakes.
PARK_DISCRETE_COMMANDS: dict[ParkAction, tuple[float, float, Gear | None]] = {
    **{ParkAction(a): (*DISCRETE_COMMANDS[a], None) for a in DiscreteAction},
    ParkAction.SELECT_REVERSE: (*DISCRETE_COMMANDS[DiscreteAction.BRAKE], Gear.R),
    ParkAction.SELECT_DRIVE: (*DISCRETE_COMMANDS[DiscreteAction.BRAKE], Gear.D),
}
PARK_CONTINUOUS_SIZE = 3  # [pedal, steer, gear]


def clip(x: float, lo: float, hi: float) -> float:
    """``x`` limited to [lo, hi], as ``np.clip`` does for a finite scalar (which costs ~2 us a call)."""
    return min(max(float(x), lo), hi)


def _discrete_index(arr: np.ndarray) -> int | None:
    """A 0-d action array as a discrete action's index: an integer, or a float with an integer value (``2.0``);
    None for anything else (``2.7``, ``True``, a string), which is never rounded or floored into an action."""
    if arr.dtype.kind in "iu":
        return int(arr)
    if arr.dtype.kind == "f" and float(arr).is_integer():
        return int(arr)
    return None


def command_from_action(action) -> tuple[float, float]:
    """``(throttle, steer)`` from a discrete action (int) or a continuous ``[throttle, steer]``; a driver's
    action that is neither (NaN or infinite included) is a ``ValueError`` naming it, never a command."""
    arr = np.asarray(action)
    if arr.ndim == 0:
        if arr.dtype.kind == "f" and not math.isfinite(arr):
            raise ValueError(f"the driver's action {action!r} is not finite (NaN or infinity); a discrete action "
                             f"is one of 0..{len(DiscreteAction) - 1}")
        try:
            return DISCRETE_COMMANDS[DiscreteAction(_discrete_index(arr))]
        except (ValueError, TypeError):
            raise ValueError(f"discrete action {action!r} is not one of 0..{len(DiscreteAction) - 1}") from None
    if arr.shape != (2,):
        raise ValueError(f"continuous action must be [throttle, steer], got shape {arr.shape}")
    try:
        throttle, steer = float(arr[0]), float(arr[1])
    except (ValueError, TypeError):
        raise ValueError(f"continuous action {action!r} must be two numbers [throttle, steer]") from None
    if not (math.isfinite(throttle) and math.isfinite(steer)):
        raise ValueError(f"the driver's action {[throttle, steer]} is not finite (NaN or infinity); a continuous "
                         "action is [throttle, steer], each in [-1, 1]")
    return clip(throttle, -1.0, 1.0), clip(steer, -1.0, 1.0)


def park_command_from_action(action) -> tuple[float, float, Gear | None]:
    """``(throttle, steer, gear request)`` from a :class:`ParkAction` or a continuous ``[pedal, steer, gear]``.

    The request is ``None`` (keep the gear) for the discrete driving actions; a continuous action
    always requests one: R when ``gear < 0``, D otherwise. A driver's action that is neither (NaN or
    infinite included) is a ``ValueError`` naming it, as in :func:`command_from_action`.
    """
    arr = np.asarray(action)
    if arr.ndim == 0:
        if arr.dtype.kind == "f" and not math.isfinite(arr):
            raise ValueError(f"the driver's action {action!r} is not finite (NaN or infinity); a discrete park "
                             f"action is one of 0..{len(ParkAction) - 1}")
        try:
            return PARK_DISCRETE_COMMANDS[ParkAction(_discrete_index(arr))]
        except (ValueError, TypeError):
            raise ValueError(f"park action {action!r} is not one of 0..{len(ParkAction) - 1}") from None
    if arr.shape != (PARK_CONTINUOUS_SIZE,):
        raise ValueError(f"continuous park action must be [pedal, steer, gear], got shape {arr.shape}")
    try:
        pedal, steer, gear = float(arr[0]), float(arr[1]), float(arr[2])
    except (ValueError, TypeError):
        raise ValueError(f"continuous park action {action!r} must be three numbers [pedal, steer, gear]") from None
    if not (math.isfinite(pedal) and math.isfinite(steer) and math.isfinite(gear)):
        raise ValueError(f"the driver's action {[pedal, steer, gear]} is not finite (NaN or infinity); a continuous "
                         "park action is [pedal, steer, gear], each in [-1, 1]")
    return clip(pedal, -1.0, 1.0), clip(steer, -1.0, 1.0), Gear.R if gear < 0 else Gear.D


def park_action_space(action_type: str):
    """The gymnasium action space of park and AVP tests: ``"discrete"`` or ``"continuous"``."""
    from gymnasium import spaces

    if action_type == "discrete":
        return spaces.Discrete(len(ParkAction))
    if action_type == "continuous":
        return spaces.Box(-1.0, 1.0, (PARK_CONTINUOUS_SIZE,), np.float32)
    raise ValueError(f"park action type {action_type!r} is not 'discrete' or 'continuous'")


def car_mjcf(name: str = EGO_NAME, vehicle: VehicleClass | None = None, ultrasonic: bool = False):
    """The car as a ``dm_control.mjcf`` model named ``name``, without its free joint (for attaching).

    ``vehicle``: a class of the fleet (:func:`garage_mj.scene.car.car_model`); None: ``models/car`` as it is.
    ``ultrasonic``: keep its bumper rangefinders (by default they are dropped: rays cast at every physics step
    that a scene without a reader of them would pay for; their sites stay)."""
    model = car_model(vehicle, name)
    model.find("joint", "root").remove()
    if not ultrasonic:
        drop_rangefinders(model)
    return model


def attach_car(arena, x: float, y: float, yaw: float, name: str = EGO_NAME, vehicle: VehicleClass | None = None,
               ultrasonic: bool = False):
    """Attach a free car to ``arena`` (an ``mjcf.RootElement``) at ground pose (x [m], y [m], yaw [rad]).

    Returns the attachment frame. The arena must use radians (``<compiler angle="radian"/>``), as
    the car model does. ``vehicle``: the class of car; ``ultrasonic``: with its rangefinders (:func:`car_mjcf`).
    """
    if arena.compiler.angle == "degree":
        raise ValueError("the arena uses angle=\"degree\"; the car needs <compiler angle=\"radian\"/>")
    frame = arena.attach(car_mjcf(name, vehicle, ultrasonic))
    frame.pos = [x, y, 0.0]
    frame.quat = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    frame.add("freejoint", name=f"{name}_root")
    return frame


def compile_mjcf(root) -> mujoco.MjModel:
    """Compile an ``mjcf.RootElement`` (with its assets) into an ``MjModel``."""
    return mujoco.MjModel.from_xml_string(root.to_xml_string(), assets=root.get_assets())


class Car:
    """A car inside a compiled model, found by name prefix (``"ego/"`` attached, ``""`` standalone).

    Holds the controller state (gear, cruise speed, steering angle); :meth:`control` writes ``data.ctrl``.
    """

    def __init__(self, model: mujoco.MjModel, config: CarConfig | None = None, prefix: str = f"{EGO_NAME}/"):
        self.model = model
        self.config = config or CarConfig()
        self.prefix = prefix

        def ident(kind, name):
            i = mujoco.mj_name2id(model, kind, prefix + name)
            if i < 0:
                raise ValueError(f"the model has no car {kind.name[6:].lower()} named {prefix + name!r}")
            return i

        A = mujoco.mjtObj.mjOBJ_ACTUATOR
        self.chassis = ident(mujoco.mjtObj.mjOBJ_BODY, "chassis")
        self._steer = [ident(A, "steer_left"), ident(A, "steer_right")]
        self._drive = [ident(A, "drive_left"), ident(A, "drive_right")]
        self._brake = [ident(A, f"brake_{w}") for w in ("fl", "fr", "rl", "rr")]
        # the free joint sits on the chassis (standalone) or on the attachment frame above it
        root = self.chassis
        while model.body_jntnum[root] == 0 or model.jnt_type[model.body_jntadr[root]] != mujoco.mjtJoint.mjJNT_FREE:
            root = int(model.body_parentid[root])
            if root == 0:
                raise ValueError(f"the car {prefix!r} has no free joint")
        self.root_body = root
        jnt = int(model.body_jntadr[root])
        self._qadr = int(model.jnt_qposadr[jnt])
        self._vadr = int(model.jnt_dofadr[jnt])
        # geometry from the compiled model, not duplicated constants
        body = {w: ident(mujoco.mjtObj.mjOBJ_BODY, w) for w in ("steer_fl", "steer_fr", "wheel_rl")}
        self.wheelbase = float(model.body_pos[body["steer_fl"], 0] - model.body_pos[body["wheel_rl"], 0])  # [m]
        self.track = float(model.body_pos[body["steer_fl"], 1] - model.body_pos[body["steer_fr"], 1])  # [m]
        self.wheel_radius = float(model.geom_size[ident(mujoco.mjtObj.mjOBJ_GEOM, "wheel_rl"), 0])  # [m]
        subtree = {root}
        for b in range(root + 1, model.nbody):
            if int(model.body_parentid[b]) in subtree:
                subtree.add(b)
        self.bodies = frozenset(subtree)
        self.geoms = frozenset(int(g) for g in np.flatnonzero(np.isin(model.geom_bodyid, list(subtree))))
        self.geom_mask = np.isin(model.geom_bodyid, list(subtree))  # (ngeom,) bool: the car's geoms
        self.gear = Gear.D
        self.cruise_speed = 0.0  # [m/s] along the gear's direction, >= 0
        self.steer_angle = 0.0  # [rad] bicycle-model angle
        self._vel = np.empty(6)  # mj_objectVelocity's output, reused

    # -- state -----------------------------------------------------------------------------------
    def pose(self, data: mujoco.MjData) -> tuple[float, float, float]:
        """(x [m], y [m], yaw [rad]) of the chassis centre."""
        xmat = data.xmat[self.chassis]
        return float(data.xpos[self.chassis, 0]), float(data.xpos[self.chassis, 1]), math.atan2(xmat[3], xmat[0])

    def speed(self, data: mujoco.MjData) -> float:
        """Signed forward speed [m/s] of the chassis (negative when reversing)."""
        vel = self._vel
        mujoco.mj_objectVelocity(self.model, data, mujoco.mjtObj.mjOBJ_XBODY, self.chassis, vel, 1)
        return float(vel[3])

    def reset(self, data: mujoco.MjData, x: float, y: float, yaw: float) -> None:
        """Place the car at rest at ground pose (x, y, yaw), wheels straight, in D; clears the controller."""
        q = self._qadr
        # every car joint (wheels, steering) back to its reference, then the free joint pose
        for b in self.bodies:
            for j in range(self.model.body_jntadr[b], self.model.body_jntadr[b] + self.model.body_jntnum[b]):
                a, n = int(self.model.jnt_qposadr[j]), (7 if self.model.jnt_type[j] == 0 else 1)
                data.qpos[a : a + n] = self.model.qpos0[a : a + n]
        data.qpos[q : q + 3] = (x, y, self.model.qpos0[q + 2])
        data.qpos[q + 3 : q + 7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        for b in self.bodies:
            d0, dn = int(self.model.body_dofadr[b]), int(self.model.body_dofnum[b])
            if dn:
                data.qvel[d0 : d0 + dn] = 0.0
        self.gear = Gear.D
        self.cruise_speed = 0.0
        self.steer_angle = 0.0
        data.ctrl[self._steer + self._drive + self._brake] = 0.0
        mujoco.mj_forward(self.model, data)

    # -- control ---------------------------------------------------------------------------------
    def control(self, data: mujoco.MjData, throttle: float, steer: float, dt: float) -> None:
        """One control period of ``dt`` s in the current gear: update cruise speed and steering, write ctrl."""
        cfg = self.config
        u = clip(throttle, -1.0, 1.0)
        s = clip(steer, -1.0, 1.0)
        rate = cfg.max_accel if u >= 0 else cfg.max_decel
        v = self.cruise_speed + u * rate * dt
        sign = self.gear.sign  # 1.0 in D: the products below are then exactly the forward-only ones
        top = cfg.max_speed if self.gear is Gear.D else cfg.max_reverse_speed
        ceiling = min(top, max(sign * self.speed(data), 0.0) + cfg.speed_lead)
        self.cruise_speed = clip(v, 0.0, max(ceiling, 0.0))
        step = cfg.steer_rate * dt
        self.steer_angle += clip(s * cfg.max_steer - self.steer_angle, -step, step)
        tan_d = math.tan(self.steer_angle)
        half = self.track / 2
        # Ackermann: both front wheels point at the same turning centre on the rear axle line
        data.ctrl[self._steer[0]] = math.atan(self.wheelbase * tan_d / (self.wheelbase - half * tan_d))
        data.ctrl[self._steer[1]] = math.atan(self.wheelbase * tan_d / (self.wheelbase + half * tan_d))
        omega = sign * self.cruise_speed / self.wheel_radius  # [rad/s], negative in R
        curvature = tan_d / self.wheelbase  # [1/m]
        data.ctrl[self._drive[0]] = omega * (1 - half * curvature)
        data.ctrl[self._drive[1]] = omega * (1 + half * curvature)
        data.ctrl[self._brake] = max(0.0, -u) * cfg.brake_gain

    def act(self, data: mujoco.MjData, action, dt: float) -> None:
        """:meth:`control` from a discrete action or a continuous ``[throttle, steer]``."""
        self.control(data, *command_from_action(action), dt)

    def park_control(self, data: mujoco.MjData, throttle: float, steer: float, gear: Gear | None,
                     dt: float) -> None:
        """:meth:`control` with a gear request (park and AVP tests): ``None`` or the current gear keeps it.

        The other gear is engaged only at rest (``|speed| < gear_change_speed``), with the cruise speed
        back to 0; while the car moves, the request brakes in full instead (steering still applies).
        """
        if gear is not None and gear is not self.gear:
            if abs(self.speed(data)) < self.config.gear_change_speed:
                self.gear = gear
                self.cruise_speed = 0.0
            else:
                throttle = -1.0
        self.control(data, throttle, steer, dt)

    def park_act(self, data: mujoco.MjData, action, dt: float) -> None:
        """:meth:`park_control` from a :class:`ParkAction` or a continuous ``[pedal, steer, gear]``."""
        self.park_control(data, *park_command_from_action(action), dt)
