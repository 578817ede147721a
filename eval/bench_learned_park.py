"""The learned parking (or AVP) driver on held-out garages, against park_assist and the oracle, by level and actors.

Runs ``garage-mj cruise``'s own path (:func:`garage_mj.driving.cruise.run_cruise`) for every held-out garage set x
park geometry x actor scenario x driver: ``--tests`` park (``--task avp``: AVP) tests per garage, the maneuver drawn
per test, half the other stalls occupied. The held-out sets are the learned cruise driver's
(``docs/learned_driver/heldout/``: run seed 4 of m5, never used in training or validation, and two other maps): the
first ``--garages`` of a set that the geometry can build (angled rows may be too deep beside a junction: those garages
are left out of that geometry, and said).

Reported per driver (and per task): success over the driven tests (infeasible and unproven tests are not driven)
with a 95% Wilson interval, by HOPE's level (``normal``, ``complex``, ``extreme``), without and with actors; the
position and heading error of the successes (mean and median); the collision rate over driven tests; and, for the
first driver, the simulated seconds per wall second of its tests (both cameras, ultrasonic and slot detector on;
``time`` over ``wall_s`` of tests.csv, reset and planning included) per worker; how the tests' park difficulty
(under each driver's park model as shipped now, whichever rated the runs) predicts each driver's failures:
per-test AUC and per-garage r, drawn as success against park difficulty per garage beside the JSON (``OUT.png``).
Each run folder is kept under ``--runs``: the same command resumes a stopped benchmark where it left off.

    .venv/bin/python eval/bench_learned_park.py --driver learned:park --workers 2 \\
        --out docs/learned_park/bench_park.json
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import statistics
import sys
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.backends import Compute
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.difficulty.park_rating import choose_park_model, park_difficulty_cell
from garage_mj.driving.difficulty.regression import auc, pearson
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sim.park_guide import MAX_REPLANS
from garage_mj.driving.sources import CruiseSettings
from garage_mj.scene.stalls import stall_layout
from garage_mj.scene.world import GeometryError, world_with

ROOT = Path(__file__).resolve().parents[1]
HELDOUT = ROOT / "docs" / "learned_driver" / "heldout"
SETS = ("m5_unseen_seed", "m7_13x13_u", "tiny_7x11")
LEVELS = ("normal", "complex", "extreme")
NOT_DRIVEN = ("infeasible", "unproven")
Z95 = 1.959964
#: The targets (success over driven tests, by level; errors of successes; collisions), CARLA's parking benchmark's
#: figures beside them.
TARGETS = {"normal_success_pct": 95.0, "complex_success_pct": 85.0, "avp_success_pct": 85.0,
           "position_error_m": 0.30, "heading_error_deg": 0.87, "collision_pct": 2.0, "sim_s_per_wall_s": 50.0}


def wilson(k: int, n: int) -> list[float] | None:
    """The 95% Wilson score interval of ``k`` successes in ``n`` [%]."""
    if n == 0:
        return None
    p = k / n
    centre = (p + Z95**2 / (2 * n)) / (1 + Z95**2 / n)
    half = Z95 * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n)) / (1 + Z95**2 / n)
    return [round(100 * (centre - half), 1), round(100 * (centre + half), 1)]


def _mean(xs: list[float]) -> float | None:
    return round(statistics.fmean(xs), 3) if xs else None


def _median(xs: list[float]) -> float | None:
    return round(statistics.median(xs), 3) if xs else None


def stats(rows: list[dict]) -> dict:
    """Success, errors and collisions of ``rows`` (tests.csv rows) over the driven ones."""
    driven = [r for r in rows if r["outcome"] not in NOT_DRIVEN]
    ok = [r for r in driven if r["outcome"] == "success"]
    pos = [float(r["position_error_m"]) for r in ok if r.get("position_error_m")]
    head = [float(r["heading_error_deg"]) for r in ok if r.get("heading_error_deg")]
    outcomes: dict[str, int] = {}
    for r in driven:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    return {"tests": len(rows), "driven": len(driven), "success": len(ok),
            "success_pct": round(100 * len(ok) / len(driven), 1) if driven else None,
            "ci95_pct": wilson(len(ok), len(driven)),
            "not_driven": {k: sum(r["outcome"] == k for r in rows) for k in NOT_DRIVEN},
            "outcomes": dict(sorted(outcomes.items())),
            "collision_pct": round(100 * outcomes.get("collision", 0) / len(driven), 1) if driven else None,
            "position_error_m": {"mean": _mean(pos), "median": _median(pos)},
            "heading_error_deg": {"mean": _mean(head), "median": _median(head)}}


def summary(rows: list[dict]) -> dict:
    """:func:`stats` of all rows, by level, and without and with actors."""
    def actors(r: dict) -> bool:
        return any(int(r.get(k) or 0) for k in ("pedestrians", "moving_cars", "clutter"))

    return {"all": stats(rows), "by_level": {lv: stats([r for r in rows if r.get("park_level") == lv]) for lv in LEVELS},
            "static": stats([r for r in rows if not actors(r)]), "actors": stats([r for r in rows if actors(r)]),
            "static_by_level": {lv: stats([r for r in rows if r.get("park_level") == lv and not actors(r)])
                                for lv in LEVELS}}


def difficulty_fit(rows: list[dict], driver: str) -> dict:
    """How the park difficulty predicts ``rows``' failures: per-test AUC and, per garage and geometry, Pearson r of the
    mean park difficulty with success % (the paper's figure for parking). Each test is rated under ``driver``'s park
    model as shipped now (:func:`~garage_mj.driving.difficulty.park_rating.choose_park_model`), whichever model rated
    its run's ``park_difficulty`` column when it was driven."""
    model = choose_park_model(True, driver).model
    rows = [{**r, "park_difficulty": park_difficulty_cell(model, r) if model is not None else ""} for r in rows]
    driven = [r for r in rows if r["outcome"] not in NOT_DRIVEN and r.get("park_difficulty") not in ("", None)]
    groups: dict[tuple, list[dict]] = {}
    for r in driven:
        groups.setdefault((r["set"], r["geometry"], r["garage_hash"]), []).append(r)
    points = [(statistics.fmean(float(r["park_difficulty"]) for r in g),
               100.0 * sum(r["outcome"] == "success" for r in g) / len(g), len(g)) for g in groups.values()]
    failed = [r["outcome"] != "success" for r in driven]
    score = [float(r["park_difficulty"]) for r in driven]
    r_value = pearson([d for d, _, _ in points], [s for _, s, _ in points]) if len(points) > 2 else math.nan
    a = auc(score, failed) if 0 < sum(failed) < len(failed) else math.nan
    return {"tests": len(driven), "garages": len(points), "auc": None if math.isnan(a) else round(a, 3),
            "r": None if math.isnan(r_value) else round(r_value, 3),
            "points": [[round(d, 4), round(s, 1), n] for d, s, n in points]}


def figure(result: dict, path: Path) -> None:
    """Success against park difficulty per garage and geometry, one panel per driver, with r."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drivers = list(result["park_difficulty"])
    fig, axes = plt.subplots(1, len(drivers), figsize=(3.6 * len(drivers), 3.4), sharey=True, squeeze=False)
    for ax, d in zip(axes[0], drivers):
        fit = result["park_difficulty"][d]
        xs = [p[0] for p in fit["points"]]
        ys = [p[1] for p in fit["points"]]
        ax.scatter(xs, ys, s=14, alpha=0.7)
        if fit["r"] is None:  # success is the same on every garage: no r, no AUC
            what = f"success {ys[0]:.0f}% on every garage" if ys and len(set(ys)) == 1 else "too few garages"
        else:
            what = f"r = {fit['r']}, AUC = {fit['auc']}"
        ax.set(xlim=(0, 1), ylim=(-5, 105), xlabel="park difficulty (garage mean)",
               title=f"{d}\n{what} ({fit['garages']} garages)")
        ax.title.set_fontsize(9)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("success of driven tests [%]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def buildable(sources: list, geometry: str) -> tuple[list, list[str]]:
    """The garages of ``sources`` that ``geometry`` can build, and the names of those it cannot."""
    world = world_with(PARK_GEOMETRIES[geometry].world or None)
    keep, left = [], []
    for s in sources:
        try:
            stall_layout(s.garage, world)
            keep.append(s)
        except GeometryError:
            left.append(s.name)
    return keep, left


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--driver", default="learned:park", help="the driver under test (default learned:park)")
    ap.add_argument("--baselines", nargs="*", default=["park_assist", "oracle"], help="drivers beside it")
    ap.add_argument("--task", choices=("park", "avp"), default="park")
    ap.add_argument("--sets", nargs="*", choices=SETS, default=list(SETS), help="held-out garage sets")
    ap.add_argument("--garages", type=int, default=6,
                    help="garages per set and geometry: the first N the geometry can build (default 6)")
    ap.add_argument("--tests", type=int, default=2, help="tests per garage, geometry and scenario (default 2)")
    ap.add_argument("--geometries", nargs="*", choices=sorted(PARK_GEOMETRIES),
                    default=["default", "tight", "angled60", "parallel"])
    ap.add_argument("--scenarios", nargs="*", default=["none", "park_mixed"], help="actor scenarios (none: no actors)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--guide-replans", type=int, default=MAX_REPLANS,
                    help=f"new plans the park guide may show a test (default {MAX_REPLANS}; 0: the test's plan only)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "bench_learned_park", help="run folders (resumable)")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "learned_park" / "bench_park.json")
    args = ap.parse_args(argv)
    prov = provenance(argv)
    t0 = time.perf_counter()
    drivers = [args.driver, *args.baselines]
    rows: dict[str, list[dict]] = {d: [] for d in drivers}
    left_out: dict[str, list[str]] = {}
    for name in args.sets:
        sources = list(load_garage_set(str(HELDOUT / f"{name}.json")))
        for geometry in args.geometries:
            built, left = buildable(sources, geometry)
            built = built[: args.garages]
            if left:
                left_out[f"{name}/{geometry}"] = left
                print(f"{name} {geometry}: {len(left)} of {len(sources)} garages not buildable, left out", flush=True)
            if not built:
                continue
            for scenario in args.scenarios:
                env = PARK_GEOMETRIES[geometry].env_kwargs()
                if scenario != "none":
                    env["scenario"] = scenario
                if args.guide_replans != MAX_REPLANS:
                    env["guide_replans"] = args.guide_replans
                for driver in drivers:
                    folder = args.runs / args.task / driver.replace(":", "_").replace("/", "_") / \
                        f"{name}_{geometry}_{scenario}"
                    settings = CruiseSettings(driver=driver, seed=args.seed, task=args.task, maneuver="any", env=env)
                    run_cruise(built, args.tests, settings, folder,
                               compute=Compute(workers=args.workers, progress=False), route_model=False)
                    got = list(csv.DictReader((folder / "tests.csv").open()))
                    for r in got:
                        r.update(set=name, geometry=geometry, scenario=scenario)
                    rows[driver] += got
                    s = stats(got)
                    print(f"{name:15s} {geometry:9s} {scenario:10s} {driver:24s} {s['success']}/{s['driven']} "
                          f"{s['outcomes']}", flush=True)
    under = rows[args.driver]
    driven = [r for r in under if r["outcome"] not in NOT_DRIVEN]
    sim = sum(float(r["time"] or 0) for r in driven)
    wall = sum(float(r["wall_s"] or 0) for r in driven)
    result = {
        "settings": {"driver": args.driver, "baselines": args.baselines, "task": args.task, "sets": args.sets,
                     "garages_per_set": args.garages, "tests_per_garage": args.tests, "geometries": args.geometries,
                     "scenarios": args.scenarios, "occupancy": 0.5, "maneuver": "any", "seed": args.seed,
                     "workers": args.workers, "guide_replans": args.guide_replans},
        "targets": TARGETS,
        "drivers": {d: summary(rows[d]) for d in drivers},
        "by_geometry": {g: {d: stats([r for r in rows[d] if r["geometry"] == g]) for d in drivers}
                        for g in args.geometries},
        "by_set": {n: {d: stats([r for r in rows[d] if r["set"] == n]) for d in drivers} for n in args.sets},
        "sim_s_per_wall_s_per_worker": round(sim / wall, 1) if wall else None,
        "park_difficulty": {d: difficulty_fit(rows[d], d) for d in drivers},
        "garages_left_out": left_out,
        "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    figure(result, args.out.with_suffix(".png"))
    a = result["drivers"][args.driver]
    print(f"{args.driver}: {a['all']['success']}/{a['all']['driven']} ({a['all']['success_pct']}%), by level "
          + ", ".join(f"{lv} {a['by_level'][lv]['success_pct']}%" for lv in LEVELS)
          + f"; {result['sim_s_per_wall_s_per_worker']} sim s per wall s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
