"""Park and AVP tests driven end to end: the oracle against the park_assist baseline on every shipped map.

For each shipped map, ``--garages`` painted garages (spread over difficulty, as ``bench_park_plan.py``
paints them); in each, ``--tests`` seeded tests of each kind: ``park`` reverse-in, ``park`` nose-in and
``avp`` (cruise from the entrance, then park; the maneuver drawn per test), the other stalls occupied
each with probability ``--occupancy``. The target stall is drawn among all stalls (``infeasible="report"``),
so the infeasible share counts tests without a cruise route to the stall as well as those without a park
plan. Every feasible test is driven by each driver from the same reset (same stall, parked cars and start).

Reported per map x kind x driver: success over feasible tests, the outcomes, the parking metrics of the
successes (position and heading error, park time), the reference planner's CPU time per test, and the
simulated seconds per wall second of stepping the env with its camera on (reset and planning excluded).
Targets (docs/spec.md section 8): the oracle succeeds on >= 99% of feasible park tests (either maneuver)
and >= 98% of feasible AVP tests. park_assist has no target: it is meant to fail more.

    .venv/bin/python eval/bench_park.py --garages 1 --tests 10         # writes docs/bench_park.json

``--geometries`` runs the same tests on each garage geometry of :data:`GEOMETRIES` (docs/spec.md section 9: stall
width and angle, aisle width, the parked fleet and its jitter) and ``--vehicles`` with each car under test
(``sedan``: models/car); each pair is one section of the result, with the verdicts before the drive (feasible,
infeasible by proof, unproven: the unproven share beside every rate) and success by level, maneuver and stall angle.
Finished garages are kept in ``OUT.rows.jsonl`` as they end: the same command resumes where a stopped run left.

    .venv/bin/python eval/bench_park.py --garages 1 --tests 8 --workers 2 \\
        --geometries default tight angled60 parallel --vehicles sedan suv --out docs/bench_park_geometry.json
"""

from __future__ import annotations

import json
import math
import platform
import statistics
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from _park_garages import (  # eval/_park_garages.py
    GEOMETRIES,
    Geometry,
    map_names,
    painted_garages,
    park_parser,
)
from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.driving.drivers import load_driver
from garage_mj.driving.sim.drive_env import GarageDriveEnv


@dataclass(frozen=True)
class Kind:
    """One kind of test of the benchmark."""

    name: str
    task: str
    maneuver: str


KINDS = (Kind("park_reverse", "park", "reverse"), Kind("park_forward", "park", "forward"), Kind("avp", "avp", "any"))


DRIVERS = ("oracle", "park_assist")
TARGETS = {"oracle_park_success_pct": 99.0, "oracle_avp_success_pct": 98.0}


def _drive(env: GarageDriveEnv, driver: str, seed: int) -> tuple[dict, float]:
    """One test from the reset of ``seed``: its last info and the wall seconds spent stepping."""
    obs, info = env.reset(seed=seed)
    d = load_driver(driver)
    d.reset(env.driver_info(seed))
    t0 = time.perf_counter()
    while "outcome" not in info:
        obs, _, _, _, info = env.step(d.act(obs))
    return info, time.perf_counter() - t0


def _garage_rows(garage, kind: Kind, tests: int, occupancy: float, seed: int, label: dict,
                 geometry: Geometry = GEOMETRIES["default"], vehicle: str | None = None) -> list[dict]:
    """Every test of one kind on one garage, each feasible one driven by every driver."""
    from garage_mj.scene.world import world_with

    env = GarageDriveEnv(garage=garage, action_type="continuous", task=kind.task, maneuver=kind.maneuver,
                         occupancy=occupancy, infeasible="report", world=world_with(geometry.world),
                         vehicle=vehicle, parked_fleet=geometry.parked_fleet, parked_jitter=geometry.parked_jitter)
    rows = []
    try:
        for k in range(tests):
            test_seed = seed * 100_003 + k
            _, info = env.reset(seed=test_seed)
            test = env._park  # the park test of this reset: its verdict and reference plan (None: no cruise route)
            plan = test.plan
            base = {**label, "kind": kind.name, "seed": test_seed, "stall": info["target_stall"],
                    "maneuver": info["maneuver"], "feasible": bool(info["feasible"]), "verdict": test.verdict,
                    "park_level": info.get("park_level"), "stall_angle": env.stalls[test.stall].angle,
                    "planning_cpu_s": None if plan is None else round(plan.planning_time, 4),
                    "plan_cusps": info["plan_cusps"]}
            if not info["feasible"]:
                rows.append({**base, "driver": None, "outcome": test.verdict, "reason": info.get("reason", "")})
                continue
            for driver in DRIVERS:
                end, wall = _drive(env, driver, test_seed)
                rows.append({**base, "driver": driver, "outcome": end["outcome"], "reason": end["reason"],
                             "sim_s": round(end["time"], 2), "wall_s": round(wall, 3),
                             "position_error": _num(end.get("position_error")),
                             "heading_error": _num(end.get("heading_error")),
                             "park_time": _num(end.get("park_time")),
                             "direction_changes": end.get("direction_changes")})
    finally:
        env.close()
    return rows


def _num(v) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else round(float(v), 4)


def _mean(values) -> float | None:
    vals = [v for v in values if v is not None]
    return round(statistics.mean(vals), 4) if vals else None


def _stats(rows: list[dict], driver: str) -> dict:
    """Success over feasible tests and the rest, for one driver over ``rows`` (one row per test per driver)."""
    tests = {(r["map"], r["garage"], r["kind"], r["seed"]): r for r in rows if r["driver"] in (None, driver)}
    infeasible = sum(r["outcome"] == "infeasible" for r in tests.values())
    unproven = sum(r["outcome"] == "unproven" for r in tests.values())
    driven = [r for r in rows if r["driver"] == driver]
    ok = [r for r in driven if r["outcome"] == "success"]
    planned = [r["planning_cpu_s"] for r in tests.values() if r["planning_cpu_s"] is not None]
    sim, wall = sum(r["sim_s"] for r in driven), sum(r["wall_s"] for r in driven)
    return {"tests": len(tests), "infeasible": infeasible,
            "infeasible_pct": round(100 * infeasible / max(len(tests), 1), 2),
            "unproven": unproven, "unproven_pct": round(100 * unproven / max(len(tests), 1), 2),
            "feasible": len(driven), "success": len(ok),
            "success_pct": round(100 * len(ok) / len(driven), 2) if driven else None,
            "outcomes": dict(Counter(r["outcome"] for r in driven)),
            "position_error_m": _mean(r["position_error"] for r in ok),
            "heading_error_deg": _mean(r["heading_error"] for r in ok),
            "park_time_s": _mean(r["park_time"] for r in ok),
            "planning_cpu_s_median": round(statistics.median(planned), 4) if planned else None,
            "planning_cpu_s_max": round(max(planned), 4) if planned else None,
            "sim_s_per_wall_s": round(sim / wall, 2) if wall > 0 else None}


def _job(job: tuple) -> list[dict]:
    """The rows of one (geometry, vehicle, garage, kind) of the grid (run in a worker process)."""
    gname, vehicle, map_name, index, seed, kind_name, tests, occupancy, paint_seed, garages = job
    from garage_mj.driving.sources import painted_sources
    from garage_mj.scene.world import GeometryError

    source = painted_sources(map_name, garages, seed=paint_seed)[index]  # as painted_garages paints them
    kind = next(k for k in KINDS if k.name == kind_name)
    label = {"geometry": gname, "vehicle": vehicle, "map": map_name, "garage": source.name}
    try:
        return _garage_rows(source.garage, kind, tests, occupancy, seed, label, GEOMETRIES[gname], vehicle)
    except GeometryError as exc:  # the garage cannot be built in this geometry: one row that says why, no tests
        return [{**label, "kind": kind.name, "seed": None, "driver": None, "outcome": "not_built", "reason": str(exc)}]


def _breakdown(rows: list[dict], key: str) -> dict:
    """Oracle and park_assist success per value of ``key`` (park_level, maneuver, stall_angle) over park tests."""
    values = sorted({r[key] for r in rows if r.get(key) is not None}, key=str)
    return {str(v): {d: _stats([r for r in rows if r.get(key) == v], d) for d in DRIVERS} for v in values}


def grid(args, maps: list[str], prov: dict) -> int:
    """The geometry x vehicle grid (module docstring), resumable from ``OUT.rows.jsonl``."""
    rows_path = args.out.with_suffix(".rows.jsonl")
    done: dict[str, list[dict]] = {}
    if rows_path.exists():
        for line in rows_path.read_text().splitlines():
            if line.strip():
                rec = json.loads(line)
                done[rec["job"]] = rec["rows"]
    jobs = [(g, v, m, k, args.seed * 1000 + k, kind.name, args.tests, args.occupancy, args.seed, args.garages)
            for g in args.geometries for v in args.vehicles for m in maps for k in range(args.garages) for kind in KINDS]
    todo = [j for j in jobs if json.dumps(j) not in done]
    print(f"{len(jobs)} jobs, {len(jobs) - len(todo)} done before, {args.workers} workers", flush=True)
    t0 = time.perf_counter()
    rows_path.parent.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(args.workers) as pool, rows_path.open("a") as sink:
        for job, got in zip(todo, pool.map(_job, todo), strict=True):
            done[json.dumps(job)] = got
            sink.write(json.dumps({"job": json.dumps(job), "rows": got}) + "\n")
            sink.flush()
            if got and got[0]["outcome"] == "not_built":
                print(f"{job[0]:9s} {job[1]:7s} {job[2]:18s} #{job[3]} not built: {got[0]['reason']}", flush=True)
                continue
            line = "  ".join(f"{d} {_stats(got, d)['success']}/{_stats(got, d)['feasible']}" for d in DRIVERS)
            print(f"{job[0]:9s} {job[1]:7s} {job[2]:18s} #{job[3]} {job[5]:13s} unproven "
                  f"{_stats(got, DRIVERS[0])['unproven']}/{args.tests}  {line}", flush=True)
    sections = []
    for g in args.geometries:
        for v in args.vehicles:
            every_row = [r for j in jobs if j[0] == g and j[1] == v for r in done[json.dumps(j)]]
            rows = [r for r in every_row if r["outcome"] != "not_built"]
            not_built = sorted({(r["map"], r["garage"], r["reason"]) for r in every_row if r["outcome"] == "not_built"})
            park = [r for r in rows if r["kind"] != "avp"]
            op, oa = _stats(park, "oracle"), _stats([r for r in rows if r["kind"] == "avp"], "oracle")
            every = _stats(rows, "oracle")
            sections.append({
                "geometry": GEOMETRIES[g].__dict__, "vehicle": v,
                "garages_not_built": [{"map": m, "garage": n, "reason": why} for m, n, why in not_built],
                "oracle_park": op, "oracle_avp": oa,
                "park_assist_park": _stats(park, "park_assist"),
                "unproven_pct": every["unproven_pct"], "infeasible_pct": every["infeasible_pct"],
                "targets_met": {"oracle_park_success_pct": (op["success_pct"] or 0) >= TARGETS["oracle_park_success_pct"],
                                "oracle_avp_success_pct": (oa["success_pct"] or 0) >= TARGETS["oracle_avp_success_pct"],
                                "unproven_pct": every["unproven_pct"] <= 1.0},
                "by_level": _breakdown(park, "park_level"), "by_maneuver": _breakdown(park, "maneuver"),
                "by_stall_angle": _breakdown(park, "stall_angle"),
                "failures": [r for r in rows if r["driver"] == "oracle" and r["outcome"] != "success"]})
            s = sections[-1]
            print(f"{g:9s} {v:7s} oracle park {op['success']}/{op['feasible']} ({op['success_pct']}%), avp "
                  f"{oa['success']}/{oa['feasible']} ({oa['success_pct']}%), unproven {s['unproven_pct']}%, "
                  f"park_assist {s['park_assist_park']['success_pct']}%", flush=True)
    result = {"settings": {"maps": maps, "garages_per_map": args.garages, "tests_per_garage_and_kind": args.tests,
                           "kinds": [k.__dict__ for k in KINDS], "drivers": list(DRIVERS), "geometries": args.geometries,
                           "vehicles": args.vehicles, "occupancy": args.occupancy, "seed": args.seed,
                           "workers": args.workers},
              "targets": {**TARGETS, "unproven_pct": 1.0}, "sections": sections,
              "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"-> {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = park_parser(__doc__, garages=1, out=Path("docs/bench_park.json"))
    ap.add_argument("--tests", type=int, default=10, help="tests per garage and kind (default 10)")
    ap.add_argument("--geometries", nargs="*", choices=sorted(GEOMETRIES), default=None,
                    help="run the geometry grid on these geometries (module docstring)")
    ap.add_argument("--vehicles", nargs="*", default=["sedan"], help="cars under test of the grid (default sedan)")
    ap.add_argument("--workers", type=int, default=1, help="worker processes of the grid (default 1)")
    args = ap.parse_args(argv)
    if args.geometries:
        return grid(args, map_names(args), provenance(argv))
    prov = provenance(argv)  # before the run: the load it starts at
    maps = map_names(args)
    rows, t0 = [], time.perf_counter()
    for pg in painted_garages(args, maps):
        for kind in KINDS:
            got = _garage_rows(pg.source.garage, kind, args.tests, args.occupancy, pg.seed,
                               {"map": pg.map, "garage": pg.source.name})
            rows += got
            line = "  ".join(f"{d} {_stats(got, d)['success']}/{_stats(got, d)['feasible']}" for d in DRIVERS)
            print(f"{pg.map:18s} {pg.source.name:28s} {kind.name:13s} infeasible "
                  f"{_stats(got, DRIVERS[0])['infeasible']}/{args.tests}  {line}", flush=True)
    per_map = [{"map": m, "kind": k.name, "driver": d, **_stats([r for r in rows if r["map"] == m and
                                                                 r["kind"] == k.name], d)}
               for m in maps for k in KINDS for d in DRIVERS]
    per_kind = {k.name: {d: _stats([r for r in rows if r["kind"] == k.name], d) for d in DRIVERS} for k in KINDS}
    park_rows = [r for r in rows if r["kind"] != "avp"]
    oracle_park = _stats(park_rows, "oracle")
    oracle_avp = per_kind["avp"]["oracle"]
    met = {"oracle_park_success_pct": (oracle_park["success_pct"] or 0) >= TARGETS["oracle_park_success_pct"],
           "oracle_avp_success_pct": (oracle_avp["success_pct"] or 0) >= TARGETS["oracle_avp_success_pct"]}
    result = {"settings": {"maps": maps, "garages_per_map": args.garages, "tests_per_garage_and_kind": args.tests,
                           "kinds": [k.__dict__ for k in KINDS], "drivers": list(DRIVERS),
                           "occupancy": args.occupancy, "seed": args.seed, "camera": "on (the env's default)",
                           "machine": f"{platform.machine()} {platform.processor() or ''}".strip()},
              "targets": TARGETS, "targets_met": met,
              "oracle_park": oracle_park, "per_kind": per_kind, "per_map": per_map,
              "failures": [r for r in rows if r["driver"] == "oracle" and r["outcome"] != "success"],
              "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    for k, per in per_kind.items():
        for d, s in per.items():
            print(f"{k:13s} {d:12s} success {s['success']}/{s['feasible']} ({s['success_pct']}%)  infeasible "
                  f"{s['infeasible_pct']}%  outcomes {s['outcomes']}  sim/wall {s['sim_s_per_wall_s']}")
    print(f"oracle park {oracle_park['success_pct']}%, avp {oracle_avp['success_pct']}%; targets met: {met}; "
          f"{result['wall_s']} s wall -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
