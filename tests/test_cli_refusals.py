"""Every command refuses bad input before its first write: exit status 2, one line, no file created or changed.

One table, :data:`BAD`, holds for every (sub)command of ``garage-mj`` the kinds of bad argument it takes: a
missing file, a file of the wrong kind, a folder where a file belongs or a file where a folder belongs, a
number that is negative, zero, NaN, infinite or huge, an id the library lacks, a setting that does not fit
another. Each row runs through the real CLI in-process, in a folder holding good inputs; the test asserts the
exit status, the one error line, and that the folder is byte for byte as it was. A command the table does not
cover fails :func:`test_every_command_has_rows`, so a new command cannot skip it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from garage_mj.cli import build_parser
from garage_mj.export.pack import export_pack
from garage_mj.generation.library import Library
from garage_mj.grid.painters import paint_garage
from tests._cli import one_line_error, snapshot

LIB, PACKS, GARAGE, TEXT, FOLDER, FILE, MISSING, OUT = ("lib.sqlite", "packs", "garage.json", "notes.txt", "folder",
                                                       "a_file", "missing.json", "out")
BAD_LAYOUT = "bad_layout.toml"  # a park geometry file with an unknown key
CASE, CROSSED = "Case1.csv", "crossed.csv"  # a TPCAP case; one whose obstacle crosses itself
TINY = ["--map", "tiny_7x11"]
GEN = ["generate", *TINY, "--difficulty", "0.2", "0.8", "--count", "1", "--library", "new.sqlite", "--no-progress"]
TRAIN = ["train", *TINY, "--timesteps", "200", "--out", OUT, "--no-progress"]
CRUISE = ["cruise", "--packs", PACKS, "--tests", "1", "--out", OUT, "--quiet"]
HUNT = ["hunt", *TINY, "--out", OUT, "--quiet"]
DEMO = ["demo", "--out", OUT]
TRAIN_DRIVER = ["train-driver", LIB, "--out", OUT, "--no-progress"]

#: (command path, argv, words the error line holds): the bad arguments of every command.
BAD: list[tuple[str, list[str], str]] = [
    ("maps list", ["maps", "list", "extra"], "unrecognized arguments"),
    ("maps validate", ["maps", "validate"], "required"),
    ("maps show", ["maps", "show", "no_such_map"], "no_such_map"),
    ("maps show", ["maps", "show", FOLDER], FOLDER),
    ("demo", [*DEMO, "--timesteps", "-5"], "-5"),
    ("demo", [*DEMO, "--garages", "0"], "0"),
    ("demo", [*DEMO, "--workers", "nan"], "nan"),
    ("demo", [*DEMO, "--workers", "5000"], "5000"),
    ("demo", [*DEMO, "--map", MISSING], MISSING),
    ("demo", ["demo", "--out", FILE], FILE),
    ("export", ["export", "--garage", MISSING, "--out", OUT], MISSING),
    ("export", ["export", "--garage", TEXT, "--out", OUT], TEXT),
    ("export", ["export", "--garage", FOLDER, "--out", OUT], FOLDER),
    ("export", ["export", "--library", LIB, "--ids", "999", "--out", OUT], "999"),
    ("export", ["export", "--library", LIB, "--difficulty", "0.8", "0.2", "--out", OUT], "0.8"),
    ("export", ["export", "--library", LIB, "--limit", "-1", "--out", OUT], "-1"),
    ("export", ["export", "--library", LIB, "--out", FILE], FILE),
    ("export", ["export", "--library", LIB, "--out", OUT, "--park-problems", FILE], FILE),
    ("export", ["export", "--library", LIB, "--out", OUT, "--carla-package", FILE], FILE),
    ("export", ["export", "--library", TEXT, "--out", OUT], TEXT),
    ("export", ["export", "--library", LIB, "--out", OUT, "--vehicle", "van"], "--park-problems"),
    ("export", ["export", "--library", LIB, "--park-problems", OUT, "--vehicle", "truck"], "truck"),
    ("export", ["export", "--library", LIB, "--out", OUT, "--stall", "0"], "--park-problems"),
    ("export", ["export", "--library", LIB, "--park-problems", OUT, "--stall", "9999"], "9999"),
    ("export", ["export", "--library", LIB, "--park-problems", OUT, "--maneuver", "sideways"], "sideways"),
    # park geometry (docs/spec.md section 9): a bay narrower than the car, an angle no block holds, a geometry the
    # garage's blocks cannot hold, bad layout files
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--stall-width", "1.8"], "stall_width (--stall-width)"),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--stall-angle", "30"], "stall angle 30"),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--aisle-width", "4"], "aisle_width (--aisle-width)"),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--stall-depth", "nan"], "stall_depth"),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--slot-length", "3"], "slot_length (--slot-length)"),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--layout", TEXT], TEXT),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--layout", MISSING], MISSING),
    ("export", ["export", "--garage", GARAGE, "--out", OUT, "--layout", BAD_LAYOUT], "unknown key(s) bogus"),
    ("check", ["check", "--library", MISSING], MISSING),
    ("check", ["check", "--library", LIB, "--max-steer", "nan"], "nan"),
    ("check", ["check", "--library", LIB, "--limit", "-1"], "-1"),
    ("check", ["check", "no_such_pack"], "no_such_pack"),
    ("check", ["check", "--library", LIB, "--json", FOLDER], FOLDER),
    ("train", ["train", *TINY, "--timesteps", "-1", "--out", OUT], "-1"),
    ("train", ["train", "--map", MISSING, "--timesteps", "100", "--out", OUT], MISSING),
    ("train", [*TRAIN, "--config", MISSING], MISSING),
    ("train", [*TRAIN, "--config", FOLDER], FOLDER),
    ("train", [*TRAIN, "--checkpoint-every", "0"], "0"),
    ("train", [*TRAIN, "--seed", "nan"], "nan"),
    ("train", ["train", *TINY, "--timesteps", "100", "--out", FILE], FILE),
    ("train", [*TRAIN, "--resume"], OUT),
    ("train", [*TRAIN, "--library", FOLDER], FOLDER),
    ("generate", [*GEN[:6], "--count", "0", *GEN[8:]], "0"),
    ("generate", [*GEN, "--max-seconds", "nan"], "nan"),
    ("generate", [*GEN, "--max-episodes", "-3"], "-3"),
    ("generate", [*GEN, "--model", MISSING], MISSING),
    ("generate", [*GEN, "--model", TEXT], TEXT),
    ("generate", ["generate", *TINY, "--difficulty", "0.8", "0.2", "--count", "1", "--library", "new.sqlite"], "0.8"),
    ("generate", [*GEN[:8], "--library", FOLDER], FOLDER),
    ("generate", [*GEN, "--metric", "route", "--route-model", MISSING], MISSING),
    ("generate", ["generate", "--map", MISSING, *GEN[3:]], MISSING),
    ("library ls", ["library", "ls", MISSING], MISSING),
    ("library ls", ["library", "ls", TEXT], TEXT),
    ("library ls", ["library", "ls", LIB, "--limit", "-1"], "-1"),
    ("library ls", ["library", "ls", LIB, "--difficulty", "0.9", "0.1"], "0.9"),
    ("library show", ["library", "show", LIB, "999"], "999"),
    ("library show", ["library", "show", LIB, "abc"], "abc"),
    ("library stats", ["library", "stats", MISSING], MISSING),
    ("library sample", ["library", "sample", LIB, "-n", "-1"], "-1"),
    ("library sample", ["library", "sample", LIB, "-n", "nan"], "nan"),
    ("library export-json", ["library", "export-json", LIB, "--out", FOLDER], FOLDER),
    ("library export-json", ["library", "export-json", MISSING, "--out", "garages.json"], MISSING),
    ("library rate", ["library", "rate", LIB, "--workers", "0"], "0"),
    ("library rate", ["library", "rate", LIB, "--model", MISSING], MISSING),
    ("plot convergence", ["plot", "convergence", MISSING], MISSING),
    ("plot convergence", ["plot", "convergence", FOLDER, "--smooth", "0"], "0"),
    ("plot heatmap", ["plot", "heatmap", "--library", MISSING, *TINY], MISSING),
    ("plot heatmap", ["plot", "heatmap", "--library", LIB, "--map", "no_such_map"], "no_such_map"),
    ("plot driver", ["plot", "driver", MISSING], MISSING),
    ("show", ["show", "999", "--library", LIB], "999"),
    ("show", ["show", "1", "--library", LIB, "--png", FOLDER], FOLDER),
    ("cruise", ["cruise", "--packs", MISSING, "--out", OUT], MISSING),
    ("cruise", [*CRUISE[:3], "--tests", "0", *CRUISE[5:]], "0"),
    ("cruise", [*CRUISE, "--driver", "no_such_driver"], "no_such_driver"),
    ("cruise", [*CRUISE, "--driver", "park_assist", "--task", "park", "--stall", "999"], "999"),
    ("cruise", [*CRUISE, "--driver", "park_assist", "--task", "cruise"], "park_assist"),
    ("cruise", [*CRUISE, "--park-model", MISSING], "--park-model"),  # a cruise run has no park difficulty
    ("cruise", [*CRUISE, "--driver", "park_assist", "--task", "park", "--park-model", MISSING], MISSING),
    ("cruise", [*CRUISE, "--driver", "park_assist", "--task", "park", "--park-model", TEXT], TEXT),
    ("cruise", [*CRUISE, "--occupancy", "2"], "2"),
    ("cruise", [*CRUISE, "--driver", "learned:park", "--task", "park", "--guide-replans", "11"], "11"),
    ("cruise", [*CRUISE, "--vehicle", "truck"], "truck"),
    ("cruise", [*CRUISE, "--parked-fleet", "random"], "random"),
    ("cruise", [*CRUISE, "--parked-jitter", "0.8"], "0.8"),
    ("cruise", [*CRUISE, "--parked-jitter", "nan"], "nan"),
    ("cruise", ["cruise", "--cases", GARAGE, "--vehicle", "van", "--out", OUT], "--vehicle"),
    ("cruise", [*CRUISE, "--test-timeout", "nan"], "nan"),
    ("cruise", [*CRUISE, "--workers", "-1"], "-1"),
    ("cruise", [*CRUISE, "--scenario", MISSING], MISSING),
    ("cruise", [*CRUISE[:5], "--out", FILE], FILE),
    ("cruise", ["cruise", "--library", LIB, "--ids", "999", "--tests", "1", "--out", OUT], "999"),
    ("cruise", [*CRUISE, "--driver", f"learned:{TEXT}"], TEXT),
    ("cruise", [*CRUISE, "--stall-width", "1.8"], "stall_width (--stall-width)"),
    ("cruise", [*CRUISE, "--aisle-width", "6.5"], "another park geometry"),  # the pack was built in the default
    ("cruise", [*CRUISE, "--layout", BAD_LAYOUT], "unknown key(s) bogus"),
    ("cruise", ["cruise", "--cases", MISSING, "--out", OUT], MISSING),
    ("cruise", ["cruise", "--cases", TEXT, "--out", OUT], TEXT),
    ("cruise", ["cruise", "--cases", GARAGE, "--out", OUT], GARAGE),
    ("cruise", ["cruise", "--cases", FOLDER, "--out", OUT], FOLDER),
    ("cruise", ["cruise", "--cases", CROSSED, "--out", OUT], CROSSED),
    ("cruise", ["cruise", "--cases", CASE, CASE, "--out", OUT], "same case"),
    ("cruise", ["cruise", "--cases", CASE, "--stall", "1", "--out", OUT], "--stall"),
    ("cruise", ["cruise", "--cases", CASE, "--vehicle", "van", "--out", OUT], "--vehicle"),
    ("cruise", ["cruise", "--cases", CASE, "--task", "avp", "--out", OUT], "--task avp"),
    ("cruise", ["cruise", "--cases", CASE, "--driver", "no_such_driver", "--out", OUT], "no_such_driver"),
    ("cruise", ["cruise", "--cases", CASE, "--out", FILE], FILE),
    ("cruise", ["cruise", "--library", LIB, "--tests", "1", "--out", OUT, "--stall-angle", "0", "--task", "park",
                "--slot-length", "4.2"], "slot_length (--slot-length)"),
    ("cruise", ["cruise", "--library", LIB, "--tests", "1", "--out", OUT, "--stall-angle", "75"], "stall angle 75"),
    ("hunt", ["hunt", "--map", "no_such_map", "--out", OUT], "no_such_map"),
    ("hunt", ["hunt", "--library", MISSING, "--out", OUT], MISSING),
    ("hunt", [*HUNT, "--budget", "0"], "0"),
    ("hunt", [*HUNT, "--driver", "no_such_driver"], "no_such_driver"),
    ("hunt", [*HUNT, "--driver", "park_assist", "--task", "cruise"], "park_assist"),
    ("hunt", [*HUNT, "--occupancy", "-0.5"], "-0.5"),
    ("hunt", [*HUNT, "--geometries", "tight"], "--geometries"),  # a cruise hunt searches no park geometry
    ("hunt", [*HUNT, "--driver", "park_assist", "--task", "park", "--geometries", "tight,narrow"], "narrow"),
    ("hunt", [*HUNT[:3], "--out", FILE], FILE),
    ("train-driver", [*TRAIN_DRIVER, "--iterations", "0"], "0"),
    ("train-driver", [*TRAIN_DRIVER, "--workers", "100000000000"], "100000000000"),
    ("train-driver", [*TRAIN_DRIVER, "--config", MISSING], MISSING),
    ("train-driver", [*TRAIN_DRIVER, "--map", "no_such_map"], "no_such_map"),
    ("train-driver", ["train-driver", MISSING, "--out", OUT], MISSING),
    ("train-driver", [*TRAIN_DRIVER, "--validation", MISSING], MISSING),
    ("train-driver", [*TRAIN_DRIVER, "-n", "0"], "0"),
    ("train-driver", [*TRAIN_DRIVER, "--resume"], OUT),
    ("train-driver", ["train-driver", LIB, "--out", FILE], FILE),
    ("train-driver", [*TRAIN_DRIVER, "--difficulty", "0.9", "0.1"], "0.9"),
    ("difficulty fit", ["difficulty", "fit", MISSING, "--out", "model.json"], MISSING),
    ("difficulty fit", ["difficulty", "fit", FOLDER, "--out", FOLDER], FOLDER),
    ("difficulty score", ["difficulty", "score", MISSING], MISSING),
    ("difficulty fit", ["difficulty", "fit", "--task", "park", FOLDER, "--out", "model.json"], FOLDER),
    ("difficulty fit", ["difficulty", "fit", "--task", "park", FOLDER, "--out", "m.json", "--features", "bogus"], "bogus"),
    ("difficulty score", ["difficulty", "score", "--task", "park", MISSING], MISSING),
    ("difficulty score", ["difficulty", "score", "--task", "park", FOLDER, "--model", MISSING], FOLDER),
    ("difficulty score", ["difficulty", "score", FOLDER, "--model", MISSING], MISSING),
    ("difficulty show", ["difficulty", "show", MISSING], MISSING),
    ("difficulty show", ["difficulty", "show", LIB, "-n", "0"], "0"),
]


def _commands(parser: argparse.ArgumentParser, path: str = "") -> list[str]:
    """Every leaf (sub)command of ``parser`` as its words (``library ls``)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [path]
    return [c for name, p in subs[0].choices.items() for c in _commands(p, f"{path} {name}".strip())]


def test_every_command_has_rows():
    covered = {command for command, _, _ in BAD}
    assert set(_commands(build_parser())) <= covered, sorted(set(_commands(build_parser())) - covered)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """A folder of good inputs (a library of 3 tiny garages, a pack, a garage JSON) and a few wrong ones."""
    root = tmp_path_factory.mktemp("inputs")
    with Library(root / LIB) as lib:
        for seed in range(3):
            lib.add(paint_garage("tiny_7x11", seed=seed), map="tiny_7x11", run="r", seed=0, episode=seed,
                    timestep=seed)
    garage = paint_garage("tiny_7x11", seed=1)
    export_pack(garage, root / PACKS)
    (root / GARAGE).write_text(garage.to_json())
    (root / TEXT).write_text("not a garage\n")
    (root / BAD_LAYOUT).write_text("stall_width = 2.3\nbogus = 1\n")
    (root / FILE).write_text("a file where a folder belongs\n")
    (root / FOLDER).mkdir()
    (root / CASE).write_text("0,0,0,10,0,0,1,4,12,2,14,2,14,-2,12,-2\r\n")
    (root / CROSSED).write_text("0,0,0,10,0,0,1,4,3,3,7,6,7,3,3,5\r\n")
    return root


@pytest.mark.parametrize(("command", "argv", "said"), BAD, ids=[" ".join(argv) for _, argv, _ in BAD])
def test_a_bad_argument_is_one_line_and_writes_nothing(command, argv, said, inputs, monkeypatch, capsys):
    monkeypatch.chdir(inputs)
    before = snapshot(inputs)
    line = one_line_error(capsys, argv)
    assert said in line, line
    assert snapshot(inputs) == before, "the refused command wrote into the folder"
