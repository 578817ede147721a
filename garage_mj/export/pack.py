"""Asset packs: one folder per garage with every export and a manifest of hashes.

A pack folder ``<name>_<hash12>/`` holds ``garage.json``, ``garage.xodr`` (OpenDRIVE 1.8),
``scene.xml`` (MJCF, + assets), ``garage.glb``, ``garage.obj`` + ``garage.mtl``, ``preview.png``
and ``manifest.json`` (sha256 of every file, metrics, garage hash, tool versions, creation time).

Writes are atomic: a pack is built in a hidden temp folder beside its final path, then renamed
into place, so a crash never leaves a half pack at the final path. Re-running skips a complete
pack (manifest present, every hash verifies) and rebuilds a partial or broken one.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from tqdm import tqdm

from garage_mj.export.meshes import garage_meshes, write_glb, write_obj
from garage_mj.export.preview import write_preview
from garage_mj.export.xodr import write_xodr
from garage_mj.errors import GarageMJError
from garage_mj.garage import Garage
from garage_mj.metrics import evaluate
from garage_mj.scene.mjcf_scene import SCENE_XML, write_scene

MANIFEST = "manifest.json"
INDEX = "index.json"
PACK_FORMAT = 1
#: Files every pack holds besides the manifest (scene assets, if any, are listed in the manifest).
PACK_FILES = ("garage.json", "garage.xodr", SCENE_XML, "garage.glb", "garage.obj", "garage.mtl", "preview.png")
_TOOLS = ("garage-mj", "mujoco", "dm-control", "trimesh")


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


def pack_name(garage: Garage) -> str:
    """Folder name of ``garage``'s pack: a filesystem-safe name plus 12 hex digits of its hash."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", garage.name or "garage").strip("-.") or "garage"
    return f"{safe}_{garage.canonical_hash()[:12]}"


@dataclass(frozen=True)
class Pack:
    """A verified pack folder."""

    path: Path
    manifest: dict

    @property
    def garage(self) -> Garage:
        return Garage.from_json((self.path / "garage.json").read_text(), source=str(self.path / "garage.json"))

    def file(self, name: str) -> Path:
        """Path of one of the pack's files (``"scene.xml"``, ``"garage.glb"``, ...)."""
        if name not in self.manifest["files"]:
            raise PackError(f"pack {self.path} has no file {name!r}; it holds {sorted(self.manifest['files'])}")
        return self.path / name


def _problem(path: Path) -> str | None:
    """Why ``path`` is not a complete pack, or None when it is."""
    if not path.is_dir():
        return "the folder is missing"
    mf = path / MANIFEST
    if not mf.is_file():
        return f"{MANIFEST} missing"
    try:
        manifest = json.loads(mf.read_text())
        files = manifest["files"]
    except (json.JSONDecodeError, KeyError, TypeError):
        return f"{MANIFEST} is unreadable"
    for name in PACK_FILES:
        if name not in files:
            return f"{name} not in the manifest"
    for name, digest in files.items():
        f = path / name
        if not f.is_file():
            return f"{name} missing"
        if _sha256(f) != digest:
            return f"{name} does not match its hash in the manifest"
    return None


def load_pack(path: str | Path) -> Pack:
    """Open a pack folder, verifying every file against the manifest."""
    path = Path(path)
    problem = _problem(path)
    if problem is not None:
        raise PackError(f"pack {path} is incomplete: {problem}; re-run garage-mj export to repair it")
    return Pack(path, json.loads((path / MANIFEST).read_text()))


def _write_files(garage: Garage, tmp: Path) -> None:
    (tmp / "garage.json").write_text(garage.to_json())
    write_xodr(garage, tmp / "garage.xodr")
    write_scene(garage, tmp)
    scene = garage_meshes(garage)
    write_glb(scene, tmp / "garage.glb")
    write_obj(scene, tmp / "garage.obj")
    write_preview(garage, tmp / "preview.png")


def _manifest(garage: Garage, tmp: Path) -> dict:
    files = {
        p.relative_to(tmp).as_posix(): _sha256(p) for p in sorted(tmp.rglob("*")) if p.is_file()
    }
    return {
        "format": PACK_FORMAT,
        "name": garage.name,
        "garage_hash": garage.canonical_hash(),
        "shape": list(garage.shape),
        "metrics": evaluate(garage).to_dict(),
        "files": files,
        "versions": _versions(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }


def export_pack(garage: Garage, out_dir: str | Path, *, force: bool = False) -> Path:
    """Write ``garage``'s pack under ``out_dir``; returns the pack folder.

    Skips a complete pack unless ``force``; a partial or broken one is rebuilt. Atomic: files go
    to a temp folder beside the target first, then one rename publishes the pack.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    final = out_dir / pack_name(garage)
    if not force and _problem(final) is None:
        return final
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp", dir=out_dir))
    try:
        _write_files(garage, tmp)
        manifest = _manifest(garage, tmp)
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        if final.exists():  # partial, broken or forced: move the old one aside, then drop it
            old = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old", dir=out_dir))
            final.rename(old / final.name)
            tmp.rename(final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(final)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def export_packs(
    garages: Iterable[Garage], out_dir: str | Path, *, force: bool = False, progress: bool = True,
    total: int | None = None,
) -> list[Path]:
    """Export many packs under ``out_dir`` and write the set's ``index.json``; returns the folders."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for garage in tqdm(garages, total=total, desc="export", unit="pack", disable=not progress):
        paths.append(export_pack(garage, out_dir, force=force))
    write_index(out_dir)
    return paths


def write_index(out_dir: str | Path) -> Path:
    """(Re)write ``index.json``: one entry per complete pack in ``out_dir``, sorted by folder."""
    out_dir = Path(out_dir)
    entries = []
    for folder in sorted(p for p in out_dir.iterdir() if p.is_dir() and not p.name.startswith(".")):
        try:
            pack = load_pack(folder)
        except PackError:
            continue
        m = pack.manifest
        entries.append(
            {
                "folder": folder.name,
                "name": m["name"],
                "garage_hash": m["garage_hash"],
                "shape": m["shape"],
                "difficulty": m["metrics"]["difficulty"],
                "coverage": m["metrics"]["coverage"],
                "stalls": m["metrics"]["stalls"],
                "usable": m["metrics"]["usable"],
                "created": m["created"],
            }
        )
    index = {"format": PACK_FORMAT, "packs": entries, "count": len(entries)}
    path = out_dir / INDEX
    tmp = path.with_name(f".{INDEX}.tmp")
    tmp.write_text(json.dumps(index, indent=2) + "\n")
    tmp.replace(path)
    return path
