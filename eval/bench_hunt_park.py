"""Does a park hunt find confirmed parking failures faster than uniform sampling? Equal test budgets.

    MUJOCO_GL=egl .venv/bin/python eval/bench_hunt_park.py [--map m5_13x13_aligned] [--driver park_assist ...]
        [--budget 150] [--tests 5] [--population 10] [--elites 3] [--geometries default,tight,...]
        [--seed 0] [--workers 1] [--scenario park_mixed] [--out runs/bench_hunt_park]
        [--json docs/bench_hunt_park.json]

For each ``--driver``:

1. ``hunt --task park`` spends ``--budget`` park tests on (garage, park geometry) candidates painted on ``--map``
   (:func:`garage_mj.driving.hunt.hunt`, its geometries ``--geometries``).
2. The uniform baseline spends the same budget on ``budget / tests`` garages painted uniformly on the same map (the
   painter's seeds of another hunt seed, ``--seed + 1``), each in a geometry drawn uniformly from the same set (of
   those that build it), ``--tests`` tests each: a hunt with no generation after its start, so its failures are
   confirmed the same way.
3. A confirmed failure is a test the driver fails while the oracle parks it (same garage, geometry and test seed).

``--scenario NAME`` (a named scenario, e.g. ``park_mixed``) puts actors in every test of both arms; the hunt then
searches actor placements too (children that keep a failing test's scene with the actors placed anew).

Reports, per driver and arm, the tests, feasible tests, failures, confirmed failures, their rate per test spent
and per feasible test, and the ratio hunt / uniform of the confirmed rate per test (the target: at least 3x);
each arm is a resumable hunt folder under ``--out``; ``by_kind`` splits an arm's candidates into those drawing
their stalls, those aimed at a stall and those keeping a failing test's scene.

4. Held out (``--holdout-tests N``, as ``eval/bench_hunt.py`` measures the cruise hunt): the hunt's ``--top``
   candidates (its ranking: confirmed failure rate) and ``--holdout-uniform`` candidates of the uniform arm (the
   first by key, an order that knows nothing of their outcomes) are each tested N times more with fresh test
   seeds (the run seed shifted by ``HOLDOUT_SEED``; a candidate aimed at a stall keeps its stall), the oracle
   re-driving every failure; the ratio of their confirmed failure rates per driven test says whether what the hunt
   returns fails more often than what uniform sampling returns, beyond the tests that picked it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

from _provenance import provenance

from garage_mj.core.backends import Compute
from garage_mj.driving.actors.config import SCENARIOS
from garage_mj.driving.cruise import run_cruise, run_test
from garage_mj.driving.episode import close_cached_env
from garage_mj.driving.hunt import (
    PARK_HUNT_GEOMETRIES,
    HuntConfig,
    HuntResult,
    Scored,
    candidate_settings,
    hunt,
    oracle_settings,
)
from garage_mj.driving.sources import CruiseSettings

TARGET_RATIO = 3.0  # confirmed failures per test: hunt / uniform
HOLDOUT_SEED = 10_000  # the held-out re-tests' run seed: the hunt's plus this (their test seeds are new)


def _wilson(k: int, n: int, z: float = 1.96) -> list[float] | None:
    """Wilson 95% interval of k successes in n trials, as percentages."""
    if not n:
        return None
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return [round(100 * (c - h), 1), round(100 * (c + h), 1)]


def _arm(res: HuntResult, seconds: float) -> dict:
    """Counts of one arm: tests, feasible, failures, confirmed (oracle parks), per geometry too."""
    tests = sum(len(s.rows) for s in res.ranked)
    feasible = sum(len(s.feasible) for s in res.ranked)
    fails = sum(len(s.failures) for s in res.ranked)
    confirmed = sum(len(s.confirmed) for s in res.ranked)
    by_geometry: dict[str, dict[str, int]] = {}
    by_kind: dict[str, dict[str, int]] = {}
    for s in res.ranked:
        kind = "scene_kept" if s.scene is not None else "stall_aimed" if s.stall is not None else "stalls_drawn"
        for key, table in ((s.geometry, by_geometry), (kind, by_kind)):
            g = table.setdefault(key, {"candidates": 0, "tests": 0, "feasible": 0, "confirmed": 0})
            g["candidates"] += 1
            g["tests"] += len(s.rows)
            g["feasible"] += len(s.feasible)
            g["confirmed"] += len(s.confirmed)
    return {"candidates": len(res.ranked), "generations": res.generations, "tests": tests, "feasible": feasible,
            "failures": fails, "confirmed": confirmed,
            "confirmed_per_test_pct": round(100 * confirmed / tests, 2) if tests else None,
            "confirmed_per_test_ci95": _wilson(confirmed, tests),
            "confirmed_per_feasible_pct": round(100 * confirmed / feasible, 2) if feasible else None,
            "by_kind": dict(sorted(by_kind.items())), "by_geometry": dict(sorted(by_geometry.items())),
            "wall_s": round(seconds, 1)}


def _holdout(candidates: list[Scored], settings: CruiseSettings, env: dict, tests: int, out: Path,
             compute: Compute) -> dict:
    """``tests`` fresh tests of each candidate (run seed ``settings.seed + HOLDOUT_SEED``), each failure re-driven by
    the oracle: tests, driven, failures, confirmed failures and their rate per driven test. Resumable: each
    candidate's run folder under ``out`` and the oracle's outcomes in ``out/oracle.json``."""
    seed = settings.seed + HOLDOUT_SEED
    oracle_file = out / "oracle.json"
    oracle = json.loads(oracle_file.read_text()) if oracle_file.is_file() else {}
    counts = {"candidates": len(candidates), "tests": 0, "driven": 0, "failures": 0, "confirmed": 0}
    for k, c in enumerate(candidates):
        mine = dataclasses.replace(candidate_settings(settings, c.geometry), seed=seed)
        res = run_cruise([c.source], tests, mine, out / f"{k:03d}_{c.source.hash[:12]}_{c.geometry}",
                         compute=compute, route_model=False, park_model=False)
        by_oracle = dataclasses.replace(oracle_settings(settings, env, c.geometry), seed=seed)
        for r in res.rows:
            counts["tests"] += 1
            if r["outcome"] in ("infeasible", "unproven"):
                continue
            counts["driven"] += 1
            if r["outcome"] == "success":
                continue
            counts["failures"] += 1
            key = f"{c.source.hash}:{c.geometry}:{r['test']}"
            if key not in oracle:
                oracle[key] = run_test(c.source, int(r["test"]), by_oracle)["outcome"]
                oracle_file.parent.mkdir(parents=True, exist_ok=True)
                oracle_file.write_text(json.dumps(oracle, indent=0) + "\n")
            counts["confirmed"] += oracle[key] == "success"
    close_cached_env()
    n, k = counts["driven"], counts["confirmed"]
    return {**counts, "confirmed_per_driven_pct": round(100 * k / n, 2) if n else None, "ci95": _wilson(k, n)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--map", default="m5_13x13_aligned")
    ap.add_argument("--driver", action="append", default=None, help="a parking driver (repeat for more; default "
                                                                      "park_assist)")
    ap.add_argument("--budget", type=int, default=150)
    ap.add_argument("--tests", type=int, default=5)
    ap.add_argument("--population", type=int, default=10)
    ap.add_argument("--elites", type=int, default=3)
    ap.add_argument("--geometries", default=",".join(PARK_HUNT_GEOMETRIES))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--scenario", choices=sorted(SCENARIOS), default=None,
                    help="actors in every test (a named scenario; default none)")
    ap.add_argument("--holdout-tests", type=int, default=0,
                    help="fresh tests per held-out candidate (0: no held-out re-test)")
    ap.add_argument("--top", type=int, default=10, help="the hunt's best candidates re-tested (default 10)")
    ap.add_argument("--holdout-uniform", type=int, default=None,
                    help="uniform candidates re-tested (default: all of the uniform arm's)")
    ap.add_argument("--out", type=Path, default=Path("runs/bench_hunt_park"))
    ap.add_argument("--json", type=Path, default=Path("docs/bench_hunt_park.json"))
    args = ap.parse_args()
    geometries = [g for g in args.geometries.split(",") if g]
    compute = Compute(workers=args.workers, progress=False)
    env = {} if args.scenario is None else {"scenario": args.scenario}
    drivers = {}
    for driver in args.driver or ["park_assist"]:
        arms, results = {}, {}
        for arm, seed, cfg in (
                ("hunt", args.seed, HuntConfig(budget=args.budget, tests=args.tests, population=args.population,
                                               elites=args.elites, worst=0)),
                ("uniform", args.seed + 1, HuntConfig(budget=args.budget, tests=args.tests,
                                                      population=args.budget // args.tests, elites=1, worst=0))):
            t = time.time()
            res = hunt(CruiseSettings(driver, seed=seed, task="park", env=env),
                       args.out / driver.replace(":", "_") / arm, map=args.map, config=cfg, compute=compute,
                       geometries=geometries)
            arms[arm] = _arm(res, time.time() - t)
            results[arm] = res
            print(driver, arm, json.dumps({k: v for k, v in arms[arm].items() if k != "by_geometry"}), flush=True)
        h, u = arms["hunt"]["confirmed_per_test_pct"], arms["uniform"]["confirmed_per_test_pct"]
        ratio = round(h / u, 2) if h is not None and u else None
        drivers[driver] = {**arms, "ratio": ratio, "met": ratio is not None and ratio >= TARGET_RATIO}
        print(f"{driver}: confirmed failures per test, hunt {h}% vs uniform {u}%: ratio {ratio}", flush=True)
        if args.holdout_tests > 0:
            t = time.time()
            top = [s for s in results["hunt"].ranked if s.feasible][: args.top]
            uniform = sorted(results["uniform"].ranked, key=lambda s: s.key)[: args.holdout_uniform]
            base = CruiseSettings(driver, seed=args.seed, task="park", env=env)
            folder = args.out / driver.replace(":", "_") / "holdout"
            held = {"tests_per_candidate": args.holdout_tests, "seed": args.seed + HOLDOUT_SEED,
                    "hunt_top": _holdout(top, base, env, args.holdout_tests, folder / "hunt_top", compute),
                    "uniform": _holdout(uniform, base, env, args.holdout_tests, folder / "uniform", compute)}
            held["hunt_top"]["variants"] = [s.geometry for s in top]
            hh, uu = held["hunt_top"]["confirmed_per_driven_pct"], held["uniform"]["confirmed_per_driven_pct"]
            held["ratio"] = round(hh / uu, 2) if hh is not None and uu else None
            held["wall_s"] = round(time.time() - t, 1)
            drivers[driver]["holdout"] = held
            print(f"{driver}: held out, confirmed failures per driven test, the hunt's top {len(top)} {hh}% vs "
                  f"{len(uniform)} uniform {uu}%: ratio {held['ratio']}", flush=True)
    out = {"what": "confirmed park failures (the driver fails, the oracle parks the same test) per test spent: "
                   "hunt --task park against uniform sampling of garages and geometries, equal budgets",
           "map": args.map, "geometries": geometries, "budget": args.budget, "tests_per_evaluation": args.tests,
           "population": args.population, "elites": args.elites, "seed": args.seed, "scenario": args.scenario,
           "holdout_tests": args.holdout_tests, "top": args.top,
           "target_ratio": TARGET_RATIO,
           "drivers": drivers, "provenance": provenance()}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
