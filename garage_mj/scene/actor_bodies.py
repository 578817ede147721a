"""The MuJoCo side of the actors (:mod:`garage_mj.scene.actor_spec`): kinematic mocap bodies, built once per env.

:func:`add_actor_bodies` adds one mocap body per actor slot of an
:class:`~garage_mj.scene.actor_spec.ActorSlots` (the drive env's
:class:`~garage_mj.driving.actors.config.ScenarioConfig`) to an ``mjcf.RootElement`` (before compiling): a
pedestrian per ``pedestrians``, a car per ``moving_cars``, and per ``clutter`` slot one body of
each clutter shape (cone, trolley, car), since a slot's shape is drawn per test. Body names
carry the semantic class (``pedestrian_0``, ``movingcar_0``, ``clutter_0_cone``...), so the
segmentation camera and the outcome monitor classify them like every other geom.

Actor geoms have ``contype=2, conaffinity=0``: they touch only geoms whose ``conaffinity`` has
bit 2, i.e. the ego car's collision geoms (``models/car``), never walls, floor or parked cars.
:class:`ActorBodies` moves them in a compiled model: unused slots wait far below the floor with
their geoms made transparent (alpha 0), which MuJoCo's scene update skips: a camera frame costs
what the placed actors cost, not what the slots do.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import mujoco
import numpy as np

from garage_mj.scene.actor_spec import SHAPE_SIZE, ActorSlots, ActorSpec
from garage_mj.scene.layout import CLASS_RGBA
from garage_mj.scene.semantics import Semantic

HIDDEN = (0.0, 0.0, -25.0)  # [m] where an unused actor body waits
CLUTTER_SHAPES = ("cone", "trolley", "car")
_ACTOR_GEOM = {"contype": 2, "conaffinity": 0, "group": 0}


def _rgba(cls: Semantic) -> list[float]:
    return list(CLASS_RGBA[cls])


def _add_shape(body, shape: str, cls: Semantic) -> None:
    hx, hy, hz = SHAPE_SIZE[shape]
    rgba = _rgba(cls)
    if shape == "pedestrian":
        body.add("geom", name=f"{body.name}_torso", type="capsule", fromto=[0, 0, 0.3, 0, 0, 1.45], size=[hx],
                 rgba=rgba, **_ACTOR_GEOM)
        body.add("geom", name=f"{body.name}_head", type="sphere", pos=[0, 0, 1.6], size=[0.13], rgba=rgba,
                 **_ACTOR_GEOM)
    elif shape == "car":
        body.add("geom", name=f"{body.name}_body", type="box", pos=[0, 0, 0.55], size=[hx, hy, 0.4], rgba=rgba,
                 **_ACTOR_GEOM)
        body.add("geom", name=f"{body.name}_cabin", type="box", pos=[-0.15, 0, 1.15], size=[1.0, hy - 0.1, 0.25],
                 rgba=rgba, **_ACTOR_GEOM)
    elif shape == "cone":
        body.add("geom", name=f"{body.name}_cone", type="cylinder", pos=[0, 0, hz], size=[hx, hz], rgba=rgba,
                 **_ACTOR_GEOM)
    elif shape == "trolley":
        body.add("geom", name=f"{body.name}_basket", type="box", pos=[0, 0, 0.65], size=[hx, hy, 0.3], rgba=rgba,
                 **_ACTOR_GEOM)
        body.add("geom", name=f"{body.name}_frame", type="box", pos=[0, 0, 0.2], size=[hx * 0.8, hy * 0.8, 0.15],
                 rgba=rgba, **_ACTOR_GEOM)
    else:
        raise ValueError(f"unknown actor shape {shape!r}")


def slot_names(config: ActorSlots) -> list[tuple[str, str]]:
    """(body name, shape) of every actor slot a scene built for ``config`` holds."""
    out = [(f"pedestrian_{k}", "pedestrian") for k in range(config.pedestrians)]
    out += [(f"movingcar_{k}", "car") for k in range(config.moving_cars)]
    out += [(f"clutter_{k}_{shape}", shape) for k in range(config.clutter) for shape in CLUTTER_SHAPES]
    return out


def slot_of(actor: ActorSpec) -> str:
    """The body that carries ``actor`` (its name, or name_shape for clutter)."""
    return f"{actor.name}_{actor.shape}" if actor.kind == "clutter" else actor.name


def add_actor_bodies(root, config: ActorSlots) -> list[str]:
    """Add the mocap bodies of ``config``'s actor slots to ``root``; returns their names."""
    classes = {"pedestrian": Semantic.PEDESTRIAN, "movingcar": Semantic.MOVING_CAR, "clutter": Semantic.CLUTTER}
    names = []
    for name, shape in slot_names(config):
        body = root.worldbody.add("body", name=name, mocap=True, pos=list(HIDDEN))
        _add_shape(body, shape, classes[name.split("_")[0]])
        names.append(name)
    return names


class ActorBodies:
    """Moves the actor slots of a compiled model (``data.mocap_pos`` / ``mocap_quat``)."""

    def __init__(self, model: mujoco.MjModel, config: ActorSlots) -> None:
        self.model = model
        self.mocap: dict[str, int] = {}
        self.geoms: dict[str, np.ndarray] = {}
        for name, _ in slot_names(config):
            b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            if b < 0 or model.body_mocapid[b] < 0:
                raise ValueError(f"the model has no mocap body {name!r}; build it with add_actor_bodies")
            self.mocap[name] = int(model.body_mocapid[b])
            adr, num = int(model.body_geomadr[b]), int(model.body_geomnum[b])
            self.geoms[name] = np.arange(adr, adr + num)

    def capacity(self, kind: str) -> int:
        prefix = {"pedestrian": "pedestrian_", "moving_car": "movingcar_", "clutter": "clutter_"}[kind]
        names = {n.rsplit("_", 1)[0] if kind == "clutter" else n for n in self.mocap if n.startswith(prefix)}
        return len(names)

    def place(self, data: mujoco.MjData, actors: Iterable[ActorSpec]) -> dict[str, int]:
        """Hide every slot, then map each actor to its slot; returns actor name -> mocap id."""
        for name, m in self.mocap.items():
            data.mocap_pos[m] = HIDDEN
            data.mocap_quat[m] = (1.0, 0.0, 0.0, 0.0)
            self.model.geom_rgba[self.geoms[name], 3] = 0.0
        out = {}
        for a in actors:
            slot = slot_of(a)
            if slot not in self.mocap:
                raise ValueError(f"actor {a.name} ({a.behaviour}) has no body in this env: build the env with a "
                                 f"scenario that has room for it")
            out[a.name] = self.mocap[slot]
            self.model.geom_rgba[self.geoms[slot], 3] = 1.0
        return out

    @staticmethod
    def set_pose(data: mujoco.MjData, mocap_id: int, pose: tuple[float, float, float]) -> None:
        x, y, yaw = pose
        data.mocap_pos[mocap_id] = (x, y, 0.0)
        data.mocap_quat[mocap_id] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def states(actors: list[ActorSpec], taus: list[float | None]) -> np.ndarray:
    """(len(actors), 4) rows (x, y, yaw, seconds since the trigger or -1) for the privileged observation."""
    out = np.zeros((len(actors), 4), dtype=np.float32)
    for k, (a, tau) in enumerate(zip(actors, taus, strict=True)):
        x, y, yaw = a.pose_at(tau)
        out[k] = (x, y, math.remainder(yaw, math.tau), -1.0 if tau is None else tau)
    return out
