"""What an asset pack holds: one table, :data:`ARTEFACTS`, one record per file.

Each :class:`Artefact` names its file, the function that writes it into a pack folder, the
optional dependency it needs (if any) and what a pack does when that is missing, the functions
of :mod:`garage_mj.export.validate` that check it, and one line saying what it is. Everything
else reads the table: :mod:`garage_mj.export.pack` writes the files in table order, lists them
(or what it skipped, and why) in ``manifest.json`` and checks every one on load;
``garage-mj export`` names the formats in its help, lists the files below it and says which
files a pack is left without here; :mod:`garage_mj.export.validate` finds the files it checks by
these names. A new file in every pack is one record here plus its writer (and its validator).

The module imports no writer (each one imports its module on first use), so the command line
reads the table without loading MuJoCo, trimesh or Assimp.
"""

from __future__ import annotations

import enum
import itertools
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import trimesh

    from garage_mj.scene.garage_scene import GarageScene

#: File names other modules refer to (each spelled here once; the table below uses them).
GARAGE_JSON = "garage.json"
XODR = "garage.xodr"
GLB = "garage.glb"
FBX = "garage.fbx"
PREVIEW = "preview.png"
#: A pack's own record of its files: sha256 of each, what was skipped, metrics, versions, creation time.
MANIFEST = "manifest.json"
#: Beside the packs of one folder: one entry per complete pack (:func:`garage_mj.export.pack.write_index`).
INDEX = "index.json"


def _entry_point(ref: str) -> Any:
    """The object a ``"package.module:name"`` reference names (its module imported on first use)."""
    module, name = ref.split(":")
    return getattr(import_module(module), name)


class PackInputs:
    """What the writers draw from: one :class:`GarageScene`, and the meshes that GLB, OBJ and FBX share (built once)."""

    def __init__(self, scene: GarageScene) -> None:
        self.scene = scene

    @cached_property
    def meshes(self) -> trimesh.Scene:
        from garage_mj.export.meshes import garage_meshes

        return garage_meshes(self.scene)


class WhenMissing(enum.Enum):
    """What a pack does when an artefact's dependency is missing."""

    SKIP = "skip"  # written without it: the manifest's ``skipped`` and one line of ``garage-mj export`` say why
    ERROR = "error"  # the export stops with the dependency's message


@dataclass(frozen=True)
class Dependency:
    """An optional dependency of a writer, and how to ask whether it can be used here."""

    name: str
    package: str  # what to install (PyPI)
    probe: str  # "module:function" returning why it cannot be used here (naming the fix), or None

    def problem(self) -> str | None:
        """Why the dependency cannot be used in this environment, naming the fix; None when it can."""
        return _entry_point(self.probe)()


@dataclass(frozen=True)
class Artefact:
    """One file of every asset pack."""

    name: str  # file name inside the pack folder
    write: Callable[[PackInputs, Path], object]  # writes ``name`` (and its companions) at the given path
    description: str  # one line, for the CLI's help
    label: str = ""  # the format's short name in the CLI's help ("" for none)
    kind: str = ""  # what it is for; labels of neighbouring files of one kind share a slash: GLB/OBJ/FBX
    companions: tuple[str, ...] = ()  # files its writer writes beside it (OBJ's material library)
    needs: Dependency | None = None
    when_missing: WhenMissing = WhenMissing.ERROR  # matters only with ``needs``
    validators: tuple[str, ...] = ()  # "module:function" references of the checks in garage_mj.export.validate

    @property
    def files(self) -> tuple[str, ...]:
        """Its file and its companions."""
        return (self.name, *self.companions)

    def problem(self) -> str | None:
        """Why it cannot be written in this environment (its dependency is missing), or None."""
        return self.needs.problem() if self.needs is not None else None


# -- the writers: (inputs, path) -> the file at path -------------------------------------------------
def _write_garage(inputs: PackInputs, path: Path) -> None:
    path.write_text(inputs.scene.garage.to_json())


def _write_xodr(inputs: PackInputs, path: Path) -> None:
    from garage_mj.export.xodr import write_xodr

    write_xodr(inputs.scene, path)


def _write_mjcf(inputs: PackInputs, path: Path) -> None:
    from garage_mj.scene.mjcf_scene import write_scene

    write_scene(inputs.scene, path.parent, file_name=path.name)


def _write_glb(inputs: PackInputs, path: Path) -> None:
    from garage_mj.export.meshes import write_glb

    write_glb(inputs.meshes, path)


def _write_obj(inputs: PackInputs, path: Path) -> None:
    from garage_mj.export.meshes import write_obj

    write_obj(inputs.meshes, path)


def _write_fbx(inputs: PackInputs, path: Path) -> None:
    from garage_mj.export.fbx import write_fbx

    write_fbx(inputs.meshes, path)


def _write_preview(inputs: PackInputs, path: Path) -> None:
    from garage_mj.export.preview import write_preview

    write_preview(inputs.scene, path)


ASSIMP = Dependency("Assimp", "cmeel-assimp", "garage_mj.export.fbx:fbx_problem")
_VALIDATE = "garage_mj.export.validate"

#: Every file of an asset pack, in the order the pack writes them (besides :data:`MANIFEST`).
ARTEFACTS: tuple[Artefact, ...] = (
    Artefact(GARAGE_JSON, _write_garage, "the garage: its name, grid and initial map (Garage.to_json)", kind="garage"),
    Artefact(XODR, _write_xodr, "the road network as ASAM OpenDRIVE 1.8", "xodr", "road network",
             validators=(f"{_VALIDATE}:check_carla_batch", f"{_VALIDATE}:check_asam_batch")),
    Artefact("scene.xml", _write_mjcf, "the MuJoCo scene (MJCF), and any assets it needs", "MJCF", "simulation"),
    Artefact(GLB, _write_glb, "the meshes as binary glTF, one node per semantic class", "GLB", "meshes"),
    Artefact("garage.obj", _write_obj, "the same meshes as Wavefront OBJ, materials in garage.mtl", "OBJ", "meshes",
             companions=("garage.mtl",)),
    Artefact(FBX, _write_fbx, "the same meshes as binary FBX (Z up, metres)", "FBX", "meshes",
             needs=ASSIMP, when_missing=WhenMissing.SKIP, validators=(f"{_VALIDATE}:check_fbx_batch",)),
    Artefact(PREVIEW, _write_preview, "a top-down picture of the garage", "preview", "picture"),
)


def pack_files() -> tuple[str, ...]:
    """Every file a complete pack holds besides the manifest, in table order (scene assets, if any, come on top)."""
    return tuple(name for a in ARTEFACTS for name in a.files)


def optional_files() -> tuple[str, ...]:
    """The files a pack may be written without (their dependency missing), the reason in the manifest's ``skipped``."""
    return tuple(name for a in ARTEFACTS if a.when_missing is WhenMissing.SKIP and a.needs is not None for name in a.files)


def left_out_here() -> dict[str, str]:
    """File -> why packs written in this environment go without it (a skippable artefact's dependency is missing)."""
    out = {}
    for a in ARTEFACTS:
        if a.when_missing is WhenMissing.SKIP and (problem := a.problem()) is not None:
            out[a.name] = problem
    return out


def formats() -> str:
    """The formats of a pack for the CLI's help: ``xodr, MJCF, GLB/OBJ/FBX, preview``."""
    labelled = [a for a in ARTEFACTS if a.label]
    return ", ".join("/".join(a.label for a in group) for _, group in itertools.groupby(labelled, key=lambda a: a.kind))


def _if_missing(artefact: Artefact) -> str:
    if artefact.needs is None:
        return ""
    verb = "left out without" if artefact.when_missing is WhenMissing.SKIP else "needs"
    return f"; {verb} {artefact.needs.name} ({artefact.needs.package})"


def contents() -> str:
    """One line per file of a pack, for the CLI's help."""
    rows = [(" + ".join(a.files), a.description + _if_missing(a)) for a in ARTEFACTS]
    rows.append((MANIFEST, "sha256 of every file, what was skipped and why, metrics, tool versions"))
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"  {name:{width}s}  {text}" for name, text in rows)
