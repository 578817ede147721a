"""File-system helpers every writer shares: atomic writes and output-folder locks.

* :func:`atomic_write` writes a file through a temp file made with ``mkstemp`` in the target's
  own folder (``O_EXCL``, unpredictable name, never follows a planted symlink), fsyncs it and
  renames it over the target, so a reader sees the old file or the new one, never half of one;
  :func:`write_json` writes JSON through it (every ``run.json``, manifest, summary and ``--json`` file).
* :class:`FolderLock` marks an output folder as in use by one long job (``cruise``, ``export``,
  ``train``, ``demo``); a second job into the same folder is refused with one line naming the
  first one's pid. The lock is an ``flock`` on ``.garage-mj.lock``, so the kernel drops it when
  its process dies, even by ``kill -9``: a stale lock file never blocks a later run. With
  ``remove=True`` the lock file is deleted when the job ends (a CARLA package folder holds only
  the package).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from garage_mj.core.errors import FolderBusy, GarageMJError

LOCK_NAME = ".garage-mj.lock"


def _read_umask() -> int:
    """The process umask, read without changing it where Linux allows (``os.umask`` sets it)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()  # read once: os.umask() would briefly change it for every thread


def public_mode(directory: bool = False) -> int:
    """The mode a normal ``open``/``mkdir`` would give under the process umask (e.g. 0644/0755)."""
    return (0o777 if directory else 0o666) & ~_UMASK


def make_temp_dir(parent: Path, prefix: str, suffix: str) -> Path:
    """``mkdtemp`` in ``parent`` (unpredictable, created exclusively), then the umask's usual mode.

    ``mkdtemp`` makes folders 0700; a published pack should be readable like any other folder.
    """
    tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=parent))
    os.chmod(tmp, public_mode(directory=True))
    return tmp


def swap_in_dir(tmp: Path, final: Path) -> None:
    """Publish the finished folder ``tmp`` (a sibling of ``final``) as ``final``: an existing ``final``
    is first moved aside into a temp folder, then dropped, so ``final`` is never half-written."""
    if final.exists():
        old = make_temp_dir(final.parent, f".{final.name}.", ".old")
        try:
            final.rename(old / final.name)
        except OSError:
            old.rmdir()  # left empty: no trace of the failed swap
            raise
        tmp.rename(final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(final)


def write_error(path: str | Path, exc: OSError) -> GarageMJError:
    """A one-line error for a failed write (read-only folder, disk full, name too long...)."""
    why = exc.strerror or str(exc)
    hint = {errno.EACCES: "make the folder writable or choose another output folder",
            errno.EROFS: "choose an output folder on a writable file system",
            errno.ENOSPC: "free some disk space and run again (finished work is kept)",
            errno.EDQUOT: "free some disk space and run again (finished work is kept)",
            errno.ENOTDIR: "a file stands where a folder is needed; choose another output folder",
            errno.EEXIST: "a file stands where a folder is needed; choose another output folder",
            errno.ENAMETOOLONG: "use a shorter name"}.get(exc.errno or 0, "check the path and run again")
    return GarageMJError(f"cannot write {path}: {why}; {hint}")


def atomic_write(path: str | Path, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` atomically and durably (mkstemp in its folder, fsync, rename).

    A path that names a device or a pipe (``/dev/stdout``) is written in place: renaming over
    it would replace the device with a file.
    """
    path = Path(path)
    raw = data.encode() if isinstance(data, str) else data
    if path.exists() and not path.is_file():
        if path.is_dir():
            raise GarageMJError(f"cannot write {path}: it is a folder; name a file")
        with open(path, "wb") as f:
            f.write(raw)
            f.flush()
        return path
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, public_mode())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    fsync_dir(path.parent)
    return path


def write_json(path: str | Path, data: Any, *, indent: int | None = 2, sort_keys: bool = False,
               default: Callable[[Any], Any] | None = None, end: str = "\n") -> Path:
    """Write ``data`` as JSON to ``path`` through :func:`atomic_write` (durable, never half a file).

    The text is ``json.dumps(data, indent=indent, sort_keys=sort_keys, default=default) + end``: each
    file keeps the layout it has always had (``indent=1`` for the large ones, a final newline).
    """
    return atomic_write(path, json.dumps(data, indent=indent, sort_keys=sort_keys, default=default) + end)


def fsync_dir(folder: str | Path) -> None:
    """fsync a folder so that a rename in it survives a power cut (best effort)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def ensure_dir(path: str | Path, what: str = "output folder") -> Path:
    """``mkdir -p`` with one-line errors (a file in the way, a read-only parent)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise GarageMJError(f"{what} {path} is a file, not a folder; choose another path")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_error(path, exc) from None
    return path


#: Names of the temp files and folders garage-mj makes: ``.<name>.<random>.tmp`` (and ``.old``).
_TEMP = re.compile(r"^\..+\.(tmp|old)$")


def clean_temp(folder: str | Path) -> list[Path]:
    """Remove the hidden ``.<name>.*.tmp``/``.old`` files and folders a killed writer left; returns them.

    Call it only while holding the folder's :class:`FolderLock`: a live writer's temp looks the
    same. Symlinks are removed, never followed.
    """
    gone = []
    for p in Path(folder).iterdir():
        if not _TEMP.match(p.name):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        gone.append(p)
    return gone


HOLDER_WAIT = 2.0  # [s] how long a refused job waits for the holder to write its name into the lock file


def _alive(pid: Any) -> bool:
    """Whether a process ``pid`` exists (on this machine)."""
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, as another user's
        return True
    return True


def _named_holder(fd: int) -> dict:
    """What a lock file open at ``fd`` says of its holder (``pid``, ``what``, ``argv``); {} when it says nothing
    readable (empty, torn or foreign)."""
    try:
        holder = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
    except (ValueError, UnicodeDecodeError):
        return {}
    return holder if isinstance(holder, dict) else {}


def lock_holder(folder: str | Path) -> dict | None:
    """Who holds ``folder``'s :class:`FolderLock` now (the lock file's ``pid``, ``what``, ``argv``), or None.

    Asks the kernel (a shared ``flock`` tried without waiting, and let go at once), so a lock file left by a
    job killed with ``kill -9`` reads as free; creates and writes nothing, and never blocks a holder.
    """
    try:
        fd = os.open(Path(folder) / LOCK_NAME, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _named_holder(fd)
        except OSError:
            return None
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


class FolderLock:
    """Exclusive lock of an output folder for one long job; a context manager.

    ``what`` names the job (``"garage-mj cruise"``); a second holder gets :class:`FolderBusy`:
    "FOLDER is in use by garage-mj cruise (pid 1234); wait for it to finish or use another folder".
    ``remove=True`` deletes the lock file on release (while still holding it); a job that then
    locks the deleted file notices that the name now leads elsewhere and locks afresh. Every job
    that holds its folder's lock from start to end passes it, so no lock file stays behind.

    The folders the lock made (``folder`` and any missing parents) go again on release when nothing but
    the lock file is in them: a job refused before its first write leaves no trace.
    """

    def __init__(self, folder: str | Path, what: str, *, remove: bool = False) -> None:
        self.folder = Path(folder)
        self.what = what
        self.remove = remove
        self._fd: int | None = None
        self._made: list[Path] = []  # the folders acquire() created, deepest first

    def acquire(self) -> FolderLock:
        self._made = [p for p in (self.folder, *self.folder.absolute().parents) if not p.exists()]
        path = self.folder / LOCK_NAME
        while True:
            ensure_dir(self.folder)  # again after a holder that made the folder removed it as it let go
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, public_mode())
            except OSError as exc:
                raise write_error(path, exc) from None
            self._wait(fd)
            if self._still_named(fd, path):
                break
            os.close(fd)  # its holder deleted the file as it let go: lock the file the name leads to now
        info = json.dumps({"pid": os.getpid(), "what": self.what, "argv": sys.argv[1:8]}).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, info, 0)
        self._fd = fd
        return self

    def _wait(self, fd: int) -> None:
        """``flock`` ``fd``, or close it and raise :class:`FolderBusy` naming the holder."""
        holder: dict = {}
        deadline = time.monotonic() + HOLDER_WAIT
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                holder = _named_holder(fd)
            # An empty file: the holder has just taken the lock and not yet said who it is, or is
            # just letting go. A file naming a process that is gone: a killed job's, and the one
            # holding it now only looks (lock_holder) or has not yet written its name. Look again
            # shortly, so the message names the holder (or the lock is ours).
            named = _alive(holder.get("pid"))
            if named or time.monotonic() >= deadline:
                os.close(fd)
                who = f"{holder.get('what', 'another garage-mj process')} (pid {holder.get('pid', '?')})"
                raise FolderBusy(f"{self.folder} is in use by {who}; wait for it to finish or use "
                                 "another output folder") from None
            time.sleep(0.02)

    def _still_named(self, fd: int, path: Path) -> bool:
        """Whether ``path`` still names the file ``fd`` locked (a removing holder may have deleted it; checked
        with or without ``remove``, so a lock that keeps its file is safe beside one that removes it)."""
        try:
            now = os.stat(path, follow_symlinks=False)
        except FileNotFoundError:
            return False
        mine = os.fstat(fd)
        return (now.st_dev, now.st_ino) == (mine.st_dev, mine.st_ino)

    def release(self) -> None:
        if self._fd is not None:
            try:
                if self.remove:
                    os.unlink(self.folder / LOCK_NAME)  # still held: no one else can hold this file now
                else:
                    os.ftruncate(self._fd, 0)
            except OSError:
                pass
            self._remove_made()  # still held: a job waiting for this lock finds the name gone and starts afresh
            os.close(self._fd)  # closing drops the flock; without remove the empty file stays (harmless)
            self._fd = None

    def _remove_made(self) -> None:
        """Remove the folders :meth:`acquire` made when nothing but the lock file is in them (deepest first)."""
        made, self._made = self._made, []
        try:
            if not made or sorted(p.name for p in self.folder.iterdir()) not in ([LOCK_NAME], []):
                return
            (self.folder / LOCK_NAME).unlink(missing_ok=True)
            for folder in made:
                folder.rmdir()  # only when empty: a job's first file keeps it (and its parents)
        except OSError:
            pass

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()
