"""Writers: OpenDRIVE, meshes, preview, asset packs and their validators.

The 3D world they write (road model, lanes, layout, MJCF scene) lives in :mod:`garage_mj.scene`;
this package only turns it into files. Public names load lazily
(``from garage_mj.export import write_xodr``), so importing one writer does not import the
others' dependencies.

- ``xodr``: ``garage.xodr`` (ASAM OpenDRIVE 1.8) spelled from the scene's road model, with lxml.
- ``meshes``: ``garage.glb`` and ``garage.obj`` + ``.mtl`` of the scene layout, with trimesh, for other engines.
- ``preview``: ``preview.png``, a top-down picture of the garage (opencv).
- ``pack``: asset packs, one folder per garage with every export and a manifest of hashes (``export_pack``, ``load_pack``).
- ``validate``: checks ``garage.xodr`` with real tools (CARLA's parser, the ASAM checker), and ``.xosc`` files
  with the ASAM OpenSCENARIO checker.
- ``carla_probe``: the child process ``validate`` runs to load maps with CARLA's parser.
- ``xosc``: a cruise test written as an OpenSCENARIO 1.2 file (with ``scenariogeneration``).
- ``xosc_read``: reads a cruise test's OpenSCENARIO file (written by ``xosc``) back.
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
    "write_preview": "preview",
})
