"""The park tests' verdicts before the drive where the aisle is narrow: feasible, infeasible (by proof) and unproven.

For each shipped map (or ``--maps``), ``--garages`` painted garages; in each, every stall whose cruise test is
feasible (its goal is the park test's start) x both maneuvers, the other stalls occupied each with probability
``--occupancy`` (seeded). The aisle in front of each stall is narrowed to ``--aisle`` metres (default 7.35) by a
wall body along it: a box from ``--aisle`` m past the stall's entry line to the far edge of the 9 m road cell,
running ``--wall-span`` m along the aisle, centred on the stall. The reference planner
(:class:`~garage_mj.scene.park_planning.ParkPlanner`, default settings: its first attempt, then its escalation)
gives each test a verdict; its CPU time (``time.process_time``) is recorded.

Every test the reference planner does not call feasible is searched again by an independent OMPL search: the
same Reeds-Shepp space (the same turning radius) and the same validity check (the footprint grown by the same
0.1 m margin), straight from the stall pose to the start (no straight exit first), RRT-Connect for
``--independent-s`` CPU seconds, then BIT* as long, each result's path checked pose by pose. Targets: the
reference planner finds a path wherever the independent search does (>= 98% of those), unproven <= 1% of the
tests, planning median <= 0.5 CPU-s and 99th percentile <= 5 CPU-s; and no test proven infeasible has an
independent path (a proof that fails is a bug).

    .venv/bin/python eval/bench_park_verdicts.py --maps tiny_7x11 m5_13x13_aligned --garages 1
        # writes docs/bench_park_verdicts.json

``--geometry NAME`` builds the garages with one of the park geometries of ``eval/_park_garages.py`` instead (the
aisle as the geometry narrows it, no added wall; docs/spec.md section 9), its parked cars where the planner sees
them.

    .venv/bin/python eval/bench_park_verdicts.py --maps tiny_7x11 m5_13x13_aligned --garages 1 --geometry tight \\
        --out docs/bench_park_verdicts_tight.json
"""

from __future__ import annotations

import json
import math
import statistics
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from _park_garages import GEOMETRIES, map_names, painted_garages, park_parser  # eval/_park_garages.py
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.scene.car import car_geometry
from garage_mj.scene.clearance import Obstacles, nearest_obstacle
from garage_mj.scene.drivable import drive_planner
from garage_mj.scene.garage_scene import GarageScene
from garage_mj.scene.park_planning import (
    BACK_GAP,
    DEFAULT_PARK,
    MANEUVERS,
    ParkPlanner,
    _Checker,
    _Curves,
    _edge,
    _join,
    _ompl_seeded,
    centre_to_rear,
    park_obstacles,
    park_pose,
)
from garage_mj.scene.world import DEFAULT_WORLD, world_with

TARGETS = {"independent_found_pct": 98.0, "unproven_pct": 1.0, "median_cpu_s": 0.5, "p99_cpu_s": 5.0}
ROAD = 9.0  # [m] the road cell in front of a stall: the aisle at its full width


def aisle_wall(stall, aisle: float, span: float) -> np.ndarray:
    """The axis-aligned box ``(x0, y0, x1, y1)`` of the wall that narrows the aisle in front of ``stall`` to ``aisle``
    metres: from ``aisle`` to :data:`ROAD` metres past its entry line, ``span`` metres along the aisle."""
    u = np.array([math.cos(stall.yaw), math.sin(stall.yaw)])
    v = np.array([-u[1], u[0]])
    entry = np.array(stall.entry)
    pts = [entry + a * u + b * v for a in (aisle, ROAD) for b in (-span / 2, span / 2)]
    lo, hi = np.min(pts, axis=0), np.max(pts, axis=0)
    return np.array([lo[0], lo[1], hi[0], hi[1]])


def independent(planner: ParkPlanner, obs: Obstacles, start, stall, maneuver: str, seconds: float,
                seed: int) -> dict:
    """RRT-Connect, then BIT*, ``seconds`` CPU-s each, from the stall pose to the start in the reference planner's
    Reeds-Shepp space and validity check: whether either finds a path clear at every pose, and its cusps."""
    car, cfg = planner.car, planner.config
    g, s = centre_to_rear(park_pose(stall, car, maneuver), car), centre_to_rear(start, car)
    d_out = stall.length - BACK_GAP + cfg.margin
    gear = MANEUVERS[maneuver].exit_gear
    out = g[:2] + gear * d_out * np.array([math.cos(g[2]), math.sin(g[2])])
    region = planner._region(np.array([g, s, [*out, g[2]]]))
    checker = _Checker(planner.near(obs, region), car, cfg.margin, region)
    if not (checker.pose_clear(*g) and checker.pose_clear(*s)):
        return {"found": False, "planner": "", "cusps": None, "cpu_s": 0.0}
    t0 = time.process_time()
    with _ompl_seeded(seed) as (ob, og):
        curves = _Curves(ob, planner.radius, region, cfg.step)
        si = ob.SpaceInformation(curves.space)
        si.setStateValidityChecker(checker)
        si.setStateValidityCheckingResolution(curves.resolution)
        si.setup()
        for name in ("RRTConnect", "BITstar"):
            pdef = ob.ProblemDefinition(si)
            pdef.setStartAndGoalStates(curves.state(g), curves.state(s), 1e-3)
            objective = ob.PathLengthOptimizationObjective(si)
            objective.setCostThreshold(ob.Cost(math.inf))
            pdef.setOptimizationObjective(objective)
            p = getattr(og, name)(si)
            if name == "RRTConnect":
                p.setRange(cfg.planner_range)
            p.setProblemDefinition(pdef)
            p.setup()
            stop = time.process_time() + seconds
            p.solve(ob.PlannerTerminationCondition(lambda stop=stop: time.process_time() > stop))
            if not pdef.hasExactSolution():
                continue
            path = pdef.getSolutionPath()
            og.PathSimplifier(si).simplifyMax(path)
            way = [np.array([st.getX(), st.getY(), st.getYaw()]) for st in path.getStates()]
            dense = _join(*(_edge(curves, checker, a, b) for a, b in zip(way[:-1], way[1:], strict=True)))
            if checker.clear(dense).all():
                d = np.diff(dense[:, :2], axis=0)
                along = np.sign(d[:, 0] * np.cos(dense[:-1, 2]) + d[:, 1] * np.sin(dense[:-1, 2]))
                along = along[along != 0]
                return {"found": True, "planner": name, "cusps": int((along[1:] != along[:-1]).sum()),
                        "cpu_s": round(time.process_time() - t0, 2)}
    return {"found": False, "planner": "", "cusps": None, "cpu_s": round(time.process_time() - t0, 2)}


def main(argv: list[str] | None = None) -> int:
    ap = park_parser(__doc__, garages=1, out=Path("docs/bench_park_verdicts.json"))
    ap.add_argument("--aisle", type=float, default=7.35, help="aisle width in front of each stall [m] (default 7.35)")
    ap.add_argument("--wall-span", type=float, default=27.0, help="the narrowing wall's length along the aisle [m]")
    ap.add_argument("--geometry", choices=sorted(GEOMETRIES), default=None,
                    help="build the garages with this park geometry (no added wall; --aisle is not used)")
    ap.add_argument("--independent-s", type=float, default=12.0,
                    help="CPU-s of each independent planner (RRT-Connect, then BIT*) per test not called feasible")
    args = ap.parse_args(argv)
    prov = provenance(argv)
    maps = map_names(args)
    car, config = car_geometry(), DEFAULT_PARK
    rows, skipped, t0 = [], 0, time.perf_counter()
    geo = GEOMETRIES[args.geometry] if args.geometry else None
    for pg in painted_garages(args, maps):
        scene = GarageScene(pg.source.garage, world_with(geo.world) if geo else DEFAULT_WORLD)
        planner = ParkPlanner(scene, car, config)
        cruise = drive_planner(scene, car)
        rng = np.random.default_rng(pg.seed)
        ids = [s.id for s in scene.stalls.stalls]
        n0 = len(rows)
        for stall in scene.stalls.stalls:
            test = cruise.plan(stall.id)
            occupied = [i for i, o in zip(ids, rng.random(len(ids)) < args.occupancy, strict=True) if o and i != stall.id]
            if not test.feasible:
                continue
            obs = park_obstacles(planner.obstacles(), stall.id, occupied)
            if geo is None:  # a wall narrows the 9 m aisle
                wall = aisle_wall(stall, args.aisle, args.wall_span)
                rear = centre_to_rear(test.goal, car)
                if nearest_obstacle(Obstacles(wall[None], ["wall"], np.array([-1])), car, rear[None, :2],
                                    rear[None, 2])[0][0] < config.margin:
                    skipped += 1  # the start (on the lane beside the stall) stands in the wall: no test there
                    continue
                obs = obs.plus(Obstacles(wall[None], ["wall"], np.array([-1])))
            for name in MANEUVERS:
                plan = planner.plan(test.goal, stall.id, name, obstacles=obs)
                row = {**plan.summary(), "map": pg.map, "garage": scene.name}
                if plan.verdict != "feasible":
                    row["independent"] = independent(planner, obs, test.goal, stall, name, args.independent_s,
                                                     pg.seed)
                rows.append(row)
        mine = rows[n0:]
        print(f"{pg.map:18s} garage {pg.index}: {len(mine)} tests, "
              + ", ".join(f"{v} {sum(r['verdict'] == v for r in mine)}" for v in ("feasible", "infeasible", "unproven")),
              flush=True)
    times = [r["planning_time"] for r in rows]
    verdicts = {v: sum(r["verdict"] == v for r in rows) for v in ("feasible", "infeasible", "unproven")}
    reasons: dict[str, int] = {}
    for r in rows:
        if r["verdict"] == "infeasible":
            key = r["reason"].split(":")[0].split(" (")[0]
            reasons[key] = reasons.get(key, 0) + 1
    checked = [r for r in rows if "independent" in r]
    indep = [r for r in checked if r["independent"]["found"]]
    # the reference planner finds a path wherever the independent search does: over the independent's paths,
    # the share where the reference planner found one too (every test not checked was found by the reference)
    both = sum(r["verdict"] == "feasible" for r in rows)
    independent_found_pct = round(100.0 * both / (both + len(indep)), 2) if both + len(indep) else None
    total = {"tests": len(rows), "skipped_start_in_wall": skipped, **verdicts,
             "unproven_pct": round(100.0 * verdicts["unproven"] / max(len(rows), 1), 2),
             "infeasible_reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1])),
             "escalated_found": sum(r["verdict"] == "feasible" and r["attempt"] > 0 for r in rows),
             "found_by_attempt": {k: sum(r["verdict"] == "feasible" and r["attempt"] == k for r in rows)
                                  for k in range(len(config.escalation) + 1)},
             "independent_checked": len(checked), "independent_found": len(indep),
             "independent_found_on_proven_infeasible": sum(r["verdict"] == "infeasible" for r in indep),
             "independent_found_pct": independent_found_pct,
             "median_cpu_s": round(statistics.median(times), 4) if times else None,
             "p99_cpu_s": round(float(np.percentile(times, 99)), 4) if times else None,
             "max_cpu_s": round(max(times), 4) if times else None}
    met = {"independent_found_pct": independent_found_pct is not None
           and independent_found_pct >= TARGETS["independent_found_pct"],
           "unproven_pct": total["unproven_pct"] <= TARGETS["unproven_pct"],
           "median_cpu_s": total["median_cpu_s"] is not None and total["median_cpu_s"] <= TARGETS["median_cpu_s"],
           "p99_cpu_s": total["p99_cpu_s"] is not None and total["p99_cpu_s"] <= TARGETS["p99_cpu_s"],
           "proofs_hold": total["independent_found_on_proven_infeasible"] == 0}
    result = {"settings": {"maps": maps, "garages_per_map": args.garages, "occupancy": args.occupancy,
                           "seed": args.seed, "geometry": None if geo is None else asdict(geo),
                           "aisle_m": None if geo else args.aisle, "wall_span_m": None if geo else args.wall_span,
                           "independent_s": args.independent_s, "config": asdict(config)},
              "targets": TARGETS, "targets_met": met, "total": total,
              "not_feasible": [{k: r[k] for k in ("map", "garage", "stall", "maneuver", "verdict", "reason",
                                                  "planning_time", "independent")} for r in checked],
              "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"TOTAL {total['tests']} tests ({args.geometry or f'aisle {args.aisle} m'}): feasible {verdicts['feasible']} "
          f"({total['escalated_found']} after escalation), infeasible {verdicts['infeasible']} {total['infeasible_reasons']}, "
          f"unproven {verdicts['unproven']} ({total['unproven_pct']}%); independent search found {len(indep)} of "
          f"{len(checked)} not called feasible ({total['independent_found_on_proven_infeasible']} of them proven "
          f"infeasible); reference finds {independent_found_pct}% of the independent's; CPU-s median "
          f"{total['median_cpu_s']} p99 {total['p99_cpu_s']} max {total['max_cpu_s']}; targets met: {met}; "
          f"{result['wall_s']} s wall -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
