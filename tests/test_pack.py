"""Asset packs: round trip, atomic writes, skip when complete, repair, clear errors, the CLI."""

from __future__ import annotations

import dataclasses
import json
import os

import mujoco
import pytest
import trimesh

from garage_mj.cli import main
from garage_mj.export import artefacts as artefacts_mod
from garage_mj.export import pack as pack_mod
from garage_mj.export import preview as preview_mod
from garage_mj.export.artefacts import ARTEFACTS, Artefact, Dependency, WhenMissing, _entry_point, formats
from garage_mj.export.pack import (
    INDEX,
    MANIFEST,
    PACK_FILES,
    PackError,
    export_pack,
    export_packs,
    load_pack,
    pack_name,
)
from garage_mj.generation.library import Library
from garage_mj.grid.metrics import evaluate
from garage_mj.scene.mjcf_scene import parked_car_bodies


def test_round_trip(painted_tiny, tmp_path):
    path = export_pack(painted_tiny, tmp_path)
    assert path == tmp_path / pack_name(painted_tiny)
    pack = load_pack(path)
    assert pack.garage == painted_tiny
    assert set(PACK_FILES) <= set(pack.manifest["files"])
    m = pack.manifest
    assert m["garage_hash"] == painted_tiny.canonical_hash()
    assert m["metrics"]["stalls"] == evaluate(painted_tiny).stalls
    assert set(m["versions"]) == {"garage-mj", "mujoco", "dm-control", "trimesh", "cmeel-assimp"}
    model = mujoco.MjModel.from_xml_path(str(pack.file("scene.xml")))
    assert len(parked_car_bodies(model)) == m["metrics"]["stalls"]
    assert "parkedcar" in {g.visual.material.name for g in trimesh.load(pack.file("garage.glb")).geometry.values()}
    assert pack.file("garage.xodr").read_text().lstrip().startswith("<?xml")
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp folders left


def test_complete_pack_is_skipped(painted_tiny, tmp_path, monkeypatch):
    path = export_pack(painted_tiny, tmp_path)
    stamp = (path / MANIFEST).stat().st_mtime_ns

    def boom(*args, **kwargs):
        raise AssertionError("a complete pack must not be rebuilt")

    monkeypatch.setattr(pack_mod, "_write_files", boom)
    assert export_pack(painted_tiny, tmp_path) == path
    assert (path / MANIFEST).stat().st_mtime_ns == stamp


def test_crash_mid_export_leaves_no_half_pack_and_rerun_repairs(painted_tiny, tmp_path, monkeypatch):
    def crash(*args, **kwargs):
        raise KeyboardInterrupt("simulated crash")

    monkeypatch.setattr(preview_mod, "write_preview", crash)  # the last file of a pack
    with pytest.raises(KeyboardInterrupt):
        export_pack(painted_tiny, tmp_path)
    assert list(tmp_path.iterdir()) == []  # neither a pack nor a temp folder
    monkeypatch.undo()
    load_pack(export_pack(painted_tiny, tmp_path))


def test_broken_pack_gives_a_clear_error_and_is_repaired(painted_tiny, tmp_path):
    path = export_pack(painted_tiny, tmp_path)
    (path / "garage.xodr").unlink()
    with pytest.raises(PackError, match=r"is incomplete: garage.xodr missing; re-run garage-mj export"):
        load_pack(path)
    (path / "preview.png").write_bytes(b"not a png")
    with pytest.raises(PackError, match="incomplete"):
        load_pack(path)
    assert export_pack(painted_tiny, tmp_path) == path
    load_pack(path)
    with pytest.raises(PackError, match="the folder is missing"):
        load_pack(tmp_path / "nowhere")


def test_export_packs_writes_an_index(painted_maps, tmp_path):
    garages = [painted_maps["tiny_7x11"], painted_maps["m4_13x13_offset"]]
    paths = export_packs(garages, tmp_path, progress=False)
    index = json.loads((tmp_path / INDEX).read_text())
    assert index["count"] == 2
    assert sorted(e["folder"] for e in index["packs"]) == sorted(p.name for p in paths)


def test_cli_exports_a_garage_file_and_a_library(painted_tiny, painted_maps, tmp_path, capsys):
    gfile = tmp_path / "garage.json"
    gfile.write_text(painted_tiny.to_json())
    assert main(["export", "--garage", str(gfile), "--out", str(tmp_path / "one"), "--quiet"]) == 0
    load_pack(tmp_path / "one" / pack_name(painted_tiny))

    lib_path = tmp_path / "library.sqlite"
    with Library(lib_path) as lib:
        for i, name in enumerate(["tiny_7x11", "m5_13x13_aligned"]):
            lib.add(painted_maps[name], map=name, run="test", seed=i, episode=0, timestep=0)
    out = tmp_path / "lib"
    argv = ["export", "--library", str(lib_path), "--map", "tiny_7x11", "--limit", "5", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    assert json.loads((out / INDEX).read_text())["count"] == 1
    assert main(["export", "--library", str(lib_path), "--map", "nope", "--out", str(out), "--quiet"]) == 2
    assert "no garage" in capsys.readouterr().err
    assert main(["export", "--library", str(tmp_path / "missing.sqlite"), "--out", str(out)]) == 2


def test_the_table_of_artefacts_drives_the_help_and_names_real_validators():
    assert formats() == "xodr, MJCF, GLB/OBJ/FBX, preview"
    assert PACK_FILES == tuple(name for a in ARTEFACTS for name in a.files)
    assert len(set(PACK_FILES)) == len(PACK_FILES) and MANIFEST not in PACK_FILES
    for artefact in ARTEFACTS:
        assert artefact.description and all(callable(_entry_point(v)) for v in artefact.validators)
        if artefact.needs is not None:
            assert callable(_entry_point(artefact.needs.probe))


def test_a_new_artefact_is_one_record(painted_tiny, tmp_path, monkeypatch):
    """A record in the table is written, hashed in the manifest and required on load; one whose missing
    dependency is an error stops the export, one that may be skipped is skipped with the reason."""
    def write_note(inputs, path):
        path.write_text(inputs.scene.garage.name)

    note = Artefact("note.txt", write_note, "a note")
    monkeypatch.setattr(artefacts_mod, "ARTEFACTS", (*ARTEFACTS, note))
    path = export_pack(painted_tiny, tmp_path)
    assert "note.txt" in load_pack(path).manifest["files"]
    (path / MANIFEST).write_text((path / MANIFEST).read_text().replace('"note.txt"', '"other.txt"'))
    with pytest.raises(PackError, match="note.txt not in the manifest"):
        load_pack(path)

    never = Dependency("Nothing", "no-such-package", "os:getcwd")  # a string: the dependency is never there
    monkeypatch.setattr(artefacts_mod, "ARTEFACTS", (*ARTEFACTS, dataclasses.replace(note, needs=never)))
    with pytest.raises(PackError, match="cannot write note.txt into asset packs"):
        export_pack(painted_tiny, tmp_path / "error")
    assert list((tmp_path / "error").iterdir()) == []
    skip = dataclasses.replace(note, needs=never, when_missing=WhenMissing.SKIP)
    monkeypatch.setattr(artefacts_mod, "ARTEFACTS", (*ARTEFACTS, skip))
    manifest = load_pack(export_pack(painted_tiny, tmp_path / "skip")).manifest
    assert "note.txt" not in manifest["files"] and manifest["skipped"] == {"note.txt": os.getcwd()}
    assert artefacts_mod.left_out_here() == {"note.txt": os.getcwd()}
