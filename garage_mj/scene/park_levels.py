"""The level of a park or AVP test (docs/spec.md section 9): ``normal``, ``complex`` or ``extreme``.

After the level rules of the HOPE parking planner (Jiang et al., 2023), so results sit beside the field's, from
the car under test's length and width, the stall's width, length and angle, the aisle's width, the start and
the solid bodies of the test (checked in this order; the first level whose rule holds):

- ``extreme``: a parallel slot (``Stall.angle == 0``) shorter than the car's length + :data:`PARALLEL_EXTREME`;
  or a bay (any other angle) narrower than the car's width + :data:`NARROW_BAY` with the start more than
  :data:`VERY_FAR` from the stall;
- ``complex``: a bay narrower than the car's width + :data:`NARROW_BAY`; or the aisle :data:`NARROW_AISLE` wide
  or less; or the start more than :data:`FAR` from the stall; or the straight way from the start to the stall
  blocked;
- ``normal``: none of these.

Precisely: *the start* is the car centre where the test starts (a park test's start pose, beside the stall;
an AVP test's, at the entrance); *from the stall* is to the stall's centre (``Stall.x``, ``Stall.y``); *the
straight way is blocked* when the straight segment from the start to the stall's centre crosses or touches
the floor outline of a solid body of the test (a wall, pillar, obstacle block or parked car as it stands; not
a stall outline, not the car under test). A bay's width is ``Stall.width``; so is a parallel slot's length, the
slot lying along its aisle and opening onto it along its length (``Stall.length`` is then its depth, ``Stall.yaw``
points at the aisle; :func:`~garage_mj.scene.stalls.row_shape`).

Where ours differ from HOPE's (``map_level.py``): HOPE measures a slot by the free space between the obstacles
nearest to the goal (left and right for a bay, front and back for a parallel slot), we by its paint; HOPE's
extreme parallel slot is shorter than min(1.2 x length, length + 0.9 m), ours than length + 0.9 m; HOPE has no
aisle rule of its own (its scenes are generated with a wall 7 m before a normal bay and 6 m before a complex one;
we take 6.5 m, between them); HOPE calls a case complex when the smallest rectangle around the start and the
room before the slot meets another obstacle, we when the straight segment from the start to the stall's centre
meets a body; and HOPE measures the start's distance to the goal pose, we to the stall's centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from garage_mj.core.words import a_noun
from garage_mj.scene.body_outlines import BodyOutlines, segment_crosses
from garage_mj.scene.stalls import Stall

#: The levels, easiest first.
LEVELS = ("normal", "complex", "extreme")
PARALLEL_EXTREME = 0.9  # [m] a parallel slot shorter than the car's length + this is extreme
NARROW_BAY = 0.85  # [m] a bay narrower than the car's width + this is complex (extreme with a very far start)
NARROW_AISLE = 6.5  # [m] an aisle this wide or less makes a test complex
FAR = 15.0  # [m] a start farther than this from the stall makes a test complex
VERY_FAR = 30.0  # [m] ... and with a narrow bay, extreme


@dataclass(frozen=True)
class ParkLevel:
    """A test's level and every rule of :data:`LEVELS` that holds for it (empty for ``normal``)."""

    level: str
    reasons: tuple[str, ...] = ()

    @property
    def reason(self) -> str:
        return "; ".join(self.reasons)


def park_level(stall: Stall, length: float, width: float, aisle: float, start, bodies: BodyOutlines | None = None
               ) -> ParkLevel:
    """The level of a test into ``stall`` of a car ``length`` x ``width`` [m] in an aisle ``aisle`` [m] wide, from
    ``start`` (car centre x, y[, yaw]) among ``bodies`` (module docstring; None: nothing blocks the way)."""
    parallel = float(stall.angle) == 0.0
    far = math.hypot(float(start[0]) - stall.x, float(start[1]) - stall.y)  # [m]
    narrow = not parallel and stall.width < width + NARROW_BAY
    extreme, complex_ = [], []
    if parallel and stall.width < length + PARALLEL_EXTREME:  # a parallel slot's length along its aisle: its width
        extreme.append(f"parallel slot {stall.width:.2f} m < vehicle length + {PARALLEL_EXTREME:g} m "
                       f"({length + PARALLEL_EXTREME:.2f} m)")
    bay = f"bay {stall.width:.2f} m < vehicle width + {NARROW_BAY:g} m ({width + NARROW_BAY:.2f} m)"
    if narrow and far > VERY_FAR:
        extreme.append(f"{bay} with the start {far:.1f} m > {VERY_FAR:g} m away")
    if extreme:
        return ParkLevel("extreme", tuple(extreme))
    if narrow:
        complex_.append(bay)
    if aisle <= NARROW_AISLE:
        complex_.append(f"aisle {aisle:.2f} m <= {NARROW_AISLE:g} m")
    if far > FAR:
        complex_.append(f"start {far:.1f} m > {FAR:g} m away")
    hit = segment_crosses(bodies, start, (stall.x, stall.y)) if bodies is not None else []
    if hit:
        complex_.append(f"the straight way to the stall crosses {a_noun(bodies.classes[hit[0]])}")
    return ParkLevel("complex", tuple(complex_)) if complex_ else ParkLevel("normal")


__all__ = ["FAR", "LEVELS", "NARROW_AISLE", "NARROW_BAY", "PARALLEL_EXTREME", "VERY_FAR", "ParkLevel", "park_level"]
