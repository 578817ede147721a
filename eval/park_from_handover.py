"""The learned parking driver's park tests from the plan's start and from where an AVP handover may leave the car.

A diagnosis, not a benchmark: the first ``--garages`` of a garage set (default the learned driver's validation
garages), ``--tests`` park tests each (the seeds ``garage-mj cruise --seed`` would use), in the default geometry
without actors, driven by ``--driver`` twice: starting on the park plan's start, as every park test does, and with
``GarageDriveEnv(handover_start=M)``: up to ``M`` metres before (on the cruise route) or after the plan's start, the
same test otherwise. Prints the outcomes of each; ``--json`` writes them.

    MUJOCO_GL=egl .venv/bin/python eval/park_from_handover.py --garages 20 --tests 2 --seed 7
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path

from garage_mj.driving.cruise import run_test
from garage_mj.driving.episode import close_cached_env
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.learning.observation import PARK_SENSORS
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.driving.sources import CruiseSettings

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--set", type=Path, default=ROOT / "models" / "drivers" / "cruise_m5_validation.json",
                    help="garage set file (default: the learned driver's validation garages)")
    ap.add_argument("--garages", type=int, default=20)
    ap.add_argument("--tests", type=int, default=2, help="park tests per garage (default 2)")
    ap.add_argument("--handover-start", type=float, default=1.5, help="[m] how far off the plan's start (default 1.5)")
    ap.add_argument("--driver", default="learned:park")
    ap.add_argument("--seed", type=int, default=7, help="run seed (the tests garage-mj cruise --seed draws)")
    ap.add_argument("--json", type=Path, help="write the counts here")
    args = ap.parse_args(argv)
    sources = list(load_garage_set(str(args.set)))[: args.garages]
    result = {}
    for start in (0.0, args.handover_start):
        env = {"handover_start": start} if start else {}
        settings = CruiseSettings.from_env_kwargs(args.driver, env, seed=args.seed, action_type="continuous",
                                                  task="park", maneuver="any").with_sensors(PARK_SENSORS)
        counts: collections.Counter = collections.Counter()
        for source in sources:
            for index in range(args.tests):
                counts[run_test(source, index, settings)["outcome"]] += 1
        close_cached_env()
        driven = sum(v for k, v in counts.items() if k not in NOT_DRIVEN)
        result[f"handover_start_{start:g}"] = {"parked": counts["success"], "driven": driven, **counts}
        print(f"handover_start {start:g} m: {counts['success']} of {driven} driven park tests parked {dict(counts)}",
              flush=True)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
