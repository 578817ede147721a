"""The ``garage-mj`` command line. Each subcommand lives in its own module of this package.

A module in :data:`COMMANDS` exposes ``register(subparsers)``, which adds its parser and sets
``func`` to a handler ``(args) -> int``. Errors a user can cause are raised as
:class:`UserError` (or a ``MapError``/``ConfigError``) and printed as one line, no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ["maps", "demo", "export", "train", "library", "plot", "show", "cruise"]


class UserError(Exception):
    """A problem the user can fix; printed as one line and exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    from garage_mj import __version__

    parser = argparse.ArgumentParser(
        prog="garage-mj",
        description=(
            "Generate adverse underground-garage scenarios with deep RL, export them as "
            "OpenDRIVE/MJCF/GLB asset packs, and test driving algorithms in them in MuJoCo."
        ),
    )
    parser.add_argument("--version", action="version", version=f"garage-mj {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"garage_mj.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    from garage_mj.config import ConfigError
    from garage_mj.garage import MapError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (UserError, MapError, ConfigError) as exc:
        print(f"garage-mj {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"garage-mj {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
