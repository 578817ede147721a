"""What a newcomer reads when something goes wrong or a figure is printed.

Each test runs the real CLI entry point (:func:`garage_mj.cli.main`) and reads what it prints.
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from garage_mj.cli import build_parser, main
from garage_mj.export.pack import export_pack


@pytest.fixture(scope="module")
def packs(tmp_path_factory, painted_tiny) -> Path:
    out = tmp_path_factory.mktemp("packs")
    export_pack(painted_tiny, out)
    return out


def _err_lines(capsys) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if line.strip()]


@pytest.fixture
def crashing_driver(tmp_path, monkeypatch) -> str:
    """A user driver module whose ``act`` raises deep inside a helper."""
    (tmp_path / "crashy_driver.py").write_text(textwrap.dedent("""
        def _steer(obs):
            return 1 / 0

        class Crash:
            action_type = "continuous"

            def reset(self, info):
                pass

            def act(self, obs):
                return [0.5, _steer(obs)]
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "crashy_driver:Crash"
    sys.modules.pop("crashy_driver", None)


def test_a_crashing_driver_is_one_line_and_debug_shows_its_traceback(packs, tmp_path, capsys, crashing_driver):
    args = ["cruise", "--packs", str(packs), "--tests", "1", "--driver", crashing_driver, "--quiet"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 2
    lines = _err_lines(capsys)
    assert len(lines) == 1, lines
    assert "driver 'crashy_driver:Crash' failed" in lines[0] and "ZeroDivisionError" in lines[0]
    assert "--debug" in lines[0]  # says how to see more

    assert main(["--debug", *args, "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "crashy_driver.py" in err and "_steer" in err  # the driver's own frames
    assert err.rstrip().splitlines()[-1].startswith("garage-mj cruise: error: driver 'crashy_driver:Crash'")


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_driver_that_cannot_be_built_is_one_line_and_writes_nothing(packs, tmp_path, capsys, monkeypatch, workers):
    """A raising ``__init__`` or a missing or corrupt learned model stops cruise before --out is touched."""
    (tmp_path / "unbuildable_driver.py").write_text(textwrap.dedent("""
        class Unbuildable:
            def __init__(self):
                raise RuntimeError("no licence for this car")

            def reset(self, info):
                pass

            def act(self, obs):
                return 0
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "corrupt.zip").write_bytes(b"not a zip")
    out = tmp_path / "run"
    base = ["cruise", "--packs", str(packs), "--tests", "1", "--workers", workers, "--quiet", "--out", str(out)]
    for driver, words in (("unbuildable_driver:Unbuildable", "RuntimeError: no licence for this car"),
                          (f"learned:{tmp_path / 'missing.zip'}", "missing.zip"),
                          (f"learned:{tmp_path / 'corrupt.zip'}", "corrupt.zip")):
        assert main([*base, "--driver", driver]) == 2
        lines = _err_lines(capsys)
        assert len(lines) == 1 and words in lines[0], lines
        assert driver.startswith("learned") or f"driver {driver!r} cannot be built" in lines[0], lines
        assert not out.exists()
        hunt = ["hunt", "--map", "tiny_7x11", "--driver", driver, "--workers", workers, "--quiet", "--out", str(out)]
        assert main(hunt) == 2 and words in _err_lines(capsys)[0]
        assert not out.exists()
    sys.modules.pop("unbuildable_driver", None)
    assert main([*base, "--driver", "oracle"]) == 0  # the corrected command runs into the same folder


def test_a_missing_library_names_the_fix_for_a_positional_path(tmp_path, capsys):
    assert main(["library", "ls", str(tmp_path / "nope.sqlite")]) == 2
    (line,) = _err_lines(capsys)
    assert "no library at" in line and "nope.sqlite" in line
    assert "--library" not in line  # `library ls` takes the path as an argument
    assert "garage-mj train" in line


def test_a_bad_scenario_file_is_named(packs, tmp_path, capsys):
    bad = tmp_path / "bad_scenario.toml"
    bad.write_text("[scenario]\npedestrianz = 1\n")
    assert main(["cruise", "--packs", str(packs), "--tests", "1", "--driver", "oracle", "--scenario", str(bad),
                 "--quiet", "--out", str(tmp_path / "c")]) == 2
    (line,) = _err_lines(capsys)
    assert str(bad) in line and "pedestrianz" in line


def test_train_seed_defaults_to_zero_like_the_other_commands():
    args = build_parser().parse_args(["train", "--map", "tiny_7x11", "--timesteps", "10", "--out", "x"])
    assert args.seed == 0
    for command in (["cruise", "--packs", "p"], ["generate", "--map", "tiny_7x11", "--difficulty", "0", "1",
                                                 "--count", "1", "--library", "l"]):
        assert build_parser().parse_args(command).seed == 0


def test_check_prints_clearances_with_their_unit(packs, capsys):
    pack = next(p for p in packs.iterdir() if (p / "manifest.json").is_file())
    assert main(["check", str(pack), "--stalls"]) == 0
    stall_lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith("stall")]
    assert stall_lines
    for ln in stall_lines:
        value = ln.split("clearance ", 1)[1].split()
        assert value[0] == "-" or (float(value[0]) >= 0 and value[1] == "m"), ln


def test_a_generate_error_starts_its_own_line(tmp_path, capsys):
    """The progress bar is ended before the one-line error, which never trails the bar's last frame."""
    assert main(["generate", "--map", "tiny_7x11", "--difficulty", "0.0", "0.01", "--count", "2", "--library",
                 str(tmp_path / "lib.sqlite"), "--max-episodes", "3", "--no-search"]) == 2
    err = capsys.readouterr().err
    last = err.rstrip("\n").split("\n")[-1]
    assert last.startswith("garage-mj generate: error: found 0 of 2"), repr(last[-300:])


def _walk_parsers(parser):
    """``parser`` and every subcommand parser under it."""
    import argparse

    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _walk_parsers(sub)


def test_no_parser_takes_a_prefix_of_an_option():
    parsers = list(_walk_parsers(build_parser()))
    assert len(parsers) > 20 and all(p.allow_abbrev is False for p in parsers)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["cruise", "--packs", "p", "--driv", "vision"])


@pytest.mark.parametrize("argv, usage, hint", [
    (["cruise", "--packs", "p", "--driv", "vision"], "usage: garage-mj cruise ",
     "garage-mj cruise: error: unrecognized arguments: --driv vision; did you mean --driver?"),
    (["cruise", "--packs", "p", "--tset=3"], "usage: garage-mj cruise ",
     "garage-mj cruise: error: unrecognized arguments: --tset=3; did you mean --tests?"),
    (["library", "ls", "lib.sqlite", "--mapp", "m"], "usage: garage-mj library ls ",
     "garage-mj library ls: error: unrecognized arguments: --mapp m; did you mean --map?"),
    (["--debgu"], "usage: garage-mj ",
     "garage-mj: error: unrecognized arguments: --debgu; did you mean --debug?"),
])
def test_a_mistyped_option_gets_its_commands_usage_and_a_suggestion(argv, usage, hint, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(usage) and err.strip().splitlines()[-1] == hint
