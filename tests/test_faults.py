"""Fuzz and fault suite: bad input gets one line and changes nothing; a crash or a second run loses nothing.

Malformed garages, maps, manifests, configs and library rows go through the real CLI and must
give one error line, a non-zero exit, no traceback, and leave every file as it was. Real
``kill -9`` of ``cruise`` (during its first test) and of ``export --library`` (mid-way) are
resumed and compared with uninterrupted runs; two cruise runs into one folder are started at
once. Tiny 7x11 garages and a handful of tests keep it fast.
"""

from __future__ import annotations

import copy
import csv
import gc
import hashlib
import io
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
import weakref
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from garage_mj.cli import main
from garage_mj.driving.results import TEST_COLUMNS, read_tests
from garage_mj.export.pack import PackError, export_pack, load_pack
from garage_mj.generation.library import Library, LibraryError
from garage_mj.grid.garage import Garage, MapError, validate_garage
from garage_mj.grid.map_io import load_map, parse_map_text
from garage_mj.grid.painters import paint_garage
from garage_mj.grid.rules import apply_stall_rule
from tests._cli import one_line_error, snapshot

CLI = str(Path(sys.executable).with_name("garage-mj"))
FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


# -- helpers ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny() -> Garage:
    return paint_garage("tiny_7x11", seed=1)


@pytest.fixture(scope="module")
def pack_dir(tiny, tmp_path_factory) -> Path:
    """A folder with one good pack of ``tiny`` (copied, never changed, by the tests)."""
    out = tmp_path_factory.mktemp("packs")
    export_pack(tiny, out)
    return out


def copy_packs(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, symlinks=True)
    return dst


def make_library(path: Path, n: int) -> Path:
    with Library(path) as lib:
        seed = 0
        while lib.count() < n:
            lib.add(paint_garage("tiny_7x11", seed=seed), map="tiny_7x11", run="r", seed=0, episode=seed,
                    timestep=seed)
            seed += 1
    return path


# -- malformed garages ------------------------------------------------------------------------------
def _with_square(g: Garage) -> dict:
    """``g`` with one 2x2 road square painted in (stall rule reapplied, so only the 2x2 rule breaks)."""
    grid = g.grid.copy()
    for r in range(1, grid.shape[0] - 2):
        for c in range(1, grid.shape[1] - 2):
            if (g.initial[r:r + 2, c:c + 2] == 0).all() and (grid[r:r + 2, c:c + 2] == 1).sum() >= 2:
                grid[r:r + 2, c:c + 2] = 1
                d = json.loads(g.to_json())
                d["grid"] = apply_stall_rule(grid, g.six_stall_axis).tolist()
                return d
    raise AssertionError("no place for a square")


def _mutated(g: Garage, how: str):
    d = json.loads(g.to_json())
    if how in ("str", "float", "bool", "big", "negative"):
        d["grid"][1][1] = {"str": "3", "float": 1.5, "bool": True, "big": 2**70, "negative": -1}[how]
        return json.dumps(d)
    if how == "infinity":
        return json.dumps(d).replace('"grid": [[2', '"grid": [[Infinity', 1)
    if how == "huge_int":  # over Python's 4,300-digit limit for converting text to int
        return json.dumps(d).replace('"grid": [[2', '"grid": [[' + "7" * 5000, 1)
    if how == "deep":
        return "[" * 100_000 + "]" * 100_000
    if how == "not_utf8":
        return b'{"name": "\xff\xfe", "grid": []}'
    if how == "long_name":
        d["name"] = "x" * 5000
        return json.dumps(d)
    if how in ("escape_name", "newline_name", "bidi_name"):
        d["name"] = {"escape_name": "\x1b[2Jgone", "newline_name": "two\nlines", "bidi_name": "abc\u202edef"}[how]
        return json.dumps(d)
    if how == "square":
        return json.dumps(_with_square(g))
    if how == "unconnected":
        d["grid"] = load_map("tiny_7x11").grid.tolist()
        return json.dumps(d)
    if how == "stall_rule":
        grid = np.array(d["grid"])
        grid[grid == 3] = 0
        d["grid"] = grid.tolist()
        return json.dumps(d)
    if how == "huge":
        big = np.zeros((1000, 1000), int)
        big[[0, -1], :] = 2
        big[:, [0, -1]] = 2
        big[0, 5], big[-1, 5] = 8, 7
        return json.dumps({"name": "huge", "grid": big.tolist(), "initial": big.tolist()})
    raise ValueError(how)


BAD_GARAGES = {"str": "not a block code", "float": "not a block code", "bool": "not a block code",
               "big": "not a block code", "negative": "not a block code", "infinity": "not a block code",
               "deep": "nested too deeply", "not_utf8": "not valid JSON", "long_name": "longer than 128",
               "huge_int": "row 0, column 0: 77777777... (5000 digits) is not a block code (an integer 0-9)",
               "escape_name": "control character", "newline_name": "control character",
               "bidi_name": "control character",
               "square": "2x2 square", "unconnected": "no road joins", "stall_rule": "stall rule",
               "huge": "larger than 64x64"}


@pytest.mark.parametrize("how", sorted(BAD_GARAGES))
def test_export_refuses_a_bad_garage_in_one_line(tiny, tmp_path, capsys, how):
    text = _mutated(tiny, how)
    src = tmp_path / "g.json"
    src.write_bytes(text if isinstance(text, bytes) else text.encode())
    out = tmp_path / "packs"
    before = snapshot(src)
    line = one_line_error(capsys, ["export", "--garage", str(src), "--out", str(out), "--quiet"])
    assert BAD_GARAGES[how] in line and str(src) in line
    assert snapshot(src) == before and not out.exists()


@FUZZ
@given(cell=st.one_of(st.integers(), st.floats(allow_nan=True, allow_infinity=True), st.booleans(), st.text(max_size=3),
                      st.none(), st.lists(st.integers(0, 9), max_size=2)),
       r=st.integers(0, 6), c=st.integers(0, 10))
def test_any_json_cell_is_a_garage_or_a_map_error(tiny, cell, r, c):
    d = json.loads(tiny.to_json())
    d["grid"][r][c] = cell
    try:
        g = Garage.from_json(json.dumps(d))
    except MapError as exc:
        assert "\n" not in str(exc)
        return
    assert type(cell) is int and 0 <= cell <= 9 and g.grid[r, c] == cell
    try:
        validate_garage(g)
    except MapError:
        pass


@FUZZ
@given(text=st.text(alphabet="0123456789²¹٣ \t\n#x-", max_size=200))
def test_any_map_text_parses_or_is_a_map_error(text):
    try:
        grid, _ = parse_map_text(text, "fuzz.txt")
    except MapError as exc:
        assert str(exc).startswith("fuzz.txt") and "\n" not in str(exc)
        return
    assert grid.dtype == np.int8 and ((grid >= 0) & (grid <= 9)).all()


def test_map_files_with_odd_tokens_or_bytes_are_one_line(tmp_path, capsys):
    for name, data in (("sup.txt", "2 2 8 2\n2 ² 0 2\n2 7 2 2\n".encode()), ("latin1.txt", b"2 2 \xe9 2\n"),
                       ("big.txt", ("0 " * 70 + "\n").encode() * 3)):
        f = tmp_path / name
        f.write_bytes(data)
        line = one_line_error(capsys, ["maps", "show", str(f)])
        assert str(f) in line


# -- malformed configs and arguments -----------------------------------------------------------------
BAD_CONFIGS = ["view_size = 4", "view_size = 0", "view_size = -3", "max_errors = -1", "learning_rate = -0.001",
               "learning_rate = nan", "learning_rate = inf", "net_arch = 256", "buffer_size = 1e14",
               "buffer_size = 100000000000000", "max_grad_norm = -1.0", "gamma = 2.0", "bogus_key = 1",
               "learning_rate = ", "\xff", "a = " + "[" * 100_000 + "]" * 100_000]


@pytest.mark.parametrize("line", BAD_CONFIGS, ids=lambda line: line[:24])
def test_train_refuses_a_bad_config_in_one_line(tmp_path, capsys, line):
    cfg = tmp_path / "dqn.toml"
    cfg.write_bytes(line.encode("latin-1"))
    out = tmp_path / "run"
    msg = one_line_error(capsys, ["train", "--map", "tiny_7x11", "--timesteps", "10", "--seed", "0",
                                  "--out", str(out), "--config", str(cfg)])
    assert str(cfg) in msg
    assert not out.exists()


BAD_DRIVER_CONFIGS = ["val_tests = -3", "learning_rate = inf", "learning_rate = nan", "net_arch = [0]",
                      "hunt_share = 5.0", "torch_threads = -1", 'net_arch = ["a", "b"]', 'curriculum = "x"',
                      "iterations = 1.5", "cnn_channels = [8, 16]", "stop_weight = 0.0", "occupancy = -0.1"]


@pytest.mark.parametrize("line", BAD_DRIVER_CONFIGS)
def test_train_driver_refuses_a_bad_config_naming_file_key_value_and_range(tmp_path, capsys, line):
    cfg = tmp_path / "driver.toml"
    cfg.write_text(line + "\n")
    out = tmp_path / "run"
    msg = one_line_error(capsys, ["train-driver", "tiny_7x11", "-n", "1", "--config", str(cfg), "--out", str(out),
                                  "--no-progress"])
    key, value = (part.strip() for part in line.split("="))
    assert str(cfg) in msg and f"{key} = {value} is not allowed: {key} must be " in msg, msg
    assert not out.exists()


def test_actor_counts_are_capped_in_one_line(pack_dir, tmp_path, capsys):
    from garage_mj.driving.actors.config import MAX_ACTORS

    out = tmp_path / "c"
    msg = one_line_error(capsys, ["cruise", "--packs", str(pack_dir), "--tests", "1", "--pedestrians", "100000",
                                  "--out", str(out), "--quiet"])
    assert "pedestrians = 100000" in msg and f"[0, {MAX_ACTORS}]" in msg
    scenario = tmp_path / "scenario.toml"
    scenario.write_text(f"[scenario]\nclutter = {MAX_ACTORS + 1}\n")
    msg = one_line_error(capsys, ["cruise", "--packs", str(pack_dir), "--tests", "1", "--scenario", str(scenario),
                                  "--out", str(out), "--quiet"])
    assert str(scenario) in msg and f"clutter = {MAX_ACTORS + 1}" in msg
    assert not out.exists()


def test_bad_arguments_are_one_line(tmp_path, capsys, pack_dir):
    lib = make_library(tmp_path / "lib.sqlite", 1)
    a_file = tmp_path / "file"
    a_file.write_text("x")
    before = snapshot(tmp_path)
    one_line_error(capsys, ["cruise", "--packs", str(pack_dir), "--seed", "-1", "--out", str(tmp_path / "c")])
    line = one_line_error(capsys, ["cruise", "--packs", str(pack_dir), "--tests", "1", "--driver", "waypoint",
                                   "--out", str(a_file), "--quiet"])
    assert str(a_file) in line and "is a file" in line
    line = one_line_error(capsys, ["export", "--library", str(lib), "--out", str(a_file), "--quiet"])
    assert str(a_file) in line
    assert "no garage with id" in one_line_error(capsys, ["library", "show", str(lib), str(10**23)])
    assert snapshot(tmp_path) == before


def test_a_full_disk_is_one_line(tmp_path, capsys):
    """/dev/full answers every write with ENOSPC, as a full disk does (and stays a device)."""
    full = Path("/dev/full")
    if not full.exists():
        pytest.skip("no /dev/full on this system")
    lib = make_library(tmp_path / "lib.sqlite", 1)
    line = one_line_error(capsys, ["library", "export-json", str(lib), "--out", str(full)])
    assert "/dev/full" in line and "disk space" in line
    assert full.is_char_device()


# -- manifests -------------------------------------------------------------------------------------
def _rehash(pack: Path, **changes) -> None:
    m = json.loads((pack / "manifest.json").read_text())
    m.update(changes)
    (pack / "manifest.json").write_text(json.dumps(m))


def _break(pack: Path, how: str, outside: Path) -> None:
    m = json.loads((pack / "manifest.json").read_text())
    if how == "not_utf8":
        (pack / "manifest.json").write_bytes(b"\xff\xfe{")
    elif how == "files_list":
        _rehash(pack, files=sorted(m["files"]))
    elif how == "dotdot":
        _rehash(pack, files={**m["files"], "../outside.txt": hashlib.sha256(outside.read_bytes()).hexdigest()})
    elif how == "absolute":
        _rehash(pack, files={**m["files"], str(outside): hashlib.sha256(outside.read_bytes()).hexdigest()})
    elif how == "symlink":
        (pack / "preview.png").unlink()
        (pack / "preview.png").symlink_to(outside)
        _rehash(pack, files={**m["files"], "preview.png": hashlib.sha256(outside.read_bytes()).hexdigest()})
    elif how == "swapped":
        other = paint_garage("tiny_7x11", seed=2)
        (pack / "garage.json").write_text(other.to_json())
        files = {**m["files"], "garage.json": hashlib.sha256((pack / "garage.json").read_bytes()).hexdigest()}
        _rehash(pack, files=files, garage_hash=other.canonical_hash(), name=other.name)
    elif how == "deep":
        (pack / "manifest.json").write_text("[" * 100_000)
    else:
        raise ValueError(how)


@pytest.mark.parametrize("how", ["not_utf8", "files_list", "dotdot", "absolute", "symlink", "swapped", "deep"])
def test_a_doctored_pack_is_refused_and_later_exports_work(tiny, pack_dir, tmp_path, capsys, how):
    packs = copy_packs(pack_dir, tmp_path / "packs")
    pack = next(p for p in packs.iterdir() if p.is_dir())
    outside = tmp_path / "outside.txt"
    outside.write_text("not part of any pack")
    _break(pack, how, outside)
    with pytest.raises(PackError, match=f"pack {pack}"):
        load_pack(pack)
    before = snapshot(packs, outside)
    line = one_line_error(capsys, ["cruise", "--packs", str(packs), "--tests", "1", "--driver", "waypoint",
                                   "--out", str(tmp_path / "cruise"), "--quiet"])
    assert str(pack) in line
    assert snapshot(packs, outside) == before
    # a later export into the folder still works: the bad pack is listed as skipped, then rebuilt
    src = tmp_path / "g.json"
    src.write_text(paint_garage("tiny_7x11", seed=4).to_json())
    assert main(["export", "--garage", str(src), "--out", str(packs), "--quiet"]) == 0
    index = json.loads((packs / "index.json").read_text())
    assert [s["folder"] for s in index["skipped"]] == [pack.name]
    (tmp_path / "t.json").write_text(tiny.to_json())
    assert main(["export", "--garage", str(tmp_path / "t.json"), "--out", str(packs), "--quiet"]) == 0
    load_pack(pack)  # repaired
    assert outside.read_text() == "not part of any pack"
    capsys.readouterr()


# -- library rows ----------------------------------------------------------------------------------
def _corrupt(lib: Path, how: str) -> None:
    con = sqlite3.connect(lib)
    grid = con.execute("SELECT grid FROM garages WHERE id = 1").fetchone()[0]
    if how == "truncated_grid":
        con.execute("UPDATE garages SET grid = ? WHERE id = 1", (grid[: len(grid) // 2],))
    elif how == "text_grid":
        con.execute("UPDATE garages SET grid = 'hello' WHERE id = 1")
    elif how == "text_difficulty":
        con.execute("UPDATE garages SET difficulty = 'hard' WHERE id = 1")
    elif how == "flipped_digit":  # a stall code 3 -> 4: still a well-formed grid, but not the stored garage
        i = grid.index("3")
        con.execute("UPDATE garages SET grid = ? WHERE id = 1", (grid[:i] + "4" + grid[i + 1:],))
    elif how == "stale_metrics":
        con.execute("UPDATE garages SET stalls = stalls + 1 WHERE id = 1")
    con.commit()
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()


@pytest.mark.parametrize("how", ["truncated_grid", "text_grid", "text_difficulty", "flipped_digit", "stale_metrics"])
def test_a_damaged_library_row_is_refused_with_its_id(tmp_path, capsys, how):
    lib = make_library(tmp_path / "lib.sqlite", 2)
    _corrupt(lib, how)
    before = snapshot(tmp_path)
    for argv in (["export", "--library", str(lib), "--out", str(tmp_path / "packs"), "--quiet"],
                 ["cruise", "--library", str(lib), "--tests", "1", "--driver", "waypoint",
                  "--out", str(tmp_path / "cruise"), "--quiet"],
                 ["library", "rate", str(lib), "--quiet"]):  # rates nothing of a library with an altered row
        line = one_line_error(capsys, argv)
        assert "row id 1" in line and str(lib) in line
    if how == "text_difficulty":  # aggregates and sampling would mix text into numbers
        for argv in (["library", "stats", str(lib)], ["library", "sample", str(lib), "-n", "1"],
                     ["plot", "heatmap", "--library", str(lib), "--map", "tiny_7x11", "--out", str(tmp_path / "h.png")]):
            assert "row id 1" in one_line_error(capsys, argv)
    if how in ("truncated_grid", "text_grid", "text_difficulty"):
        assert "row id 1" in one_line_error(capsys, ["library", "ls", str(lib)])
    else:  # well-formed rows still list (the check that recomputes them runs before export and cruise)
        assert main(["library", "ls", str(lib)]) == 0
    capsys.readouterr()
    assert snapshot(tmp_path) == before  # nothing written, not even SQLite's -wal/-shm


@pytest.mark.parametrize("column", ["map", "run"])
def test_a_library_name_with_a_control_character_is_refused_with_its_id(tmp_path, capsys, column):
    lib = make_library(tmp_path / "lib.sqlite", 2)
    con = sqlite3.connect(lib)
    con.execute(f"UPDATE garages SET {column} = ? WHERE id = 2", ("\x1b[2Jgone\nx",))
    con.commit()
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()
    before = snapshot(tmp_path)
    argvs = [["library", "ls", str(lib)], ["library", "show", str(lib), "2"],
             ["export", "--library", str(lib), "--out", str(tmp_path / "packs"), "--quiet"]]
    if column == "map":  # listed per map without reading the rows
        argvs.append(["library", "stats", str(lib)])
    for argv in argvs:
        line = one_line_error(capsys, argv)
        assert "row id 2" in line and "control character" in line and str(lib) in line
    assert snapshot(tmp_path) == before
    with Library(tmp_path / "new.sqlite") as fresh, pytest.raises(LibraryError, match="control character"):
        fresh.add(paint_garage("tiny_7x11", seed=1), map="tiny_7x11", run="a\x07b", seed=0, episode=0, timestep=0)


def test_a_map_file_name_with_a_control_character_is_one_line(tmp_path, capsys):
    f = tmp_path / "m\x1b[2J.txt"
    f.write_text(load_map("tiny_7x11").to_text())
    line = one_line_error(capsys, ["maps", "show", str(f)])
    assert "control character" in line and "rename the file" in line
    assert main(["maps", "validate", str(f)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("INVALID") and "\x1b" not in out


def test_a_pack_folder_name_with_a_control_character_is_one_line(pack_dir, tmp_path, capsys):
    packs = copy_packs(pack_dir, tmp_path / "packs")
    pack = next(p for p in packs.iterdir() if p.is_dir())
    pack.rename(packs / ("\x1b[2J" + pack.name))
    before = snapshot(packs)
    line = one_line_error(capsys, ["cruise", "--packs", str(packs), "--tests", "1", "--driver", "waypoint",
                                   "--out", str(tmp_path / "cruise"), "--quiet"])
    assert "control character" in line and "rename it" in line
    assert snapshot(packs) == before and not (tmp_path / "cruise").exists()


def _unprivileged(argv: list[str], home: Path) -> subprocess.CompletedProcess:
    """Run the CLI as a user that write permissions apply to (``nobody`` via setpriv when we are root).

    ``nobody`` keeps CAP_DAC_READ_SEARCH (read and search only), so it can reach the checkout's
    virtualenv wherever the clone lies (``mktemp -d`` folders are 0700); every write is still
    checked against the permissions, which is what these tests are about.
    """
    env = {**os.environ, "HOME": str(home), "MPLCONFIGDIR": str(home)}
    prefix: list[str] = []
    if os.geteuid() == 0:
        if not shutil.which("setpriv"):
            pytest.skip("running as root without setpriv: permissions cannot be tested")
        prefix = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups",
                  "--inh-caps=+dac_read_search", "--ambient-caps=+dac_read_search"]
    return subprocess.run([*prefix, CLI, *argv], capture_output=True, text=True, env=env, timeout=300)


@pytest.fixture
def shared_tmp():
    """A temp folder other users may enter (pytest's tmp_path is private to its owner)."""
    path = Path(tempfile.mkdtemp(prefix="garage_mj_faults_"))
    os.chmod(path, 0o777)
    yield path
    for p in path.rglob("*"):
        if p.is_dir() and not p.is_symlink():
            os.chmod(p, 0o755)
    shutil.rmtree(path)


def test_read_only_library_lists_and_read_only_out_is_one_line(shared_tmp, tiny):
    folder = shared_tmp / "ro"
    folder.mkdir()
    lib = make_library(folder / "library.sqlite", 2)
    garage = folder / "g.json"
    garage.write_text(tiny.to_json())
    os.chmod(lib, 0o444)
    os.chmod(folder, 0o555)
    before = snapshot(folder)
    done = _unprivileged(["library", "ls", str(lib)], shared_tmp)
    assert done.returncode == 0 and "2 garage(s)" in done.stdout, done.stderr
    for argv in (["export", "--garage", str(garage), "--out", str(folder / "packs"), "--quiet"],
                 ["export", "--library", str(lib), "--out", str(folder), "--quiet"]):
        done = _unprivileged(argv, shared_tmp)
        err = [ln for ln in done.stderr.splitlines() if ln.startswith("garage-mj")]
        assert done.returncode == 2 and "Traceback" not in done.stderr and len(err) == 1, done.stderr
        assert "Permission denied" in err[0] and str(folder) in err[0]
    assert snapshot(folder) == before


@pytest.mark.parametrize("where", ["file", "folder"])
def test_writing_into_a_read_only_library_is_one_line(shared_tmp, where):
    """``library rate``, ``check --store`` and ``generate`` refuse a read-only library (file or folder) up front."""
    folder = shared_tmp / "ro"
    folder.mkdir()
    lib = make_library(folder / "library.sqlite", 2)
    os.chmod(lib, 0o444 if where == "file" else 0o644)
    if where == "folder":
        os.chmod(folder, 0o555)
    before = snapshot(folder)
    for argv in (["library", "rate", str(lib), "--quiet"], ["check", "--library", str(lib), "--store"],
                 ["generate", "--map", "tiny_7x11", "--difficulty", "0", "1", "--count", "1", "--library", str(lib),
                  "--no-progress"]):
        done = _unprivileged(argv, shared_tmp)
        err = [ln for ln in done.stderr.splitlines() if ln.strip()]
        assert done.returncode == 2 and len(err) == 1, done.stderr
        assert str(lib) in err[0] and "read-only" in err[0] and "writable" in err[0], err[0]
    assert snapshot(folder) == before


def test_a_closed_stdout_ends_quietly(tmp_path):
    """``garage-mj library ls | head -1``: the reader goes away, the command ends without a message."""
    lib = make_library(tmp_path / "lib.sqlite", 2)
    for argv in (["library", "ls", str(lib)], ["maps", "show", "tiny_7x11"], ["--help"]):
        proc = subprocess.Popen([CLI, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        proc.stdout.close()  # before the command writes its first line
        err = proc.stderr.read()
        assert proc.wait(timeout=60) in (0, 141) and err == "", (argv, err)  # 141: as if killed by SIGPIPE


def test_a_read_only_carla_package_target_is_one_line_naming_it(shared_tmp, tiny):
    from garage_mj.export.fbx import fbx_problem

    if fbx_problem() is not None:
        pytest.skip(fbx_problem())
    garage = shared_tmp / "g.json"
    garage.write_text(tiny.to_json())
    (shared_tmp / "ro").mkdir()
    os.chmod(shared_tmp / "ro", 0o555)
    ours = shared_tmp / "pkgs" / "carla"  # a package of ours, read-only: it cannot be moved aside
    assert main(["export", "--garage", str(garage), "--carla-package", str(ours), "--quiet"]) == 0
    os.chmod(shared_tmp / "pkgs", 0o777)
    os.chmod(ours, 0o555)
    before = snapshot(shared_tmp)
    for target in (shared_tmp / "ro" / "carla", ours):
        done = _unprivileged(["export", "--garage", str(garage), "--out", str(shared_tmp / "packs"),
                              "--carla-package", str(target), "--quiet"], shared_tmp)
        err = [ln for ln in done.stderr.splitlines() if ln.strip()]
        assert done.returncode == 2 and len(err) == 1, done.stderr
        assert f"--carla-package {target}:" in err[0] and "read-only" in err[0] and ".tmp" not in err[0], err[0]
    assert snapshot(shared_tmp) == before and sorted(p.name for p in (shared_tmp / "pkgs").iterdir()) == ["carla"]


# -- tests.csv repair ------------------------------------------------------------------------------
def _row(i: int) -> dict[str, str]:
    return {c: f"{c}{i}" for c in TEST_COLUMNS} | {"garage_hash": f"h{i % 3}", "test": str(i), "outcome": "success",
                                                   "wall_s": "0.5", "hit_geom": 'geom "a", b'}


def _csv(rows, header=True) -> str:
    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=TEST_COLUMNS)
    if header:
        w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


@FUZZ
@given(n=st.integers(0, 6), header=st.booleans(), cut=st.integers(0, 400), dup=st.booleans())
def test_read_tests_keeps_every_complete_row(tmp_path, n, header, cut, dup):
    rows = [_row(i) for i in range(n)]
    text = _csv(rows + rows[:1] * dup, header)
    cut = min(cut, len(text))
    torn = text[: len(text) - cut] if cut else text  # a kill -9 tears the end of the file
    path = tmp_path / f"t{n}{header}{cut}{dup}.csv"
    path.write_text(torn)
    got = read_tests(path)
    complete = [r for r in rows if _csv([r], header=False) in torn]
    assert {r["test"] for r in complete} <= {r["test"] for r in got}
    assert len({(r["garage_hash"], r["test"]) for r in got}) == len(got)
    assert all(r in rows for r in got)
    assert path.read_text().startswith(",".join(TEST_COLUMNS) + "\n")  # repaired: header and whole lines
    assert read_tests(path) == got


# -- real kills and concurrent runs ----------------------------------------------------------------
def _spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen([CLI, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(cond, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    t0 = time.monotonic()
    while not cond():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.005)


def _results(path: Path) -> list[tuple]:
    with open(path, newline="") as f:
        return sorted(tuple((k, v) for k, v in r.items() if k != "wall_s") for r in csv.DictReader(f))


def test_kill_9_during_the_first_cruise_test_then_resume(pack_dir, tmp_path):
    out, ref = tmp_path / "killed", tmp_path / "whole"
    args = ["cruise", "--packs", str(pack_dir), "--tests", "3", "--driver", "waypoint", "--quiet"]
    proc = _spawn(*args, "--out", str(out))
    _wait_for(lambda: (out / "tests.csv").exists(), proc)  # written just before the first test starts
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (out / "tests.csv").read_text().startswith(",".join(TEST_COLUMNS) + "\n")  # the header survived
    assert subprocess.run([CLI, *args, "--out", str(out)], capture_output=True).returncode == 0  # not locked
    assert subprocess.run([CLI, *args, "--out", str(ref)], capture_output=True).returncode == 0
    assert _results(out / "tests.csv") == _results(ref / "tests.csv") and len(_results(ref / "tests.csv")) == 3


def test_an_empty_tests_csv_is_repaired_not_mangled(tiny, tmp_path):
    from garage_mj.core.backends import Compute
    from garage_mj.driving.cruise import run_cruise
    from garage_mj.driving.sources import CruiseSettings

    out = tmp_path / "c"
    out.mkdir()
    (out / "tests.csv").write_text("")  # what a kill -9 before the first flush used to leave
    (out / ".summary.csv.k1ll3d.tmp").write_text("half")  # a killed run's atomic-write temp file
    fast = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}
    for _ in range(3):
        run_cruise([tiny], 2, CruiseSettings("waypoint", env=fast), out, compute=Compute(progress=False))
    with open(out / "tests.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["test"] for r in rows] == ["0", "1"]
    assert list(rows[0]) == list(TEST_COLUMNS)
    with open(out / "summary.csv", newline="") as f:
        assert [r["tests"] for r in csv.DictReader(f)] == ["2"]
    assert not (out / ".summary.csv.k1ll3d.tmp").exists()


def test_two_cruise_runs_into_one_folder(pack_dir, tmp_path):
    out = tmp_path / "c"
    args = ["cruise", "--packs", str(pack_dir), "--tests", "12", "--driver", "waypoint", "--quiet", "--out", str(out)]
    a, b = _spawn(*args), _spawn(*args)
    (_, ea), (_, eb) = a.communicate(timeout=300), b.communicate(timeout=300)
    codes = sorted([(a.returncode, ea, b.pid), (b.returncode, eb, a.pid)])
    assert [c for c, _, _ in codes] == [0, 2], codes
    refused, winner = codes[1][1], codes[1][2]
    assert len(refused.strip().splitlines()) == 1 and f"in use by garage-mj cruise (pid {winner})" in refused
    rows = _results(out / "tests.csv")
    assert len(rows) == 12 and len(set(rows)) == 12
    with open(out / "summary.csv", newline="") as f:
        assert [r["tests"] for r in csv.DictReader(f)] == ["12"]


def test_kill_9_mid_export_then_resume(tmp_path):
    lib = make_library(tmp_path / "lib.sqlite", 5)
    out, ref = tmp_path / "killed", tmp_path / "whole"
    args = ["export", "--library", str(lib), "--quiet"]
    proc = _spawn(*args, "--out", str(out))
    _wait_for(lambda: out.is_dir() and any(not p.name.startswith(".") for p in out.iterdir() if p.is_dir()), proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "index.json").exists()  # really killed mid-way
    assert subprocess.run([CLI, *args, "--out", str(out)], capture_output=True).returncode == 0
    assert subprocess.run([CLI, *args, "--out", str(ref)], capture_output=True).returncode == 0
    hidden = [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != ".garage-mj.lock"]
    assert hidden == []  # the killed run's temp folders are gone

    def packs(root: Path) -> dict[str, dict]:
        return {p.name: json.loads((p / "manifest.json").read_text())["files"]
                for p in sorted(root.iterdir()) if p.is_dir()}

    assert packs(out) == packs(ref) and len(packs(ref)) == 5
    assert json.loads((out / "index.json").read_text())["count"] == 5
    for p in out.iterdir():
        if p.is_dir():
            assert p.stat().st_mode & 0o777 == 0o777 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_truncated_cruise_run_json_is_one_line(pack_dir, tmp_path, capsys):
    out = tmp_path / "c"
    out.mkdir()
    (out / "run.json").write_text('{"driver": "wayp')
    (out / "tests.csv").write_text(_csv([_row(0)]))
    before = snapshot(out)
    line = one_line_error(capsys, ["cruise", "--packs", str(pack_dir), "--tests", "1", "--driver", "waypoint",
                                   "--out", str(out), "--quiet"])
    assert str(out / "run.json") in line
    assert {k: v for k, v in snapshot(out).items() if not k.endswith(".lock")} == \
        {k: v for k, v in before.items() if not k.endswith(".lock")}


def test_garage_validation_is_shared_by_export_and_cruise(tiny):
    for how in ("square", "unconnected", "stall_rule"):
        g = Garage.from_json(_mutated(tiny, how))
        with pytest.raises(MapError):
            validate_garage(g)
    assert validate_garage(copy.deepcopy(tiny)) == tiny


def test_demo_with_a_map_path_writes_only_inside_out(tmp_path):
    from garage_mj.reporting.demo import DemoConfig, run_demo

    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "m.txt").write_text(load_map("tiny_7x11").to_text() + "\n")
    before = snapshot(maps)
    out = tmp_path / "out"
    cfg = DemoConfig(map=str((maps / "m.txt").resolve()), timesteps=3000, train_seeds=(0,), garages=1, tests=1,
                     drivers=("waypoint",), workers=1, out=str(out))
    report = run_demo(cfg)  # used to say "stored no usable garage": it looked the library up by the path
    assert report == out / "report.html" and (out / "runs" / "m_s0" / "run.json").is_file()
    assert sorted(p.name for p in maps.iterdir()) == ["m.txt"] and snapshot(maps) == before


@pytest.mark.parametrize("command", ["cruise", "export", "train", "demo"])
def test_every_long_job_refuses_a_locked_out_folder(pack_dir, tmp_path, capsys, command):
    from garage_mj.core.fsutil import FolderLock

    out = tmp_path / "out"
    garage = tmp_path / "g.json"
    garage.write_text(paint_garage("tiny_7x11", seed=1).to_json())
    argv = {"cruise": ["cruise", "--packs", str(pack_dir), "--tests", "1", "--driver", "waypoint", "--quiet"],
            "export": ["export", "--garage", str(garage), "--quiet"],
            "train": ["train", "--map", "tiny_7x11", "--timesteps", "10", "--seed", "0"],
            "demo": ["demo", "--timesteps", "10"]}[command]
    with FolderLock(out, "garage-mj test"):
        before = snapshot(out)
        line = one_line_error(capsys, [*argv, "--out", str(out)])
        assert f"{out} is in use by garage-mj test (pid {os.getpid()})" in line
        assert snapshot(out) == before


@pytest.mark.parametrize("second_removes", [True, False])
def test_a_lock_that_removes_its_file_is_never_held_twice(tmp_path, monkeypatch, second_removes):
    import fcntl

    from garage_mj.core.errors import FolderBusy
    from garage_mj.core.fsutil import LOCK_NAME, FolderLock

    out = tmp_path / "pkg"
    first = FolderLock(out, "garage-mj export", remove=True).acquire()
    real, jobs = fcntl.flock, []

    def first_lets_go_then_third_comes(fd, op):  # between the second job's open and its flock
        if not jobs:
            jobs.append(FolderLock(out, "garage-mj export (third)", remove=True))
            first.release()  # deletes the file the second job has just opened
            jobs[0].acquire()
        return real(fd, op)

    monkeypatch.setattr(fcntl, "flock", first_lets_go_then_third_comes)
    with pytest.raises(FolderBusy, match=r"is in use by garage-mj export \(third\)"):
        FolderLock(out, "garage-mj export", remove=second_removes).acquire()  # not the deleted file's lock
    monkeypatch.undo()
    jobs[0].release()
    assert not (out / LOCK_NAME).exists()  # the lock file goes with the job
    with FolderLock(out, "garage-mj export", remove=True):
        with pytest.raises(FolderBusy, match=f"{out} is in use by garage-mj export"):
            FolderLock(out, "garage-mj export", remove=True).acquire()
    assert not out.exists()  # the folder the locks made goes with the last one, as nothing was written in it


def test_a_lock_leaves_no_folder_it_made_when_nothing_was_written(tmp_path):
    from garage_mj.core.fsutil import FolderLock

    with FolderLock(tmp_path / "a" / "b" / "out", "garage-mj test"):
        pass
    assert os.listdir(tmp_path) == []  # the parents it made go too
    with FolderLock(tmp_path / "kept" / "out", "garage-mj test", remove=True):
        (tmp_path / "kept" / "out" / "result.csv").write_text("x")
    assert os.listdir(tmp_path / "kept" / "out") == ["result.csv"]  # a job's first file keeps its folder
    (tmp_path / "mine").mkdir()
    with FolderLock(tmp_path / "mine", "garage-mj test", remove=True):
        pass
    assert (tmp_path / "mine").is_dir()  # a folder that was there stays


# -- a driver that crashes its process or never returns ---------------------------------------------------
FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}
REPO = Path(__file__).resolve().parents[1]


def _cruise(tiny, out: Path, driver: str, workers: int, tests: int = 1, timeout: float = 120.0):
    from garage_mj.core.backends import Compute
    from garage_mj.driving.cruise import run_cruise
    from garage_mj.driving.sources import CruiseSettings

    return run_cruise([tiny], tests, CruiseSettings(driver, env=FAST, test_timeout=timeout), out,
                      compute=Compute(workers=workers, progress=False), route_model=False)


def test_a_driver_that_segfaults_is_a_driver_crash_and_the_run_ends(tiny, tmp_path):
    """--workers 2: the worker's death is noticed, the test given once more to a fresh worker, then recorded."""
    start = time.monotonic()
    res = _cruise(tiny, tmp_path / "c", "tests._crashing:SegfaultDriver", workers=2)
    assert time.monotonic() - start < 15
    (row,) = res.rows
    assert row["outcome"] == "driver_crash" and row["feasible"] == "" and row["time"] == ""
    assert row["reason"] == ("driver tests._crashing:SegfaultDriver: its process was killed by signal SIGSEGV on "
                             "each of 2 tries")
    assert res.stats["failures"]["driver_crash"] == 1 and res.stats["paper_failures"]["deadlock"] == 1
    assert res.stats["success_pct"] == 0.0 and res.stats["seconds_per_test"] is None
    with open(tmp_path / "c" / "summary.csv", newline="") as f:
        assert [r["driver_crashes"] for r in csv.DictReader(f)] == ["1"]


def test_a_driver_that_segfaults_with_one_worker_names_the_signal_and_the_line(pack_dir, tmp_path):
    """--workers 1 runs the tests in the command's own process: a segfault ends it, saying where."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([CLI, "cruise", "--packs", str(pack_dir), "--tests", "1", "--quiet", "--driver",
                           "tests._crashing:SegfaultDriver", "--out", str(tmp_path / "c")],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == -signal.SIGSEGV
    assert "Segmentation fault" in proc.stderr and "_crashing.py" in proc.stderr and "in act" in proc.stderr


@pytest.mark.parametrize("workers", [1, 2])
def test_a_driver_whose_act_never_returns_is_a_driver_timeout(tiny, tmp_path, workers):
    """The same row with any worker count (wall_s apart): in this process an interval timer stops it, in a pool
    the worker is killed and replaced; the next test still runs."""
    start = time.monotonic()
    res = _cruise(tiny, tmp_path / "c", "tests._crashing:SleepDriver", workers=workers, tests=2, timeout=1.0)
    assert time.monotonic() - start < 15
    assert sorted((r["test"], r["outcome"], r["reason"]) for r in res.rows) == [
        (str(i), "driver_timeout", "driver tests._crashing:SleepDriver: ran past the time limit of 1 s of wall time")
        for i in (0, 1)]
    assert all(1.0 <= float(r["wall_s"]) < 5 for r in res.rows)
    assert res.stats["failures"]["driver_timeout"] == 2 and res.stats["paper_failures"]["timeout"] == 2


class _SlowFinalizer:
    def __del__(self):
        end = time.monotonic() + 0.6
        while time.monotonic() < end:  # the time limit's alarm lands in here
            pass


def _finalizes_then_sleeps(_job):
    obj = _SlowFinalizer()
    del obj
    time.sleep(10)


def test_a_time_limit_running_out_in_a_finalizer_is_not_lost(monkeypatch):
    """An alarm landing in a ``__del__`` would be swallowed there and reported as unraisable (pytest's warning); the
    limit waits for its next alarm and still stops the job, with nothing reported."""
    from garage_mj.core import backends

    lost = []
    monkeypatch.setattr(sys, "unraisablehook", lost.append)
    start = time.monotonic()
    res = backends._limited(_finalizes_then_sleeps, None, 0.3)
    assert isinstance(res, backends.LostJob) and res.kind == "timeout"
    assert time.monotonic() - start < 3 and lost == []


def _slow_gc_callback(phase, info):  # noqa: ARG001
    end = time.monotonic() + 0.6
    while time.monotonic() < end:  # the time limit's alarm lands in here (hypothesis registers such a callback)
        pass


def _collects_then_sleeps(_job):
    gc.collect()  # runs the gc callbacks: one of them slow
    time.sleep(10)


def test_a_time_limit_running_out_in_a_gc_callback_is_not_lost(monkeypatch):
    """The same for a callback of the garbage collector (``gc.callbacks``: hypothesis's pytest plugin keeps one),
    where a raise is swallowed too: the warning a full ``make test`` showed now and then."""
    from garage_mj.core import backends

    lost = []
    monkeypatch.setattr(sys, "unraisablehook", lost.append)
    gc.callbacks.append(_slow_gc_callback)
    try:
        start = time.monotonic()
        res = backends._limited(_collects_then_sleeps, None, 0.3)
    finally:
        gc.callbacks.remove(_slow_gc_callback)
    assert isinstance(res, backends.LostJob) and res.kind == "timeout"
    assert time.monotonic() - start < 3 and lost == []


class _Referent:
    pass


def _slow_weakref_callback(_ref):
    end = time.monotonic() + 0.6
    while time.monotonic() < end:  # a plain weakref callback: no frame says it is one
        pass


def _drops_a_watched_object_then_sleeps(_job):
    obj = _Referent()
    ref = weakref.ref(obj, _slow_weakref_callback)
    del obj  # the callback runs now, from the dealloc: a raise in it is swallowed
    time.sleep(10)
    return ref


def test_a_time_limit_swallowed_where_no_frame_tells_is_not_reported_and_still_stops_the_job(monkeypatch):
    """Where the raise lands in a callback that no frame marks (a weakref callback run by a dealloc in C), Python
    swallows it: it is not reported (the next alarm raises it again) and the job still stops; anything else that
    is unraisable is reported as before."""
    from garage_mj.core import backends

    lost = []
    monkeypatch.setattr(sys, "unraisablehook", lost.append)
    start = time.monotonic()
    res = backends._limited(_drops_a_watched_object_then_sleeps, None, 0.3)
    assert isinstance(res, backends.LostJob) and res.kind == "timeout"
    assert time.monotonic() - start < 3 and lost == [] and sys.unraisablehook == lost.append

    class _Raises:
        def __del__(self):
            raise ValueError("not ours")

    def drop(_job):
        obj = _Raises()
        del obj
        return 1

    assert backends._limited(drop, None, 5.0) == 1
    assert [type(u.exc_value) for u in lost] == [ValueError]


def test_the_test_timeout_is_a_stored_setting_and_old_runs_resume(pack_dir, tmp_path, capsys):
    out = tmp_path / "c"
    args = ["cruise", "--packs", str(pack_dir), "--tests", "1", "--quiet", "--out", str(out), "--driver",
            "tests._crashing:SleepDriver"]
    assert main([*args, "--test-timeout", "0.5", "--workers", "2"]) == 0
    assert "1 driver_timeout: the driver's process died or hung" in capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    assert run["test_timeout"] == 0.5
    assert main(args) == 2 and "test_timeout 0.5 there, 120.0 now" in capsys.readouterr().err
    # a run.json written before the setting existed holds the default: the same command resumes it
    del run["test_timeout"]
    (out / "run.json").write_text(json.dumps(run))
    assert main([*args, "--test-timeout", "120"]) == 0 and "(0 new)" in capsys.readouterr().out
    assert "error: argument --test-timeout: 0 must be a number of seconds > 0" in one_line_error(
        capsys, [*args, "--test-timeout", "0"])


def _children(pid: int) -> list[int]:
    """The process ids whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds the worker processes through /proc")
def test_kill_9_of_a_cruise_worker_is_retried_and_the_run_completes(pack_dir, tmp_path):
    """The run that used to wait for ever: a pool worker killed mid-test; its test runs again, same rows."""
    out, ref = tmp_path / "killed", tmp_path / "whole"
    args = ["cruise", "--packs", str(pack_dir), "--tests", "6", "--driver", "waypoint", "--quiet"]
    proc = _spawn(*args, "--workers", "2", "--out", str(out))
    start = time.monotonic()
    _wait_for(lambda: len((out / "tests.csv").read_text().splitlines()) > 1 if (out / "tests.csv").exists()
              else False, proc)  # a test ended: the workers are up and busy
    workers = [p for p in _children(proc.pid) if "spawn_main" in Path(f"/proc/{p}/cmdline").read_text()]
    assert workers, _children(proc.pid)
    os.kill(workers[0], signal.SIGKILL)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and time.monotonic() - start < 30, err
    assert main([*args, "--out", str(ref)]) == 0
    assert _results(out / "tests.csv") == _results(ref / "tests.csv") and len(_results(ref / "tests.csv")) == 6
