"""The scene: the 3D world derived from a garage, computed once per garage as a :class:`GarageScene`.

World frame and sizes (``world``), road network matrix (``roadnet``), stalls (``stalls``), road
model and plan view (``roadmodel``, ``planview``), lanes and routes (``lanes``, ``route``),
drivable routes and their checks (``drivable``), layout and the MJCF builder (``layout``,
``mjcf_scene``, ``templates``) and semantic classes (``semantics``). The writers in
:mod:`garage_mj.export` and the drive env read this package; it imports neither.
Public names load lazily (``from garage_mj.scene import GarageScene``).
"""

from __future__ import annotations

from importlib import import_module

#: Public name -> submodule that defines it.
_EXPORTS: dict[str, str] = {
    "GarageScene": "garage_scene",
    "WorldConfig": "world",
    "DEFAULT_WORLD": "world",
    "road_network": "roadnet",
    "stall_layout": "stalls",
    "build_road_model": "roadmodel",
    "RoadModel": "roadmodel",
    "lane_graph": "lanes",
    "route": "lanes",
    "entrance_pose": "lanes",
    "exit_pose": "lanes",
    "Route": "route",
    "build_layout": "layout",
    "build_scene": "mjcf_scene",
    "compile_scene": "mjcf_scene",
    "set_parked": "mjcf_scene",
    "DrivePlanner": "drivable",
    "TestPlan": "drivable",
    "drivability": "drivable",
    "Semantic": "semantics",
    "geom_classes": "semantics",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
