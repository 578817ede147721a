"""Child process for :func:`garage_mj.export.validate.read_fbx_batch`: read FBX files with Blender.

Run with a Python that has Blender's ``bpy`` module (``.venv-blender``, made by ``make install``):
``python blender_probe.py RESULT.json FILE.fbx...``. Imports each file with Blender's own FBX
importer (``bpy.ops.import_scene.fbx``, default options: the file's axes and unit are applied)
into an empty scene and writes one JSON list to ``RESULT.json`` (Blender prints its own lines on
stdout): per file, Blender's version, the file's FBX version and ``GlobalSettings`` (axes, unit)
as Blender's FBX parser reads them, and per mesh object its material names, triangle count,
vertex count and world bounding box [m]; or the error that stopped the import. Imports only ``bpy``, ``numpy`` and the standard
library: it is an independent reader of what :mod:`garage_mj.export.fbx` (Assimp) writes.
"""

from __future__ import annotations

import json
import sys


def global_settings(path: str) -> tuple[dict[str, int | float], int]:
    """The file's numeric ``GlobalSettings`` (axes, unit) and FBX version, by Blender's own FBX parser."""
    from io_scene_fbx import parse_fbx  # the first step of Blender's importer

    root, version = parse_fbx.parse(path)
    for elem in root.elems:
        if elem.id == b"GlobalSettings":
            for props in elem.elems:
                if props.id == b"Properties70":
                    return {p.props[0].decode(): p.props[4] for p in props.elems
                            if p.id == b"P" and len(p.props) > 4 and isinstance(p.props[4], (int, float))}, version
    return {}, version


def read(path: str) -> dict:
    import bpy
    import numpy as np

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=path)
    objects = {}
    for ob in bpy.context.scene.objects:
        if ob.type != "MESH":
            continue
        mesh = ob.data
        mesh.calc_loop_triangles()
        co = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
        matrix = np.array(ob.matrix_world)
        world = co.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
        objects[ob.name] = {
            "materials": [m.name for m in mesh.materials if m is not None],
            "triangles": len(mesh.loop_triangles),
            "vertices": len(mesh.vertices),
            "lo": world.min(axis=0).tolist() if len(world) else [0.0, 0.0, 0.0],
            "hi": world.max(axis=0).tolist() if len(world) else [0.0, 0.0, 0.0],
        }
    settings, version = global_settings(path)
    return {"path": path, "reader": f"Blender {bpy.app.version_string}", "objects": objects,
            "global_settings": settings, "version": version}


def main(argv: list[str]) -> int:
    result, paths = argv[0], argv[1:]
    out = []
    for p in paths:
        try:
            out.append(read(p))
        except Exception as exc:  # a file Blender cannot import: reported per file, the batch goes on
            out.append({"path": p, "error": f"{type(exc).__name__}: {str(exc).strip()[-400:]}"})
    with open(result, "w") as f:
        json.dump(out, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
