"""Jobs and drivers that die or hang, for the tests of worker supervision (imported by spawned workers)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np


def square_or_die(job: tuple[int, str]) -> int:
    """``n * n``; job ``(n, path)`` with a path kills its own process with SIGKILL the first time (the file
    marks that it did), so the retry succeeds."""
    n, mark = job
    if mark and not Path(mark).exists():
        Path(mark).write_text("died once")
        os.kill(os.getpid(), signal.SIGKILL)
    return n * n


def square_or_segfault(n: int) -> int:
    """``n * n``, except job 3 always segfaults."""
    if n == 3:
        os.kill(os.getpid(), signal.SIGSEGV)
    return n * n


def square_or_hang(n: int) -> int:
    """``n * n``, except job 2 sleeps for ever."""
    if n == 2:
        time.sleep(3600)
    return n * n


class _Stop:
    """A driver that stands still (the base of the bad drivers here)."""

    def reset(self, info) -> None:
        self.steps = 0

    def act(self, obs):
        return np.zeros(2, dtype=np.float32)


class SegfaultDriver(_Stop):
    """Segfaults on its first action (as a broken C extension in a user's driver would)."""

    def act(self, obs):
        os.kill(os.getpid(), signal.SIGSEGV)


class SleepDriver(_Stop):
    """Its act() never returns."""

    def act(self, obs):
        time.sleep(3600)


def pid_then_hang(folder: str) -> None:
    """Writes its worker's pid into ``folder`` (a file named after it), then sleeps for ever."""
    Path(folder, str(os.getpid())).write_text("")
    time.sleep(3600)


def square_or_exit(n: int) -> int:
    """``n * n``, except job 2 raises SystemExit(0) (as ``sys.exit(0)`` in a user's code would)."""
    if n == 2:
        raise SystemExit(0)
    return n * n


class ExitDriver(_Stop):
    """Calls ``sys.exit(0)`` on its first action."""

    def act(self, obs):
        raise SystemExit(0)


class InterruptDriver(_Stop):
    """Raises KeyboardInterrupt on its first action (as Ctrl-C during act() would)."""

    def act(self, obs):
        raise KeyboardInterrupt
