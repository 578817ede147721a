"""The learned parking driver's actions: 90 park commands, one of which it picks per step.

The continuous park action is ``[pedal, steer, gear]`` (:func:`~garage_mj.driving.sim.vehicle.park_command_from_action`).
A network that regresses it averages the oracle's modes (reverse first or forward first, brake or go) into a command
neither would give: the parking policy trained that way parked none of its validation tests. Picking one of a grid
of commands by argmax keeps a mode whole. :data:`PARK_COMMANDS` is every combination of :data:`PEDAL_LEVELS`,
:data:`STEER_LEVELS` and the two gears; quantised to it (:func:`nearest_park_action`), the oracle parked 19 of 20
tests of 4 painted m5 garages.
"""

from __future__ import annotations

import numpy as np

PEDAL_LEVELS = (-1.0, -0.3, 0.0, 0.3, 1.0)  # brake in full ... accelerate in full
STEER_LEVELS = (-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0)  # road-wheel target, fraction of full lock
GEARS = (1.0, -1.0)  # D, R
#: (n, 3) float32: the park command ``[pedal, steer, gear]`` of each action index, gear slowest, steer fastest.
PARK_COMMANDS = np.array([(p, s, g) for g in GEARS for p in PEDAL_LEVELS for s in STEER_LEVELS], dtype=np.float32)


def park_command(index: int) -> np.ndarray:
    """The ``[pedal, steer, gear]`` command of action ``index`` (a copy)."""
    return PARK_COMMANDS[int(index)].copy()


def nearest_park_action(command) -> int:
    """The action index whose command is nearest ``command`` (``[pedal, steer, gear]``): the same gear (R when
    ``gear < 0``), then the least ``|pedal error| + |steer error|`` (the first of equals)."""
    pedal, steer, gear = (float(v) for v in np.asarray(command, dtype=float).reshape(-1)[:3])
    same = PARK_COMMANDS[:, 2] == (-1.0 if gear < 0 else 1.0)
    cost = np.abs(PARK_COMMANDS[:, 0] - pedal) + np.abs(PARK_COMMANDS[:, 1] - steer)
    return int(np.argmin(np.where(same, cost, np.inf)))
