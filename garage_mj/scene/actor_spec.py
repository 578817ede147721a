"""What an actor of a cruise test is: its kind, behaviour, body shape and size, trajectory and trigger.

The adverse events of a test (pedestrians, moving cars, clutter) are drawn
(:mod:`garage_mj.driving.actors.placement`) and judged (:mod:`garage_mj.driving.actors.judging`) in
driving; this module holds only the data they are made of, so the scene
(:mod:`garage_mj.scene.actor_bodies`, the actors' mocap bodies) and the OpenSCENARIO writer
(:mod:`garage_mj.export.xosc`) read it without reaching into driving.

Actors
------
=============  ===============  ==============================================================
kind           behaviour        what it does
=============  ===============  ==============================================================
pedestrian     ``cross``        walks across the aisle ahead of the car, edge to edge
pedestrian     ``step_out``     steps out between two parked cars and crosses the aisle
pedestrian     ``along``        walks along the right edge of the car's lane, toward the car
moving_car     ``reverse_out``  reverses out of a stall on the car's left into the opposite lane,
                                waits, then drives off past the car
moving_car     ``oncoming``     drives the opposite lane of a straight stretch toward the car
moving_car     ``junction_wait``  waits on a side road at a junction the car crosses, creeps
                                up to the junction as the car approaches
clutter        ``cone``         a traffic cone at the edge of the aisle (static)
clutter        ``trolley``      a shopping trolley at the edge of the aisle (static)
clutter        ``bad_parking``  a car parked crooked, its nose out of its stall into the aisle
=============  ===============  ==============================================================

Park and AVP tests (docs/spec.md section 8) draw their actors around the target stall and the reference
park plan instead (:mod:`garage_mj.driving.actors.park_placement`):

=============  ================  =============================================================
kind           behaviour         what it does
=============  ================  =============================================================
pedestrian     ``behind_stall``  crosses the mouth of the target stall, behind the reversing car
                                 (starts as the car reaches the plan's first reverse stretch)
pedestrian     ``beside_stall``  walks along the aisle past the target stall
moving_car     ``pull_out``      reverses out of an occupied stall near the target into the aisle,
                                 waits, then drives off along the aisle away from the target
clutter        ``cone``          a cone in the aisle beside the park plan's swept path (static)
clutter        ``trolley``       a trolley in the aisle beside the park plan's swept path (static)
=============  ================  =============================================================

The trigger
-----------
A moving actor waits at its first waypoint until the ego car's centre comes within
``trigger_radius`` of its trigger point (a point of the car's route), then follows its waypoints
(time measured from the trigger, linear in between) and stays at the last one. A static actor
has one waypoint and no trigger.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

KINDS = ("pedestrian", "moving_car", "clutter")
#: The behaviours a cruise test draws among, per kind.
CRUISE_BEHAVIOURS = {
    "pedestrian": ("cross", "step_out", "along"),
    "moving_car": ("reverse_out", "oncoming", "junction_wait"),
    "clutter": ("cone", "trolley", "bad_parking"),
}
#: The behaviours a park or AVP test draws among, per kind (placed around the target stall and the park plan).
PARK_BEHAVIOURS = {
    "pedestrian": ("behind_stall", "beside_stall"),
    "moving_car": ("pull_out",),
    "clutter": ("cone", "trolley"),
}
#: Every behaviour of each kind: a scenario config may list any; each task draws among its own.
BEHAVIOURS = {k: CRUISE_BEHAVIOURS[k] + tuple(b for b in PARK_BEHAVIOURS[k] if b not in CRUISE_BEHAVIOURS[k])
              for k in CRUISE_BEHAVIOURS}
#: Body shape of each behaviour (the MJCF template the env moves).
SHAPES = {"cross": "pedestrian", "step_out": "pedestrian", "along": "pedestrian", "reverse_out": "car",
          "oncoming": "car", "junction_wait": "car", "cone": "cone", "trolley": "trolley", "bad_parking": "car",
          "behind_stall": "pedestrian", "beside_stall": "pedestrian", "pull_out": "car"}
#: Half extents (length/2 along the actor's yaw, width/2, height/2) [m] of each shape's body.
SHAPE_SIZE = {"pedestrian": (0.25, 0.25, 0.85), "car": (2.15, 0.95, 0.7), "cone": (0.18, 0.18, 0.35),
              "trolley": (0.45, 0.3, 0.5)}
ROUND = frozenset({"pedestrian", "cone"})  # shapes whose body is a vertical cylinder (capsule) of radius hx


class ActorSlots(Protocol):
    """How many actors of each kind a test may hold: a scene builds one body per slot.

    :class:`garage_mj.driving.actors.config.ScenarioConfig` is one.
    """

    @property
    def pedestrians(self) -> int: ...

    @property
    def moving_cars(self) -> int: ...

    @property
    def clutter(self) -> int: ...


@dataclass(frozen=True)
class ActorSpec:
    """One actor of a test: its body, its trajectory and what starts it.

    ``waypoints`` is (K, 4): time after the trigger [s], x [m], y [m], yaw [rad]; the actor stands
    at the first until triggered, moves linearly between them, and stays at the last. A static
    actor has one waypoint and no trigger.
    """

    name: str  # unique in the test, e.g. "pedestrian_0" (also its MJCF body)
    kind: str  # "pedestrian" | "moving_car" | "clutter"
    behaviour: str  # see the module table
    waypoints: np.ndarray
    trigger: tuple[float, float] | None = None  # (x, y) [m]: the ego's centre within trigger_radius starts it
    trigger_radius: float = 0.0
    stall: int = -1  # the stall it takes (kept free of a parked car), or -1

    @property
    def shape(self) -> str:
        return SHAPES[self.behaviour]

    @property
    def static(self) -> bool:
        return self.trigger is None or len(self.waypoints) < 2

    @property
    def duration(self) -> float:
        """[s] from the trigger to the last waypoint."""
        return float(self.waypoints[-1, 0]) if len(self.waypoints) else 0.0

    def pose_at(self, tau: float | None) -> tuple[float, float, float]:
        """(x, y, yaw) ``tau`` seconds after the trigger (None or < 0: not triggered yet)."""
        w = self.waypoints
        if tau is None or tau <= w[0, 0] or len(w) == 1:
            return float(w[0, 1]), float(w[0, 2]), float(w[0, 3])
        if tau >= w[-1, 0]:
            return float(w[-1, 1]), float(w[-1, 2]), float(w[-1, 3])
        k = int(np.searchsorted(w[:, 0], tau, side="right")) - 1
        t0, t1 = w[k, 0], w[k + 1, 0]
        a = (tau - t0) / (t1 - t0) if t1 > t0 else 1.0
        yaw = w[k, 3] + a * math.remainder(w[k + 1, 3] - w[k, 3], math.tau)
        return (float(w[k, 1] + a * (w[k + 1, 1] - w[k, 1])), float(w[k, 2] + a * (w[k + 1, 2] - w[k, 2])),
                float(yaw))

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "behaviour": self.behaviour,
                "waypoints": [[round(float(v), 6) for v in row] for row in self.waypoints],
                "trigger": None if self.trigger is None else [float(self.trigger[0]), float(self.trigger[1])],
                "trigger_radius": float(self.trigger_radius), "stall": int(self.stall)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ActorSpec:
        try:
            kind, behaviour = str(d["kind"]), str(d["behaviour"])
            if kind not in KINDS or behaviour not in BEHAVIOURS[kind]:
                raise ValueError(f"unknown actor kind/behaviour {kind!r}/{behaviour!r}")
            w = np.asarray(d["waypoints"], dtype=float).reshape(-1, 4)
            if not len(w) or not np.isfinite(w).all() or (np.diff(w[:, 0]) < 0).any():
                raise ValueError("waypoints must be finite rows (t, x, y, yaw) with non-decreasing t")
            trig = d.get("trigger")
            trig = None if trig is None else (float(trig[0]), float(trig[1]))
            return cls(str(d["name"]), kind, behaviour, w, trig, float(d.get("trigger_radius", 0.0)),
                       int(d.get("stall", -1)))
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"malformed actor {d!r}: {exc}") from None
