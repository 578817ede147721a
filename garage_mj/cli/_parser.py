"""The command line's argument parser: no prefix matching, and a mistyped option answered by its own command.

Stock argparse takes ``--driv vision`` for ``--driver vision`` (a later option starting the same way would
silently change what it means), and reports an option a subcommand does not know with the top-level usage.
:class:`CLIParser` turns prefixes off for every parser of ``garage-mj`` and has each subcommand report its own
unknown options with its usage and the closest option it has ("did you mean --driver?").
"""

from __future__ import annotations

import argparse
import difflib
from typing import Any, NoReturn

#: How close (difflib ratio) an unknown option must be to one of the command's to be suggested.
SUGGEST_CUTOFF = 0.6


class CLIParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` without prefix matching whose subcommands report their own unknown options."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["allow_abbrev"] = False
        super().__init__(*args, **kwargs)
        self.register("action", "parsers", _SubcommandsAction)

    def parse_args(self, args: Any = None, namespace: Any = None) -> argparse.Namespace:  # type: ignore[override]
        """Parse ``args``; an unknown one ends the run as :meth:`unknown` says."""
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            self.unknown(extras)
        return parsed

    def option_strings(self) -> list[str]:
        """Every long and short option this parser (not its subcommands) knows."""
        return [o for action in self._actions for o in action.option_strings]

    def unknown(self, extras: list[str]) -> NoReturn:
        """Exit with this parser's usage, the arguments it does not know and the closest option it has."""
        message = f"unrecognized arguments: {' '.join(extras)}"
        for arg in extras:
            if arg.startswith("-"):
                close = difflib.get_close_matches(arg.split("=")[0], self.option_strings(), n=1, cutoff=SUGGEST_CUTOFF)
                if close:
                    message += f"; did you mean {close[0]}?"
                    break
        self.error(message)


class _SubcommandsAction(argparse._SubParsersAction):
    """The subcommand action, ending the run with the subcommand's own usage when it leaves arguments unknown
    (argparse would hand them up to the top-level parser, whose usage does not list them)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        super().__call__(parser, namespace, values, option_string)
        extras = getattr(namespace, argparse._UNRECOGNIZED_ARGS_ATTR, None)
        sub = self._name_parser_map.get(values[0])
        if extras and isinstance(sub, CLIParser):
            sub.unknown(list(extras))
