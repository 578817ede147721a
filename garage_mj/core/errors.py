"""The one base class of every error a user can cause.

Each stage keeps its own subclass (``MapError``, ``ConfigError``, ``LibraryError``, ``PackError``,
``CruiseError``, ...), and the CLI turns any :class:`GarageMJError` into one line on stderr and
exit status 2, never a traceback (``garage-mj --debug`` shows it). A message names the file (and the
row or cell) and the fix.
"""

from __future__ import annotations

import unicodedata


class GarageMJError(Exception):
    """A problem the user can fix (bad input file, busy or unwritable folder, bad setting).

    ``details``: the traceback of the failure behind it, when there is one (a user's driver that
    raised, say), kept as text so that it survives a worker process; ``garage-mj --debug`` prints it.
    """

    details: str | None = None


class FolderBusy(GarageMJError):
    """Another garage-mj process holds the lock of an output folder."""


#: Unicode categories that make a terminal do something instead of showing a character: C0/C1
#: controls (escape sequences, newline, bell), format characters (bidi overrides), surrogates,
#: line and paragraph separators.
CONTROL_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})


def control_character(text: str) -> str | None:
    """The first character of ``text`` a terminal would act on rather than print, or None.

    Names a user gives (garage names, library map and run names) are refused when they hold one,
    so that nothing printed later can clear the screen, retitle the terminal or split a line.
    """
    return next((ch for ch in text if unicodedata.category(ch) in CONTROL_CATEGORIES), None)


def printable(text: str) -> str:
    """``text`` with every control character (:func:`control_character`) written as its escape (``\\x1b``)."""
    if control_character(text) is None:
        return text
    return "".join(ch.encode("unicode_escape").decode("ascii") if unicodedata.category(ch) in CONTROL_CATEGORIES
                   else ch for ch in text)
