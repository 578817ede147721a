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
"""

from __future__ import annotations

import json
import math
import platform
import statistics
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from _park_garages import map_names, painted_garages, park_parser  # eval/_park_garages.py: options, garages
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


def _garage_rows(garage, kind: Kind, tests: int, occupancy: float, seed: int, label: dict) -> list[dict]:
    """Every test of one kind on one garage, each feasible one driven by every driver."""
    env = GarageDriveEnv(garage=garage, action_type="continuous", task=kind.task, maneuver=kind.maneuver,
                         occupancy=occupancy, infeasible="report")
    rows = []
    try:
        for k in range(tests):
            test_seed = seed * 100_003 + k
            _, info = env.reset(seed=test_seed)
            plan = env._park.plan  # the reference plan of this reset (its CPU time; None: no cruise route)
            base = {**label, "kind": kind.name, "seed": test_seed, "stall": info["target_stall"],
                    "maneuver": info["maneuver"], "feasible": bool(info["feasible"]),
                    "planning_cpu_s": None if plan is None else round(plan.planning_time, 4),
                    "plan_cusps": info["plan_cusps"]}
            if not info["feasible"]:
                rows.append({**base, "driver": None, "outcome": "infeasible", "reason": info.get("reason", "")})
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
    driven = [r for r in rows if r["driver"] == driver]
    ok = [r for r in driven if r["outcome"] == "success"]
    planned = [r["planning_cpu_s"] for r in tests.values() if r["planning_cpu_s"] is not None]
    sim, wall = sum(r["sim_s"] for r in driven), sum(r["wall_s"] for r in driven)
    return {"tests": len(tests), "infeasible": infeasible,
            "infeasible_pct": round(100 * infeasible / max(len(tests), 1), 2),
            "feasible": len(driven), "success": len(ok),
            "success_pct": round(100 * len(ok) / len(driven), 2) if driven else None,
            "outcomes": dict(Counter(r["outcome"] for r in driven)),
            "position_error_m": _mean(r["position_error"] for r in ok),
            "heading_error_deg": _mean(r["heading_error"] for r in ok),
            "park_time_s": _mean(r["park_time"] for r in ok),
            "planning_cpu_s_median": round(statistics.median(planned), 4) if planned else None,
            "planning_cpu_s_max": round(max(planned), 4) if planned else None,
            "sim_s_per_wall_s": round(sim / wall, 2) if wall > 0 else None}


def main(argv: list[str] | None = None) -> int:
    ap = park_parser(__doc__, garages=1, out=Path("docs/bench_park.json"))
    ap.add_argument("--tests", type=int, default=10, help="tests per garage and kind (default 10)")
    args = ap.parse_args(argv)
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
