"""Initial maps: the shipped ones load, bad ones fail with one clear MapError."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from garage_mj import Block, MapError, list_maps, load_map

SHIPPED = ["tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]

GOOD = """\
# a small valid map
2 2 8 2 2
2 0 0 0 2
2 0 0 0 2
2 7 2 2 2
"""


def write(tmp_path, text: str | bytes, name: str = "m.txt"):
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


def test_shipped_maps_are_listed_and_load():
    infos = {m.name: m for m in list_maps()}
    assert sorted(infos) == sorted(SHIPPED)
    assert (infos["tiny_7x11"].rows, infos["tiny_7x11"].cols) == (7, 11)
    for name in SHIPPED:
        g = load_map(name)
        assert g.name == name
        assert infos[name].description, f"{name} needs a describing comment"
        assert g.grid[g.entrance] == Block.ENTRANCE and g.grid[g.exit] == Block.EXIT
        assert np.array_equal(g.grid, g.initial)


def test_m6_and_m7_block_the_straight_route():
    """The S and U maps must not allow a straight line from entrance to exit."""
    for name in ("m6_13x13_s", "m7_13x13_u"):
        g = load_map(name)
        (er, ec), (xr, xc) = g.entrance, g.exit
        if ec == xc:
            assert (g.grid[min(er, xr) : max(er, xr), ec] == Block.OBSTACLE).any()
        else:
            assert (g.grid[1:-1, 6] == Block.OBSTACLE).sum() >= 6


def test_load_from_file(tmp_path):
    g = load_map(write(tmp_path, GOOD, "small.txt"))
    assert g.name == "small"
    assert g.entrance == (3, 1) and g.exit == (0, 2)


@pytest.mark.parametrize(
    "text, expect",
    [
        (GOOD.replace("2 7 2 2 2", "2 7 2 7 2"), "2 entrances"),
        (GOOD.replace("2 2 8 2 2", "2 2 2 2 2"), "no exit"),
        (GOOD.replace("2 2 8 2 2", "8 2 2 2 2"), "corner"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 0 8 0 2\n2 7").replace("2 2 8 2 2", "2 2 2 2 2"), "inside the grid"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 2 0 0 2\n2 7"), "sealed"),
        (GOOD.replace("2 2 8 2 2", "2 0 8 2 2"), "opens onto 2 cells"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 0 6 0 2\n2 7"), "stall code 6"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 0 1 0 2\n2 7"), "code 1 (ROAD)"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 0 0 2\n2 7"), "ragged row"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 0 x 0 2\n2 7"), "bad token 'x'"),
        (GOOD.replace("2 0 0 0 2\n2 7", "2 0 12 0 2\n2 7"), "bad token '12'"),
        ("# only a comment\n\n", "empty"),
        ("", "empty"),
    ],
)
def test_bad_maps_raise_map_error(tmp_path, text, expect):
    path = write(tmp_path, text)
    with pytest.raises(MapError) as err:
        load_map(path)
    msg = str(err.value)
    assert expect in msg
    assert str(path) in msg, "the error must name the file"


def test_errors_name_row_and_column(tmp_path):
    path = write(tmp_path, GOOD.replace("2 2 8 2 2", "8 2 2 2 2"))
    with pytest.raises(MapError, match=r"row 0, column 0"):
        load_map(path)
    path = write(tmp_path, GOOD.replace("2 0 0 0 2\n2 7", "2 0 0 4 2\n2 7"))
    with pytest.raises(MapError, match=r"row 2, column 3"):
        load_map(path)


def test_binary_and_missing_files(tmp_path):
    with pytest.raises(MapError, match="binary"):
        load_map(write(tmp_path, b"\x89PNG\x00\x00\x01"))
    with pytest.raises(MapError, match="not UTF-8"):
        load_map(write(tmp_path, b"2 2 \xff\xfe"))
    with pytest.raises(MapError, match="shipped maps: .*tiny_7x11"):
        load_map("no_such_map")


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "garage_mj", *args], capture_output=True, text=True, timeout=120
    )


def test_cli_validate_prints_one_line_and_fails(tmp_path):
    bad = write(tmp_path, GOOD.replace("2 2 8 2 2", "2 2 2 2 2"))
    out = run_cli("maps", "validate", str(bad))
    assert out.returncode != 0
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1 and "no exit" in lines[0] and str(bad) in lines[0]
    assert "Traceback" not in out.stdout + out.stderr
    ok = run_cli("maps", "validate", str(write(tmp_path, GOOD, "ok.txt")), "tiny_7x11")
    assert ok.returncode == 0 and ok.stdout.count("OK") == 2


def test_cli_maps_list():
    out = run_cli("maps", "list")
    assert out.returncode == 0
    for name in SHIPPED:
        assert name in out.stdout
