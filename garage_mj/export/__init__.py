"""Exporters: MJCF scene, meshes, preview and asset packs (and the OpenDRIVE writer).

Public names load lazily (``from garage_mj.export import write_xodr``), so importing one
exporter does not import the others' dependencies.
"""

from __future__ import annotations

from importlib import import_module

#: Public name -> submodule that defines it.
_EXPORTS: dict[str, str] = {
    "write_xodr": "xodr",
    "XodrResult": "xodr",
    "build_road_model": "roadmodel",
    "RoadModel": "roadmodel",
    "lane_graph": "lanes",
    "route": "lanes",
    "entrance_pose": "lanes",
    "exit_pose": "lanes",
    "check_carla": "validate",
    "check_asam": "validate",
    "export_pack": "pack",
    "export_packs": "pack",
    "load_pack": "pack",
    "PackError": "pack",
    "build_scene": "mjcf_scene",
    "compile_scene": "mjcf_scene",
    "set_parked": "mjcf_scene",
    "garage_meshes": "meshes",
    "write_preview": "preview",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
