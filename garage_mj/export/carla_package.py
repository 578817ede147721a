"""CARLA import packages (``garage-mj export --carla-package DIR``): garages as maps for ``make import``.

CARLA 0.9.x ingests maps built from source with ``make import`` (``Util/BuildTools/Import.py``,
the ``ImportAssets`` commandlet), which reads every package folder under ``carla/Import/``
("Manual package preparation", https://carla.readthedocs.io/en/0.9.16/tuto_M_manual_map_package/).
:func:`write_carla_package` lays out such a package folder::

    DIR/                        the package: copy it into carla/Import/
      DIR.json                  {"maps": [{"name", "source", "use_carla_materials", "xodr"}], "props": []}
      <map>/<map>.fbx           the garage meshes (garage.fbx of the pack, CARLA's tag names)
      <map>/<map>.xodr          the garage's OpenDRIVE (garage.xodr of the pack)

What the import does with it, and so what the layout must be:

- The JSON's file name without ``.json`` is the package name, used in Unreal paths
  (``/Game/<package>/Maps/<map>``); Import.py takes *every* ``*.json`` under ``Import/`` as a
  package, so the folder holds no other JSON. The package name is the folder's name and map
  names are pack names with ``-`` and ``.`` made ``_``: letters, digits and underscores only.
- Per map: ``name`` (the Unreal map; the OpenDRIVE is copied to ``<name>.xodr`` beside it),
  ``source`` (the FBX) and ``xodr``, both relative to the JSON's folder, and
  ``use_carla_materials``; ``props`` lists no props.
- Import.py imports the FBX with Unreal's ``bConvertScene`` and ``bConvertSceneUnit``: the file's
  axes (Z up) and unit (metres) are converted (see :mod:`garage_mj.export.fbx`).
- The ``MoveAssets`` commandlet files a map's meshes for semantic segmentation by name
  (RoadRunner's convention): a name containing ``Road_Road`` goes to ``Static/Road`` (class
  Road), ``Road_Marking`` to ``Static/RoadLines``; with ``use_carla_materials`` the
  ``PrepareAssetsForCooking`` commandlet gives those CARLA's road and lane-marking materials,
  after dropping the name's first ``_``-separated word. So the floor is named
  ``Garage_Road_Road_floor``, the lane and stall markings ``Garage_Road_Marking_roadmark`` and
  ``Garage_Road_Marking_stallmark``, every other class ``Garage_<class>`` (kept with its own
  material). No name contains ``light`` or ``sign``, whose meshes that commandlet leaves out.

An export into ``DIR`` holds its lock for the whole export (:func:`package_lock`: the
``.garage-mj.lock`` of the ``--out`` packs, deleted when the export ends, also on error); a
second export into ``DIR`` meanwhile stops at once with one line naming the folder. A package
accumulates, like ``--out`` packs: maps already in ``DIR`` stay, the JSON lists the old maps and
then the new ones, and a map of a garage already there is rebuilt only when a file of it is
missing (or with ``force``). Each map is built in a hidden ``.<map>.XXXXXXXX.tmp`` folder in
``DIR`` and renamed into place (a map folder already there gets its files renamed over the old
ones, one by one); the JSON is written last, atomically. So the JSON only ever lists whole maps
of whole files: a crash, even ``kill -9``, leaves the earlier package valid, and the next export
removes what the killed one left (its temp folders hold no ``.json``, so ``make import`` skips
them meanwhile). A ``DIR`` holding anything else is refused.
"""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import LOCK_NAME, FolderLock, clean_temp, fsync_dir, make_temp_dir, write_json
from garage_mj.export.fbx import fbx_problem, write_fbx
from garage_mj.export.meshes import CLASS_NAMES, garage_meshes
from garage_mj.export.pack import pack_name
from garage_mj.export.xodr import write_xodr
from garage_mj.grid.garage import Garage, validate_garage
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.semantics import Semantic

#: Node name per class in the package's FBX (CARLA's RoadRunner tags; see the module docstring).
CARLA_NAMES: dict[str, str] = {
    name: "Garage_" + {Semantic.FLOOR: "Road_Road_", Semantic.ROAD_MARKING: "Road_Marking_",
                       Semantic.STALL_MARKING: "Road_Marking_"}.get(cls, "") + name
    for cls, name in CLASS_NAMES.items()
}
_NAME = re.compile(r"[A-Za-z0-9_]+")


class CarlaPackageError(GarageMJError):
    """The CARLA package cannot be written where asked; the message names the folder and the fix."""


def map_name(garage: Garage) -> str:
    """The garage's map name in the package: its pack name with ``-`` and ``.`` made ``_``."""
    return re.sub(r"[^A-Za-z0-9_]", "_", pack_name(garage))


#: Hidden temp entries of this module and :func:`~garage_mj.core.fsutil.atomic_write`:
#: ``.<map>.XXXXXXXX.tmp`` folders and ``.<package>.json.XXXXXXXX.tmp`` files (``mkdtemp``/``mkstemp``).
_TEMP = re.compile(r"\.[A-Za-z0-9_]+(\.json)?\.[a-z0-9_]{8}\.(tmp|old)")
#: A map folder a killed export renamed into place before it wrote the JSON: a map name (12 hex
#: digits of the garage's hash at the end) holding only that map's files.
_MAP = re.compile(r"[A-Za-z0-9_]+_[0-9a-f]{12}")


def _listed(folder: Path) -> list[dict]:
    """The map entries of ``folder``'s package JSON; ``[]`` without one. Raises ``ValueError`` when
    the JSON is not such a package description."""
    description = folder / f"{folder.name}.json"
    if not description.exists():
        return []
    try:
        maps = json.loads(description.read_text())["maps"]
        if not all(isinstance(m, dict) and isinstance(m["name"], str) for m in maps):
            raise TypeError
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{description} is not a package description") from exc
    return maps


def _ours(folder: Path) -> bool:
    """Whether ``folder`` is empty or a package this module wrote: its JSON, its map folders, and
    what a killed export of it can leave (the lock file, temp entries, a map not yet listed)."""
    try:
        maps = {m["name"] for m in _listed(folder)}
    except ValueError:
        return False
    for entry in folder.iterdir():
        if entry.name in (f"{folder.name}.json", LOCK_NAME) or _TEMP.fullmatch(entry.name):
            continue
        if entry.is_symlink() or not entry.is_dir() or not (entry.name in maps or _MAP.fullmatch(entry.name)):
            return False
        if {p.name for p in entry.iterdir()} - {f"{entry.name}.fbx", f"{entry.name}.xodr"}:
            return False
    return True


def _check_name(out_dir: Path) -> None:
    """Refuse a folder that cannot be a package whatever it holds (before anything is created)."""
    if not _NAME.fullmatch(out_dir.resolve().name):
        raise CarlaPackageError(
            f"--carla-package {out_dir}: CARLA takes the folder's name {out_dir.resolve().name!r} as the "
            "package name in Unreal paths; name the folder with letters, digits and underscores only")
    problem = fbx_problem()
    if problem is not None:
        raise CarlaPackageError(f"--carla-package {out_dir}: CARLA imports maps as FBX; {problem}")
    if out_dir.is_symlink() or (out_dir.exists() and not out_dir.is_dir()):
        raise CarlaPackageError(f"--carla-package {out_dir} is not a folder; give a new or empty folder")
    _check_writable(out_dir)


def _check_writable(out_dir: Path) -> None:
    """Refuse a package folder this process cannot write: everything is written inside it, and a
    new one is made in the nearest folder above that exists (so that one must be writable)."""
    folder = out_dir if out_dir.is_dir() else next((p for p in out_dir.resolve().parents if p.exists()), None)
    if folder is not None and not os.access(folder, os.W_OK | os.X_OK):
        raise CarlaPackageError(f"--carla-package {out_dir}: the folder {folder} is read-only; make it writable "
                                "or choose another folder")


def _check_contents(out_dir: Path) -> None:
    """Refuse a folder holding anything but a package of ours (CARLA reads every JSON in it)."""
    if out_dir.is_dir() and not _ours(out_dir):
        raise CarlaPackageError(
            f"--carla-package {out_dir} holds files that are not a garage-mj CARLA package (CARLA would "
            "import any .json there as a package); give a new or empty folder")


@contextmanager
def package_lock(out_dir: str | Path) -> Iterator[Path]:
    """Check ``out_dir`` and hold its lock for the whole export (the CLI takes it before any work).

    A second export into the same folder meanwhile stops with one line ("DIR is in use by
    garage-mj export (pid N)"). Under the lock, a killed export's temp entries are removed. The
    lock file goes when the export ends, and so does a folder made only to hold it.
    """
    out_dir = Path(out_dir)
    _check_name(out_dir)
    with FolderLock(out_dir, "garage-mj export", remove=True):
        _check_contents(out_dir)  # under the lock: no other export is changing it
        clean_temp(out_dir)
        yield out_dir


def _complete(folder: Path) -> bool:
    """Whether the map folder ``folder`` holds both its files."""
    return all((folder / f"{folder.name}{ext}").is_file() for ext in (".fbx", ".xodr"))


def _build_map(garage: Garage, out_dir: Path, name: str) -> None:
    """Build ``garage``'s map in a temp folder in ``out_dir``, then move it into ``out_dir/name``.

    A new map folder is renamed into place whole; into one already there, each file is renamed
    over the old one, so every file in the folder is always whole.
    """
    tmp = make_temp_dir(out_dir, f".{name}.", ".tmp")
    try:
        scene = GarageScene(garage)
        write_xodr(scene, tmp / f"{name}.xodr")
        write_fbx(garage_meshes(scene), tmp / f"{name}.fbx", names=CARLA_NAMES)
        final = out_dir / name
        if final.is_dir():
            for ext in (".xodr", ".fbx"):
                os.replace(tmp / f"{name}{ext}", final / f"{name}{ext}")
            fsync_dir(final)
        else:
            tmp.rename(final)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def write_carla_package(garages: Iterable[Garage], out_dir: str | Path, *, use_carla_materials: bool = True,
                        force: bool = False, locked: bool = False) -> Path:
    """Add ``garages`` to the CARLA import package in ``out_dir`` (made if new); returns the package JSON.

    One map per distinct garage (see the module docstring); maps already in the package are
    kept, and rebuilt only when incomplete or with ``force``. ``use_carla_materials`` gives the
    floor and the markings CARLA's road and lane-marking materials. ``locked``: the caller holds
    :func:`package_lock` (the CLI holds it for the whole export); else this takes it.
    """
    garages = [validate_garage(g) for g in garages]
    if not garages:
        raise CarlaPackageError(f"--carla-package {out_dir}: no garage to put in it")
    if not locked:
        with package_lock(out_dir) as folder:
            return _write(garages, folder, use_carla_materials, force)
    return _write(garages, Path(out_dir), use_carla_materials, force)


def _write(garages: list[Garage], out_dir: Path, use_carla_materials: bool, force: bool) -> Path:
    """The work of :func:`write_carla_package`, under the package lock; a failed write names the package."""
    try:
        return _add_maps(garages, out_dir, use_carla_materials, force)
    except OSError as exc:  # a full disk, a file made read-only meanwhile: name the package, not a temp file
        hint = ("free some disk space and run again" if exc.errno in (errno.ENOSPC, errno.EDQUOT)
                else "make it writable or choose another folder")
        raise CarlaPackageError(f"--carla-package {out_dir}: cannot write in it ({exc.strerror or exc}); {hint} "
                                "(the package keeps the maps it had)") from None


def _add_maps(garages: list[Garage], out_dir: Path, use_carla_materials: bool, force: bool) -> Path:
    """Build the maps missing from the package (or all with ``force``), then write its JSON."""
    package = out_dir.resolve().name
    entries = {m["name"]: m for m in _listed(out_dir)}  # the old maps, in their order; new ones follow
    done: set[str] = set()
    for garage in garages:
        name = map_name(garage)
        if name in done:
            continue
        done.add(name)
        if force or name not in entries or not _complete(out_dir / name):  # an unlisted folder: rebuilt
            _build_map(garage, out_dir, name)
        entries[name] = {"name": name, "source": f"./{name}/{name}.fbx",
                         "use_carla_materials": use_carla_materials, "xodr": f"./{name}/{name}.xodr"}
    fsync_dir(out_dir)  # the map folders' renames are on disk before the JSON lists them
    return write_json(out_dir / f"{package}.json", {"maps": list(entries.values()), "props": []})
