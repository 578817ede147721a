"""garage.fbx: written by Assimp, read back by Blender (an independent reader), equal to the GLB."""

from __future__ import annotations

import json
import time

import pytest

from garage_mj.cli import main
from garage_mj.export import fbx as fbx_mod
from garage_mj.export.artefacts import FBX
from garage_mj.export.fbx import fbx_bytes
from garage_mj.export.meshes import garage_meshes
from garage_mj.export.pack import MANIFEST, PackError, export_pack, load_pack
from garage_mj.export.validate import check_fbx_batch, fbx_problems, read_fbx_batch
from garage_mj.scene.layout import build_layout

CLASSES = {"floor", "wall", "obstacle", "parkedcar", "stallmark", "roadmark", "entrance", "exit", "pillar"}


@pytest.fixture(scope="module")
def packs(painted_maps, tmp_path_factory):
    """Packs of tiny_7x11 and one 13x13 garage, each with its garage.fbx."""
    out = tmp_path_factory.mktemp("fbx_packs")
    return [export_pack(painted_maps[m], out) for m in ("tiny_7x11", "m4_13x13_offset")]


@pytest.fixture(scope="module")
def blender(packs):
    """Blender's reading of both packs' FBX files (one Blender process)."""
    return read_fbx_batch([p / FBX for p in packs])


def test_blender_reads_the_same_classes_triangles_and_boxes_as_the_glb(packs, blender):
    assert check_fbx_batch(packs) == {p: [] for p in packs}
    for pack, report in zip(packs, blender):
        assert report.reader.startswith("Blender ") and report.error is None
        assert set(report.objects) == CLASSES  # one object per class ...
        assert all(o.materials == (name,) for name, o in report.objects.items())  # ... one material each
        assert fbx_problems(report, pack / "garage.glb") == []


#: Z up, front -Y, coord +X (right-handed: Blender's own system, Unreal's import target), 1 unit = 100 cm.
CARLA_AXES = {"UpAxis": 2, "UpAxisSign": 1, "FrontAxis": 1, "FrontAxisSign": -1, "CoordAxis": 0,
              "CoordAxisSign": 1, "UnitScaleFactor": 100.0}


def test_the_fbx_is_z_up_in_metres_on_the_xodr_frame(painted_maps, packs, blender):
    """The header says Z up, metres; Blender applies it: the floor spans the grid in x (east), y (north)."""
    assert {k: blender[0].settings[k] for k in CARLA_AXES} == CARLA_AXES
    assert blender[0].version >= 7400  # binary FBX 7.4+, what Unreal's FBX SDK reads
    sx, sy = build_layout(painted_maps["tiny_7x11"]).size
    floor, wall = blender[0].objects["floor"], blender[0].objects["wall"]
    assert floor.lo[:2] == pytest.approx((0.0, 0.0), abs=1e-4)
    assert floor.hi[:2] == pytest.approx((sx, sy), abs=1e-3)
    assert wall.hi[2] == pytest.approx(3.0, abs=1e-4)  # ceiling height [m], z up


def test_the_comparison_fails_on_another_garage(packs, blender):
    """The read-back check can fail: the tiny garage's FBX is not the 13x13 garage's GLB."""
    problems = fbx_problems(blender[0], packs[1] / "garage.glb")
    assert any("triangles" in p for p in problems) and any("box" in p for p in problems)


def test_a_broken_fbx_is_one_line_from_blender(packs, tmp_path):
    bad = tmp_path / FBX
    bad.write_bytes((packs[0] / FBX).read_bytes()[:5000])
    (problem,) = fbx_problems(read_fbx_batch([bad])[0], packs[0] / "garage.glb")
    assert problem.startswith(f"Blender could not import {FBX}: ") and "\n" not in problem


def test_one_garage_gives_the_same_fbx_bytes_on_every_run(painted_tiny):
    """Assimp stamps the time into the header; the writer fixes it, so pack hashes are reproducible."""
    meshes = garage_meshes(painted_tiny)
    first = fbx_bytes(meshes)
    time.sleep(1.05)  # the stamp has a resolution of one second
    assert fbx_bytes(meshes) == first


def test_the_manifest_hashes_the_fbx(painted_tiny, tmp_path):
    path = export_pack(painted_tiny, tmp_path)
    manifest = load_pack(path).manifest
    assert FBX in manifest["files"] and manifest["skipped"] == {}
    (path / FBX).write_bytes(b"Kaydara FBX Binary  \x00 not this garage")
    with pytest.raises(PackError, match=f"{FBX} does not match its hash in the manifest"):
        load_pack(path)
    assert main(["check", str(path)]) == 2  # garage-mj check verifies packs the same way
    assert export_pack(painted_tiny, tmp_path) == path  # repaired
    assert load_pack(path).file(FBX).read_bytes().startswith(b"Kaydara FBX Binary")


def test_without_assimp_packs_say_they_skip_the_fbx(painted_tiny, tmp_path, monkeypatch, capsys):
    reason = "FBX export needs Assimp, from the PyPI package cmeel-assimp: run `pip install cmeel-assimp`"
    monkeypatch.setattr(fbx_mod, "_assimp", lambda: reason)
    gfile = tmp_path / "garage.json"
    gfile.write_text(painted_tiny.to_json())
    assert main(["export", "--garage", str(gfile), "--out", str(tmp_path / "packs"), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"{FBX} left out of the packs: {reason}"]
    (path,) = [p for p in (tmp_path / "packs").iterdir() if p.is_dir()]
    manifest = load_pack(path).manifest  # a complete pack that says what it left out
    assert FBX not in manifest["files"] and manifest["skipped"] == {FBX: reason}
    with pytest.raises(fbx_mod.FbxError, match="needs Assimp"):
        fbx_bytes(garage_meshes(painted_tiny))

    monkeypatch.undo()  # Assimp is back: the next export adds the FBX
    export_pack(painted_tiny, tmp_path / "packs")
    assert FBX in load_pack(path).manifest["files"]

    skips_a_required_file = json.loads((path / MANIFEST).read_text())
    skips_a_required_file["skipped"] = {"garage.xodr": "no reason"}
    (path / MANIFEST).write_text(json.dumps(skips_a_required_file))
    with pytest.raises(PackError, match=r"skips files a pack must hold: \['garage.xodr'\]"):
        load_pack(path)
