"""The ``garage-mj`` command line. Each subcommand lives in its own module of this package.

- ``maps``: list, show and validate map files.
- ``demo``: the main job on a small garage (``garage_mj.reporting.demo``).
- ``export``: asset packs from a library or garage files.
- ``check``: drivability of a pack's or library's garages (routes, clearance).
- ``train``: one DQN generation run.
- ``generate``: garages on demand in a difficulty band.
- ``library``: browse, sample and export the scenario library; rate its garages' route difficulty.
- ``plot``: convergence and heatmap figures.
- ``show``: draw one garage as text or PNG.
- ``cruise``: batch cruise tests of a driver; ``cruise_cases``: its park tests from problem files (``--cases``).
- ``hunt``: search for garages that break a driver.
- ``train-driver``: train a learned cruise driver over many garages (``train_driver``).
- ``difficulty``: fit, score and compute the route-aware difficulty.

A module in :data:`COMMANDS` exposes ``register(subparsers)``, which adds its parser and sets
``func`` to a handler ``(args) -> int``. Errors a user can cause derive from
:class:`garage_mj.core.errors.GarageMJError` (``UserError``, ``MapError``, ``ConfigError``,
``LibraryError``, ``PackError``, ``CruiseError``, ...) and are printed as one line with exit
status 2, no traceback; so are file-system failures (read-only or full folder: ``OSError``).
Modules here import heavy packages (torch, SB3, MuJoCo, matplotlib) inside the handlers only,
so ``--help`` and the light commands start fast.
"""

from __future__ import annotations

import argparse
import errno
import faulthandler
import importlib
import os
import sys
import traceback

from garage_mj.cli._parser import CLIParser
from garage_mj.core import __version__
from garage_mj.core.errors import GarageMJError, printable

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ["maps", "demo", "export", "check", "train", "generate", "library", "plot", "show", "cruise", "hunt", "train_driver",
            "difficulty"]


class UserError(GarageMJError):
    """A problem the user can fix; printed as one line and exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    """The ``garage-mj`` parser: every (sub)command a :class:`CLIParser` (no prefix matching; a mistyped
    option is answered with the command's own usage and the closest option it has)."""
    parser = CLIParser(
        prog="garage-mj",
        description=(
            "Generate adverse underground-garage scenarios with deep RL, export them as "
            "OpenDRIVE/MJCF/GLB asset packs, and test driving algorithms in them in MuJoCo."
        ),
    )
    parser.add_argument("--version", action="version", version=f"garage-mj {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="on an error, print its full traceback (and that of a failing driver) before the "
                             "one-line message: for bug reports and for debugging your own driver")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")  # CLIParsers: no prefixes, own usage
    for name in COMMANDS:
        importlib.import_module(f"garage_mj.cli.{name}").register(sub)
    return parser


def one_line(text: object, limit: int = 600) -> str:
    """``text`` on one line, at most ``limit`` characters, control characters escaped (a message may
    quote user input: a name holding an escape sequence must not act on the terminal)."""
    line = printable(" ".join(str(text).split()))
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _close_progress_bars() -> None:
    """End any progress bar still open, so an error is printed on a line of its own."""
    tqdm = sys.modules.get("tqdm")
    for bar in list(getattr(getattr(tqdm, "tqdm", None), "_instances", ()) or ()):
        bar.close()


def main(argv: list[str] | None = None) -> int:
    """Run the command of ``argv``; returns the exit status (0, 2 for a user error, 130 on Ctrl-C,
    141 when the reader of stdout went away, as in ``garage-mj library ls | head``)."""
    try:
        try:
            return _run(argv)
        finally:
            sys.stdout.flush()  # a closed pipe shows here, not at exit
    except BrokenPipeError:
        return _stdout_closed()


def _stdout_closed() -> int:
    """End quietly, as Unix tools do, when stdout's reader has gone (exit status 141, SIGPIPE's).

    As Python's docs advise (the note on SIGPIPE in :mod:`signal`), stdout is pointed at
    ``/dev/null`` so that the flush at exit does not fail again and print a message.
    """
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is not a file descriptor (captured in tests)
        pass
    return 141


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    if not faulthandler.is_enabled():  # a crash in this process (a driver's segfault with --workers 1) names the
        faulthandler.enable()  # signal and the line it came from, not a bare exit code
    try:
        return int(args.func(args) or 0)
    except GarageMJError as exc:
        _close_progress_bars()
        if args.debug:
            traceback.print_exc()
            if exc.details:
                print(f"the failure behind it:\n{exc.details}", file=sys.stderr, end="")
        print(f"garage-mj {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # stdout's reader went away: main ends quietly
        raise
    except OSError as exc:  # the file system refused: read-only or full folder, a file in the way
        _close_progress_bars()
        if args.debug:
            traceback.print_exc()
        where = f" {exc.filename}" if exc.filename else ""
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            hint = "free some disk space and run again (finished work is kept)"
        elif exc.errno == errno.EROFS:
            hint = "the file system is mounted read-only: write to a path in a writable place"
        elif exc.errno in (errno.EEXIST, errno.ENOTDIR) and exc.filename and os.path.isfile(exc.filename):
            hint = "it is a file, not a folder; name a path in a folder"
        else:
            hint = "check the path and its permissions"
        print(f"garage-mj {args.command}: error:{where}: {one_line(exc.strerror or exc)}; {hint}",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"garage-mj {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
