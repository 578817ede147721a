"""``garage.fbx``: the garage meshes as binary FBX, written by Assimp's FBX exporter.

The FBX holds exactly what ``garage.glb`` holds (:mod:`garage_mj.export.meshes`): one mesh
(an FBX ``Model`` with its ``Geometry``) and one material per semantic class, named after the
class (``floor``, ``wall``, ``parkedcar``, ...), coloured as in the GLB, with flat normals.

Axes and units follow CARLA (and Unreal's FBX import target): **Z up, metres, right-handed,
file (x, y, z) = world (x east, y north, z up)**, the same x and y as ``garage.xodr``'s
inertial frame. The file's ``GlobalSettings`` say so: ``UpAxis`` 2 (+Z), ``FrontAxis`` 1 with
sign -1 (-Y), ``CoordAxis`` 0 (+X), which is the axis system Unreal converts every FBX to, so
its conversion is the identity here; ``UnitScaleFactor`` 100 (one file unit is 100 cm), which
Unreal's ``bConvertSceneUnit`` (set by CARLA's ``make import``) turns into centimetres. Unreal
then mirrors y to its left-handed frame exactly as CARLA maps OpenDRIVE ``(x, y)`` to Unreal
``(x, -y)``, so the meshes land on the roads. Blender's importer reads the same file as Z up in
metres with world x and y unchanged (the read-back test checks this).

How it is written: the trimesh scene is handed to Assimp (libassimp from the PyPI package
``cmeel-assimp``, Linux and macOS wheels) as an in-memory GLB in the world frame; Assimp imports
it (generating flat normals, dropping its own unused default material) and its FBX exporter
(``aiExportSceneToBlob``, format ``fbx``, FBX 7.5 binary) writes the file. The exporter takes
the ``GlobalSettings`` values above from the scene's metadata, which is set for the export only;
the header's creation time stamp is then fixed to 1970-01-01 so that a garage's FBX is the same
bytes on every run.
The binding is a few C calls through :mod:`ctypes` (Assimp's C API, ``cimport.h`` and
``cexport.h``); Assimp writes the whole file, here only the stamp's seven numbers are set. :func:`fbx_problem` says why FBX cannot be written
in this environment (no wheel for the platform) and how to get it.
"""

from __future__ import annotations

import ctypes
import struct
from collections.abc import Mapping
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import numpy as np
import trimesh

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write
from garage_mj.export.meshes import Z_UP_TO_Y_UP

ASSIMP_PACKAGE = "cmeel-assimp"  # PyPI package shipping libassimp (Linux and macOS wheels)
UNIT_SCALE_FACTOR = 100.0  # [cm per file unit]: FBX's unit is the centimetre, so 100 says metres
#: FBX GlobalSettings written through the scene metadata that Assimp's FBX exporter reads.
#: Axis 0/1/2 = x/y/z: up +Z, front -Y, coord +X (Blender's and Unreal's right-handed Z-up system).
GLOBAL_SETTINGS: dict[str, int | float] = {
    "UpAxis": 2, "UpAxisSign": 1, "FrontAxis": 1, "FrontAxisSign": -1, "CoordAxis": 0, "CoordAxisSign": 1,
    "OriginalUpAxis": 2, "OriginalUpAxisSign": 1,
    "UnitScaleFactor": UNIT_SCALE_FACTOR, "OriginalUnitScaleFactor": UNIT_SCALE_FACTOR,
}
#: File (glTF, y up) -> world (z up): the inverse of meshes.Z_UP_TO_Y_UP.
Y_UP_TO_Z_UP = np.linalg.inv(Z_UP_TO_Y_UP)

# Assimp post-processing flags (postprocess.h) for the import of the GLB.
_GEN_NORMALS = 0x20  # flat normals (the GLB has none: glTF viewers draw boxes flat)
_VALIDATE = 0x400  # aiProcess_ValidateDataStructure
_REMOVE_REDUNDANT_MATERIALS = 0x1000  # drops the importer's unused default material
_RRM_EXCLUDE_LIST = b"PP_RRM_EXCLUDE_LIST"  # materials that step must keep as they are
_AI_INT32, _AI_DOUBLE = 1, 4  # aiMetadataType (metadata.h)
#: The header's CreationTimeStamp, fixed: Assimp writes the local time there, and one garage must
#: always give the same bytes (packs are reproducible; their hashes compare across runs).
CREATION_TIME = {"Year": 1970, "Month": 1, "Day": 1, "Hour": 0, "Minute": 0, "Second": 0, "Millisecond": 0}
_AI_MAXLEN = 1024  # aiString's buffer (types.h)


class FbxError(GarageMJError):
    """FBX cannot be written here (Assimp missing) or Assimp refused the scene; the message says why."""


class _AiString(ctypes.Structure):
    _fields_ = [("length", ctypes.c_uint32), ("data", ctypes.c_char * _AI_MAXLEN)]


class _AiMetadataEntry(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int), ("data", ctypes.c_void_p)]


class _AiMetadata(ctypes.Structure):
    _fields_ = [("count", ctypes.c_uint), ("keys", ctypes.POINTER(_AiString)),
                ("values", ctypes.POINTER(_AiMetadataEntry))]


class _AiScene(ctypes.Structure):
    """The leading fields of ``aiScene`` (scene.h) up to ``mMetaData``: all this module touches."""

    _fields_ = [
        ("flags", ctypes.c_uint), ("root", ctypes.c_void_p),
        ("num_meshes", ctypes.c_uint), ("meshes", ctypes.c_void_p),
        ("num_materials", ctypes.c_uint), ("materials", ctypes.c_void_p),
        ("num_animations", ctypes.c_uint), ("animations", ctypes.c_void_p),
        ("num_textures", ctypes.c_uint), ("textures", ctypes.c_void_p),
        ("num_lights", ctypes.c_uint), ("lights", ctypes.c_void_p),
        ("num_cameras", ctypes.c_uint), ("cameras", ctypes.c_void_p),
        ("metadata", ctypes.c_void_p),  # aiMetadata*, as an address (a POINTER field would alias the struct)
    ]


class _AiExportDataBlob(ctypes.Structure):
    _fields_ = [("size", ctypes.c_size_t), ("data", ctypes.c_void_p), ("name", _AiString),
                ("next", ctypes.c_void_p)]


def _ai_string(text: str) -> _AiString:
    raw = text.encode()
    if len(raw) >= _AI_MAXLEN:
        raise FbxError(f"Assimp takes strings of at most {_AI_MAXLEN - 1} bytes; got {len(raw)}")
    return _AiString(len(raw), raw)


def _library_files() -> list[Path]:
    try:
        files = metadata.files(ASSIMP_PACKAGE) or []
    except metadata.PackageNotFoundError:
        return []
    libs = [f for f in files if f.name.startswith("libassimp") and (".so" in f.name or f.name.endswith(".dylib"))]
    return [Path(str(f.locate())) for f in sorted(libs, key=lambda f: len(f.name))]


@lru_cache(maxsize=1)
def _assimp() -> ctypes.CDLL | str:
    """The loaded libassimp with its C signatures, or why it cannot be loaded (with the fix)."""
    paths = _library_files()
    if not paths:
        return (f"FBX export needs Assimp, from the PyPI package {ASSIMP_PACKAGE} (a dependency of garage-mj "
                f"on Linux and macOS): run `pip install '{ASSIMP_PACKAGE}>=6.0,<7'`")
    errors = []
    for path in paths:
        try:
            lib = ctypes.CDLL(str(path))
            break
        except OSError as exc:
            errors.append(str(exc))
    else:
        return f"libassimp from {ASSIMP_PACKAGE} does not load ({errors[-1]}); reinstall it: " \
               f"`pip install --force-reinstall '{ASSIMP_PACKAGE}>=6.0,<7'`"
    scene_p = ctypes.POINTER(_AiScene)
    lib.aiCreatePropertyStore.restype = ctypes.c_void_p
    lib.aiCreatePropertyStore.argtypes = []
    lib.aiReleasePropertyStore.argtypes = [ctypes.c_void_p]
    lib.aiSetImportPropertyString.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.POINTER(_AiString)]
    lib.aiImportFileFromMemoryWithProperties.restype = scene_p
    lib.aiImportFileFromMemoryWithProperties.argtypes = [
        ctypes.c_char_p, ctypes.c_uint, ctypes.c_uint, ctypes.c_char_p, ctypes.c_void_p]
    lib.aiReleaseImport.argtypes = [scene_p]
    lib.aiExportSceneToBlob.restype = ctypes.POINTER(_AiExportDataBlob)
    lib.aiExportSceneToBlob.argtypes = [scene_p, ctypes.c_char_p, ctypes.c_uint]
    lib.aiReleaseExportBlob.argtypes = [ctypes.POINTER(_AiExportDataBlob)]
    lib.aiGetErrorString.restype = ctypes.c_char_p
    return lib


def fbx_problem() -> str | None:
    """Why FBX cannot be written in this environment, naming the fix; None when it can."""
    lib = _assimp()
    return lib if isinstance(lib, str) else None


def _library() -> ctypes.CDLL:
    lib = _assimp()
    if isinstance(lib, str):
        raise FbxError(lib)
    return lib


def _metadata(settings: Mapping[str, int | float]) -> tuple[_AiMetadata, list]:
    """An ``aiMetadata`` holding ``settings`` (ints as int32, floats as double) and the buffers it points to."""
    n = len(settings)
    keys, values, keep = (_AiString * n)(), (_AiMetadataEntry * n)(), []
    for i, (key, value) in enumerate(settings.items()):
        keys[i] = _ai_string(key)
        if isinstance(value, float):
            data, kind = ctypes.c_double(value), _AI_DOUBLE
        else:
            data, kind = ctypes.c_int32(value), _AI_INT32
        keep.append(data)
        values[i] = _AiMetadataEntry(kind, ctypes.addressof(data))
    keep += [keys, values]
    return _AiMetadata(n, keys, values), keep


def _fixed_time(data: bytes) -> bytes:
    """``data`` with :data:`CREATION_TIME` in its header's CreationTimeStamp (seven int32 fields).

    Each field is a binary FBX node record whose name (length byte, name) is followed by its one
    property, type code ``I`` and a little-endian int32; exactly one such record per field.
    """
    out = bytearray(data)
    for key, value in CREATION_TIME.items():
        tag = bytes([len(key)]) + key.encode() + b"I"
        at = out.find(tag)
        if at < 0 or out.find(tag, at + 1) >= 0:
            raise FbxError(f"Assimp's FBX has no single CreationTimeStamp {key} field; cannot make it reproducible")
        out[at + len(tag):at + len(tag) + 4] = struct.pack("<i", value)
    return bytes(out)


def world_scene(scene: trimesh.Scene, names: Mapping[str, str] | None = None) -> trimesh.Scene:
    """``scene`` (glTF frame, y up) in the world frame (z up), nodes renamed by ``names``.

    Each node's transform is taken back to the world frame; round-off below 1e-12 is zeroed so
    that the FBX's nodes carry exact identity transforms (the vertices are already in metres).
    """
    out = trimesh.Scene()
    for node in scene.graph.nodes_geometry:
        transform, geom = scene.graph[node]
        matrix = Y_UP_TO_Z_UP @ transform
        matrix[np.abs(matrix) < 1e-12] = 0.0
        name = (names or {}).get(node, node)
        out.add_geometry(scene.geometry[geom], node_name=name, geom_name=name, transform=matrix)
    return out


def fbx_bytes(scene: trimesh.Scene, names: Mapping[str, str] | None = None) -> bytes:
    """The binary FBX of ``scene``, a trimesh scene in the glTF frame (:func:`meshes.garage_meshes`).

    ``names`` renames nodes (class name -> node name; materials keep the class names), e.g. for
    CARLA's semantic tags (:mod:`garage_mj.export.carla_package`).
    """
    lib = _library()
    glb = world_scene(scene, names).export(file_type="glb", include_normals=False)
    materials = sorted({g.visual.material.name for g in scene.geometry.values()})
    store = lib.aiCreatePropertyStore()
    try:
        keep = _ai_string(" ".join(materials))
        lib.aiSetImportPropertyString(store, _RRM_EXCLUDE_LIST, ctypes.byref(keep))
        flags = _GEN_NORMALS | _VALIDATE | _REMOVE_REDUNDANT_MATERIALS
        imported = lib.aiImportFileFromMemoryWithProperties(glb, len(glb), flags, b"glb", store)
    finally:
        lib.aiReleasePropertyStore(store)
    if not imported:
        raise FbxError(f"Assimp could not read the garage meshes: {lib.aiGetErrorString().decode(errors='replace')}")
    try:
        own, _buffers = _metadata(GLOBAL_SETTINGS)  # kept alive until the export is done
        theirs = imported.contents.metadata
        imported.contents.metadata = ctypes.addressof(own)
        try:
            blob = lib.aiExportSceneToBlob(imported, b"fbx", 0)
        finally:
            imported.contents.metadata = theirs  # Assimp frees its own metadata on release, never ours
        if not blob:
            raise FbxError(f"Assimp's FBX exporter failed: {lib.aiGetErrorString().decode(errors='replace')}")
        try:
            return _fixed_time(ctypes.string_at(blob.contents.data, blob.contents.size))
        finally:
            lib.aiReleaseExportBlob(blob)
    finally:
        lib.aiReleaseImport(imported)


def write_fbx(scene: trimesh.Scene, path: str | Path, names: Mapping[str, str] | None = None) -> Path:
    """Write ``scene`` (a trimesh scene in the glTF frame) as binary FBX at ``path``, atomically."""
    return atomic_write(path, fbx_bytes(scene, names))
