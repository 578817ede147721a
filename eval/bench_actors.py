"""Adverse events: the oracle with actors, replay of exported .xosc files, vision vs actor density.

    .venv/bin/python eval/bench_actors.py [--parts oracle replay density] [--workers 2]
        [--garages 5] [--tests 25] [--replays 100] [--density-garages 10] [--density-tests 10]
        [--out runs/bench_actors] [--json docs/bench_actors.json]

``oracle``: on each shipped 13x13 map, ``--garages`` painted garages spread over difficulty
(:func:`garage_mj.driving.sources.painted_sources`) x ``--tests`` tests, the privileged ``oracle`` with
continuous actions and 2 pedestrians, 1 moving car and 2 clutter objects per test; every test
also written as OpenSCENARIO (``--xosc``). Reports success over feasible tests, the infeasible
share (and reasons), failures, and simulated seconds per wall second per worker (camera on).

``replay``: the first ``--replays`` exported ``.xosc`` files (sorted by name) replayed with
:func:`garage_mj.driving.replay.replay_xosc`; a replay is identical when outcome, simulated time, what was
hit and path length equal the batch's row.

``density``: the ``vision`` driver (continuous actions) on ``--density-garages`` painted
m5_13x13_aligned garages x ``--density-tests`` tests at actor densities 0-4 (pedestrians,
moving cars, clutter per test: (0,0,0) (1,0,1) (2,1,2) (3,1,3) (4,2,4)); success over feasible
tests per density, plotted to ``docs/vision_actor_density.png``.

Every part is a resumable cruise run (its own folder under ``--out``); ``--json`` gets the figures.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from garage_mj.core.backends import Compute
from garage_mj.driving.replay import replay_xosc
from garage_mj.driving.results import read_tests
from garage_mj.driving.sources import CruiseSettings, painted_sources
from garage_mj.reporting.cruise import run_cruise

MAPS = ["m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]
ACTORS = {"pedestrians": 2, "moving_cars": 1, "clutter": 2}
DENSITIES = [(0, 0, 0), (1, 0, 1), (2, 1, 2), (3, 1, 3), (4, 2, 4)]


def _rates(rows: list[dict]) -> dict:
    kinds = [r["outcome"] for r in rows]
    feasible = [r for r in rows if r["outcome"] != "infeasible"]
    driven = [r for r in feasible if float(r["wall_s"]) > 0]
    reasons: dict[str, int] = {}
    for r in rows:
        if r["outcome"] == "infeasible":
            key = r["reason"].split(" (")[0].split(":")[0][:70]
            reasons[key] = reasons.get(key, 0) + 1
    fails: dict[str, int] = {}
    for r in feasible:
        if r["outcome"] != "success":
            key = f"{r['outcome']}:{r['hit']}" if r["hit"] else r["outcome"]
            fails[key] = fails.get(key, 0) + 1
    placed = {k: sum(int(r[k] or 0) for r in rows) for k in ("pedestrians", "moving_cars", "clutter")}
    return {
        "tests": len(rows), "feasible": len(feasible), "infeasible": kinds.count("infeasible"),
        "infeasible_pct": round(100.0 * kinds.count("infeasible") / len(rows), 2) if rows else None,
        "success": kinds.count("success"),
        "success_pct_of_feasible": round(100.0 * kinds.count("success") / len(feasible), 2) if feasible else None,
        "failures": fails, "infeasible_reasons": reasons, "actors_placed": placed,
        "sim_s_per_wall_s_per_worker": round(sum(float(r["time"]) for r in driven)
                                             / max(sum(float(r["wall_s"]) for r in driven), 1e-9), 1),
    }


def part_oracle(args) -> dict:
    out: dict = {"actors": ACTORS, "garages_per_map": args.garages, "tests_per_garage": args.tests, "maps": {}}
    rows_all = []
    for m in MAPS:
        t0 = time.perf_counter()
        res = run_cruise(painted_sources(m, args.garages, seed=0), args.tests,
                         CruiseSettings("oracle", seed=0, action_type="continuous", env={"scenario": ACTORS}),
                         args.out / "oracle" / m, xosc=True, compute=Compute(workers=args.workers))
        out["maps"][m] = {**_rates(res.rows), "wall_s_this_call": round(time.perf_counter() - t0, 1)}
        rows_all += res.rows
        print(m, out["maps"][m], flush=True)
    out["all"] = _rates(rows_all)
    print("all", out["all"], flush=True)
    return out


def part_replay(args) -> dict:
    files = sorted(p for m in MAPS for p in (args.out / "oracle" / m / "xosc").glob("*.xosc"))[: args.replays]
    if not files:
        raise SystemExit("no .xosc files: run --parts oracle first")
    rows = {}
    for m in MAPS:
        for r in read_tests(args.out / "oracle" / m / "tests.csv"):
            rows[(r["garage_hash"][:12], int(r["test"]))] = r
    same, differ, t0 = 0, [], time.perf_counter()
    for f in files:
        h, i = f.stem.rsplit("_", 1)
        want = rows.get((h, int(i)))
        if want is None:
            continue
        got = replay_xosc(f)
        a = (got["outcome"], float(got["time"]), got["hit"], float(got["path_length"]))
        b = (want["outcome"], float(want["time"]), want["hit"], float(want["path_length"]))
        if a == b:
            same += 1
        else:
            differ.append({"file": f.name, "batch": b, "replay": a})
    out = {"replayed": same + len(differ), "identical": same, "differ": differ,
           "wall_s": round(time.perf_counter() - t0, 1)}
    print("replay", out, flush=True)
    return out


def part_density(args) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    srcs = painted_sources("m5_13x13_aligned", args.density_garages, seed=1)
    points = []
    for p, mc, c in DENSITIES:
        scen = {"pedestrians": p, "moving_cars": mc, "clutter": c}
        settings = CruiseSettings("vision", seed=0, action_type="continuous",
                                  env={"scenario": scen} if p + mc + c else {})
        res = run_cruise(srcs, args.density_tests, settings, args.out / "density" / f"p{p}_m{mc}_c{c}",
                         compute=Compute(workers=args.workers))
        r = _rates(res.rows)
        points.append({"actors_per_test": p + mc + c, **scen, **r})
        print("density", points[-1], flush=True)
    xs = [pt["actors_per_test"] for pt in points]
    ys = [pt["success_pct_of_feasible"] for pt in points]
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    ax.plot(xs, ys, "o-", color="#1f5fa8")
    for pt in points:
        ax.annotate(f"{pt['pedestrians']}p {pt['moving_cars']}m {pt['clutter']}c", (pt["actors_per_test"],
                    pt["success_pct_of_feasible"]), textcoords="offset points", xytext=(4, 6), fontsize=7)
    ax.set_xlabel("actors per test (pedestrians + moving cars + clutter)")
    ax.set_ylabel("vision success, % of feasible tests")
    ax.set_ylim(0, 100)
    ax.set_title(f"vision (continuous) on {len(srcs)} m5 garages x {args.density_tests} tests per density", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    args.plot.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.plot, dpi=120)
    plt.close(fig)
    return {"points": points, "plot": str(args.plot)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", nargs="+", default=["oracle", "replay", "density"],
                    choices=["oracle", "replay", "density"])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--garages", type=int, default=5)
    ap.add_argument("--tests", type=int, default=25)
    ap.add_argument("--replays", type=int, default=100)
    ap.add_argument("--density-garages", type=int, default=10)
    ap.add_argument("--density-tests", type=int, default=10)
    ap.add_argument("--out", type=Path, default=Path("runs/bench_actors"))
    ap.add_argument("--json", type=Path, default=Path("docs/bench_actors.json"))
    ap.add_argument("--plot", type=Path, default=Path("docs/vision_actor_density.png"))
    args = ap.parse_args()
    results = json.loads(args.json.read_text()) if args.json.is_file() else {}
    for part in args.parts:
        results[part] = {"oracle": part_oracle, "replay": part_replay, "density": part_density}[part](args)
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")  # after every part: a crash keeps the rest
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
