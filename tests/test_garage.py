"""The Garage model: JSON round trip, hashing and validation of painted grids."""

from __future__ import annotations

import json

import numpy as np
import pytest

from garage_mj import Block, Garage, MapError, load_map


def test_json_round_trip(painted_tiny):
    g = painted_tiny
    data = json.loads(g.to_json())
    assert set(data) == {"name", "grid", "initial", "six_stall_axis"}
    back = Garage.from_json(g.to_json())
    assert back == g and back.name == g.name
    assert back.canonical_hash() == g.canonical_hash()
    assert back.entrance == g.entrance and back.exit == g.exit


def test_hash_depends_on_grid_and_axis(painted_tiny):
    g = painted_tiny
    other_axis = Garage(g.grid, g.initial, "EW" if g.six_stall_axis == "NS" else "NS")
    assert other_axis.canonical_hash() != g.canonical_hash()
    blank = load_map("tiny_7x11")
    assert blank.canonical_hash() != g.canonical_hash()


@pytest.mark.parametrize(
    "mutate, expect",
    [
        (lambda d: d.update(grid=d["grid"][:-1]), "grid is 6x11"),
        (lambda d: d["grid"][0].__setitem__(0, 0), "fixed cell OBSTACLE became FREE"),
        (lambda d: d["grid"][2].__setitem__(3, 2), "OBSTACLE where the initial map is FREE"),
        (lambda d: d["grid"][2].__setitem__(3, 11), "row 2, column 3: 11 is not a block code"),
        (lambda d: d.update(six_stall_axis="XY"), "six_stall_axis"),
        (lambda d: d.pop("initial"), "missing key(s) initial"),
        (lambda d: d["grid"].__setitem__(1, [0, 1]), "rectangular"),
    ],
)
def test_from_json_rejects_broken_garages(painted_tiny, mutate, expect):
    data = json.loads(painted_tiny.to_json())
    mutate(data)
    with pytest.raises(MapError) as err:
        Garage.from_json(json.dumps(data))
    assert expect in str(err.value)


def test_from_json_rejects_non_json():
    with pytest.raises(MapError, match="not valid JSON"):
        Garage.from_json("{nope")


def test_initial_map_rules_apply_to_garages():
    initial = load_map("tiny_7x11").initial.copy()
    initial[6, 2] = Block.OBSTACLE  # remove the entrance
    with pytest.raises(MapError, match="no entrance"):
        Garage.from_initial(initial)
    assert np.array_equal(Garage.from_initial(load_map("tiny_7x11").initial).grid, load_map("tiny_7x11").grid)
