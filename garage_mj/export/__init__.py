"""Writers: OpenDRIVE, meshes, preview, asset packs and their validators.

The 3D world they write (road model, lanes, layout, MJCF scene) lives in :mod:`garage_mj.scene`;
this package only turns it into files. Public names load lazily
(``from garage_mj.export import write_xodr``), so importing one writer does not import the
others' dependencies.
"""

from __future__ import annotations

from importlib import import_module

#: Public name -> submodule that defines it.
_EXPORTS: dict[str, str] = {
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
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
