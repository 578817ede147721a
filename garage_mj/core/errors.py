"""The one base class of every error a user can cause.

Each stage keeps its own subclass (``MapError``, ``ConfigError``, ``LibraryError``, ``PackError``,
``CruiseError``, ...), and the CLI turns any :class:`GarageMJError` into one line on stderr and
exit status 2, never a traceback (``garage-mj --debug`` shows it). A message names the file (and the
row or cell) and the fix.
"""

from __future__ import annotations


class GarageMJError(Exception):
    """A problem the user can fix (bad input file, busy or unwritable folder, bad setting).

    ``details``: the traceback of the failure behind it, when there is one (a user's driver that
    raised, say), kept as text so that it survives a worker process; ``garage-mj --debug`` prints it.
    """

    details: str | None = None


class FolderBusy(GarageMJError):
    """Another garage-mj process holds the lock of an output folder."""
