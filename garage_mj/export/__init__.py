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
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
