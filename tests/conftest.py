"""Shared fixtures: tiny painted garages made deterministically by the scripted painter."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from garage_mj import Garage  # noqa: E402
from garage_mj.grid.painters import paint_garage  # noqa: E402

SHIPPED_MAPS = ["tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]


@pytest.fixture(scope="session")
def painted_tiny() -> Garage:
    """A usable painted tiny_7x11 garage (same every run)."""
    return paint_garage("tiny_7x11", seed=1)


@pytest.fixture(scope="session")
def painted_maps() -> dict[str, Garage]:
    """One usable painted garage per shipped map (same every run)."""
    return {m: paint_garage(m, seed=3) for m in SHIPPED_MAPS}


JUNCTIONS_7X11 = """\
2 2 2 2 2 2 2 2 8 2 2
2 0 0 1 1 1 1 0 1 0 2
2 0 0 1 0 0 1 0 1 0 2
2 1 1 1 1 1 1 1 1 0 2
2 0 1 0 0 0 1 0 0 0 2
2 0 1 0 0 0 1 0 0 0 2
2 2 7 2 2 2 2 2 2 2 2"""


@pytest.fixture(scope="session")
def junction_garage() -> Garage:
    """A hand-drawn usable tiny garage with two adjacent T junctions, a cross, a loop and a dead end."""
    import numpy as np

    from garage_mj.grid.map_io import load_map
    from garage_mj.grid.rules import apply_stall_rule

    grid = np.array([[int(v) for v in line.split()] for line in JUNCTIONS_7X11.splitlines()])
    return Garage(apply_stall_rule(grid, "NS"), load_map("tiny_7x11").initial, name="junctions_7x11")
