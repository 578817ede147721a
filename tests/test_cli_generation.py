"""The generation-stage CLI: train, library, plot, show; good input exits 0, bad input one line."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from garage_mj.cli import main
from garage_mj.generation.library import Library
from garage_mj.generation.runs import latest_checkpoint
from garage_mj.generation.training import train


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "run"
    rc = main(["train", "--map", "tiny_7x11", "--timesteps", "1500", "--seed", "0", "--out", str(out),
               "--checkpoint-every", "500", "--no-progress"])
    assert rc == 0
    return out


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_train_writes_run_and_library(trained, capsys):
    manifest = json.loads((trained / "run.json").read_text())
    # the default (fast) learner's 32 envs step together: the run stops at the first multiple of 32 >= 1500
    assert manifest["status"] == "finished" and 1500 <= manifest["timesteps"] < 1500 + 32
    assert not (trained / ".garage-mj.lock").exists()  # the run's lock goes when it ends
    with Library(trained / "library.sqlite") as lib:
        assert lib.count() == manifest["garages_stored"] >= 1


def test_train_bar_ends_on_the_summary_counts_and_says_what_was_learned(tmp_path, capsys):
    import re

    out = tmp_path / "run"
    assert main(["train", "--map", "tiny_7x11", "--timesteps", "1500", "--seed", "0", "--out", str(out)]) == 0
    printed = capsys.readouterr()
    bar = printed.err.replace("\r", "\n").strip().splitlines()[-1]
    got = re.search(r"episodes=(\d+), garages=(\d+)\]$", bar)
    assert got, bar
    summary = re.search(r"(\d+) episodes, (\d+) garages in ", printed.out)
    assert summary and summary.groups() == got.groups(), (bar, printed.out)
    manifest = json.loads((out / "run.json").read_text())
    r = manifest["returns"]
    assert r["episodes"] == manifest["episodes"] and r["window"] == max(1, round(r["episodes"] / 10))
    assert (f"learning: mean episode return {r['first_mean']:.1f} over the first {r['window']} episodes, "
            f"{r['last_mean']:.1f} over the last {r['window']}") in printed.out


def test_library_commands(trained, capsys, tmp_path):
    lib = str(trained / "library.sqlite")
    assert main(["library", "ls", lib, "--map", "tiny_7x11", "--difficulty", "0", "1", "--limit", "5"]) == 0
    out = capsys.readouterr().out
    assert "tiny_7x11" in out and "garage(s)" in out
    with Library(lib) as library:
        first = library.query(limit=1)[0]
    assert main(["library", "show", lib, str(first.id)]) == 0
    assert "X" in capsys.readouterr().out  # the drawing has the exit
    assert main(["library", "stats", lib, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["maps"]["tiny_7x11"]["garages"] >= 1
    assert main(["library", "sample", lib, "-n", "1", "--seed", "3"]) == 0
    assert "1 garage(s)" in capsys.readouterr().out
    dump = tmp_path / "garages.json"
    assert main(["library", "export-json", lib, "--coverage", "0", "1", "--out", str(dump)]) == 0
    data = json.loads(dump.read_text())
    assert data[0]["grid"] == first.grid and data[0]["hash"] == first.hash


def test_plot_and_show(trained, capsys, tmp_path):
    lib = str(trained / "library.sqlite")
    for argv, png in (
        (["plot", "convergence", str(trained), "--out", str(tmp_path / "c.png")], tmp_path / "c.png"),
        (["plot", "heatmap", "--library", lib, "--map", "tiny_7x11", "--out", str(tmp_path / "h.png")],
         tmp_path / "h.png"),
        (["show", "1", "--library", lib, "--png", str(tmp_path / "g.png")], tmp_path / "g.png"),
    ):
        assert main(argv) == 0
        assert png.read_bytes().startswith(b"\x89PNG")
    assert "E entrance" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, match",
    [
        (["library", "ls", "{tmp}/missing.sqlite"], "no library at"),
        (["library", "ls", "{foreign}"], "not a garage-mj library"),
        (["library", "show", "{lib}", "9999"], "no garage with id 9999"),
        (["library", "ls", "{lib}", "--difficulty", "0.9", "0.1"], "LO is above HI"),
        (["show", "1", "--library", "{tmp}/missing.sqlite"], "no library at"),
        (["plot", "heatmap", "--library", "{lib}", "--map", "m7_13x13_u"], "no garage of map"),
        (["plot", "convergence", "{tmp}"], "no monitor.csv"),
        (["train", "--map", "tiny_7x11", "--timesteps", "10", "--seed", "0", "--out", "{run}"], "already holds a run"),
        (["train", "--map", "no_such_map", "--timesteps", "10", "--seed", "0", "--out", "{tmp}/x"], "no map named"),
        (["train", "--map", "tiny_7x11", "--timesteps", "10", "--seed", "0", "--out", "{tmp}/x",
          "--config", "{badcfg}"], "unknown key"),
    ],
)
def test_bad_input_is_one_line(trained, tmp_path, capsys, argv, match):
    foreign = tmp_path / "foreign.sqlite"
    con = sqlite3.connect(foreign)
    con.execute("CREATE TABLE t (x)")
    con.close()
    badcfg = tmp_path / "bad.toml"
    badcfg.write_text("learning_rat = 1\n")
    subst = {"tmp": tmp_path, "foreign": foreign, "lib": trained / "library.sqlite", "run": trained, "badcfg": badcfg}
    assert main([a.format(**subst) for a in argv]) == 2
    assert match in _err_line(capsys)


def test_usage_errors_exit_nonzero(capsys):
    with pytest.raises(SystemExit) as info:
        main(["train", "--map", "tiny_7x11", "--timesteps", "0", "--seed", "0", "--out", "x"])
    assert info.value.code == 2
    with pytest.raises(SystemExit):
        main(["library", "ls", "x.sqlite", "--coverage", "0", "2"])
    capsys.readouterr()


def test_kill_9_then_resume_loses_nothing(tmp_path):
    """A real SIGKILL in the middle of a run: every reported garage survives, none is stored twice."""
    out = tmp_path / "run"
    exe = Path(sys.executable).with_name("garage-mj")
    proc = subprocess.Popen(
        [str(exe), "train", "--map", "tiny_7x11", "--timesteps", "100000", "--seed", "0", "--out", str(out),
         "--checkpoint-every", "500", "--no-progress"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            ckpt = latest_checkpoint(out) if (out / "checkpoints").exists() else None
            if ckpt and ckpt[1]["timesteps"] >= 1500:
                break
            time.sleep(0.2)
        else:
            pytest.fail("the training subprocess made no checkpoint in 60 s")
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    with Library(out / "library.sqlite") as lib:
        before = {r.hash for r in lib.query()}
    assert before
    ckpt = latest_checkpoint(out)
    manifest = train("tiny_7x11", ckpt[1]["timesteps"] + 1000, 0, out, progress=False, resume=True)
    assert manifest["status"] == "finished"
    with Library(out / "library.sqlite") as lib:
        hashes = [r.hash for r in lib.query()]
    assert before <= set(hashes) and len(hashes) == len(set(hashes))
