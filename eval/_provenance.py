"""Where a benchmark's figures come from: the command, the date, the machine and the commit.

A benchmark that writes JSON adds ``"provenance": provenance()`` to it, so the figure carries its own
record; ``eval/render_pages.py`` prefers it over the data file's fields when it renders the results
and performance pages.
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str:
    """A git command's output in the repository, or "" where git or the history is missing."""
    try:
        out = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _commit() -> str:
    """The short commit measured; "-dirty" where tracked files differ from it (the figure is of changed code)."""
    head = _git("rev-parse", "--short", "HEAD")
    if not head:
        return "unknown"
    return head + ("-dirty" if _git("status", "--porcelain", "--untracked-files=no") else "")


def _cpu() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo, else what the platform says)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _gpu() -> str:
    """The GPU nvidia-smi names, or "no GPU"."""
    if not shutil.which("nvidia-smi"):
        return "no GPU"
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return "no GPU"
    names = [n.strip() for n in out.stdout.splitlines() if n.strip()]
    return ", ".join(names) if out.returncode == 0 and names else "no GPU"


def machine() -> str:
    """One line on the machine: cores, CPU, GPU and the load average when the figure was taken."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{os.cpu_count()}-core {_cpu()}, {_gpu()}, load average {load:.1f} at the start"


def command(argv: list[str] | None = None, script: str | None = None) -> str:
    """The command line that reruns the benchmark from the repository root."""
    argv = sys.argv[1:] if argv is None else argv
    path = Path(script or sys.argv[0]).resolve()
    try:
        path = path.relative_to(ROOT)
    except ValueError:
        pass
    return shlex.join([".venv/bin/python", str(path), *argv])


def provenance(argv: list[str] | None = None, script: str | None = None) -> dict[str, str]:
    """{"command", "date", "machine", "commit"} of the running benchmark (argv: its arguments, default sys.argv)."""
    return {"command": command(argv, script), "date": datetime.date.today().isoformat(), "machine": machine(),
            "commit": _commit()}


if __name__ == "__main__":
    print(provenance())
