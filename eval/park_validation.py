"""A parking driver on the training validation garages, static park tests per geometry: where env-side choices (the
park guide's, the monitor's) are tried before the held-out benchmark sees them.

    MUJOCO_GL=egl .venv/bin/python eval/park_validation.py --geometries parallel default tight parallel_short \\
        --json docs/learned_park/park_validation.json

``--tests`` park tests (the maneuver drawn per test, occupancy 0.5, no actors, run seed ``--seed``: other tests than
the trainer's validation) on each of the 40 validation garages (``models/drivers/cruise_m5_validation.json``, which
chose the shipped models' iterations and are no held-out garages) a geometry can build, in this one process, per
geometry; the outcome counts per geometry. Run it at two commits to compare a change.
"""

from __future__ import annotations

import argparse
import collections
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.fsutil import write_json
from garage_mj.driving.cruise import run_test
from garage_mj.driving.drivers import action_type_of
from garage_mj.driving.episode import close_cached_env
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sources import CruiseSettings
from garage_mj.scene.world import GeometryError

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--driver", default="learned:park")
    ap.add_argument("--geometries", nargs="+", default=["parallel", "default", "tight", "parallel_short"],
                    choices=sorted(PARK_GEOMETRIES))
    ap.add_argument("--tests", type=int, default=2, help="park tests per garage and geometry (default 2)")
    ap.add_argument("--seed", type=int, default=11, help="run seed of the tests (default 11)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    prov = provenance(argv)
    sources = list(load_garage_set(str(ROOT / "models" / "drivers" / "cruise_m5_validation.json")))
    counts: dict[str, collections.Counter] = {}
    t0 = time.perf_counter()
    for geometry in args.geometries:
        settings = CruiseSettings(driver=args.driver, seed=args.seed, task="park", maneuver="any",
                                  env=PARK_GEOMETRIES[geometry].env_kwargs()).resolved(action_type_of(args.driver))
        c = counts[geometry] = collections.Counter()
        for source in sources:
            try:
                for index in range(args.tests):
                    c[run_test(source, index, settings)["outcome"]] += 1
            except GeometryError:  # the garage cannot be built in this geometry
                c["not_built"] += 1
            finally:
                close_cached_env()
        print(geometry, dict(c), flush=True)
    out = {"driver": args.driver, "tests_per_garage": args.tests, "seed": args.seed, "garages": len(sources),
           "outcomes": {g: dict(c) for g, c in counts.items()}, "wall_s": round(time.perf_counter() - t0, 1),
           "provenance": prov}
    if args.json:
        write_json(args.json, out, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
