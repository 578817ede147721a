"""Writers: OpenDRIVE, meshes, FBX, preview, asset packs, CARLA import packages and their validators.

The 3D world they write (road model, lanes, layout, MJCF scene) lives in :mod:`garage_mj.scene`;
this package only turns it into files. Public names load lazily
(``from garage_mj.export import write_xodr``), so importing one writer does not import the
others' dependencies.

- ``xodr``: ``garage.xodr`` (ASAM OpenDRIVE 1.8) spelled from the scene's road model, with lxml.
- ``meshes``: ``garage.glb`` and ``garage.obj`` + ``.mtl`` of the scene layout, with trimesh, for other engines.
- ``fbx``: ``garage.fbx``, the same meshes written by Assimp's FBX exporter (Z up, metres: CARLA's convention).
- ``preview``: ``preview.png``, a top-down picture of the garage (opencv).
- ``artefacts``: the table of a pack's files (name, writer, optional dependency, validators, description).
- ``pack``: asset packs, one folder per garage with every export and a manifest of hashes (``export_pack``, ``load_pack``).
- ``carla_package``: a package folder for CARLA's ``make import`` (``<map>.fbx`` + ``<map>.xodr`` per garage, the package JSON).
- ``validate``: checks ``garage.xodr`` with real tools (CARLA's parser, the ASAM checker), ``.xosc`` files
  with the ASAM OpenSCENARIO checker, and ``garage.fbx`` against ``garage.glb`` with Blender.
- ``carla_probe``: the child process ``validate`` runs to load maps with CARLA's parser.
- ``blender_probe``: the child process ``validate`` runs to read ``garage.fbx`` back with Blender's FBX importer.
- ``xosc``: a cruise test written as an OpenSCENARIO 1.2 file (with ``scenariogeneration``).
- ``xosc_read``: reads a cruise test's OpenSCENARIO file (written by ``xosc``) back.
- ``park_problems``: every park test as a planning problem (start pose, stall pose, obstacle polygons), in
  JSON and as a case of the TPCAP parking benchmark, and the reader of both.
"""

from __future__ import annotations

from garage_mj.core.lazy import lazy_exports

__getattr__, __all__ = lazy_exports(__name__, {
    "write_xodr": "xodr",
    "XodrResult": "xodr",
    "check_carla": "validate",
    "check_asam": "validate",
    "export_pack": "pack",
    "export_packs": "pack",
    "load_pack": "pack",
    "PackError": "pack",
    "garage_meshes": "meshes",
    "write_fbx": "fbx",
    "write_carla_package": "carla_package",
    "write_preview": "preview",
    "write_park_problems": "park_problems",
    "read_park_problem": "park_problems",
})
