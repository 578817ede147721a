"""Asset packs: one folder per garage with every export and a manifest of hashes.

A pack folder ``<name>_<hash12>/`` holds the files of :data:`garage_mj.export.artefacts.ARTEFACTS`
(``garage.json``, ``garage.xodr`` (OpenDRIVE 1.8), ``scene.xml`` (MJCF, + assets), ``garage.glb``,
``garage.obj`` + ``garage.mtl``, ``garage.fbx``, ``preview.png``), written in that table's order
from one :class:`~garage_mj.scene.garage_scene.GarageScene`, and ``manifest.json`` (sha256 of every
file, metrics, garage hash, park geometry, tool versions, creation time).

The park geometry (docs/spec.md section 9: stall width, depth and angle, aisle width, parallel slot
length) is the pack's parameter: the manifest's ``geometry`` records it, every file is built in it, and
:attr:`Pack.world` reads it back (a pack without it, written before geometry was a parameter, reads as
today's defaults). A pack of another than the default geometry has it in its folder name
(``<name>-bay2.3x4.5-aisle6.5-angle90_<hash12>``), so that packs of one garage in two geometries
live side by side.

A file whose dependency is missing and whose record says to skip it (``garage.fbx`` needs Assimp,
PyPI ``cmeel-assimp``, a dependency on Linux and macOS) is left out and the pack says so: the
manifest's ``skipped`` maps the file to the reason, ``garage-mj export`` prints that reason once,
and a later export with the dependency rebuilds such a pack. A pack that neither lists nor skips
a file of :data:`PACK_FILES` is incomplete.

Writes are atomic: a pack is built in a hidden temp folder beside its final path, then renamed
into place, so a crash never leaves a half pack at the final path. Re-running skips a complete
pack (manifest present, every hash verifies) and rebuilds a partial or broken one.

A pack is not trusted because it has a manifest: :func:`load_pack` also checks that every listed
path stays inside the folder (no ``..``, no absolute path, no symlink), that ``garage.json`` is the
garage the manifest's ``garage_hash`` and the folder name say, and that it is a usable garage.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from tqdm import tqdm

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import FolderLock, atomic_write, clean_temp, ensure_dir, make_temp_dir, swap_in_dir
from garage_mj.export import artefacts as table
from garage_mj.export.artefacts import GARAGE_JSON, INDEX, MANIFEST, PackInputs, WhenMissing
from garage_mj.grid.garage import Garage, MapError, validate_garage
from garage_mj.grid.metrics import evaluate
from garage_mj.scene.drivable import drivability
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.stalls import stall_layout
from garage_mj.scene.world import DEFAULT_WORLD, GeometryError, WorldConfig, geometry, world_with

PACK_FORMAT = 1
#: Files every pack holds besides the manifest (scene assets, if any, are listed in the manifest).
PACK_FILES = table.pack_files()
#: Files a pack may be written without, with the reason in the manifest's ``skipped`` table.
OPTIONAL_FILES = table.optional_files()
_TOOLS = ("garage-mj", "mujoco", "dm-control", "trimesh", "cmeel-assimp")


class PackError(GarageMJError):
    """A pack folder cannot be used; the message names the folder and the fix."""


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _versions() -> dict[str, str]:
    out = {}
    for tool in _TOOLS:
        try:
            out[tool] = metadata.version(tool)
        except metadata.PackageNotFoundError:
            out[tool] = "unknown"
    return out


def pack_name(garage: Garage, world: WorldConfig = DEFAULT_WORLD) -> str:
    """Folder name of ``garage``'s pack: a filesystem-safe name, the park geometry when it is not the
    default (:func:`geometry_tag`), and 12 hex digits of the garage's hash."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", garage.name or "garage")[:64].strip("-.") or "garage"
    return f"{safe}{geometry_tag(world)}_{garage.canonical_hash()[:12]}"


def geometry_tag(world: WorldConfig) -> str:
    """``-bay2.3x4.5-aisle6.5-angle90`` (``-slot6`` added for parallel slots): what a pack folder's name says
    of a park geometry other than the default ("" for the default)."""
    if world.is_default_geometry:
        return ""
    g = geometry(world)
    tag = f"-bay{g['stall_width']:g}x{g['stall_depth']:g}-aisle{g['aisle_width']:g}-angle{g['stall_angle']:g}"
    return tag + (f"-slot{g['slot_length']:g}" if g["stall_angle"] == 0 else "")


def manifest_world(manifest: dict, where: str = "manifest") -> WorldConfig:
    """The world a pack was built in: its manifest's ``geometry`` (none: the defaults)."""
    geo = manifest.get("geometry")
    if geo is None:
        return DEFAULT_WORLD
    if not isinstance(geo, dict):
        raise GeometryError(f"{where}: geometry is not a table of {', '.join(geometry(DEFAULT_WORLD))}")
    return world_with(geo, where=where)


@dataclass(frozen=True)
class Pack:
    """A verified pack folder."""

    path: Path
    manifest: dict

    @property
    def garage(self) -> Garage:
        return Garage.from_json((self.path / GARAGE_JSON).read_text(), source=str(self.path / GARAGE_JSON))

    @property
    def world(self) -> WorldConfig:
        """The world the pack was built in (its park geometry; a pack without one: the defaults)."""
        return manifest_world(self.manifest, f"pack {self.path}")

    def file(self, name: str) -> Path:
        """Path of one of the pack's files (``"scene.xml"``, ``"garage.glb"``, ...)."""
        if name not in self.manifest["files"]:
            raise PackError(f"pack {self.path} has no file {name!r}; it holds {sorted(self.manifest['files'])}")
        return self.path / name


def _member_problem(pack: Path, name: str) -> str | None:
    """Why manifest entry ``name`` is not a plain file inside ``pack``, or None."""
    parts = name.split("/")
    if not name or name.startswith("/") or "\\" in name or any(p in ("", ".", "..") for p in parts):
        return f"the manifest lists {name[:80]!r}, a path outside the pack"
    p = pack
    for part in parts:
        p = p / part
        if p.is_symlink():
            return f"{name[:80]} is a symlink; a pack holds plain files only"
    if not p.is_file():
        return f"{name[:80]} missing"
    return None


def _check(path: Path) -> tuple[str | None, dict]:
    """(why ``path`` is not a complete, genuine pack or None, its manifest)."""
    if path.is_symlink() or not path.is_dir():
        return "the folder is missing", {}
    mf = path / MANIFEST
    if mf.is_symlink() or not mf.is_file():
        return f"{MANIFEST} missing", {}
    try:
        manifest = json.loads(mf.read_bytes().decode("utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError, OSError) as exc:
        return f"{MANIFEST} is unreadable ({type(exc).__name__})", {}
    files = manifest.get("files") if isinstance(manifest, dict) else None
    if not isinstance(files, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        return f"{MANIFEST} has no 'files' table of name -> sha256", {}
    if not isinstance(manifest.get("garage_hash"), str):
        return f"{MANIFEST} has no garage_hash", {}
    skipped = manifest.get("skipped", {})
    if not isinstance(skipped, dict) or not set(skipped) <= set(table.optional_files()):
        return f"{MANIFEST} skips files a pack must hold: {sorted(skipped)[:5]}", {}
    for artefact in table.ARTEFACTS:
        for name in artefact.files:  # a skipped artefact's companions are skipped with it
            if name not in files and artefact.name not in skipped:
                return f"{name} not in the manifest", {}
    for name, digest in files.items():
        problem = _member_problem(path, name)
        if problem is not None:
            return problem, {}
        if _sha256(path / name) != digest:
            return f"{name} does not match its hash in the manifest", {}
    try:
        garage = Garage.from_json((path / GARAGE_JSON).read_bytes(), source=str(path / GARAGE_JSON), usable=True)
    except MapError as exc:
        return f"{GARAGE_JSON} is not a garage ({exc})", {}
    digest = garage.canonical_hash()
    if digest != manifest["garage_hash"]:
        return f"{GARAGE_JSON} is not the garage of the manifest's garage_hash", {}
    if not path.name.endswith(f"_{digest[:12]}"):
        return f"its folder name does not end in _{digest[:12]}, the hash of its {GARAGE_JSON}", {}
    try:
        manifest_world(manifest)
    except GeometryError as exc:
        return f"its park geometry cannot be read ({exc})", {}
    return None, manifest


def _problem(path: Path) -> str | None:
    """Why ``path`` is not a complete pack, or None when it is."""
    return _check(path)[0]


def load_pack(path: str | Path) -> Pack:
    """Open a pack folder, verifying every file and the garage against the manifest."""
    path = Path(path)
    problem, manifest = _check(path)
    if problem is not None:
        raise PackError(f"pack {path} is incomplete: {problem}; re-run garage-mj export to repair it")
    return Pack(path, manifest)


def _write_files(scene: GarageScene, tmp: Path) -> dict[str, str]:
    """Every artefact of :data:`~garage_mj.export.artefacts.ARTEFACTS` in order, all drawn from one
    :class:`GarageScene` (each part derived once).

    Returns the files left out, each with the reason (``garage.fbx`` without Assimp).
    """
    inputs = PackInputs(scene)
    skipped = {}
    for artefact in table.ARTEFACTS:
        problem = artefact.problem()
        if problem is None:
            artefact.write(inputs, tmp / artefact.name)
        elif artefact.when_missing is WhenMissing.SKIP:
            skipped[artefact.name] = problem
        else:
            raise PackError(f"cannot write {artefact.name} into asset packs: {problem}")
    return skipped


def _writable_now(skipped: dict[str, str]) -> bool:
    """Whether a file a pack skipped could be written now (its dependency is back)."""
    return any(a.name in skipped and a.problem() is None for a in table.ARTEFACTS)


def _manifest(scene: GarageScene, tmp: Path, skipped: dict[str, str]) -> dict:
    garage = scene.garage
    files = {
        p.relative_to(tmp).as_posix(): _sha256(p) for p in sorted(tmp.rglob("*")) if p.is_file()
    }
    return {
        "format": PACK_FORMAT,
        "name": garage.name,
        "garage_hash": garage.canonical_hash(),
        "shape": list(garage.shape),
        "metrics": evaluate(garage).to_dict(),
        "geometry": geometry(scene.world),  # the park geometry every file was built in (docs/spec.md section 9)
        "drivability": drivability(scene),  # for models/car: feasible stalls, clearance, curvature
        "files": files,
        "skipped": skipped,
        "versions": _versions(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }


def export_pack(garage: Garage, out_dir: str | Path, *, force: bool = False, world: WorldConfig = DEFAULT_WORLD) -> Path:
    """Write ``garage``'s pack under ``out_dir``, built in ``world`` (its park geometry); returns the pack folder.

    Skips a complete pack unless ``force``; a partial or broken one is rebuilt, and so is one
    written without a file whose dependency is now there (``garage.fbx`` once Assimp is).
    Atomic: files go to a temp folder beside the target first, then one rename publishes the pack.
    """
    validate_garage(garage)
    out_dir = ensure_dir(out_dir, "--out")
    final = out_dir / pack_name(garage, world)
    if not force:
        problem, manifest = _check(final)
        if problem is None and not (manifest.get("skipped") and _writable_now(manifest["skipped"])) \
                and geometry(manifest_world(manifest)) == geometry(world):
            return final  # complete, in this geometry, and nothing it skipped could be written now
    tmp = make_temp_dir(out_dir, f".{final.name}.", ".tmp")
    try:
        scene = GarageScene(garage, world)
        skipped = _write_files(scene, tmp)
        manifest = _manifest(scene, tmp, skipped)
        atomic_write(tmp / MANIFEST, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        if final.is_symlink() or final.is_file():
            final.unlink()
        swap_in_dir(tmp, final)  # a partial, broken or forced old pack is moved aside, then dropped
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def export_packs(
    garages: Iterable[Garage], out_dir: str | Path, *, force: bool = False, progress: bool = True,
    total: int | None = None, world: WorldConfig = DEFAULT_WORLD,
) -> list[Path]:
    """Export many packs under ``out_dir``, built in ``world``, and write the set's ``index.json``; returns the folders.

    Holds the lock of ``out_dir`` (a second export into it is refused, naming this one) and first
    removes the hidden temp folders a killed export left behind. Every garage is validated
    (:func:`garage_mj.grid.garage.validate_garage`), and its stalls laid out in ``world``
    (:func:`check_geometry`), before any file is written.
    """
    garages = [validate_garage(g) for g in garages]
    check_geometry(garages, world)
    out_dir = ensure_dir(out_dir, "--out")
    with FolderLock(out_dir, "garage-mj export", remove=True):
        clean_temp(out_dir)
        paths = []
        for garage in tqdm(garages, total=total, desc="export", unit="pack", disable=not progress):
            paths.append(export_pack(garage, out_dir, force=force, world=world))
        write_index(out_dir)
    return paths


def check_geometry(garages: Iterable[Garage], world: WorldConfig) -> None:
    """Refuse a park geometry one of ``garages`` cannot be built in (a :class:`GeometryError` naming the garage,
    the block and the fix), before anything is written."""
    if world.is_default_geometry:
        return  # every garage holds the default geometry
    for garage in garages:
        stall_layout(garage, world)


def write_index(out_dir: str | Path) -> Path:
    """(Re)write ``index.json``: one entry per complete pack in ``out_dir``, sorted by folder.

    A folder that is not a complete, genuine pack is listed under ``skipped`` with the reason.
    """
    out_dir = Path(out_dir)
    entries, skipped = [], []
    for folder in sorted(p for p in out_dir.iterdir() if p.is_dir() and not p.name.startswith(".")):
        problem, m = _check(folder)
        if problem is not None:
            skipped.append({"folder": folder.name, "problem": problem})
            continue
        try:
            entry = {
                "folder": folder.name,
                "name": m["name"],
                "garage_hash": m["garage_hash"],
                "shape": m["shape"],
                "difficulty": m["metrics"]["difficulty"],
                "coverage": m["metrics"]["coverage"],
                "stalls": m["metrics"]["stalls"],
                "usable": m["metrics"]["usable"],
                "geometry": geometry(manifest_world(m)),
                "created": m["created"],
            }
        except (KeyError, TypeError):
            skipped.append({"folder": folder.name, "problem": f"{MANIFEST} lacks the metrics"})
            continue
        entries.append(entry)
    index = {"format": PACK_FORMAT, "packs": entries, "count": len(entries), "skipped": skipped}
    return atomic_write(out_dir / INDEX, json.dumps(index, indent=2) + "\n")
