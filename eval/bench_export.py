"""Benchmark: milliseconds per 13x13 garage for each export format.

    python eval/bench_export.py [--map m5_13x13_aligned] [--garages 5] [--repeat 3] [--seed 0]

Garages come from the scripted painter (deterministic). Each format is timed in memory (no disk):
``xodr`` (road model + OpenDRIVE text), ``lanes`` (road model + lane graph), ``mjcf`` (dm_control build + XML + MuJoCo compile),
``meshes`` (trimesh scene + GLB and OBJ bytes), ``preview`` (the PNG picture), and ``pack`` (a
whole asset pack on disk, hashes included). Target: xodr + mjcf < 100 ms.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable

import mujoco
import trimesh

from garage_mj.export.meshes import garage_meshes
from garage_mj.export.pack import export_pack
from garage_mj.export.preview import render_preview
from garage_mj.export.xodr import write_xodr
from garage_mj.grid.garage import Garage
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.mjcf_scene import build_scene
from garage_mj.scene.opendrive_lanes import lane_graph


def _mjcf(garage: Garage) -> None:
    root = build_scene(garage)
    mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())


def _meshes(garage: Garage) -> None:
    scene = garage_meshes(garage)
    scene.export(file_type="glb")
    trimesh.exchange.obj.export_obj(scene, include_texture=True, return_texture=True, mtl_name="g.mtl")


def _pack(garage: Garage) -> None:
    with tempfile.TemporaryDirectory() as d:
        export_pack(garage, d)


#: Format -> function doing that export for one garage.
FORMATS: dict[str, Callable[[Garage], object]] = {
    "xodr": lambda g: write_xodr(g),
    "lanes": lambda g: lane_graph(g),  # the lane graph routing uses (same road model as xodr)
    "mjcf": _mjcf,
    "meshes": _meshes,
    "preview": render_preview,
    "pack": _pack,
}


def time_format(fn: Callable[[Garage], object], garages: list[Garage], repeat: int) -> float:
    """Median over ``repeat`` runs of the mean milliseconds per garage."""
    fn(garages[0])  # warm caches (templates, imports)
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for g in garages:
            fn(g)
        runs.append(1e3 * (time.perf_counter() - t0) / len(garages))
    return statistics.median(runs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--garages", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--formats", nargs="+", default=list(FORMATS), choices=list(FORMATS))
    args = ap.parse_args()
    garages = [paint_garage(args.map, seed=args.seed + i) for i in range(args.garages)]
    print(f"map {args.map}, {len(garages)} painted garages, median of {args.repeat} runs")
    ms = {}
    for name in args.formats:
        ms[name] = time_format(FORMATS[name], garages, args.repeat)
        print(f"{name:8s} {ms[name]:8.1f} ms/garage")
    if "xodr" in ms and "mjcf" in ms:
        total = ms["xodr"] + ms["mjcf"]
        print(f"xodr + mjcf {total:.1f} ms/garage (target < 100 ms): {'OK' if total < 100 else 'SLOW'}")


if __name__ == "__main__":
    main()
