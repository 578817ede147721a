"""The core helpers every writer and every resumable job share: the JSON writer and the settings check."""

from __future__ import annotations

import json
import os

import pytest

from garage_mj.core.config import refuse_other_settings, settings_diff
from garage_mj.core.fsutil import write_json


class Refused(Exception):
    """The caller's own error class, built from the differing keys."""


def _refuse(diff: list[str]) -> Refused:
    return Refused(f"other settings ({', '.join(diff)})")


@pytest.mark.parametrize("kw", [{}, {"indent": 1}, {"indent": 1, "sort_keys": True}, {"indent": None, "end": ""}])
def test_write_json_writes_what_json_dumps_gives(tmp_path, kw):
    data = {"b": [1, 2.5, None], "a": {"z": "é", "y": (3, 4)}, "c": True}
    path = write_json(tmp_path / "out.json", data, **kw)
    want = json.dumps(data, indent=kw.get("indent", 2), sort_keys=kw.get("sort_keys", False)) + kw.get("end", "\n")
    assert path == tmp_path / "out.json"
    assert path.read_bytes() == want.encode()


def test_write_json_default_writes_what_json_cannot(tmp_path):
    write_json(tmp_path / "d.json", {"where": tmp_path}, indent=None, default=str, end="")
    assert (tmp_path / "d.json").read_text() == json.dumps({"where": str(tmp_path)})


def test_write_json_replaces_the_file_atomically_and_leaves_no_temp(tmp_path):
    path = tmp_path / "run.json"
    path.write_text("old")
    os.link(path, tmp_path / "reader_view")  # a reader that opened the old file keeps it whole
    write_json(path, {"new": 1})
    assert json.loads(path.read_text()) == {"new": 1}
    assert (tmp_path / "reader_view").read_text() == "old"  # renamed over, not rewritten in place
    assert sorted(p.name for p in tmp_path.iterdir()) == ["reader_view", "run.json"]


def test_write_json_that_fails_leaves_the_old_file_and_no_temp(tmp_path):
    path = tmp_path / "run.json"
    path.write_text("old")
    with pytest.raises(TypeError):
        write_json(path, {"not json": object()})
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["run.json"]


def test_settings_diff_names_the_differing_keys():
    stored = {"seed": 0, "map": "a", "env": {"x": [1, 2]}, "old": 1}
    wanted = {"seed": 1, "map": "a", "env": {"x": [1, 3]}, "new": 2}
    assert settings_diff(stored, wanted) == ["env", "new", "old", "seed"]  # sorted
    assert settings_diff(stored, wanted, keys=("seed", "map", "env")) == ["seed", "env"]  # in the order given


def test_refuse_other_settings_raises_the_callers_error_naming_the_keys():
    stored = {"seed": 0, "env": {"x": [1, 2]}, "driver": "oracle"}
    refuse_other_settings(stored, {"seed": 0, "env": {"x": (1, 2)}, "driver": "oracle"}, _refuse)  # tuples as JSON lists
    with pytest.raises(Refused, match=r"^other settings \(driver, seed\)$"):
        refuse_other_settings(stored, {"seed": 3, "env": {"x": [1, 2]}, "driver": "vision"}, _refuse)
    # only the keys given are compared, and the first one differing comes first
    refuse_other_settings(stored, {"seed": 0, "env": {"x": [1, 2]}, "driver": "vision"}, _refuse, keys=("seed", "env"))
    with pytest.raises(Refused, match=r"^other settings \(env\)$"):
        refuse_other_settings(stored, {"seed": 0, "env": {}}, _refuse, keys=("seed", "env"))


def test_refuse_other_settings_refuses_a_key_one_side_lacks():
    with pytest.raises(Refused, match=r"\(new\)"):
        refuse_other_settings({"a": 1}, {"a": 1, "new": 0}, _refuse)
    with pytest.raises(Refused):  # held as None on one side only: the mappings differ, though no value does
        refuse_other_settings({"a": 1, "gone": None}, {"a": 1}, _refuse)


# -- load_config: every value checked against its field's type and declared bounds ---------------------
def _bounded_config():
    from dataclasses import dataclass

    from garage_mj.core.config import bounded

    @dataclass(frozen=True)
    class Toy:
        count: int = bounded(2, ge=1, le=10)
        share: float = bounded(0.5, ge=0.0, le=1.0)
        rate: float = 1e-3  # no bounds: only finite
        widths: tuple[int, ...] = bounded((8, 8), ge=1, min_items=1)
        kind: str = bounded("a", choices=("a", "b"))
        table: dict[int, float] = None  # type: ignore[assignment]

    return Toy


@pytest.mark.parametrize("line, key, allowed", [
    ("count = 0", "count", "an integer in [1, 10]"), ("count = 11", "count", "an integer in [1, 10]"),
    ("count = 2.5", "count", "an integer in [1, 10]"), ("share = 5.0", "share", "a finite number in [0, 1]"),
    ("share = nan", "share", "a finite number"), ("rate = inf", "rate", "a finite number"),
    ("rate = -inf", "rate", "a finite number"), ("widths = [0]", "widths", "a non-empty list of integers, each >= 1"),
    ('widths = ["a"]', "widths", "each >= 1"), ("widths = []", "widths", "non-empty"),
    ("widths = 3", "widths", "list of integers"), ('kind = "c"', "kind", "one of a, b"),
    ("table = {1 = nan}", "table", "table = {1 = nan}"), ("count = true", "count", "an integer"),
])
def test_load_config_refuses_a_value_outside_its_type_or_bounds_naming_file_key_value(tmp_path, line, key, allowed):
    from garage_mj.core.config import ConfigError, load_config, read_toml

    toy = _bounded_config()
    path = tmp_path / "toy.toml"
    path.write_text(line + "\n")
    with pytest.raises(ConfigError) as err:
        load_config(toy, path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: {key} = ") and allowed in msg
    with pytest.raises(ConfigError, match=f"^Toy: {key} = "):  # a mapping is named by the class
        load_config(toy, read_toml(path))


def test_load_config_coerces_lists_to_tuples_and_a_built_config_can_be_held_to_its_bounds():
    from dataclasses import dataclass

    from garage_mj.core.config import ConfigError, bounded, check_bounds, load_config

    toy = _bounded_config()
    cfg = load_config(toy, {"widths": [4, 5], "share": 1})
    assert cfg.widths == (4, 5) and cfg.share == 1.0 and isinstance(cfg.share, float)
    with pytest.raises(ConfigError, match=r"^Toy: count = 0 is not allowed: count must be an integer in \[1, 10\]"):
        load_config(toy, {}, count=0)  # an override is named by the class, not the file

    @dataclass(frozen=True)
    class Checked:
        n: int = bounded(1, ge=1)

        def __post_init__(self) -> None:
            check_bounds(self)

    with pytest.raises(ConfigError, match="Checked: n = -1 is not allowed"):
        Checked(n=-1)


def test_messages_put_an_before_a_vowel_sound():
    from garage_mj.core.words import a_noun
    from garage_mj.reporting.demo import _cruise_note

    said = {w: a_noun(w) for w in ("obstacle", "outside_stall", "infeasible", "unproven", "entrance", "exit",
                                   "parked_car", "wall", "unique", "one-way", 84, 64, 8, 11, 18, 110)}
    assert said == {"obstacle": "an obstacle", "outside_stall": "an outside stall", "infeasible": "an infeasible",
                    "unproven": "an unproven", "entrance": "an entrance", "exit": "an exit",
                    "parked_car": "a parked car", "wall": "a wall", "unique": "a unique", "one-way": "a one-way",
                    84: "an 84", 64: "a 64", 8: "an 8", 11: "an 11", 18: "an 18", 110: "a 110"}
    note = _cruise_note()  # the demo's cruise table note names each failure kind the paper's classes hold
    assert "an outside stall counts as a deadlock" in note and "a missed goal counts as a deadlock" in note
    assert " a outside" not in note and " a o" not in note
