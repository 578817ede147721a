"""What the route difficulty of a garage costs: planning every stall, then the features and the model.

Per 13x13 map, ``--garages`` garages of ``--library`` (stratified by the paper's difficulty, seeded;
painted by the scripted painter without a library), each in a fresh ``GarageScene``: CPU seconds
(``time.process_time``) of the plan of every stall (``DrivePlanner.plans``) and of the whole route
difficulty (scene, plans, features, model). With ``--baseline-tree DIR`` (a ``git worktree`` of
older code) it times that tree's planner on the same garages in a subprocess, interleaved per map.

    .venv/bin/python eval/bench_route_difficulty.py --library runs/paper_10pct/library.sqlite \\
        --json docs/route_difficulty/bench_route_difficulty.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

MAPS = ("m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u")


def _garages(library: Path | None, map_name: str, n: int):
    if library is None:
        from garage_mj.driving.sources import painted_sources

        return [s.garage for s in painted_sources(map_name, n, 0)]
    from garage_mj.driving.garage_set import GarageSet

    return [s.garage for s in GarageSet.from_library(library, map=map_name, n=n, seed=0)]


def plan_seconds(library: Path | None, map_name: str, n: int) -> list[float]:
    """CPU seconds of planning every stall of each garage (a fresh scene each; the scene build not counted)."""
    from garage_mj.scene.drivable import drive_planner
    from garage_mj.scene.garage_scene import GarageScene

    out = []
    drive_planner(GarageScene(_garages(library, map_name, 1)[0])).plans()  # loads the car model once
    for g in _garages(library, map_name, n):
        scene = GarageScene(g)
        scene.network, scene.stalls, scene.layout, scene.lane_graph  # noqa: B018 (built before the clock)
        t = time.process_time()
        drive_planner(scene).plans()
        out.append(time.process_time() - t)
    return out


def route_seconds(library: Path | None, map_name: str, n: int, route_model: str | None = None
                  ) -> tuple[list[float], list[int]]:
    """CPU seconds of the whole route difficulty of each garage (scene included) under ``route_model`` (a file
    or a shipped model's name; None: the default), and its stall counts."""
    from garage_mj.scene.garage_scene import GarageScene
    from garage_mj.scene.route_difficulty import load_route_model, route_difficulty

    model = load_route_model(route_model)
    garages = _garages(library, map_name, n)
    route_difficulty(garages[0], model)  # loads the car model once
    out, stalls = [], []
    for g in garages:
        t = time.process_time()
        scene = GarageScene(g)
        route_difficulty(scene, model)
        out.append(time.process_time() - t)
        stalls.append(len(scene.stalls.stalls))
    return out, stalls


def _stats(xs: list[float]) -> dict[str, float]:
    return {"mean": round(statistics.fmean(xs), 3), "median": round(statistics.median(xs), 3),
            "max": round(max(xs), 3)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--library", type=Path, help="library to draw the garages from (default: paint them)")
    p.add_argument("--garages", type=int, default=20, help="garages per map (default 20)")
    p.add_argument("--maps", default=",".join(MAPS))
    p.add_argument("--baseline-tree", type=Path, help="a worktree of older code: time its planner too")
    p.add_argument("--plan-only", action="store_true", help=argparse.SUPPRESS)  # the baseline subprocess
    p.add_argument("--route-model", help="route difficulty model timed: a file or a shipped model's name "
                   "(route, learned; default: the default model)")
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    maps = args.maps.split(",")
    if args.plan_only:
        print(json.dumps({m: plan_seconds(args.library, m, args.garages) for m in maps}))
        return 0
    prov = provenance(argv)  # before the run: the load it starts at
    result = {}
    for m in maps:
        row: dict = {}
        plan = plan_seconds(args.library, m, args.garages)
        route, stalls = route_seconds(args.library, m, args.garages, args.route_model)
        row = {"route_model": args.route_model or "route", "garages": len(plan), "stalls": _stats([float(s) for s in stalls]), "plan_cpu_s": _stats(plan),
               "route_difficulty_cpu_s": _stats(route)}
        if args.baseline_tree is not None:
            env = {**os.environ, "PYTHONPATH": str(args.baseline_tree.resolve())}
            cmd = [sys.executable, str(Path(__file__).resolve()), "--plan-only", "--maps", m, "--garages",
                   str(args.garages)] + (["--library", str(args.library.resolve())] if args.library else [])
            before = json.loads(subprocess.run(cmd, env=env, cwd=args.baseline_tree, check=True, capture_output=True,
                                               text=True).stdout)[m]
            row["plan_cpu_s_before"] = _stats(before)
            row["plan_speedup_median"] = round(statistics.median(before) / statistics.median(plan), 2)
        result[m] = row
        extra = (f", before {row['plan_cpu_s_before']['median']:.3f} s ({row['plan_speedup_median']}x)"
                 if "plan_cpu_s_before" in row else "")
        print(f"{m}: {len(plan)} garages, {row['stalls']['mean']:.0f} stalls on average; plan of every stall "
              f"median {row['plan_cpu_s']['median']:.3f} CPU-s (max {row['plan_cpu_s']['max']:.3f}){extra}; "
              f"route difficulty median {row['route_difficulty_cpu_s']['median']:.3f} CPU-s "
              f"(mean {row['route_difficulty_cpu_s']['mean']:.3f}, max {row['route_difficulty_cpu_s']['max']:.3f})",
              flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({**result, "provenance": prov}, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
