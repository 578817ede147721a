"""Benchmark: what garage.fbx adds to an asset pack, in milliseconds per 13x13 garage.

    python eval/bench_fbx.py [--map m5_13x13_aligned] [--garages 5] [--repeat 5] [--json docs/bench_fbx.json]

Garages come from the scripted painter (deterministic). The figure: what a pack does for its
FBX on top of the meshes it builds anyway, timed alone: ``write_fbx`` (trimesh scene -> in-memory
GLB -> Assimp import -> FBX blob -> atomic file write) plus the manifest's sha256 of the file,
median over rounds of the mean per garage. As a check, whole packs are also written with FBX and
with FBX switched off (as without Assimp), interleaved so that load from other jobs falls on both
alike; their difference is noisier than the FBX's own cost on a loaded machine.
Target: FBX adds <= 200 ms per 13x13 garage to a pack.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path
from unittest import mock

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.export import fbx as fbx_mod
from garage_mj.export.meshes import garage_meshes
from garage_mj.export.pack import _sha256, export_pack
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.garage_scene import GarageScene

TARGET_MS = 200.0  # [ms] per 13x13 garage


def _packs_ms(garages, fbx: bool) -> float:
    """Mean milliseconds per garage to write each garage's pack into a fresh folder."""
    with tempfile.TemporaryDirectory() as d:
        off = mock.patch.object(fbx_mod, "_assimp", lambda: "benchmark: FBX switched off")
        if not fbx:
            off.start()
        try:
            t0 = time.perf_counter()
            for g in garages:
                export_pack(g, d)
            return 1e3 * (time.perf_counter() - t0) / len(garages)
        finally:
            if not fbx:
                off.stop()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--garages", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, help="also write the figures here")
    args = ap.parse_args()
    prov = provenance()  # before the run: the load it starts at
    garages = [paint_garage(args.map, seed=args.seed + i) for i in range(args.garages)]
    meshes = [garage_meshes(GarageScene(g)) for g in garages]
    fbx_mod.fbx_bytes(meshes[0])  # load libassimp once, as the first pack of an export does
    _packs_ms(garages[:1], True), _packs_ms(garages[:1], False)  # warm caches (templates, imports)

    alone, sizes = [], [len(fbx_mod.fbx_bytes(m)) for m in meshes]
    with tempfile.TemporaryDirectory() as d:
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            for i, m in enumerate(meshes):
                _sha256(fbx_mod.write_fbx(m, Path(d) / f"{i}.fbx"))
            alone.append(1e3 * (time.perf_counter() - t0) / len(meshes))
    with_fbx, without, added = [], [], []
    for _ in range(args.repeat):
        a, b = _packs_ms(garages, True), _packs_ms(garages, False)
        with_fbx.append(a), without.append(b), added.append(a - b)
    out = {
        "map": args.map, "garages": len(garages), "repeat": args.repeat, "load_average": list(os.getloadavg()),
        "fbx_adds_ms": statistics.median(alone), "fbx_adds_ms_rounds": alone,
        "pack_with_fbx_ms": statistics.median(with_fbx), "pack_without_fbx_ms": statistics.median(without),
        "pack_difference_ms": statistics.median(added), "pack_difference_ms_rounds": added,
        "fbx_bytes": statistics.median(sizes), "target_ms": TARGET_MS, "provenance": prov,
    }
    out["met"] = out["fbx_adds_ms"] <= TARGET_MS
    print(f"map {args.map}, {len(garages)} painted garages, median of {args.repeat} rounds, "
          f"load {out['load_average'][0]:.1f}")
    print(f"pack with FBX   {out['pack_with_fbx_ms']:7.1f} ms/garage")
    print(f"pack without    {out['pack_without_fbx_ms']:7.1f} ms/garage (difference "
          f"{out['pack_difference_ms']:.1f} ms, rounds {', '.join(f'{x:.1f}' for x in added)})")
    print(f"FBX adds        {out['fbx_adds_ms']:7.1f} ms/garage, write + hash of {out['fbx_bytes'] / 1e3:.0f} kB "
          f"(target <= {TARGET_MS:.0f} ms): {'OK' if out['met'] else 'SLOW'}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
