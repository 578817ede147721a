"""The park tests' reference planner: planning time and infeasible share on painted garages of every shipped map.

For each shipped map, ``--garages`` painted garages (spread over difficulty, as ``bench_drivable.py``
paints them); in each, every stall whose cruise test is feasible (its goal is the park test's start) x
both maneuvers (reverse-in, nose-in), with the other stalls occupied each with probability
``--occupancy`` (drawn per stall, seeded). Per test the planner's CPU time (``ParkPlan.planning_time``,
``time.process_time``), whether a plan was found and how (analytic: straight exit + one Reeds-Shepp
curve; else the sampling planner). Every infeasible test is planned again with ``--budget-factor``
times the iteration budget: how many that overturns says how much the budget, not the scene, decides.
Targets: median <= 0.5 CPU-s per park test, max <= 3 CPU-s, infeasible <= 10% per maneuver.

    .venv/bin/python eval/bench_park_plan.py --garages 2           # writes docs/bench_park_plan.json
"""

from __future__ import annotations

import json
import platform
import statistics
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from _park_garages import map_names, painted_garages, park_parser  # eval/_park_garages.py: options, garages
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.scene.car import car_geometry
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import DEFAULT_PARK, MANEUVERS, ParkPlanner

TARGETS = {"median_cpu_s": 0.5, "max_cpu_s": 3.0, "infeasible_pct": 10.0}


def _garage_tests(scene: GarageScene, planner: ParkPlanner, occupancy: float, seed: int) -> list[dict]:
    """Every park test of one garage: its plan's numbers (no path)."""
    cruise = drive_planner(scene, planner.car)
    rng = np.random.default_rng(seed)
    ids = [s.id for s in scene.stalls.stalls]
    rows = []
    for stall in scene.stalls.stalls:
        test = cruise.plan(stall.id)
        occupied = [i for i, o in zip(ids, rng.random(len(ids)) < occupancy, strict=True) if o and i != stall.id]
        if not test.feasible:
            continue
        for name in MANEUVERS:
            plan = planner.plan(test.goal, stall.id, name, occupied=occupied)
            rows.append({**plan.summary(), "garage": scene.name, "start": test.goal, "occupied": occupied})
    return rows


def _stats(rows: list[dict]) -> dict:
    times = [r["planning_time"] for r in rows]
    infeasible = [r for r in rows if not r["found"]]
    found = [r for r in rows if r["found"]]
    return {"tests": len(rows), "infeasible": len(infeasible),
            "infeasible_pct": round(100 * len(infeasible) / max(len(rows), 1), 2),
            "median_cpu_s": round(statistics.median(times), 4) if times else None,
            "p95_cpu_s": round(float(np.percentile(times, 95)), 4) if times else None,
            "max_cpu_s": round(max(times), 4) if times else None,
            "analytic_pct": round(100 * sum(r["method"] == "analytic" for r in found) / max(len(found), 1), 2),
            "mean_cusps": round(statistics.mean(r["cusps"] for r in found), 2) if found else None,
            "max_cusps": max((r["cusps"] for r in found), default=None),
            "mean_length_m": round(statistics.mean(r["length"] for r in found), 2) if found else None,
            "min_clearance_m": min((r["min_clearance"] for r in found if r["min_clearance"] is not None), default=None)}


def main(argv: list[str] | None = None) -> int:
    ap = park_parser(__doc__, garages=2, out=Path("docs/bench_park_plan.json"))
    ap.add_argument("--budget-factor", type=int, default=10, help="re-plan each infeasible test with this x the budget")
    args = ap.parse_args(argv)
    prov = provenance(argv)  # before the run: the load it starts at
    maps = map_names(args)
    car, config = car_geometry(), DEFAULT_PARK
    big = replace(config, iterations=config.iterations * args.budget_factor)
    rows, scenes, t0 = [], {}, time.perf_counter()
    for pg in painted_garages(args, maps):
        scene = scenes[pg.map, pg.index] = GarageScene(pg.source.garage)
        got = _garage_tests(scene, ParkPlanner(scene, car, config), args.occupancy, pg.seed)
        for r in got:
            r["map"], r["scene"] = pg.map, (pg.map, pg.index)
        rows += got
        print(f"{pg.map:18s} garage {pg.index}: {len(got)} tests, {sum(not r['found'] for r in got)} infeasible",
              flush=True)
    # every infeasible test again with a bigger budget
    overturned = []
    for r in (r for r in rows if not r["found"]):
        again = ParkPlanner(scenes[r["scene"]], car, big).plan(r["start"], r["stall"], r["maneuver"], occupied=r["occupied"])
        r["replanned"] = again.summary()
        overturned += [r] if again.found else []
    per_map = [{"map": m, "maneuver": n, **_stats([r for r in rows if r["map"] == m and r["maneuver"] == n])}
               for m in maps for n in MANEUVERS]
    per_maneuver = {n: _stats([r for r in rows if r["maneuver"] == n]) for n in MANEUVERS}
    total = _stats(rows)
    met = {"median_cpu_s": total["median_cpu_s"] is not None and total["median_cpu_s"] <= TARGETS["median_cpu_s"],
           "max_cpu_s": total["max_cpu_s"] is not None and total["max_cpu_s"] <= TARGETS["max_cpu_s"],
           "infeasible_pct": all(s["infeasible_pct"] <= TARGETS["infeasible_pct"] for s in per_maneuver.values())}
    result = {"settings": {"maps": maps, "garages_per_map": args.garages, "occupancy": args.occupancy,
                           "seed": args.seed, "budget_factor": args.budget_factor, "config": asdict(config),
                           "machine": f"{platform.machine()} {platform.processor() or ''}".strip()},
              "targets": TARGETS, "targets_met": met, "total": total, "per_maneuver": per_maneuver,
              "per_map": per_map,
              "replanned": {"infeasible": sum(not r["found"] for r in rows), "overturned": len(overturned),
                            "budget": big.iterations},
              "infeasible_tests": [{k: r[k] for k in ("map", "garage", "stall", "maneuver", "reason", "replanned")}
                                   for r in rows if not r["found"]],
              "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    for n, s in per_maneuver.items():
        print(f"{n:8s} tests {s['tests']:5d}  infeasible {s['infeasible_pct']:5.2f}%  CPU-s median {s['median_cpu_s']} "
              f"p95 {s['p95_cpu_s']} max {s['max_cpu_s']}  analytic {s['analytic_pct']}%  cusps mean {s['mean_cusps']}")
    print(f"TOTAL {total['tests']} tests, {total['infeasible']} infeasible ({total['infeasible_pct']}%), "
          f"{len(overturned)} overturned by {args.budget_factor}x the budget; median {total['median_cpu_s']} CPU-s, "
          f"max {total['max_cpu_s']} CPU-s; targets met: {met}; {result['wall_s']} s wall -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
