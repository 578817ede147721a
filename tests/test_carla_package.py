"""CARLA import packages: the layout and JSON that `make import` reads, tag names, clear refusals."""

from __future__ import annotations

import fnmatch
import json
import os

import pytest

from garage_mj.cli import main
from garage_mj.export import fbx as fbx_mod
from garage_mj.export.carla_package import CARLA_NAMES, CarlaPackageError, map_name, write_carla_package
from garage_mj.export.meshes import CLASS_NAMES, garage_meshes, write_glb
from garage_mj.export.pack import INDEX
from garage_mj.export.validate import fbx_problems, read_fbx_batch
from garage_mj.export.xodr import write_xodr


def _import_py_jsons(import_dir):
    """The package descriptions CARLA's Util/BuildTools/Import.py finds: every *.json under Import/."""
    return [os.path.join(root, f) for root, _, files in os.walk(import_dir) for f in fnmatch.filter(files, "*.json")]


def test_cli_lays_out_a_package_that_import_py_reads(painted_tiny, tmp_path, capsys):
    gfile = tmp_path / "garage.json"
    gfile.write_text(painted_tiny.to_json())
    package = tmp_path / "Import" / "garage_maps"
    assert main(["export", "--garage", str(gfile), "--carla-package", str(package), "--quiet"]) == 0
    assert "copy the folder into CARLA's Import/ folder and run `make import`" in capsys.readouterr().out
    (description,) = _import_py_jsons(tmp_path / "Import")  # one package, no other JSON
    assert description == str(package / "garage_maps.json")  # the package name is the JSON's name
    data = json.loads(open(description).read())
    assert data["props"] == []
    (entry,) = data["maps"]
    name = map_name(painted_tiny)
    assert entry == {"name": name, "source": f"./{name}/{name}.fbx", "use_carla_materials": True,
                     "xodr": f"./{name}/{name}.xodr"}
    assert name.replace("_", "").isalnum()
    # Import.py joins both paths to the JSON's folder
    fbx = package / entry["source"]
    xodr = package / entry["xodr"]
    assert fbx.read_bytes().startswith(b"Kaydara FBX Binary")
    assert xodr.read_text() == write_xodr(painted_tiny).text
    assert sorted(p.name for p in (package / name).iterdir()) == [f"{name}.fbx", f"{name}.xodr"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Import", "garage.json"]  # no --out: no packs


def test_the_package_fbx_carries_carlas_tag_names(painted_tiny, tmp_path):
    write_carla_package([painted_tiny], tmp_path / "pkg")
    name = map_name(painted_tiny)
    glb = write_glb(garage_meshes(painted_tiny), tmp_path / "garage.glb")
    (report,) = read_fbx_batch([tmp_path / "pkg" / name / f"{name}.fbx"])
    assert fbx_problems(report, glb, names=CARLA_NAMES) == []  # the pack's FBX, renamed
    road = {n for n in report.objects if "road_road" in n.lower()}
    lines = {n for n in report.objects if "road_marking" in n.lower()}
    assert road == {"Garage_Road_Road_floor"}  # CARLA's MoveAssets: Static/Road
    assert lines == {"Garage_Road_Marking_roadmark", "Garage_Road_Marking_stallmark"}  # Static/RoadLines
    for n in road | lines:  # PrepareAssetsForCooking drops the first word, then matches the tag
        assert ("Road_Road" if n in road else "Road_Marking") in n.split("_", 1)[1]
    # PrepareAssetsForCooking leaves out meshes whose name or material says light or sign
    words = set(report.objects) | {m for o in report.objects.values() for m in o.materials}
    assert not [w for w in words if "light" in w.lower() or "sign" in w.lower()]
    assert set(CARLA_NAMES) == set(CLASS_NAMES.values())


def test_with_out_and_many_garages_a_rerun_replaces_the_package(painted_maps, tmp_path):
    garages = [painted_maps["tiny_7x11"], painted_maps["m4_13x13_offset"]]
    description = write_carla_package(garages + garages[:1], tmp_path / "pkg")
    assert [m["name"] for m in json.loads(description.read_text())["maps"]] == [map_name(g) for g in garages]
    write_carla_package(garages[1:], tmp_path / "pkg")  # a package of ours is replaced whole
    assert sorted(p.name for p in (tmp_path / "pkg").iterdir()) == sorted(["pkg.json", map_name(garages[1])])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp folders left

    gfile = tmp_path / "garage.json"
    gfile.write_text(garages[0].to_json())
    argv = ["export", "--garage", str(gfile), "--out", str(tmp_path / "packs"), "--carla-package",
            str(tmp_path / "both"), "--quiet"]
    assert main(argv) == 0
    assert json.loads((tmp_path / "packs" / INDEX).read_text())["count"] == 1
    assert (tmp_path / "both" / "both.json").is_file()


def test_bad_targets_are_one_clear_line(painted_tiny, tmp_path, monkeypatch, capsys):
    gfile = tmp_path / "garage.json"
    gfile.write_text(painted_tiny.to_json())

    def export(target):
        assert main(["export", "--garage", str(gfile), "--carla-package", str(target), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "Traceback" not in err
        return err

    assert "letters, digits and underscores" in export(tmp_path / "my-maps")
    foreign = tmp_path / "Import"
    foreign.mkdir()
    (foreign / "notes.json").write_text("{}")
    assert "not a garage-mj CARLA package" in export(foreign)
    assert (foreign / "notes.json").read_text() == "{}"  # left alone
    (tmp_path / "a_file").write_text("x")
    assert "is not a folder" in export(tmp_path / "a_file")
    assert main(["export", "--garage", str(gfile)]) == 2
    assert "give --out DIR (asset packs), --carla-package DIR" in capsys.readouterr().err
    monkeypatch.setattr(fbx_mod, "_assimp", lambda: "FBX export needs Assimp: run `pip install cmeel-assimp`")
    assert "CARLA imports maps as FBX; FBX export needs Assimp" in export(tmp_path / "pkg")
    monkeypatch.undo()
    with pytest.raises(CarlaPackageError, match="no garage to put in it"):
        write_carla_package([], tmp_path / "empty")
