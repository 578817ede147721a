"""Semantic classes of docs/spec.md section 6 and the MJCF naming rule that carries them.

Every exporter and the segmentation camera share this one rule, so a segmentation image maps to
classes, never to raw geom ids.

Naming convention (the MJCF scene builder must follow it)
----------------------------------------------------------
A geom's class comes from its **name**. The name is split on ``/`` (the separator
``dm_control.mjcf`` puts between an attached model's name and its elements), and each part's
leading run of letters, lower-cased, is looked up in :data:`PREFIXES`; the **first** part that
matches decides. So ``wall_n_3``, ``pillar_r2c4_1``, ``parkedcar_17/chassis`` and ``ego/wheel_fl``
classify as wall, pillar, parked car and ego car. Attaching a reusable model (e.g. ``models/car``)
under a model named ``parkedcar_<i>`` or ``ego`` therefore classifies all its geoms at once.

A geom without a matching name inherits the class of its body, then of the body's ancestors
(same rule on body names). Anything still unmatched is :attr:`Semantic.BACKGROUND`;
:func:`unclassified_geoms` lists such geoms so scene tests can assert there are none.

=============  ====================  ============================================
class          name prefix(es)       what
=============  ====================  ============================================
floor          ``floor``             the drivable slab (roads, stall floors)
road marking   ``roadmark``          lane lines, arrows (thin visual geoms)
stall marking  ``stallmark``         stall outlines (thin visual geoms)
wall           ``wall``, ``ceiling`` outer walls and the optional ceiling
pillar         ``pillar``            0.6 m square pillars
obstacle       ``obstacle``          OBSTACLE blocks, barriers of obstructed stalls
parked car     ``parkedcar``         a parked car in a stall
ego car        ``ego``               the car under test
entrance       ``entrance``          entrance gate marker / floor
exit           ``exit``              exit gate marker / floor
pedestrian     ``pedestrian``        a walking person (kinematic actor, :mod:`garage_mj.driving.actors.scenario`)
moving car     ``movingcar``         a car that drives during the test (kinematic actor)
clutter        ``clutter``           cones, trolleys, a badly parked car (static actors)
=============  ====================  ============================================
"""

from __future__ import annotations

import enum
import re

import numpy as np


class Semantic(enum.IntEnum):
    """Segmentation class ids (docs/spec.md section 6), 0 = nothing rendered / unclassified."""

    BACKGROUND = 0
    FLOOR = 1
    ROAD_MARKING = 2
    STALL_MARKING = 3
    WALL = 4
    PILLAR = 5
    OBSTACLE = 6
    PARKED_CAR = 7
    EGO_CAR = 8
    ENTRANCE = 9
    EXIT = 10
    PEDESTRIAN = 11
    MOVING_CAR = 12
    CLUTTER = 13


NUM_CLASSES = len(Semantic)

#: Name prefix (leading letters of a name part, lower-case) -> class.
PREFIXES: dict[str, Semantic] = {
    "floor": Semantic.FLOOR,
    "roadmark": Semantic.ROAD_MARKING,
    "stallmark": Semantic.STALL_MARKING,
    "wall": Semantic.WALL,
    "ceiling": Semantic.WALL,
    "pillar": Semantic.PILLAR,
    "obstacle": Semantic.OBSTACLE,
    "parkedcar": Semantic.PARKED_CAR,
    "ego": Semantic.EGO_CAR,
    "entrance": Semantic.ENTRANCE,
    "exit": Semantic.EXIT,
    "pedestrian": Semantic.PEDESTRIAN,
    "movingcar": Semantic.MOVING_CAR,
    "clutter": Semantic.CLUTTER,
}

#: Classes a car may drive on (the vision driver's drivable area).
DRIVABLE = frozenset(
    {Semantic.FLOOR, Semantic.ROAD_MARKING, Semantic.STALL_MARKING, Semantic.ENTRANCE, Semantic.EXIT}
)
#: Classes whose contact with the ego car is a collision (docs/spec.md section 7).
COLLIDABLE = frozenset({Semantic.WALL, Semantic.PILLAR, Semantic.OBSTACLE, Semantic.PARKED_CAR,
                        Semantic.PEDESTRIAN, Semantic.MOVING_CAR, Semantic.CLUTTER})

#: Display colours (RGB, 0-255) per class, for previews and videos.
PALETTE = np.array(
    [
        (0, 0, 0),  # background
        (128, 128, 128),  # floor
        (255, 255, 255),  # road marking
        (255, 215, 0),  # stall marking
        (150, 75, 50),  # wall
        (70, 130, 180),  # pillar
        (200, 40, 40),  # obstacle
        (0, 160, 80),  # parked car
        (255, 0, 255),  # ego car
        (0, 220, 255),  # entrance
        (255, 140, 0),  # exit
        (255, 60, 160),  # pedestrian
        (0, 90, 255),  # moving car
        (255, 120, 40),  # clutter
    ],
    dtype=np.uint8,
)

_LETTERS = re.compile(r"[a-z]+")


def classify_name(name: str | None) -> Semantic | None:
    """The class a geom or body name carries, or None when no part of it matches."""
    if not name:
        return None
    for part in name.split("/"):
        m = _LETTERS.match(part.lower())
        if m and m.group(0) in PREFIXES:
            return PREFIXES[m.group(0)]
    return None


def geom_name(kind: Semantic, *parts: object) -> str:
    """A geom name carrying ``kind``, e.g. ``geom_name(Semantic.PILLAR, 2, 4)`` -> ``pillar_2_4``."""
    prefix = next(p for p, k in PREFIXES.items() if k == kind)
    return "_".join([prefix, *(str(p) for p in parts)])


def geom_classes(model) -> np.ndarray:
    """Class id per geom of a compiled ``mujoco.MjModel`` (int array of length ``model.ngeom``).

    Geom name first, then its body and the body's ancestors (see the module docstring).
    """
    import mujoco

    body_cls: list[Semantic | None] = []
    for b in range(model.nbody):
        cls = classify_name(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b))
        if cls is None and b > 0:
            cls = body_cls[int(model.body_parentid[b])]  # parents come before children
        body_cls.append(cls)
    out = np.zeros(model.ngeom, dtype=np.int32)
    for g in range(model.ngeom):
        cls = classify_name(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g))
        if cls is None:
            cls = body_cls[int(model.geom_bodyid[g])]
        out[g] = int(cls) if cls is not None else int(Semantic.BACKGROUND)
    return out


def unclassified_geoms(model) -> list[str]:
    """Names (or ``#id``) of geoms that map to no class: a scene test asserts this is empty."""
    import mujoco

    classes = geom_classes(model)
    return [
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
        for g in np.flatnonzero(classes == int(Semantic.BACKGROUND))
    ]


def colorize(segmentation: np.ndarray) -> np.ndarray:
    """An (H, W, 3) uint8 picture of a class-id image, using :data:`PALETTE`."""
    return PALETTE[np.clip(segmentation, 0, NUM_CLASSES - 1)]
