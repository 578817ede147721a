"""Park problems as files: JSON and TPCAP cases written per park test, read back, a malformed file refused."""

from __future__ import annotations

import csv
import json
import math
import os
import random
from pathlib import Path

import pytest

from garage_mj.cli import main
from garage_mj.core.fsutil import LOCK_NAME, FolderLock
from garage_mj.export.park_problems import (
    INDEX,
    ParkProblemError,
    read_park_problem,
    read_tpcap_case,
    write_park_problems,
)
from garage_mj.scene.car import car_geometry
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import centre_to_rear, park_pose
from tests._cli import one_line_error, snapshot
from tests.test_faults import _unprivileged, shared_tmp  # noqa: F401 (a fixture)


@pytest.fixture(scope="module")
def written(painted_tiny, tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("park_problems")
    index = write_park_problems([painted_tiny], out)
    return out, json.loads(index.read_text())


def test_every_stall_with_a_cruise_test_gives_two_problems(painted_tiny, written):
    out, index = written
    scene = GarageScene(painted_tiny)
    feasible = [p.stall for p in drive_planner(scene).plans() if p.feasible]
    assert sorted((e["stall"], e["maneuver"]) for e in index["problems"]) == \
        sorted((s, m) for s in feasible for m in ("reverse", "forward"))
    assert len(index["skipped"]) == len(scene.stalls.stalls) - len(feasible)
    car = car_geometry()
    for entry in index["problems"][:6]:
        problem = read_park_problem(out / entry["json"])
        stall = scene.stalls.stalls[problem.stall]
        assert problem.goal_centre == pytest.approx(park_pose(stall, car, problem.maneuver))
        assert problem.goal == pytest.approx(tuple(centre_to_rear(problem.goal_centre, car)))
        assert problem.start_centre == pytest.approx(drive_planner(scene).plan(problem.stall).goal)
        assert {c for c, _ in problem.obstacles} <= {"wall", "obstacle", "pillar", "parked_car"}
        assert problem.obstacles  # walls at least
        assert problem.car == index["car"]  # the vehicle of every problem, which a TPCAP case has no place for


def test_json_and_tpcap_files_round_trip(written):
    out, index = written
    for entry in index["problems"][:6]:
        path = out / entry["json"]
        problem = read_park_problem(path)
        assert problem.to_json() == json.loads(path.read_text())
        raw = (out / entry["csv"]).read_bytes()
        assert raw.endswith(b"\r\n") and raw.count(b"\n") == 1 and b" " not in raw  # one line, as TPCAP's CaseN.csv
        fields = raw.decode("ascii")[:-2].split(",")
        n = len(problem.obstacles)
        assert len(fields) == 7 + n + 2 * sum(len(v) for _, v in problem.obstacles) and int(fields[6]) == n
        assert fields[7:7 + n] == [str(len(v)) for _, v in problem.obstacles]  # counts written as integers
        start, goal, polygons = read_tpcap_case(out / entry["csv"])
        assert start == problem.start and goal == problem.goal  # exact: every float to its last bit
        assert polygons == [list(v) for _, v in problem.obstacles]


@pytest.mark.parametrize(("text", "says"), [
    ("{not json", "is not JSON"),
    ("[1, 2]", "no JSON object"),
    ('{"format": "something else", "version": 1}', "format 'something else'"),
    (None, "no 'obstacles' key"),
    ("NaN", "not a finite number"),
])
def test_a_malformed_problem_is_refused_in_one_line(written, tmp_path, text, says):
    out, index = written
    good = json.loads((out / index["problems"][0]["json"]).read_text())
    if text is None:
        del good["obstacles"]
        text = json.dumps(good)
    elif text == "NaN":
        good["start"][0] = float("nan")
        text = json.dumps(good)
    bad = tmp_path / "bad.json"
    bad.write_text(text)
    with pytest.raises(ParkProblemError) as err:
        read_park_problem(bad)
    message = str(err.value)
    assert says in message and str(bad) in message and "\n" not in message
    with pytest.raises(ParkProblemError, match="cannot read park problem"):
        read_park_problem(tmp_path / "missing.json")


def test_a_tpcap_case_with_wrong_counts_is_refused(tmp_path):
    bad = tmp_path / "Case1.csv"
    bad.write_text("\n".join(["0", "0", "0", "1", "1", "0", "1", "4", "0", "0", "1", "0"]) + "\n")
    with pytest.raises(ParkProblemError, match="does not hold the vertices"):
        read_tpcap_case(bad)


def test_export_cli_writes_the_park_problems_of_the_stalls_and_maneuver_asked_for(painted_tiny, written, tmp_path,
                                                                                     capsys):
    """``--stall`` (repeated) and ``--maneuver`` pick problems of the whole export (``written``), byte for byte."""
    garage = tmp_path / "garage.json"
    garage.write_text(painted_tiny.to_json())
    out = tmp_path / "park"
    assert main(["export", "--garage", str(garage), "--park-problems", str(out), "--stall", "3", "--stall", "0",
                 "--maneuver", "reverse"]) == 0
    index = json.loads((out / INDEX).read_text())
    assert [(p["stall"], p["maneuver"]) for p in index["problems"]] == [(0, "reverse"), (3, "reverse")]
    assert "2 park problem(s) of 1 garage(s)" in capsys.readouterr().out
    every, every_index = written
    for entry in index["problems"]:
        for key in ("json", "csv"):
            assert (out / entry[key]).read_bytes() == (every / entry[key]).read_bytes(), entry[key]
    assert {(p["stall"], p["maneuver"]) for p in every_index["problems"]} >= {(0, "forward"), (3, "forward")}
    before = snapshot(tmp_path)
    line = one_line_error(capsys, ["export", "--garage", str(garage), "--park-problems", str(tmp_path / "more"),
                                   "--stall", "0", "--stall", "999"])
    assert "--stall 999" in line and f"0..{len(GarageScene(painted_tiny).stalls.stalls) - 1}" in line, line
    assert snapshot(tmp_path) == before  # refused before anything is written


# -- every bad file is one line ------------------------------------------------------------------------
def _good(written) -> tuple[Path, dict]:
    out, index = written
    path = out / index["problems"][0]["json"]
    return path, json.loads(path.read_text())


def _at(data: dict, *keys):
    for k in keys:
        data = data[k]
    return data


def _set(*keys, v):
    def edit(d: dict) -> None:
        _at(d, *keys[:-1])[keys[-1]] = v
    return edit


def _del(*keys):
    def edit(d: dict) -> None:
        del _at(d, *keys[:-1])[keys[-1]]
    return edit


class _Text:
    """An edit of the good file's text rather than of its object: ``edit(text)`` gives the file's text or bytes."""

    def __init__(self, edit) -> None:
        self.edit = edit


def _rows(edit):
    """An edit of the garage grid's rows (a list of strings of block codes)."""
    def apply(d: dict) -> None:
        d["garage_grid"] = edit(list(d["garage_grid"]))
    return apply


#: (what, an edit of the good problem's JSON object (or a :class:`_Text` edit of its text), what the message says). Each file is refused with ParkProblemError in one line naming the file.
BAD_PROBLEMS = [
    ("start too large an integer", _set("start", 0, v=10**400), "start"),
    ("nested 100,000 deep", _Text(lambda t: "[" * 100_000 + "]" * 100_000), "nested too deeply"),
    ("nested deep in car", _Text(lambda t: t.replace('"car": {', '"car": {"x": ' + "[" * 100_000 + "]" * 100_000
                                                     + ", ", 1)), "nested too deeply"),
    ("garage name with an escape", _set("garage", v="evil\x1b[2J"), "control character"),
    ("garage name with a newline", _set("garage", v="a\nb"), "control character"),
    ("garage name with a bidi override", _set("garage", v="a\u202eb"), "control character"),
    ("garage name too long", _set("garage", v="a" * 500), "128 characters"),
    *[(f"car.{k} {v}", _set("car", k, v=v), f"car.{k}")
      for k in ("wheelbase", "length", "width", "min_turning_radius") for v in (-1.0, 0.0, 1e300)],
    ("car.wheelbase NaN", _set("car", "wheelbase", v=float("nan")), "car.wheelbase holds nan, not a finite number"),
    ("car.wheelbase inf", _set("car", "wheelbase", v=float("inf")), "car.wheelbase holds inf, not a finite number"),
    ("car.front_overhang negative", _set("car", "front_overhang", v=-0.5), "car.front_overhang"),
    ("car.rear_overhang negative", _set("car", "rear_overhang", v=-0.5), "car.rear_overhang"),
    ("car.max_steer negative", _set("car", "max_steer", v=-0.7), "car.max_steer"),
    ("car.max_steer past a right angle", _set("car", "max_steer", v=2.0), "car.max_steer"),
    ("car length not its parts", _set("car", "length", v=9.0), "car.length"),
    ("car turning radius not its steering", _set("car", "min_turning_radius", v=9.0), "car.min_turning_radius"),
    ("car without wheelbase", _del("car", "wheelbase"), "car has no 'wheelbase' key"),
    ("car with an unknown key", _set("car", "colour", v=1.0), "car.colour"),
    ("car a list", _set("car", v=[1.0]), "car is not an object"),
    ("planner margin negative", _set("planner", "margin", v=-0.1), "planner.margin"),
    ("planner turning radius zero", _set("planner", "turning_radius", v=0.0), "planner.turning_radius"),
    ("planner without margin", _del("planner", "margin"), "planner has no 'margin' key"),
    ("planner with an unknown key", _set("planner", "seed", v=3), "planner.seed"),
    ("region inverted in x", lambda d: d.update(region=[d["region"][2], d["region"][1], d["region"][0], d["region"][3]]),
     "region"),
    ("region inverted in y", lambda d: d.update(region=[d["region"][0], d["region"][3], d["region"][2], d["region"][1]]),
     "region"),
    ("region empty", _set("region", v=[1.0, 1.0, 1.0, 1.0]), "region"),
    ("start outside the region", lambda d: d["start"].__setitem__(0, d["region"][2] + 50), "start"),
    ("goal outside the region", lambda d: d["goal"].__setitem__(1, d["region"][1] - 50), "goal"),
    ("start yaw huge", _set("start", 2, v=1e300), "start"),
    ("reference without poses", _del("reference", "poses"), "reference has no 'poses' key"),
    ("reference found a string", _set("reference", "found", v="yes"), "reference.found"),
    ("reference verdict unknown", _set("reference", "verdict", v="maybe"), "reference.verdict"),
    ("reference verdict not its found", _set("reference", "verdict", v="unproven"), "reference.verdict"),
    ("reference gear 0", _set("reference", "directions", 0, v=0), "reference.directions"),
    ("reference poses one short", lambda d: d["reference"]["poses"].pop(), "reference.poses"),
    ("reference pose far away", _set("reference", "poses", 1, 0, v=1e300), "reference pose"),
    ("reference length negative", _set("reference", "length", v=-1.0), "reference.length"),
    ("reference cusps a float", _set("reference", "cusps", v=1.5), "reference.cusps"),
    ("reference settings unknown key", _set("reference", "settings", "colour", v=1), "reference.settings.colour"),
    ("obstacle vertex far away", _set("obstacles", 0, "vertices", 0, v=[1e300, 0.0]), "obstacle 0"),
    ("forged garage_hash", _set("garage_hash", v="0" * 64), "garage_hash"),
    ("garage_hash not hex", _set("garage_hash", v="xyz"), "garage_hash"),
    ("garage_grid ragged", _rows(lambda r: [r[0][:-1], *r[1:]]), "garage_grid"),
    ("garage_grid with a letter", _rows(lambda r: ["x" + r[0][1:], *r[1:]]), "garage_grid"),
    ("garage_grid of other digits", _rows(lambda r: ["\u0661" + r[0][1:], *r[1:]]), "garage_grid"),
    ("garage_grid too large", _rows(lambda r: ["2" * 65] * 65), "garage_grid"),
    ("garage_grid not a list", _set("garage_grid", v="2222"), "garage_grid"),
    ("six_stall_axis unknown", _set("six_stall_axis", v="UP"), "six_stall_axis"),
    ("version true", _set("version", v=True), "version True"),
    ("version a float", lambda d: d.update(version=float(d["version"])), "version"),
    ("stall past the garage's stalls", _set("stall", v=10**6), "stall 1000000"),
    ("stall far too large", _set("stall", v=10**30), "stall"),
    ("maneuver a list", _set("maneuver", v=["reverse"]), "maneuver"),
    ("obstacle of an unknown class", _set("obstacles", 0, "class", v="tree"), "'tree'"),
    ("obstacle with an unknown key", _set("obstacles", 0, "height", v=2.0), "obstacle 0"),
    ("obstacle of zero area", _set("obstacles", 0, "vertices", v=[[0, 0], [1, 0], [2, 0]]), "obstacle 0"),
    ("obstacle clockwise", lambda d: d["obstacles"][0]["vertices"].reverse(), "counter-clockwise"),
    ("stall_outline of zero area", _set("stall_outline", v=[[0, 0], [1, 1], [2, 2]]), "stall_outline"),
    ("an unknown key", _set("colour", v="red"), "'colour'"),
    ("a key twice", _Text(lambda t: t.replace('"start": ', '"start": [0, 0, 0], "start": ', 1)), "'start' twice"),
    ("UTF-16", _Text(lambda t: t.encode("utf-16")), "UTF-8"),
    ("more than the size limit", _Text(lambda t: b" " * (17 << 20) + t.encode()), "MiB"),
    ("empty", _Text(lambda t: ""), "is not JSON"),
]


def _refused(read, bad: Path, data: str | bytes, says: str) -> str:
    """Write ``data`` to ``bad``, read it with ``read``: one ParkProblemError line naming the file and ``says``."""
    bad.write_bytes(data if isinstance(data, bytes) else data.encode())
    with pytest.raises(ParkProblemError) as err:
        read(bad)
    message = str(err.value)
    assert says in message and str(bad) in message and "\n" not in message, message
    return message


@pytest.mark.parametrize(("edit", "says"), [b[1:] for b in BAD_PROBLEMS], ids=[b[0] for b in BAD_PROBLEMS])
def test_every_bad_problem_file_is_one_line(written, tmp_path, edit, says):
    path, good = _good(written)
    assert read_park_problem(path).to_json() == good  # the file the edits start from is good
    if isinstance(edit, _Text):
        data = edit.edit(json.dumps(good, indent=2))
    else:
        edited = json.loads(json.dumps(good))
        edit(edited)
        data = json.dumps(edited, indent=2)
    message = _refused(read_park_problem, tmp_path / "bad.json", data, says)
    assert "garage-mj export --park-problems" in message, message  # the fix


def test_a_folder_or_a_pipe_is_not_a_problem_file(tmp_path):
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    for reader in (read_park_problem, read_tpcap_case):
        for path in (tmp_path, fifo):  # a pipe without a writer would block the read for ever
            with pytest.raises(ParkProblemError, match="is not a file") as err:
                reader(path)
            assert str(path) in str(err.value) and "\n" not in str(err.value)


def _case(lines: list[str]) -> str:
    """The numbers ``lines`` as a case one number per line (the column vector V)."""
    return "".join(f"{v}\n" for v in lines)


def _row(values: list[str]) -> str:
    """The numbers ``values`` as a case laid out as TPCAP publishes it: one comma-separated line, CRLF."""
    return ",".join(values) + "\r\n"


def _fields(path: Path) -> list[str]:
    """The numbers of the case file ``path`` as written, in either layout."""
    text = path.read_text()
    return text.strip().split(",") if "," in text else text.split()


#: (what, a function of the good case's numbers and a layout (:func:`_row` or :func:`_case`) giving the
#: file's text or bytes, what the message says)
BAD_CASES = [
    ("obstacle count NaN", lambda v, case: case([*v[:6], "nan", *v[7:]]), "V[7] holds nan, not a finite number"),
    ("obstacle count inf", lambda v, case: case([*v[:6], "inf", *v[7:]]), "V[7] holds inf, not a finite number"),
    ("obstacle count -inf", lambda v, case: case([*v[:6], "-inf", *v[7:]]), "V[7] holds -inf"),
    ("obstacle count 1e400", lambda v, case: case([*v[:6], "1e400", *v[7:]]), "V[7] holds 1e400"),
    ("vertex count NaN", lambda v, case: case([*v[:7], "nan", *v[8:]]), "V[8] holds nan"),
    ("vertex count inf", lambda v, case: case([*v[:7], "inf", *v[8:]]), "V[8] holds inf"),
    ("start x NaN", lambda v, case: case(["nan", *v[1:]]), "V[1] holds nan"),
    ("start yaw inf", lambda v, case: case([*v[:2], "inf", *v[3:]]), "V[3] holds inf"),
    ("goal yaw 1e400", lambda v, case: case([*v[:5], "1e400", *v[6:]]), "V[6] holds 1e400"),
    ("vertex x NaN", lambda v, case: case([*v[:-2], "nan", v[-1]]), "holds nan, not a finite number"),
    ("vertex y -inf", lambda v, case: case([*v[:-1], "-inf"]), "holds -inf, not a finite number"),
    ("vertex far away", lambda v, case: case([*v[:-1], "1e300"]), "= 1e+300 is not allowed"),
    ("yaw huge", lambda v, case: case([*v[:2], "1e300", *v[3:]]), "V[3] = 1e+300 is not allowed"),
    ("a number with an underscore", lambda v, case: case(["1_0", *v[1:]]), "V[1] holds '1_0', not a number"),
    ("a digit of another script", lambda v, case: case(["\u0661", *v[1:]]), "not a number"),
    ("a polygon of zero area", lambda v, case: case([*v[:6], "1", "3", "0", "0", "1", "1", "2", "2"]), "zero area"),
    ("goal 20 km from the start", lambda v, case: case([*v[:3], repr(float(v[0]) + 20_000), *v[4:]]),
     "V[4], V[5] = ("),
    ("vertex 20 km from the start", lambda v, case: case([*v[:-1], repr(float(v[1]) - 20_000)]),
     "a case spans at most 10000 m"),
    ("latin-1", lambda v, case: case(v).encode() + "\u00e9\n".encode("latin-1"), "UTF-8"),
    ("more than the size limit", lambda v, case: case(v) + " " * (17 << 20), "MiB"),
]


@pytest.mark.parametrize("layout", [_row, _case], ids=["row", "column"])
@pytest.mark.parametrize(("edit", "says"), [b[1:] for b in BAD_CASES], ids=[b[0] for b in BAD_CASES])
def test_every_bad_tpcap_case_is_one_line(written, tmp_path, edit, says, layout):
    out, index = written
    good = out / index["problems"][0]["csv"]
    read_tpcap_case(good)
    data = edit(_fields(good), layout)
    _refused(read_tpcap_case, tmp_path / "Case1.csv", data, says)


#: (what, a function of the good case's numbers giving a file in a layout TPCAP's readers do not read as V, what
#: the message says)
BAD_LAYOUTS = [
    ("two lines of comma-separated numbers", lambda v: _row(v[:7]) + _row(v[7:]), "2 lines with commas"),
    ("an empty field", lambda v: _row([*v[:3], "", *v[3:]]), "empty field V[4]"),
    ("a leading comma", lambda v: "," + _row(v), "empty field V[1]"),
    ("two trailing commas", lambda v: ",".join(v) + ",,\r\n", "empty field"),
    ("two numbers on one of several lines", lambda v: _case([f"{v[0]} {v[1]}", *v[2:]]), "numbers on"),
    ("semicolons", lambda v: ";".join(v) + "\r\n", "V[1] holds"),
]


@pytest.mark.parametrize(("edit", "says"), [b[1:] for b in BAD_LAYOUTS], ids=[b[0] for b in BAD_LAYOUTS])
def test_a_tpcap_case_in_another_layout_is_one_line(written, tmp_path, edit, says):
    out, index = written
    bad = tmp_path / "Case1.csv"
    bad.write_text(edit(_fields(out / index["problems"][0]["csv"])), newline="")
    with pytest.raises(ParkProblemError) as err:
        read_tpcap_case(bad)
    message = str(err.value)
    assert says in message and str(bad) in message and "\n" not in message, message
    assert "one line of comma-separated numbers" in message, message  # the fix


#: (what, a function of the good case's numbers giving a file that TPCAP's readers read as the same V)
GOOD_LAYOUTS = [
    ("one number per line", _case),
    ("one number per line, CRLF", lambda v: "".join(f"{x}\r\n" for x in v)),
    ("LF", lambda v: ",".join(v) + "\n"),
    ("no line end", lambda v: ",".join(v)),
    ("a trailing comma", lambda v: ",".join(v) + ",\r\n"),
    ("spaces around the commas", lambda v: " " + " , ".join(v) + " \r\n"),
    ("blank lines after it", lambda v: _row(v) + "\r\n \r\n"),
    ("a byte-order mark", lambda v: "\ufeff" + _row(v)),
]


@pytest.mark.parametrize("edit", [b[1] for b in GOOD_LAYOUTS], ids=[b[0] for b in GOOD_LAYOUTS])
def test_a_tpcap_case_is_read_in_every_layout_tpcap_reads(written, tmp_path, edit):
    out, index = written
    good = out / index["problems"][0]["csv"]
    other = tmp_path / "Case1.csv"
    other.write_text(edit(_fields(good)), newline="")
    assert read_tpcap_case(other) == read_tpcap_case(good)


def _tpcap_reader(path: Path) -> tuple[tuple, tuple, list[list[tuple[float, float]]], int]:
    """A case as TPCAP's own demos read it (re-implemented here): the first row of the CSV file as floats V
    (its Python demo's ``csv.reader``; MATLAB's ``readmatrix``), then V taken in order as its MATLAB
    ``LoadCase`` does: start, goal, n, the n vertex counts, then each obstacle's x, y pairs. Also the count
    of numbers left over (TPCAP ignores them; a good case has none)."""
    with open(path) as f:
        v = [float(x) for x in next(csv.reader(f))]
    start, goal, n = (v[0], v[1], v[2]), (v[3], v[4], v[5]), int(v[6])
    counts, rest = [int(c) for c in v[7:7 + n]], v[7 + n:]
    obstacles = []
    for c in counts:
        obstacles.append([(rest[2 * j], rest[2 * j + 1]) for j in range(c)])
        rest = rest[2 * c:]
    return start, goal, obstacles, len(rest)


def test_tpcap_s_own_reader_takes_the_exported_case(written):
    out, index = written
    for entry in index["problems"][:6]:
        problem = read_park_problem(out / entry["json"])
        start, goal, obstacles, left = _tpcap_reader(out / entry["csv"])
        assert start == problem.start and goal == problem.goal and left == 0
        assert obstacles == [list(v) for _, v in problem.obstacles]


#: The shape of TPCAP's 20 published cases (Case1.csv ... Case20.csv of github.com/libai1943/TPCAP_benchmarks):
#: the vertex count of each obstacle, in order. The files are published without a licence, so they are not
#: copied here; :func:`_published_like` writes cases of their shape and layout instead.
TPCAP_SHAPES = {
    1: [4] * 3, 2: [4] * 3, 3: [4] * 3, 4: [4] * 33, 5: [4] * 53, 6: [4] * 29, 7: [4] * 3, 8: [4] * 3, 9: [4] * 2,
    10: [4, 4, 5, 5, 5], 11: [5, 4, 6, 5, 5], 12: [4, 4, 5, 5, 4], 13: [4] * 4, 14: [4] * 4, 15: [4] * 4,
    16: [5] * 10 + [4], 17: [7] * 9 + [4], 18: [8] * 10 + [4, 4], 19: [11] * 27 + [4, 4] + [6] * 8,
    20: [5, 5, 5, 4, 3] + [6] * 11,
}
#: Roughly where the published cases that lie far from the origin are (x, y) [m].
TPCAP_FAR = {13: (4.484e9, -3.543e8), 14: (4.509e9, -5.511e9), 15: (7.009e9, -8.722e9)}


def _tpcap_text(v: list[float]) -> str:
    """Numbers as TPCAP's case files spell them: each of TPCAP's 20 published files is exactly this."""
    return ",".join(f"{x:.15g}" for x in v) + "\r\n"


def _published_like(k: int, folder: Path) -> Path:
    """A case of the shape of TPCAP's ``Case<k>.csv`` in its layout: seeded poses within 20 m of its place (yaws
    up to a turn either way, as the published ones), star-shaped obstacles of its vertex counts, and in the
    far cases a 1 cm sliver (their published obstacles hold such)."""
    rng = random.Random(k)
    ox, oy = TPCAP_FAR.get(k, (0.0, 0.0))
    shape = TPCAP_SHAPES[k]

    def xy() -> list[float]:
        return [ox + rng.uniform(-20, 20), oy + rng.uniform(-20, 20)]

    v = [*xy(), rng.uniform(-6.2, 6.2), *xy(), rng.uniform(-6.2, 6.2), len(shape), *shape]
    for i, c in enumerate(shape):
        (cx, cy), turn, r = xy(), rng.uniform(0, math.tau), rng.uniform(0.5, 3.0)
        if k in TPCAP_FAR and i == 2:  # a sliver: a long thin quadrilateral
            v += [cx, cy, cx + 1.6, cy + 0.01, cx + 1.6, cy + 0.02, cx, cy + 0.01]
            continue
        for j in range(c):
            a = turn + math.tau * (j + rng.uniform(0.0, 0.5)) / c
            v += [cx + r * math.cos(a), cy + r * math.sin(a)]
    path = folder / f"Case{k}.csv"
    path.write_text(_tpcap_text(v), newline="")
    return path


def _check_tpcap_case(path: Path, k: int) -> None:
    start, goal, polygons = read_tpcap_case(path)
    ref_start, ref_goal, ref_obstacles, left = _tpcap_reader(path)
    assert (start, goal, left) == (ref_start, ref_goal, 0), path
    assert [len(p) for p in polygons] == TPCAP_SHAPES[k], path
    assert polygons == ref_obstacles, path


@pytest.mark.parametrize("k", sorted(TPCAP_SHAPES))
def test_cases_of_the_shape_and_layout_of_tpcap_s_published_ones_read(tmp_path, k):
    _check_tpcap_case(_published_like(k, tmp_path), k)


TPCAP_CASES = os.environ.get("GARAGE_MJ_TPCAP_CASES")


@pytest.mark.skipif(not TPCAP_CASES, reason="GARAGE_MJ_TPCAP_CASES names no folder of TPCAP's Case1.csv ... "
                                            "Case20.csv (a clone of github.com/libai1943/TPCAP_benchmarks)")
def test_tpcap_s_published_cases_read():
    for k in sorted(TPCAP_SHAPES):
        path = Path(TPCAP_CASES) / f"Case{k}.csv"
        _check_tpcap_case(path, k)
        start, goal, polygons = read_tpcap_case(path)
        values = [*start, *goal, len(polygons), *map(len, polygons), *(c for p in polygons for xy in p for c in xy)]
        assert path.read_bytes() == _tpcap_text(values).encode(), path  # what _published_like writes


# -- the export's folder ----------------------------------------------------------------------------------
def test_a_second_park_problems_export_into_a_busy_folder_is_one_line(painted_tiny, tmp_path, capsys):
    garage = tmp_path / "garage.json"
    garage.write_text(painted_tiny.to_json())
    out = tmp_path / "park"
    with FolderLock(out, "garage-mj export"):  # a first export, still running
        before = snapshot(out)
        line = one_line_error(capsys, ["export", "--garage", str(garage), "--park-problems", str(out)])
        assert f"{out} is in use by garage-mj export (pid {os.getpid()})" in line, line
        assert snapshot(out) == before  # nothing written
    for flag in ("--out", "--carla-package"):  # one folder for two kinds of output: refused before any work
        line = one_line_error(capsys, ["export", "--garage", str(garage), "--park-problems", str(out), flag, str(out)])
        assert "--park-problems" in line and flag in line and "a folder of their own" in line, line
    assert main(["export", "--garage", str(garage), "--park-problems", str(out), "--stall", "0"]) == 0
    assert not (out / LOCK_NAME).exists()


def test_a_read_only_park_problems_target_is_one_line_naming_it(painted_tiny, shared_tmp):  # noqa: F811
    garage = shared_tmp / "garage.json"
    garage.write_text(painted_tiny.to_json())
    out = shared_tmp / "park"
    assert main(["export", "--garage", str(garage), "--park-problems", str(out), "--stall", "0"]) == 0
    folder = next(p for p in out.iterdir() if p.is_dir())
    os.chmod(out, 0o777)
    for target in (folder, out):  # the garage's folder, then the whole output folder
        os.chmod(folder, 0o777)
        os.chmod(target, 0o555)
        before = snapshot(shared_tmp)
        done = _unprivileged(["export", "--garage", str(garage), "--park-problems", str(out), "--quiet",
                              "--out", str(shared_tmp / "packs")], shared_tmp)
        err = [ln for ln in done.stderr.splitlines() if ln.strip()]
        assert done.returncode == 2 and len(err) == 1, done.stderr
        assert f"--park-problems {out}:" in err[0] and str(target) in err[0] and ".tmp" not in err[0], err[0]
        assert "read-only" in err[0] and "writable" in err[0], err[0]
        assert snapshot(shared_tmp) == before and not (shared_tmp / "packs").exists()  # refused before any pack


def test_every_yaw_written_lies_in_minus_pi_to_pi(written):
    """OMPL's SO2 bounds (and its Reeds-Shepp space's) are [-pi, pi): a yaw written as pi is refused there."""
    out, index = written
    yaws = []
    for entry in index["problems"]:
        data = json.loads((out / entry["json"]).read_text())
        yaws += [data[key][2] for key in ("start", "goal", "start_centre", "goal_centre")]
        fields = (out / entry["csv"]).read_text().split(",")
        yaws += [float(fields[2]), float(fields[5])]
    assert all(-math.pi <= y < math.pi for y in yaws)
    assert -math.pi in yaws  # the tiny garage has stalls facing west: their yaw is pi, written as -pi


@pytest.mark.parametrize(("yaw", "read"), [
    (math.pi, -math.pi), (-math.pi, -math.pi), (3 * math.pi, -math.pi), (math.tau + 0.5, 0.5), (-4.0, math.tau - 4.0),
    (1000.25, 1000.25 - 159 * math.tau),
])
def test_reader_takes_any_finite_yaw_and_wraps_it(written, tmp_path, yaw, read):
    out, index = written
    data = json.loads((out / index["problems"][0]["json"]).read_text())
    data["goal_centre"][2] = yaw
    path = tmp_path / "p.json"
    path.write_text(json.dumps(data))
    got = read_park_problem(path).goal_centre[2]
    assert -math.pi <= got < math.pi and got == pytest.approx(read, abs=1e-12)


def test_each_problem_carries_the_reference_plan(written):
    """The reference: a path another planner can be scored against, from the start to the goal, every pose clear."""
    out, index = written
    for entry in index["problems"][:12]:
        problem = read_park_problem(out / entry["json"])
        ref = problem.reference
        assert ref["found"] and ref["verdict"] == "feasible" and ref["reason"] == ""
        poses = ref["poses"]
        assert poses[0] == pytest.approx(list(problem.start), abs=1e-6)
        assert poses[-1] == pytest.approx(list(problem.goal), abs=1e-6)
        steps = [math.dist(a[:2], b[:2]) for a, b in zip(poses, poses[1:], strict=False)]
        assert max(steps) <= ref["spacing"] + ref["settings"]["step"] + 1e-6  # subsampled, nothing skipped
        assert sum(steps) <= ref["length"] + 1e-6 and ref["length"] >= math.dist(poses[0][:2], poses[-1][:2])
        gears = ref["directions"]
        assert set(gears) <= {-1, 1} and len(gears) == len(poses)
        assert ref["cusps"] == sum(a != b for a, b in zip(gears[:-2], gears[1:-1], strict=True))  # every cusp kept
        assert ref["min_clearance"] >= problem.planner["margin"] - 1e-6
        assert ref["settings"]["margin"] == problem.planner["margin"]
        assert ref["settings"]["turning_radius"] == problem.planner["turning_radius"]


def test_version_2_files_still_read_and_version_3_needs_its_reference(written, tmp_path):
    path, data = _good(written)
    assert data["version"] == 3
    old = {k: v for k, v in data.items() if k != "reference"} | {"version": 2}
    (tmp_path / "v2.json").write_text(json.dumps(old))
    problem = read_park_problem(tmp_path / "v2.json")
    assert problem.reference is None and problem.to_json() == old
    (tmp_path / "v3.json").write_text(json.dumps(old | {"version": 3}))
    with pytest.raises(ParkProblemError, match="no 'reference' key"):
        read_park_problem(tmp_path / "v3.json")
    (tmp_path / "v2x.json").write_text(json.dumps(data | {"version": 2}))
    with pytest.raises(ParkProblemError, match="unknown key 'reference'"):
        read_park_problem(tmp_path / "v2x.json")


def _schema_validator():
    jsonschema = pytest.importorskip("jsonschema")
    from garage_mj.export.park_problems import SCHEMA

    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _descriptions(node, at="") -> list[str]:
    """Paths of the schema's properties that have no description."""
    missing = []
    for name, sub in node.get("properties", {}).items():
        if "description" not in sub:
            missing.append(f"{at}{name}")
        missing += _descriptions(sub, f"{at}{name}.")
        if isinstance(sub.get("items"), dict):
            missing += _descriptions(sub["items"], f"{at}{name}[].")
    return missing


def test_every_problem_written_validates_against_the_shipped_schema(written):
    validator = _schema_validator()
    assert not _descriptions(validator.schema)  # every field says what it is, its unit and frame
    out, index = written
    for entry in index["problems"]:
        errors = list(validator.iter_errors(json.loads((out / entry["json"]).read_text())))
        assert not errors, (entry["json"], [e.message for e in errors[:3]])


@pytest.mark.parametrize("edit", [
    _set("start", 2, v=math.pi),  # OMPL's SO2 bounds refuse it
    _set("maneuver", v="sideways"),
    _del("reference"),
    _set("planner", "seed", v=3),
    _set("obstacles", 0, "class", v="tree"),
    _set("reference", "directions", 0, v=0),
    lambda d: d.update(version=2),  # a version 2 file has no reference
])
def test_a_broken_problem_does_not_validate(written, edit):
    validator = _schema_validator()
    _, data = _good(written)
    assert validator.is_valid(data)
    edit(data)
    assert not validator.is_valid(data)


def schema_table(schema: dict) -> str:
    """The field table of docs/park-problems.md, made from the shipped schema: one row per field, nested ones dotted."""
    def kind(node: dict) -> str:
        if "const" in node:
            return f"`{json.dumps(node['const'])}`"
        if "enum" in node:
            return " or ".join(f"`{json.dumps(v)}`" for v in node["enum"])
        if "prefixItems" in node:
            return f"array of {len(node['prefixItems'])} numbers"
        t = node.get("type", "")
        return " or ".join(t) if isinstance(t, list) else t

    def rows(node: dict, at: str) -> list[str]:
        out = []
        for name, sub in node.get("properties", {}).items():
            required = name in node.get("required", [])
            out.append(f"| `{at}{name}` | {kind(sub)} | {'yes' if required else 'no'} | {sub['description']} |")
            out += rows(sub, f"{at}{name}.")
            if isinstance(sub.get("items"), dict):
                out += rows(sub["items"], f"{at}{name}[].")
        return out

    head = ["| field | type | required | what |", "|---|---|---|---|"]
    return "\n".join(head + rows(schema, "")) + "\n"


def test_the_docs_field_table_is_the_schemas():
    from garage_mj.export.park_problems import SCHEMA

    table = schema_table(json.loads(SCHEMA.read_text()))
    page = (Path(__file__).resolve().parents[1] / "docs" / "park-problems.md").read_text()
    assert table in page, "docs/park-problems.md's field table differs from the schema; paste this:\n" + table
