"""Where ``learned:avp`` hands over from the cruise model to the parking model, and what comes of it.

A diagnosis, not a benchmark: it reads the env's privileged state (the car's pose, the park plan) to measure the
handover, which the driver itself never sees. For the first ``--garages`` of a held-out garage set
(``docs/learned_driver/heldout/``, or a garage set file) in one park geometry, ``--tests`` AVP tests each (the seeds ``garage-mj cruise``
would use with ``--seed``), driven by ``learned:avp`` with its handover rule (``--rule guide``: from where the park guide
begins, on at a crawl to the plan's start, the driver's own), braking where the guide begins (``--rule stop``) or
the slot detector's (``--rule slot``: the stall alongside, centre within 1 m ahead or behind and 8 m away, the rule a
parking model without the guide gets). Per test: the outcome, where the car was when
the parking model took over (distance to the park plan's start, how far ahead of it and to its left, heading off it,
the slot detector's reading), and how many of the plan's stretches the guide reached.

    MUJOCO_GL=egl .venv/bin/python eval/avp_handover.py --rule guide --garages 5 --tests 2
    MUJOCO_GL=egl .venv/bin/python eval/avp_handover.py --rule slot --garages 5 --tests 2
    MUJOCO_GL=egl .venv/bin/python eval/avp_handover.py --set models/drivers/cruise_m5_validation.json --garages 10
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from garage_mj.driving.drivers.learned import LearnedAVPDriver
from garage_mj.driving.episode import cached_env
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.learning.observation import PARK_SENSORS
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.driving.sources import CruiseSettings, cruise_seed

HELDOUT = Path(__file__).resolve().parents[1] / "docs" / "learned_driver" / "heldout"


class StopWhereGuideBegins(LearnedAVPDriver):
    """``learned:avp`` braking to rest where the park guide begins, without its approach at a crawl to the plan's
    start (its handover before that approach)."""

    def _approached(self) -> bool:
        return True


class SlotHandover(LearnedAVPDriver):
    """``learned:avp`` with the slot detector's handover whatever the parking model reads."""

    def _at_park_start(self, obs) -> bool:
        return self._stall_alongside(obs)


def capped(driver_class: type, cap: float) -> type:
    """``driver_class`` whose cruise phase holds the car at most ``cap`` m/s (the pedal brakes above it; below it, the
    cruise model's pedal)."""

    class Capped(driver_class):
        def act(self, obs):
            action = super().act(obs)
            speed = abs(float(np.asarray(obs["speed"]).reshape(-1)[0]))
            if self.phase == "cruise" and speed > cap:
                action = np.array([-1.0, action[1], action[2]], dtype=np.float32)
            return action

    return Capped


def drive(env, driver, seed: int) -> dict:
    """One AVP test to its end: its outcome and the handover's pose against the park plan's start."""
    obs, info = env.reset(seed=seed)
    if info.get("outcome") in NOT_DRIVEN:
        return {"outcome": info["outcome"]}
    driver.reset(env.driver_info(seed))
    start = env._park.plan.poses[0]  # privileged: measured here, never given to the driver
    handover, furthest = None, 0
    while True:
        action = driver.act(obs)
        if driver.phase == "park" and handover is None:
            x, y, yaw = env.car.pose(env.data)
            dx, dy = x - start[0], y - start[1]
            handover = {"time_s": round(float(env.data.time), 1),
                        "from_plan_start_m": round(math.hypot(dx, dy), 2),
                        # in the plan start's frame: ahead of it (negative: short of it) and to its left
                        "along_m": round(dx * math.cos(start[2]) + dy * math.sin(start[2]), 2),
                        "left_m": round(-dx * math.sin(start[2]) + dy * math.cos(start[2]), 2),
                        "heading_off_deg": round(math.degrees(math.remainder(yaw - start[2], math.tau)), 1),
                        "slot": [round(float(v), 2) for v in np.asarray(obs["slot"]).reshape(-1)[:2]]}
        obs, _, term, trunc, info = env.step(action)
        furthest = max(furthest, env.park_guide.stretch if env.park_guide is not None else 0)
        if term or trunc:
            break
    stretches = len(env.park_guide.tracker.segments) if env.park_guide is not None else 0
    return {"outcome": info["outcome"], "maneuver": info.get("maneuver"), "handover": handover,
            "stretches_reached": furthest + 1, "stretches": stretches, "reason": info["reason"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rule", choices=("guide", "stop", "slot"), default="guide",
                    help="the handover rule: guide (the driver's: from where the park guide begins, on at a crawl to "
                         "the plan's start), stop (brake where the guide begins), slot (the stall alongside)")
    ap.add_argument("--set", default="m5_unseen_seed",
                    help="held-out garage set (default m5_unseen_seed), or a garage set file (e.g. the learned "
                         "driver's validation garages, models/drivers/cruise_m5_validation.json)")
    ap.add_argument("--geometry", default="default", choices=sorted(PARK_GEOMETRIES))
    ap.add_argument("--garages", type=int, default=5)
    ap.add_argument("--tests", type=int, default=2, help="AVP tests per garage (default 2)")
    ap.add_argument("--seed", type=int, default=0, help="run seed (the tests garage-mj cruise --seed draws)")
    ap.add_argument("--cruise-cap", type=float, default=None, metavar="M/S",
                    help="hold the cruise phase at most this fast (default: the cruise model's own speed)")
    ap.add_argument("--json", type=Path, help="write the per-test records here")
    args = ap.parse_args(argv)
    path = Path(args.set) if args.set.endswith(".json") else HELDOUT / f"{args.set}.json"
    sources = list(load_garage_set(str(path)))[: args.garages]
    settings = CruiseSettings(driver="learned:avp", seed=args.seed, task="avp", maneuver="any",
                              action_type="continuous", env=PARK_GEOMETRIES[args.geometry].env_kwargs()
                              ).with_sensors(PARK_SENSORS)
    kind = {"slot": SlotHandover, "stop": StopWhereGuideBegins}.get(args.rule, LearnedAVPDriver)
    driver = (kind if args.cruise_cap is None else capped(kind, args.cruise_cap))()
    records = []
    for source in sources:
        env = cached_env(source, settings)
        for index in range(args.tests):
            record = {"garage": source.name, "test": index,
                      **drive(env, driver, cruise_seed(args.seed, source.hash, index))}
            records.append(record)
            print(json.dumps(record), flush=True)
    driven = [r for r in records if r["outcome"] not in NOT_DRIVEN]
    near = [r for r in driven if r["handover"] and r["handover"]["from_plan_start_m"] <= 1.5]
    rule = f"--rule {args.rule}" + ("" if args.cruise_cap is None else f" --cruise-cap {args.cruise_cap:g}")
    print(f"{rule}: {sum(r['outcome'] == 'success' for r in driven)} of {len(driven)} driven AVP tests "
          f"completed; {len(near)} handovers within 1.5 m of the park plan's start, "
          f"{sum(r['handover'] is None for r in driven)} tests ended before any")
    if args.json:
        args.json.write_text(json.dumps(records, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
