"""Validate exported files with real tools: CARLA's parser, the ASAM checkers, Blender's FBX importer.

- :func:`check_carla` loads the text with ``carla.Map`` (the ``carla`` wheel, extra ``[carla]``)
  in a child process, counts waypoints per road and follows ``waypoint.next`` from the
  entrance lane to the exit lane.
- :func:`check_asam` runs the ASAM Quality Checker (``asam-qc-opendrive``, command
  ``qc_opendrive``) from its own virtualenv ``.venv-qc`` (it pins numpy < 2) and counts the
  issues in its XQAR result.
- :func:`check_xosc` runs the ASAM OpenSCENARIO XML checker bundle (``asam-qc-openscenarioxml``,
  command ``qc_openscenario``, same virtualenv) on a ``.xosc`` (schema of its version,
  references, parameters, data types) and counts the issues the same way.
- :func:`check_fbx_batch` reads each pack's ``garage.fbx`` (written by Assimp) with an independent
  reader, Blender's own FBX importer (``bpy`` from its own virtualenv ``.venv-blender``: it pins
  numpy < 2), and compares it with ``garage.glb``: same classes and materials, triangle counts
  and world bounding boxes.

All take batches (one child process per batch) because starting the tools costs more than
checking a file. ``make install`` installs the tools.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.util import find_spec
from pathlib import Path

from lxml import etree

from garage_mj.core.errors import GarageMJError
from garage_mj.export.artefacts import FBX, GLB

#: No entity expansion, no DTD or network fetches: the files parsed here may come from anywhere.
_SAFE_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)

QC_ENV = "GARAGE_MJ_QC_OPENDRIVE"  # optional path to a qc_opendrive executable
QC_XOSC_ENV = "GARAGE_MJ_QC_OPENSCENARIO"  # optional path to a qc_openscenario executable
BLENDER_ENV = "GARAGE_MJ_BLENDER_PYTHON"  # optional path to a Python with Blender's bpy module
BLENDER_PACKAGE = "bpy==5.0.1"  # Blender as a Python module, CPython 3.11 only (Makefile: .venv-blender)
_REPO = Path(__file__).resolve().parents[2]
_PROBE = Path(__file__).with_name("carla_probe.py")
_BLENDER_PROBE = Path(__file__).with_name("blender_probe.py")
_QC_DRIVER = "import sys\nfrom qc_opendrive import main\nfor c in sys.argv[1:]:\n    sys.argv = ['qc_opendrive', '-c', c]\n    main.main()\n"
_QC_XOSC_DRIVER = _QC_DRIVER.replace("qc_opendrive", "qc_openscenario")


class ToolMissing(GarageMJError, RuntimeError):
    """A validation tool is not installed; the message says how to install it."""


class ToolFailed(RuntimeError):
    """A validation tool crashed or printed something unreadable."""


@dataclass(frozen=True)
class CarlaReport:
    name: str
    waypoints: int
    waypoints_per_road: dict[int, int]
    roads: tuple[int, ...]  # road ids declared in the file
    topology_edges: int
    entrance_reaches_exit: bool

    @property
    def roads_without_waypoints(self) -> list[int]:
        return [r for r in self.roads if self.waypoints_per_road.get(r, 0) == 0]

    @property
    def ok(self) -> bool:
        return self.entrance_reaches_exit and not self.roads_without_waypoints


@dataclass(frozen=True)
class QcIssue:
    checker: str
    level: int  # 1 error, 2 warning, 3 information
    description: str
    xpath: str
    location: str = ""  # the checker's own words on where (e.g. the schema error), "(row N)" when given


@dataclass(frozen=True)
class QcReport:
    path: Path
    issues: list[QcIssue] = field(default_factory=list)
    completed: int = 0  # checkers that ran to completion
    skipped: int = 0  # checkers not applicable to the file's version
    errored: int = 0  # checkers with an internal error

    @property
    def ok(self) -> bool:
        return not self.issues and not self.errored


# -- CARLA ---------------------------------------------------------------------------------------
def _gates(text: str) -> tuple[list[int], list[int], list[int]]:
    """Road ids, and (road, lane) of the entrance and exit lanes, from the writer's road names."""
    root = etree.fromstring(text.encode(), _SAFE_PARSER)
    roads = [int(r.get("id")) for r in root.iter("road")]
    ent = ext = None
    for r in root.iter("road"):
        words = r.get("name", "").split("_")
        if "entrance" in words:
            ent = [int(r.get("id")), -1]  # the entrance road starts at the gate, lane -1 drives in
        if "exit" in words:
            ext = [int(r.get("id")), -1]  # the exit road ends at the gate, lane -1 drives out
    if ent is None or ext is None:
        raise ValueError("the OpenDRIVE text names no entrance_/exit_ road; pass entrance= and exit=")
    return roads, ent, ext


def check_carla_batch(
    texts: Sequence[str], names: Sequence[str] | None = None, timeout: float = 120.0
) -> list[CarlaReport]:
    """:func:`check_carla` for many maps in one child process."""
    if find_spec("carla") is None:
        raise ToolMissing(
            "CARLA's Python package is not installed in this environment; run `make install` "
            "(or `pip install 'garage-mj[carla]'`, Python 3.10-3.12 on Linux or Windows)"
        )
    names = list(names) if names is not None else [f"garage_{i}" for i in range(len(texts))]
    jobs, declared = [], []
    for name, text in zip(names, texts):
        roads, ent, ext = _gates(text)
        declared.append(tuple(roads))
        jobs.append({"name": name, "text": text, "entrance": ent, "exit": ext})
    proc = subprocess.run(
        [sys.executable, str(_PROBE)], input=json.dumps(jobs), capture_output=True, text=True, timeout=timeout
    )
    if proc.returncode != 0:
        raise ToolFailed(
            f"CARLA's OpenDRIVE parser crashed (exit code {proc.returncode}) on {names}: "
            f"{proc.stderr.strip()[-600:] or 'no message'}"
        )
    out = json.loads(proc.stdout)
    return [
        CarlaReport(
            name=r["name"],
            waypoints=r["waypoints"],
            waypoints_per_road={int(k): v for k, v in r["waypoints_per_road"].items()},
            roads=roads,
            topology_edges=r["topology_edges"],
            entrance_reaches_exit=r["entrance_reaches_exit"],
        )
        for r, roads in zip(out, declared)
    ]


def check_carla(xodr_text: str, name: str = "garage") -> CarlaReport:
    """Load ``xodr_text`` with ``carla.Map`` in a child process; waypoints, topology, entrance -> exit."""
    return check_carla_batch([xodr_text], [name])[0]


# -- ASAM Quality Checker ------------------------------------------------------------------------
def _find_checker(env: str, command: str, package: str, what: str) -> Path:
    """A checker command: $``env``, the repo's ``.venv-qc``, or PATH; else one line naming the fix."""
    for cand in (os.environ.get(env), _REPO / ".venv-qc" / "bin" / command, shutil.which(command)):
        if cand and Path(cand).is_file():
            return Path(cand)
    raise ToolMissing(f"the ASAM {what} checker ({command}) is not installed; run `make install` "
                      f"(it puts {package} in .venv-qc), or set {env} to its path")


def qc_executable() -> Path:
    """The ``qc_opendrive`` command: $GARAGE_MJ_QC_OPENDRIVE, the repo's ``.venv-qc``, or PATH."""
    return _find_checker(QC_ENV, "qc_opendrive", "asam-qc-opendrive", "OpenDRIVE")


def _config(xodr: Path, result: Path, bundle_name: str = "xodrBundle") -> str:
    root = etree.Element("Config")
    etree.SubElement(root, "Param", name="InputFile", value=str(xodr))
    bundle = etree.SubElement(root, "CheckerBundle", application=bundle_name)
    etree.SubElement(bundle, "Param", name="resultFile", value=str(result))
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8").decode()


def parse_xqar(path: Path, xodr: Path) -> QcReport:
    """Issues and checker statuses of one XQAR result file."""
    root = etree.parse(str(path), _SAFE_PARSER).getroot()
    issues, status = [], {"completed": 0, "skipped": 0, "error": 0}
    for checker in root.iter("Checker"):
        st = checker.get("status", "")
        status[st] = status.get(st, 0) + 1
        for issue in checker.iter("Issue"):
            loc = issue.find(".//XMLLocation")
            where = [w for w in (issue.xpath("string(Locations/@description)"),) if w]
            where += [f"(row {r})" for r in issue.xpath("Locations/FileLocation/@row")[:1]]
            issues.append(
                QcIssue(
                    checker.get("checkerId", ""),
                    int(issue.get("level", "1")),
                    issue.get("description", ""),
                    "" if loc is None else loc.get("xpath", ""),
                    " ".join(where),
                )
            )
    return QcReport(xodr, issues, status["completed"], status["skipped"], status["error"])


def _qc_batch(paths: Sequence[str | Path], exe: Path, bundle: str, driver: str, timeout: float) -> list[QcReport]:
    """Run one ASAM checker bundle on many files in one child process (the checker's start-up dominates)."""
    python = exe.parent / "python"
    with tempfile.TemporaryDirectory(prefix=f"garage_qc_{bundle}_") as tmp:
        configs, results = [], []
        for i, p in enumerate(paths):
            res = Path(tmp) / f"result_{i}.xqar"
            cfg = Path(tmp) / f"config_{i}.xml"
            cfg.write_text(_config(Path(p).resolve(), res, bundle))
            configs.append(str(cfg))
            results.append(res)
        if python.is_file():  # one interpreter for the batch, through the checker's own main()
            cmds = [[str(python), "-c", driver, *configs]]
        else:
            cmds = [[str(exe), "-c", c] for c in configs]
        for cmd in cmds:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
            if proc.returncode != 0:
                raise ToolFailed(
                    f"{exe.name} failed (exit code {proc.returncode}): {proc.stderr.strip()[-600:]}"
                )
        missing = [str(p) for p, r in zip(paths, results) if not r.is_file()]
        if missing:
            raise ToolFailed(f"{exe.name} wrote no result for {missing}")
        return [parse_xqar(r, Path(p)) for p, r in zip(paths, results)]


def check_asam_batch(paths: Sequence[str | Path], timeout: float = 300.0) -> list[QcReport]:
    """:func:`check_asam` for many files in one child process (the checker's start-up dominates)."""
    return _qc_batch(paths, qc_executable(), "xodrBundle", _QC_DRIVER, timeout)


def check_asam(xodr_path: str | Path) -> QcReport:
    """Run the ASAM OpenDRIVE Quality Checker on one file; its issues (zero for a good file)."""
    return check_asam_batch([xodr_path])[0]


# -- ASAM OpenSCENARIO XML checker ---------------------------------------------------------------
def qc_xosc_executable() -> Path:
    """The ``qc_openscenario`` command: $GARAGE_MJ_QC_OPENSCENARIO, the repo's ``.venv-qc``, or PATH."""
    return _find_checker(QC_XOSC_ENV, "qc_openscenario", "asam-qc-openscenarioxml", "OpenSCENARIO XML")


def check_xosc_batch(paths: Sequence[str | Path], timeout: float = 300.0) -> list[QcReport]:
    """:func:`check_xosc` for many files in one child process (the checker's start-up dominates)."""
    return _qc_batch(paths, qc_xosc_executable(), "xoscBundle", _QC_XOSC_DRIVER, timeout)


def check_xosc(xosc_path: str | Path) -> QcReport:
    """Run the ASAM OpenSCENARIO XML checker bundle on one ``.xosc``; its issues (zero for a good file)."""
    return check_xosc_batch([xosc_path])[0]


# -- Blender: FBX read back ----------------------------------------------------------------------
@dataclass(frozen=True)
class FbxObject:
    """One mesh object as Blender imported it: materials, triangles and world bounding box [m]."""

    name: str
    materials: tuple[str, ...]
    triangles: int
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass(frozen=True)
class FbxReport:
    """What Blender's FBX importer made of one file: its mesh objects by name, or why it failed."""

    path: Path
    reader: str
    objects: dict[str, FbxObject]
    error: str | None = None
    settings: dict[str, int | float] = field(default_factory=dict)  # GlobalSettings: axes, UnitScaleFactor
    version: int = 0  # FBX version, e.g. 7500


def blender_python() -> Path:
    """A Python with Blender's ``bpy``: $GARAGE_MJ_BLENDER_PYTHON or the repo's ``.venv-blender``."""
    for cand in (os.environ.get(BLENDER_ENV), _REPO / ".venv-blender" / "bin" / "python"):
        if cand and Path(cand).is_file():
            return Path(cand)
    raise ToolMissing(f"Blender's Python module (bpy) is not installed; run `make install` (it puts "
                      f"{BLENDER_PACKAGE} in .venv-blender) or set {BLENDER_ENV} to a Python that has bpy")


def read_fbx_batch(paths: Sequence[str | Path], timeout: float = 300.0) -> list[FbxReport]:
    """Import each FBX with Blender's own importer in one child process (Blender's start-up dominates)."""
    python = blender_python()
    with tempfile.TemporaryDirectory(prefix="garage_fbx_") as tmp:
        result = Path(tmp) / "result.json"
        proc = subprocess.run([str(python), str(_BLENDER_PROBE), str(result), *map(str, paths)],
                              capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0 or not result.is_file():
            raise ToolFailed(f"Blender's FBX importer failed (exit code {proc.returncode}): "
                             f"{proc.stderr.strip()[-600:] or 'no message'}")
        out = json.loads(result.read_text())
    return [
        FbxReport(
            Path(r["path"]), r.get("reader", "Blender"),
            {name: FbxObject(name, tuple(o["materials"]), o["triangles"], tuple(o["lo"]), tuple(o["hi"]))
             for name, o in r.get("objects", {}).items()},
            r.get("error"),
            r.get("global_settings", {}),
            r.get("version", 0),
        )
        for r in out
    ]


def fbx_problems(report: FbxReport, glb: str | Path, names: dict[str, str] | None = None,
                 atol: float = 1e-3) -> list[str]:
    """How ``report`` (an FBX read by Blender) differs from ``glb``: axes, classes, materials, triangles, boxes.

    The file's axes and unit must be :data:`garage_mj.export.fbx.GLOBAL_SETTINGS`. Each GLB node (a semantic class) must be one FBX object, named ``names.get(class, class)``,
    with that class's one material, the same triangle count and the same world bounding box
    (the GLB's y-up frame taken back to z up) within ``atol`` metres. Empty when they agree.
    """
    import numpy as np
    import trimesh

    from garage_mj.export.fbx import GLOBAL_SETTINGS, Y_UP_TO_Z_UP

    if report.error:
        return [f"Blender could not import {report.path.name}: {report.error}"]
    problems = [f"GlobalSettings {key} is {report.settings.get(key)}, not {value}"
                for key, value in GLOBAL_SETTINGS.items() if report.settings.get(key) != value]
    names = names or {}
    scene = trimesh.load(glb, force="scene")
    expected = {}
    for node in scene.graph.nodes_geometry:
        transform, geom = scene.graph[node]
        mesh = scene.geometry[geom]
        points = trimesh.transform_points(mesh.vertices, Y_UP_TO_Z_UP @ transform)
        expected[names.get(node, node)] = (mesh.visual.material.name, len(mesh.faces), points.min(0), points.max(0))
    if set(report.objects) != set(expected):
        problems.append(f"objects {sorted(report.objects)} are not the GLB's classes {sorted(expected)}")
    for name in sorted(set(report.objects) & set(expected)):
        obj, (material, triangles, lo, hi) = report.objects[name], expected[name]
        if obj.materials != (material,):
            problems.append(f"{name}: materials {list(obj.materials)}, GLB {material!r}")
        if obj.triangles != triangles:
            problems.append(f"{name}: {obj.triangles} triangles, GLB {triangles}")
        if not (np.allclose(obj.lo, lo, atol=atol) and np.allclose(obj.hi, hi, atol=atol)):
            problems.append(f"{name}: box {np.round(obj.lo, 3).tolist()}-{np.round(obj.hi, 3).tolist()} m, "
                            f"GLB {np.round(lo, 3).tolist()}-{np.round(hi, 3).tolist()} m")
    return problems


def check_fbx_batch(packs: Sequence[str | Path], timeout: float = 300.0) -> dict[Path, list[str]]:
    """Read every pack's ``garage.fbx`` with Blender and compare it with its ``garage.glb``.

    Returns each pack folder's problems (:func:`fbx_problems`; empty when the FBX matches).
    """
    packs = [Path(p) for p in packs]
    reports = read_fbx_batch([p / FBX for p in packs], timeout)
    return {p: fbx_problems(r, p / GLB) for p, r in zip(packs, reports)}
