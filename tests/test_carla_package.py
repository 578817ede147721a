"""CARLA import packages: the layout and JSON that `make import` reads, tag names, clear refusals."""

from __future__ import annotations

import fnmatch
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from garage_mj.cli import main
from garage_mj.core.fsutil import FolderLock
from garage_mj.export import carla_package
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


def test_with_out_and_many_garages_in_one_package(painted_maps, tmp_path):
    garages = [painted_maps["tiny_7x11"], painted_maps["m4_13x13_offset"]]
    description = write_carla_package(garages + garages[:1], tmp_path / "pkg")
    assert [m["name"] for m in json.loads(description.read_text())["maps"]] == [map_name(g) for g in garages]
    assert sorted(p.name for p in (tmp_path / "pkg").iterdir()) == sorted(["pkg.json", *map(map_name, garages)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pkg"]  # no temp folders, no lock file left

    gfile = tmp_path / "garage.json"
    gfile.write_text(garages[0].to_json())
    argv = ["export", "--garage", str(gfile), "--out", str(tmp_path / "packs"), "--carla-package",
            str(tmp_path / "both"), "--quiet"]
    assert main(argv) == 0
    assert json.loads((tmp_path / "packs" / INDEX).read_text())["count"] == 1
    assert (tmp_path / "both" / "both.json").is_file()


def _package(folder: Path) -> dict[str, tuple[bytes, bytes]]:
    """The maps ``folder``'s package JSON lists, each with its FBX and OpenDRIVE bytes (all must exist)."""
    data = json.loads((folder / f"{folder.name}.json").read_text())
    assert data["props"] == [] and len({m["name"] for m in data["maps"]}) == len(data["maps"])
    return {m["name"]: ((folder / m["source"]).read_bytes(), (folder / m["xodr"]).read_bytes()) for m in data["maps"]}


def _garage_file(garage, target: Path) -> Path:
    """``garage`` as a JSON file beside ``target``'s folder (not in it: CARLA would take it for a package)."""
    gfile = target.parent.parent / "garages" / f"{map_name(garage)}.json"
    gfile.parent.mkdir(exist_ok=True)
    gfile.write_text(garage.to_json())
    return gfile


def _export(garage, target: Path, *extra: str) -> int:
    gfile = _garage_file(garage, target)
    return main(["export", "--garage", str(gfile), "--carla-package", str(target), "--quiet", *extra])


def test_a_second_export_adds_its_map_and_keeps_the_first(painted_tiny, painted_maps, tmp_path, capsys):
    first, second = painted_tiny, painted_maps["tiny_7x11"]
    pkg = tmp_path / "Import" / "garage_maps"
    pkg.parent.mkdir()
    assert _export(first, pkg) == 0
    before = _package(pkg)
    a = pkg / map_name(first) / f"{map_name(first)}.fbx"
    inode = a.stat().st_ino
    assert _export(second, pkg) == 0
    assert "2 map(s) in" in capsys.readouterr().out
    after = _package(pkg)
    assert list(after) == [map_name(first), map_name(second)]  # old maps first, then the new one
    assert after[map_name(first)] == before[map_name(first)] and a.stat().st_ino == inode  # kept, not rebuilt
    assert sorted(p.name for p in pkg.iterdir()) == sorted(["garage_maps.json", *after])  # no lock, no temp
    assert _import_py_jsons(pkg.parent) == [str(pkg / "garage_maps.json")]

    assert _export(first, pkg) == 0  # complete: kept as it is
    assert _package(pkg) == after and a.stat().st_ino == inode
    xodr = pkg / map_name(second) / f"{map_name(second)}.xodr"
    xodr.unlink()  # an incomplete map is rebuilt
    assert _export(second, pkg) == 0
    assert _package(pkg) == after
    assert _export(first, pkg, "--force") == 0  # --force rebuilds it
    assert _package(pkg) == after and a.stat().st_ino != inode
    assert sorted(p.name for p in pkg.iterdir()) == sorted(["garage_maps.json", *after])


def test_an_export_into_a_package_in_use_fails_at_once(painted_tiny, painted_maps, tmp_path, capsys):
    pkg = tmp_path / "pkg"
    write_carla_package([painted_tiny], pkg)
    before = _package(pkg)
    with FolderLock(pkg, "garage-mj export"):  # what another export holds while it writes
        t0 = time.monotonic()
        assert _export(painted_maps["tiny_7x11"], pkg) == 2
        assert time.monotonic() - t0 < 1.5
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert f"{pkg} is in use by garage-mj export (pid {os.getpid()})" in line
    assert _package(pkg) == before


def test_an_export_that_fails_midway_changes_nothing(painted_tiny, painted_maps, tmp_path, monkeypatch, capsys):
    pkg = tmp_path / "pkg"
    write_carla_package([painted_tiny], pkg)
    before = sorted(p.name for p in pkg.iterdir())
    data = _package(pkg)

    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(carla_package, "write_fbx", full)
    assert _export(painted_maps["tiny_7x11"], pkg) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert _package(pkg) == data and sorted(p.name for p in pkg.iterdir()) == before  # lock file removed too
    new = tmp_path / "new_pkg"
    assert _export(painted_tiny, new) == 2
    assert not new.exists()  # a folder made for the lock goes with it


# Real processes: two exports at once, and kill -9 while one writes.
def _spawn_export(garage, target: Path, pause: str | None = None) -> subprocess.Popen:
    """``garage-mj export --garage G --carla-package target`` in a new process; with ``pause``, the
    process stops (for a kill) in the function of that name of the package module, after it ran."""
    gfile = _garage_file(garage, target)
    argv = ["export", "--garage", str(gfile), "--carla-package", str(target), "--quiet"]
    code = ("import sys, time\n"
            "from garage_mj.cli import main\n"
            "import garage_mj.export.carla_package as m\n"
            f"pause = {pause!r}\n"
            "if pause:\n"
            "    real = getattr(m, pause)\n"
            "    def stop(*a, **k):\n"
            "        real(*a, **k)\n"
            "        print('paused', flush=True)\n"
            "        time.sleep(60)\n"
            "    setattr(m, pause, stop)\n"
            f"sys.exit(main({argv!r}))\n")
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_two_exports_at_once_never_lose_a_map(painted_tiny, painted_maps, tmp_path):
    pkg = tmp_path / "pkg"
    write_carla_package([painted_maps["m4_13x13_offset"]], pkg)
    garages = [painted_tiny, painted_maps["tiny_7x11"]]
    procs = [_spawn_export(g, pkg) for g in garages]
    results = [(p.wait(timeout=120), p.stdout.read(), p.stderr.read()) for p in procs]
    maps = _package(pkg)
    assert map_name(painted_maps["m4_13x13_offset"]) in maps
    assert any(rc == 0 for rc, _, _ in results), results
    for garage, (rc, out, err) in zip(garages, results):
        if rc == 0:  # a reported success has its map in the package
            assert "CARLA package pkg" in out and map_name(garage) in maps, (results, list(maps))
        else:  # or the export was refused in one line, naming the folder
            assert rc == 2 and len(err.strip().splitlines()) == 1, results
            assert f"{pkg} is in use by garage-mj export (pid " in err, results
    assert not [p.name for p in pkg.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("pause", ["write_fbx", "fsync_dir"])
def test_kill_9_mid_export_leaves_the_earlier_package_readable(pause, painted_tiny, painted_maps, tmp_path):
    pkg = tmp_path / "pkg"
    write_carla_package([painted_tiny], pkg)
    before = _package(pkg)
    proc = _spawn_export(painted_maps["tiny_7x11"], pkg, pause=pause)
    assert proc.stdout.readline() == "paused\n", proc.stderr.read()  # mid-write: a map built or moved in
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert _package(pkg) == before  # the earlier package, whole
    assert _import_py_jsons(pkg) == [str(pkg / "pkg.json")]
    write_carla_package([painted_maps["tiny_7x11"]], pkg)  # not locked; the killed run's temp files go
    assert list(_package(pkg)) == [map_name(painted_tiny), map_name(painted_maps["tiny_7x11"])]
    assert sorted(p.name for p in pkg.iterdir()) == sorted(["pkg.json", *_package(pkg)])
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


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
