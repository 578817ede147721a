"""Does ``hunt`` find garages that break a driver? Hunted vs uniformly drawn library garages, equal budgets.

    .venv/bin/python eval/bench_hunt.py --library runs/paper_5pct/library.sqlite [--map m5_13x13_aligned]
        [--driver vision] [--action-type continuous] [--budget 1000] [--tests 5] [--top 10]
        [--holdout-tests 10] [--holdout-uniform 10] [--workers 2] [--out runs/bench_hunt]
        [--json docs/bench_hunt.json]

1. ``hunt`` spends ``--budget`` tests starting from the library's garages of ``--map``.
2. The uniform baseline spends the same budget on ``budget / tests`` garages drawn uniformly from
   the same library, ``--tests`` tests each (the hunt's tests per evaluation).
3. Held out: the hunt's ``--top`` garages and ``--holdout-uniform`` of the uniform garages (the
   first drawn; default as many as ``--top``) are re-tested with ``--holdout-tests`` fresh test
   seeds each (a run seed the hunt never used), so the hunted rate is not inflated by selecting
   on the same tests' luck.

Reports failure rates on feasible tests (in-search and held out) and their ratio; every stage is a
resumable run folder under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from garage_mj.core.backends import Compute
from garage_mj.driving.hunt import HuntConfig
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.generation.library import Library
from garage_mj.reporting.cruise import run_cruise
from garage_mj.reporting.hunt import hunt

HOLDOUT_FIRST = 1000  # held-out test indices start here (the hunt uses far fewer per garage)


def _rate(rows: list[dict]) -> dict:
    feas = [r for r in rows if r["outcome"] != "infeasible"]
    fails = [r for r in feas if r["outcome"] != "success"]
    kinds: dict[str, int] = {}
    for r in fails:
        k = f"{r['outcome']}:{r['hit']}" if r["hit"] else r["outcome"]
        kinds[k] = kinds.get(k, 0) + 1
    return {"tests": len(rows), "feasible": len(feas), "failures": len(fails),
            "failure_pct": round(100.0 * len(fails) / len(feas), 2) if feas else None, "kinds": kinds}


def _holdout(srcs: list[CruiseSource], args, out: Path) -> dict:
    """``--holdout-tests`` fresh tests per garage: indices HOLDOUT_FIRST.. via a shifted run seed."""
    res = run_cruise(srcs, args.holdout_tests,
                     CruiseSettings(args.driver, seed=args.seed + HOLDOUT_FIRST, action_type=args.action_type),
                     out, compute=Compute(workers=args.workers, progress=False))
    return _rate(res.rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--library", type=Path, required=True)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--driver", default="vision")
    ap.add_argument("--action-type", default="continuous")
    ap.add_argument("--budget", type=int, default=1000)
    ap.add_argument("--tests", type=int, default=5)
    ap.add_argument("--population", type=int, default=20)
    ap.add_argument("--elites", type=int, default=5)
    ap.add_argument("--top", type=int, default=10)
    ap.add_argument("--holdout-tests", type=int, default=10)
    ap.add_argument("--holdout-uniform", type=int, default=None, help="uniform garages re-tested (default --top)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("runs/bench_hunt"))
    ap.add_argument("--json", type=Path, default=Path("docs/bench_hunt.json"))
    args = ap.parse_args()
    t0 = time.perf_counter()
    res = hunt(CruiseSettings(args.driver, seed=args.seed, action_type=args.action_type), args.out / "hunt",
               map=args.map, library=args.library,
               config=HuntConfig(budget=args.budget, tests=args.tests, population=args.population,
                                 elites=args.elites, worst=3),
               compute=Compute(workers=args.workers), videos=True)
    hunt_s = time.perf_counter() - t0
    hunt_rows = [r for s in res.ranked for r in s.rows]
    n_uniform = args.budget // args.tests
    with Library(args.library, create=False) as lib:
        recs = lib.verified(lib.sample(n_uniform, args.seed + 1, stratify=None, map=args.map))
    uniform = [CruiseSource.from_record(r) for r in recs]
    t1 = time.perf_counter()
    uni = run_cruise(uniform, args.tests,
                     CruiseSettings(args.driver, seed=args.seed, action_type=args.action_type),
                     args.out / "uniform", compute=Compute(workers=args.workers, progress=False))
    uniform_s = time.perf_counter() - t1
    top = [s.source for s in res.ranked if s.feasible][: args.top]
    result = {
        "library": str(args.library), "map": args.map, "driver": args.driver, "action_type": args.action_type,
        "budget": args.budget, "tests_per_garage": args.tests, "seed": args.seed,
        "hunt": {**_rate(hunt_rows), "garages": len(res.ranked), "generations": res.generations,
                 "wall_s": round(hunt_s, 1),
                 "top": [{"garage": s.source.name, "difficulty": round(s.source.difficulty, 3),
                          "tests": len(s.feasible), "failure_pct": round(100 * s.rate, 1)}
                         for s in res.ranked[: args.top] if s.feasible]},
        "uniform": {**_rate(uni.rows), "garages": len(uniform), "wall_s": round(uniform_s, 1)},
        "holdout": {"tests_per_garage": args.holdout_tests,
                    "hunt_top": _holdout(top, args, args.out / "holdout_hunt"),
                    "uniform_garages": args.holdout_uniform or args.top,
                    "uniform": _holdout(uniform[: args.holdout_uniform or args.top], args,
                                        args.out / "holdout_uniform")},
    }
    h, u = result["holdout"]["hunt_top"]["failure_pct"], result["holdout"]["uniform"]["failure_pct"]
    result["holdout"]["ratio"] = round(h / u, 2) if h is not None and u else None
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
