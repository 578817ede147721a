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

The folder is built beside ``DIR`` and then renamed into place (a previous package of ours at
``DIR`` is replaced whole); a ``DIR`` holding anything else is refused.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Iterable
from pathlib import Path

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write, make_temp_dir, swap_in_dir
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


def _ours(folder: Path) -> bool:
    """Whether ``folder`` is empty or a package this module wrote (its JSON, its map folders only)."""
    entries = list(folder.iterdir())
    if not entries:
        return True
    description = folder / f"{folder.name}.json"
    try:
        maps = {m["name"] for m in json.loads(description.read_text())["maps"]}
    except (OSError, ValueError, KeyError, TypeError):
        return False
    for entry in entries:
        if entry == description:
            continue
        if entry.is_symlink() or not entry.is_dir() or entry.name not in maps:
            return False
        if {p.name for p in entry.iterdir()} - {f"{entry.name}.fbx", f"{entry.name}.xodr"}:
            return False
    return True


def check_target(out_dir: str | Path) -> Path:
    """``out_dir`` as a package folder, or one line saying why it cannot be one (before any work)."""
    out_dir = Path(out_dir)
    if not _NAME.fullmatch(out_dir.resolve().name):
        raise CarlaPackageError(
            f"--carla-package {out_dir}: CARLA takes the folder's name {out_dir.resolve().name!r} as the "
            "package name in Unreal paths; name the folder with letters, digits and underscores only")
    problem = fbx_problem()
    if problem is not None:
        raise CarlaPackageError(f"--carla-package {out_dir}: CARLA imports maps as FBX; {problem}")
    if out_dir.is_symlink() or (out_dir.exists() and not out_dir.is_dir()):
        raise CarlaPackageError(f"--carla-package {out_dir} is not a folder; give a new or empty folder")
    if out_dir.is_dir() and not _ours(out_dir):
        raise CarlaPackageError(
            f"--carla-package {out_dir} holds files that are not a garage-mj CARLA package (CARLA would "
            "import any .json there as a package); give a new or empty folder")
    _check_writable(out_dir)
    return out_dir


def _check_writable(out_dir: Path) -> None:
    """Refuse a package folder this process cannot write: the package is built beside it and renamed in
    (so its folder must be writable), and a package there already is moved aside (so it must be too)."""
    above = next((p for p in out_dir.resolve().parents if p.exists()), None)
    for folder in ([out_dir] if out_dir.is_dir() else []) + ([above] if above is not None else []):
        if not os.access(folder, os.W_OK | os.X_OK):
            raise CarlaPackageError(f"--carla-package {out_dir}: the folder {folder} is read-only; make it writable "
                                    "or choose another folder")


def write_carla_package(garages: Iterable[Garage], out_dir: str | Path, *, use_carla_materials: bool = True) -> Path:
    """Lay out ``garages`` as a CARLA import package in ``out_dir``; returns the package JSON.

    One map per distinct garage (see the module docstring); ``use_carla_materials`` gives the
    floor and the markings CARLA's road and lane-marking materials.
    """
    out_dir = check_target(out_dir)
    garages = [validate_garage(g) for g in garages]
    if not garages:
        raise CarlaPackageError(f"--carla-package {out_dir}: no garage to put in it")
    parent = out_dir.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    package = out_dir.resolve().name
    try:
        tmp = make_temp_dir(parent, f".{package}.", ".tmp")
    except OSError as exc:  # name the package folder, not the temp folder beside it
        raise CarlaPackageError(f"--carla-package {out_dir}: cannot write in {parent} ({exc.strerror}); make it "
                                "writable or choose another folder") from None
    try:
        maps, seen = [], set()
        for garage in garages:
            name = map_name(garage)
            if name in seen:
                continue
            seen.add(name)
            folder = tmp / name
            folder.mkdir()
            scene = GarageScene(garage)
            write_xodr(scene, folder / f"{name}.xodr")
            write_fbx(garage_meshes(scene), folder / f"{name}.fbx", names=CARLA_NAMES)
            maps.append({"name": name, "source": f"./{name}/{name}.fbx",
                         "use_carla_materials": use_carla_materials, "xodr": f"./{name}/{name}.xodr"})
        atomic_write(tmp / f"{package}.json", json.dumps({"maps": maps, "props": []}, indent=2) + "\n")
        final = parent / package
        try:
            swap_in_dir(tmp, final)
        except OSError as exc:
            raise CarlaPackageError(f"--carla-package {out_dir}: cannot replace it ({exc.strerror}); make it and "
                                    f"{parent} writable or choose another folder") from None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final / f"{package}.json"
