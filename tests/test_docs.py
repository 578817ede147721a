"""The documentation: the site builds with ``mkdocs build --strict`` and the README stays a front door."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 300


def test_readme_stays_short():
    lines = (ROOT / "README.md").read_text().count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines (at most {README_MAX_LINES}): move detail into docs/"


def test_the_site_builds_strict(tmp_path):
    """A broken link or anchor, or a page left out of mkdocs.yml's nav, fails the build."""
    pytest.importorskip("mkdocs", reason="mkdocs is in the dev extra: pip install -e '.[dev]'")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                          "-d", str(tmp_path / "site")], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr



def test_the_readme_python_example_runs(capsys):
    text = (ROOT / "README.md").read_text()
    start = text.index("```python\n") + len("```python\n")
    code = text[start:text.index("```", start)]
    exec(compile(code, "README.md", "exec"), {})
    assert "True" in capsys.readouterr().out  # the painted garage is usable


# A ```python block of docs/*.md runs as it stands, offline, in a few seconds. A block that cannot
# (a CARLA server, a library the paper's experiment builds, the user's own stack) carries an HTML comment
# `<!-- not run: REASON -->` on the line right before its fence; a marker without a reason fails.
_BLOCK = re.compile(r"(?:<!--\s*not run:(?P<reason>[^>]*?)-->\n)?```python\n(?P<code>.*?)```", re.S)
DOC_BLOCK_TIMEOUT_S = 60  # a guard against a hanging example, not a timing test: a loaded machine takes 20 s to import torch


def _doc_blocks() -> list:
    """One pytest param per ```python block of docs/*.md, the not-run ones skipped with their reason."""
    params = []
    for page in sorted((ROOT / "docs").glob("*.md")):
        text = page.read_text()
        for m in _BLOCK.finditer(text):
            line = text.count("\n", 0, m.start("code")) + 1
            marks = ()
            if m.group("reason") is not None:
                assert m.group("reason").strip(), f"{page.name}:{line}: `not run:` needs a reason"
                marks = (pytest.mark.skip(reason=f"not run: {m.group('reason').strip()}"),)
            params.append(pytest.param(m.group("code"), id=f"{page.name}:{line}", marks=marks))
    return params


@pytest.mark.parametrize("code", _doc_blocks())
def test_the_docs_python_examples_run(code, tmp_path):
    """Each runnable docs example runs in a fresh interpreter in an empty folder."""
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=DOC_BLOCK_TIMEOUT_S)
    assert out.returncode == 0, out.stdout + out.stderr


def _page_block(page: str, lang: str, containing: str) -> str:
    """The body of the first ```LANG block of docs/PAGE that contains CONTAINING."""
    for m in re.finditer(rf"```{lang}\n(.*?)```", (ROOT / "docs" / page).read_text(), re.S):
        if containing in m.group(1):
            return m.group(1)
    raise AssertionError(f"docs/{page} has no ```{lang} block with {containing!r}")


def test_a_newcomer_follows_the_docs_to_their_own_driver(tmp_path):
    """docs/own-driver.md's driver file and commands, then docs/pytest-plugin.md's test file, taken from the
    pages themselves; `garage-mj` runs as `python -m garage_mj`. The pytest file's `my_stack` is the
    plugin page's example driver (docs/pytest_example), since the own-driver placeholder only accelerates."""
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    (tmp_path / "my_driver.py").write_text(_page_block("own-driver.md", "python", "class MyDriver"))
    for line in _page_block("own-driver.md", "sh", "my_driver.py:MyDriver").splitlines():
        args = shlex.split(line, comments=True)
        assert args[0] == "garage-mj", line
        out = subprocess.run([sys.executable, "-m", "garage_mj", *args[1:]], capture_output=True, text=True,
                             cwd=tmp_path, env=env, timeout=60)
        assert out.returncode == 0, line + "\n" + out.stdout + out.stderr
    assert (tmp_path / "runs" / "mine" / "tests.csv").is_file()
    (tmp_path / "my_stack.py").write_text((ROOT / "docs" / "pytest_example" / "test_my_driver.py").read_text())
    (tmp_path / "test_my_driver.py").write_text(_page_block("pytest-plugin.md", "python", "from my_stack import"))
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_my_driver.py"],
                         capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert out.returncode == 0 and "1 passed" in out.stdout, out.stdout + out.stderr


def test_a_newcomer_brings_their_own_parking_stack(tmp_path):
    """docs/own-parking-stack.md as a newcomer follows it: its parker is docs/parking_example/my_parker.py word for
    word, the test file's heart is in test_my_parker.py, and the page's commands run on those files in an empty
    folder (`garage-mj` as `python -m garage_mj`): park tests from the CLI and under pytest (every one parked),
    then a problem file exported and planned with docs/park_problem_example.py, clear of the obstacles and scored
    against the reference plan. About 20 s on 2 busy cores: one garage, 3 park tests twice, 1 problem planned."""
    import glob
    import json

    example = ROOT / "docs" / "parking_example"
    assert _page_block("own-parking-stack.md", "python", "class MyParker") == (example / "my_parker.py").read_text()
    heart = _page_block("own-parking-stack.md", "python", "def test_my_parker_parks")
    assert all(line in (example / "test_my_parker.py").read_text() for line in heart.splitlines() if line.strip())
    for name in ("my_parker.py", "test_my_parker.py"):
        (tmp_path / name).write_text((example / name).read_text())
    (tmp_path / "park_problem_example.py").write_text((ROOT / "docs" / "park_problem_example.py").read_text())
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    program = {"garage-mj": ["-m", "garage_mj"], "python": [], "pytest": ["-m", "pytest", "-p", "no:cacheprovider"]}
    commands = (_page_block("own-parking-stack.md", "sh", "--driver my_parker.py:MyParker").splitlines()
                + _page_block("own-parking-stack.md", "sh", "--park-problems").splitlines()
                + _page_block("own-parking-stack.md", "sh", "pytest test_my_parker.py").splitlines()[:1])
    printed = {}
    for line in commands:
        args = shlex.split(line, comments=True)
        if not args:  # a comment line: what the command before it prints
            continue
        args = [hit for a in args for hit in (sorted(glob.glob(a, root_dir=tmp_path)) if "*" in a else [a])]
        assert args[0] in program, line
        out = subprocess.run([sys.executable, *program[args[0]], *args[1:]], capture_output=True, text=True,
                             cwd=tmp_path, env=env, timeout=120)
        assert out.returncode == 0, line + "\n" + out.stdout + out.stderr
        printed[args[0]] = out.stdout
    summary = json.loads((tmp_path / "runs" / "park" / "summary.json").read_text())
    assert summary["task"] == "park" and summary["feasible"] == 3 and summary["success_pct"] == 100.0, summary
    scored = json.loads(printed["python"].strip().splitlines()[-1])
    assert scored["found"] and scored["clear"] and 0.5 < scored["length_ratio"] < 3, scored
    assert "1 passed" in printed["pytest"], printed["pytest"]
