"""Bad numbers and paths given to the commands: exit status 2, one error line, nothing written.

NaN, infinite, negative, zero and huge numbers, missing files, files of the wrong kind and an
output path that is a file or a folder, for the light commands' options (no training, no rollouts).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from garage_mj.cli import build_parser, main
from tests._cli import one_line_error, snapshot

GENERATE = ["generate", "--map", "tiny_7x11", "--difficulty", "0.3", "0.4"]


@pytest.mark.parametrize("option, value, said", [
    ("--max-seconds", "nan", "a number of seconds > 0"),
    ("--max-seconds", "inf", "a number of seconds > 0"),
    ("--max-seconds", "-5", "a number of seconds > 0"),
    ("--max-seconds", "0", "a number of seconds > 0"),
    ("--count", "0", "from 1 to 1,000,000"),
    ("--count", "1000001", "from 1 to 1,000,000"),
    ("--count", "1e12", "from 1 to 1,000,000"),
    ("--count", "1" + "0" * 5000, "from 1 to 1,000,000"),
    ("--max-episodes", "0", "from 1 to 1,000,000,000"),
    ("--max-episodes", "-3", "from 1 to 1,000,000,000"),
    ("--max-episodes", "10000000000", "from 1 to 1,000,000,000"),
    ("--train-timesteps", "0", "from 1 to 1,000,000,000"),
    ("--train-timesteps", "nan", "from 1 to 1,000,000,000"),
    ("--train-timesteps", "99999999999", "from 1 to 1,000,000,000"),
    ("--seed", "-1", "seeds are integers from 0 to 4294967295"),
    ("--difficulty", "nan", "outside [0, 1]"),
])
def test_generate_refuses_a_bad_number_before_it_writes(tmp_path, capsys, option, value, said):
    argv = [*GENERATE, "--count", "2", "--library", str(tmp_path / "l.sqlite")]
    if option == "--difficulty":
        argv[argv.index("--difficulty") + 1] = value
    elif option == "--count":
        argv[argv.index("--count") + 1] = value
    else:
        argv += [option, value]
    line = one_line_error(capsys, argv)
    assert line.startswith("garage-mj generate: error: argument ") and option in line and said in line, line
    assert list(tmp_path.iterdir()) == []


def test_generate_declares_its_bounds_in_its_help(capsys):
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "1 to 1,000,000)" in text  # --count
    assert "seconds > 0" in text  # --max-seconds


def test_the_cli_bounds_are_the_generators():
    from garage_mj.cli import generate as cli
    from garage_mj.generation import generator

    assert (cli.MAX_COUNT, cli.MAX_EPISODES) == (generator.MAX_COUNT, generator.MAX_EPISODES)


@pytest.mark.parametrize("kwargs, said", [
    ({"max_seconds": float("nan")}, "--max-seconds nan"),
    ({"max_seconds": -5.0}, "--max-seconds -5"),
    ({"max_episodes": 0}, "--max-episodes 0"),
    ({"count": 10**12}, "--count 1000000000000"),
])
def test_generate_refuses_a_bad_budget_before_it_writes(tmp_path, kwargs, said):
    from garage_mj.generation.generator import GenerationError, generate

    args = {"count": 2, **kwargs}
    with pytest.raises(GenerationError, match=said):
        generate("tiny_7x11", (0.3, 0.4), args.pop("count"), tmp_path / "l.sqlite", progress=False, **args)
    assert list(tmp_path.iterdir()) == []


def test_the_parser_takes_good_numbers():
    args = build_parser().parse_args([*GENERATE, "--count", "1_000_000", "--library", "l", "--max-seconds", "0.5",
                                      "--max-episodes", "7", "--train-timesteps", "2_000"])
    assert (args.count, args.max_seconds, args.max_episodes, args.train_timesteps) == (1_000_000, 0.5, 7, 2000)


@pytest.fixture
def read_only_mount(tmp_path, monkeypatch):
    """``tmp_path/ro`` as a read-only mount looks: ``statvfs`` has ``ST_RDONLY`` and ``access(W_OK)`` is False
    (EROFS), for root too; a library made there before the "mount"."""
    import os

    from garage_mj.generation.library import Library

    ro = tmp_path / "ro"
    ro.mkdir()
    Library(ro / "lib.sqlite").close()
    real_statvfs, real_access = os.statvfs, os.access

    def inside(path) -> bool:
        return Path(os.fspath(path)).resolve().is_relative_to(ro)

    class ReadOnly:
        def __init__(self, st):
            self._st = st
            self.f_flag = st.f_flag | os.ST_RDONLY

        def __getattr__(self, name):
            return getattr(self._st, name)

    monkeypatch.setattr(os, "statvfs", lambda p: ReadOnly(real_statvfs(p)) if inside(p) else real_statvfs(p))
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: (False if mode & os.W_OK and inside(p)
                                                                 else real_access(p, mode, **kw)))
    return ro


@pytest.mark.parametrize("name", ["lib.sqlite", "new.sqlite", "sub/new.sqlite"])
def test_a_library_on_a_read_only_file_system_says_so(read_only_mount, capsys, name):
    from garage_mj.generation.library import LibraryError, check_writable

    lib = read_only_mount / name
    before = snapshot(read_only_mount)
    with pytest.raises(LibraryError) as info:
        check_writable(lib)
    said = str(info.value)
    assert "read-only file system" in said and "chmod" not in said and "a writable place" in said, said
    line = one_line_error(capsys, [*GENERATE, "--count", "1", "--library", str(lib)])
    assert "read-only file system" in line and str(lib) in line and "chmod" not in line, line
    assert snapshot(read_only_mount) == before


def test_a_library_on_a_read_only_file_system_can_still_be_listed(read_only_mount, capsys):
    assert main(["library", "ls", str(read_only_mount / "lib.sqlite")]) == 0
    assert "0 garage(s)" in capsys.readouterr().out


def test_an_oserror_of_a_read_only_file_system_says_so(monkeypatch, capsys):
    import errno
    import os

    def refuse(args):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), "/mnt/ro/picture.png")

    monkeypatch.setattr("garage_mj.cli.show.run", refuse)
    line = one_line_error(capsys, ["show", "1"])
    assert line.startswith("garage-mj show: error: /mnt/ro/picture.png: Read-only file system; ") and \
        "mounted read-only" in line and "permissions" not in line, line


@pytest.fixture
def files(tmp_path):
    """A small library, a text file, a foreign SQLite file, a plain file and a folder."""
    import sqlite3

    from garage_mj.generation.library import Library
    from garage_mj.grid.painters import paint_garage

    with Library(tmp_path / "lib.sqlite") as lib:
        for s in (1, 2):
            lib.add(paint_garage("tiny_7x11", seed=s), map="tiny_7x11", run="r", seed=0, episode=s, timestep=s)
    (tmp_path / "text.txt").write_text("hello\n")
    con = sqlite3.connect(tmp_path / "foreign.sqlite")
    con.execute("CREATE TABLE t (x)")
    con.close()
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    return tmp_path


@pytest.mark.parametrize("library, said", [
    ("adir", "is a folder"),
    ("text.txt", "not an SQLite database"),
    ("foreign.sqlite", "not a garage-mj library"),
    ("afile/lib.sqlite", "afile is a file, not a folder"),
])
def test_generate_refuses_a_bad_library_before_it_rolls_out(files, capsys, library, said):
    before = snapshot(files)
    line = one_line_error(capsys, [*GENERATE, "--count", "1", "--library", str(files / library)])
    assert said in line, line
    assert snapshot(files) == before


@pytest.mark.parametrize("argv, said", [
    (["library", "ls", "{lib}", "--limit", "99999999999999999999999"], "argument --limit"),
    (["library", "sample", "{lib}", "-n", "99999999999999999999999"], "argument -n"),
    (["library", "sample", "{lib}", "-n", "2", "--limit", "99999999999999999999999"], "argument --limit"),
    (["library", "export-json", "{lib}", "--limit", "99999999999999999999999", "--out", "{tmp}/x.json"],
     "argument --limit"),
    (["library", "rate", "{lib}", "--limit", "99999999999999999999999"], "argument --limit"),
    (["library", "rate", "{lib}", "--workers", "99999999999999999999"], "argument --workers"),
    (["check", "--library", "{lib}", "--limit", "-1"], "argument --limit"),
    (["check", "--library", "{lib}", "--limit", "99999999999999999999999"], "argument --limit"),
    (["check", "--library", "{lib}", "--difficulty", "nan", "1"], "argument --difficulty"),
    (["plot", "convergence", "{tmp}", "--smooth", "99999999999999999999999"], "argument --smooth"),
])
def test_huge_and_nan_numbers_are_one_line(files, capsys, argv, said):
    before = snapshot(files)
    line = one_line_error(capsys, [a.format(lib=files / "lib.sqlite", tmp=files) for a in argv])
    assert said in line and any(s in line for s in ("from 0 to 1,000,000,000", "from 1 to", "outside [0, 1]")), line
    assert snapshot(files) == before


def test_a_file_where_a_folder_should_be_is_named(files, capsys):
    line = one_line_error(capsys, ["show", "1", "--library", str(files / "lib.sqlite"), "--png",
                                   str(files / "afile" / "x.png")])
    assert str(files / "afile") in line and "it is a file, not a folder" in line, line


def test_check_store_with_a_bad_json_path_changes_no_library(files, capsys):
    before = snapshot(files)
    for target in ("adir", "afile/x.json", "missing/x.json"):
        line = one_line_error(capsys, ["check", "--library", str(files / "lib.sqlite"), "--limit", "1", "--store",
                                       "--json", str(files / target)])
        assert "--json" in line and str(files / target) in line, line
        assert snapshot(files) == before  # no drivability stored before the refusal


@pytest.mark.parametrize("argv, said", [
    (["train", "--map", "tiny_7x11", "--timesteps", "99999999999999999999999", "--out", "{tmp}/t"],
     "argument --timesteps"),
    (["difficulty", "show", "tiny_7x11", "-n", "99999999999999999999"], "argument -n"),
    (["difficulty", "show", "tiny_7x11", "-n", "1", "--stalls", "99999999999999999999"], "argument --stalls"),
])
def test_a_huge_count_of_work_is_refused(files, capsys, argv, said):
    before = snapshot(files)
    line = one_line_error(capsys, [a.format(tmp=files) for a in argv])
    assert said in line and "from 1 to" in line, line
    assert snapshot(files) == before


def test_generate_names_a_file_in_the_way_of_its_model_out(files, capsys):
    mine = files / "mine.txt"
    mine.write_text("2 2 7 2 2\n2 0 0 0 2\n2 0 0 0 2\n2 0 0 0 2\n2 2 8 2 2\n")
    before = snapshot(files)
    line = one_line_error(capsys, ["generate", "--map", str(mine), "--difficulty", "0.1", "0.9", "--count", "1",
                                   "--library", str(files / "new.sqlite"), "--model-out",
                                   str(files / "afile" / "g.zip")])
    assert f"--model-out {files / 'afile' / 'g.zip'}" in line and "is a file, not a folder" in line, line
    assert snapshot(files) == before


@pytest.mark.parametrize("argv", [
    ["library", "export-json", "{lib}", "--out", "{lib}"],
    ["check", "--library", "{lib}", "--limit", "1", "--json", "{lib}"],
    ["check", "--library", "{lib}", "--limit", "1", "--store", "--json", "{lib}"],
    ["difficulty", "fit", "{tmp}/adir", "--library", "{lib}", "--out", "{lib}"],
    ["difficulty", "score", "{tmp}/adir", "--library", "{lib}", "--json", "{lib}"],
    ["difficulty", "score", "{tmp}/adir", "--json", "{tmp}/adir/tests.csv"],
])
def test_an_output_never_overwrites_an_input(files, capsys, argv):
    (files / "adir" / "tests.csv").write_text("garage_hash,test\n")
    before = snapshot(files)
    line = one_line_error(capsys, [a.format(lib=files / "lib.sqlite", tmp=files) for a in argv])
    assert "is an input of this command" in line, line
    assert snapshot(files) == before


@pytest.mark.parametrize("extra", [[], ["--model", "tiny_7x11"]])
def test_generate_refuses_a_model_out_it_would_not_use(tmp_path, capsys, extra):
    line = one_line_error(capsys, [*GENERATE, "--count", "1", "--library", str(tmp_path / "l.sqlite"),
                                   "--model-out", str(tmp_path / "g.zip"), *extra])
    assert "drop --model-out" in line, line
    assert list(tmp_path.iterdir()) == []
