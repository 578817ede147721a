"""Learned cruise drivers on held-out garages built in the park geometries: success and collisions per geometry.

    MUJOCO_GL=egl .venv/bin/python eval/bench_cruise_geometries.py \\
        --drivers learned learned:models/drivers/avp_cruise_m5.zip oracle --geometries default tight parallel \\
        --garages 12 --tests 4 --workers 2 --json docs/learned_park/cruise_geometries.json

Cruise tests (the paper's task: entrance to the lane beside the target stall, occupancy 0.5, no actors) on the first
``--garages`` garages of each held-out set (``docs/learned_driver/heldout/``: m5 of run seed 4 and m7_13x13_u, never
used in training or validation) that a geometry can build, ``--tests`` per garage, the same test seeds for every
driver. Learned drivers take the paper's 4 discrete actions, the others continuous actions. Each set x geometry x
driver is one ``garage-mj cruise`` run kept under ``--runs`` (the same command resumes it). Reported per driver and
geometry: driven tests, success % with a 95% Wilson interval, collisions and what they hit.
"""

from __future__ import annotations

import argparse
import collections
import csv
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit
from bench_learned_park import (  # the park bench's: garages a geometry builds, Wilson interval
    buildable,
    wilson,
)

from garage_mj.core.backends import Compute
from garage_mj.core.fsutil import write_json
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.driving.sources import CruiseSettings

ROOT = Path(__file__).resolve().parents[1]
HELDOUT = ROOT / "docs" / "learned_driver" / "heldout"
SETS = ("m5_unseen_seed", "m7_13x13_u")


def stats(rows: list[dict]) -> dict:
    driven = [r for r in rows if r["outcome"] not in NOT_DRIVEN]
    ok = sum(r["outcome"] == "success" for r in driven)
    return {"driven": len(driven), "success": ok, "success_pct": round(100 * ok / len(driven), 1) if driven else None,
            "ci95_pct": wilson(ok, len(driven)),
            "outcomes": dict(collections.Counter(r["outcome"] for r in driven)),
            "hits": dict(collections.Counter(r["hit"] for r in driven if r["outcome"] == "collision"))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--drivers", nargs="+", default=["learned", "oracle"])
    ap.add_argument("--geometries", nargs="+", default=["default", "tight", "parallel"], choices=sorted(PARK_GEOMETRIES))
    ap.add_argument("--sets", nargs="+", default=list(SETS), choices=SETS)
    ap.add_argument("--garages", type=int, default=12)
    ap.add_argument("--tests", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "bench_cruise_geometries")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    prov = provenance(argv)
    t0 = time.perf_counter()
    rows: dict[tuple[str, str], list[dict]] = collections.defaultdict(list)
    for name in args.sets:
        sources = list(load_garage_set(str(HELDOUT / f"{name}.json")))
        for geometry in args.geometries:
            built = buildable(sources, geometry)[0][: args.garages]
            for driver in args.drivers:
                learned = driver.split(":")[0] == "learned"
                settings = CruiseSettings(driver=driver, seed=args.seed, env=PARK_GEOMETRIES[geometry].env_kwargs(),
                                          action_type="discrete" if learned else "continuous")
                folder = args.runs / name / geometry / driver.replace(":", "_").replace("/", "_")
                run_cruise(built, args.tests, settings, folder, compute=Compute(workers=args.workers, progress=False),
                           route_model=False)
                got = list(csv.DictReader((folder / "tests.csv").open()))
                rows[(driver, geometry)] += got
                s = stats(got)
                print(f"{name:15s} {geometry:9s} {driver:40s} {s['success']}/{s['driven']} {s['outcomes']}", flush=True)
    result = {"settings": vars(args) | {"runs": str(args.runs), "json": str(args.json)},
              "drivers": {d: {g: stats(rows[(d, g)]) for g in args.geometries} for d in args.drivers},
              "wall_s": round(time.perf_counter() - t0, 1), "provenance": prov}
    for d, per in result["drivers"].items():
        print(d, {g: f"{s['success']}/{s['driven']}" for g, s in per.items()})
    if args.json:
        write_json(args.json, result, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
