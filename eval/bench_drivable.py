"""Cruise tests you can trust: infeasible share and reference-driver success on every shipped map.

For each shipped map, ``--garages`` painted garages (spread over difficulty) x ``--tests`` tests
with occupancy 0.5, driven by each ``--drivers`` entry (``name:action_type``). Also runs the same
on the hand-made shapes in ``tests/data`` (obstacle islands, non-square). Each run is a resumable
``garage-mj cruise`` folder under ``--out``; the table it prints (and writes to
``OUT/summary.json``) gives per map and driver: tests, infeasible share, success over feasible
tests, failures by class, and simulated seconds per wall second.

    .venv/bin/python eval/bench_drivable.py --workers 2                 # 5 maps x 20 x 10, oracle
    .venv/bin/python eval/bench_drivable.py --drivers waypoint:continuous waypoint:discrete
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from garage_mj import list_maps
from garage_mj.core.backends import Compute
from garage_mj.driving.sources import CruiseSettings, CruiseSource, painted_sources
from garage_mj.grid.garage import Garage
from garage_mj.reporting.cruise import run_cruise

SHAPES = Path(__file__).resolve().parent.parent / "tests" / "data" / "shapes"


def _shape_sources() -> list[CruiseSource]:
    out = []
    for path in sorted(SHAPES.glob("*.json")):
        out.append(CruiseSource.from_garage(Garage.from_json(path.read_text()), path.stem))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="*", default=None, help="maps (default: every shipped map)")
    ap.add_argument("--garages", type=int, default=20, help="painted garages per map (default 20)")
    ap.add_argument("--tests", type=int, default=10, help="tests per garage (default 10)")
    ap.add_argument("--drivers", nargs="*", default=["oracle:continuous"], help="NAME:ACTION_TYPE entries")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-shapes", action="store_true", help="skip the hand-made shapes of tests/data/shapes")
    ap.add_argument("--out", type=Path, default=Path("runs/bench_drivable"))
    args = ap.parse_args(argv)
    maps = args.maps or [m.name for m in list_maps()]
    groups = {m: painted_sources(m, args.garages, seed=args.seed) for m in maps}
    if not args.no_shapes:
        groups["shapes (islands, non-square)"] = _shape_sources()
    table = []
    for spec in args.drivers:
        driver, action = spec.split(":") if ":" in spec else (spec, "continuous")
        for name, sources in groups.items():
            t0 = time.perf_counter()
            folder = args.out / f"{driver}_{action}" / name.split(" ")[0]
            res = run_cruise(sources, args.tests, CruiseSettings(driver, seed=args.seed, action_type=action),
                             folder, compute=Compute(workers=args.workers, progress=False))
            s = res.stats
            row = {"driver": driver, "action_type": action, "group": name, "garages": len(sources),
                   "tests": s["tests"], "infeasible": s["infeasible"],
                   "infeasible_pct": round(100 * s["infeasible"] / max(s["tests"], 1), 2),
                   "feasible": s["feasible"], "success_pct": s["success_pct"], "failures": s["failures"],
                   "hits": s["hits"], "sim_s_per_wall_s": s["sim_seconds_per_wall_second"],
                   "wall_s": round(time.perf_counter() - t0, 1)}
            table.append(row)
            print(f"{driver:9s} {action:10s} {name:30s} tests {row['tests']:5d}  infeasible {row['infeasible_pct']:5.2f}%  "
                  f"success {row['success_pct']}% of {row['feasible']}  failures {row['failures']}  "
                  f"sim/wall {row['sim_s_per_wall_s']}", flush=True)
    for spec in args.drivers:
        driver, action = spec.split(":") if ":" in spec else (spec, "continuous")
        mine = [r for r in table if r["driver"] == driver and r["action_type"] == action]
        tests = sum(r["tests"] for r in mine)
        feas = sum(r["feasible"] for r in mine)
        succ = sum(round(r["success_pct"] * r["feasible"] / 100) for r in mine if r["success_pct"] is not None)
        infeas = sum(r["infeasible"] for r in mine)
        print(f"TOTAL {driver} {action}: {tests} tests, {infeas} infeasible ({100 * infeas / max(tests, 1):.2f}%), "
              f"success {succ}/{feas} = {100 * succ / max(feas, 1):.2f}% of feasible")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(table, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
