"""Actors in park and AVP tests: the oracle on each named park scenario, and the same tests with a blind oracle.

    .venv/bin/python eval/bench_park_actors.py [--tests 20] [--tasks park avp] [--workers 1]
        [--out runs/bench_park_actors] [--json docs/bench_park_actors.json]

On the tiny_7x11 garage (painted, seed 1), ``--tests`` tests per task and per named scenario
(:data:`garage_mj.driving.actors.config.SCENARIOS`), the privileged ``oracle`` with continuous actions; then the
same tests with ``oracle_blind`` (the oracle told nothing of the actors: it does not yield), which shows whether
the events are adverse at all. Reports, per scenario: outcomes, success over feasible tests, and the actors placed
(of those asked for). Every scenario is a resumable cruise run under ``--out``; ``--json`` gets the figures.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

from garage_mj.core.backends import Compute
from garage_mj.driving.actors.config import SCENARIOS, load_scenario_config
from garage_mj.driving.drivers.oracle import OracleDriver
from garage_mj.driving.results import read_tests
from garage_mj.driving.sources import CruiseSettings
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.cruise import run_cruise


class BlindOracle(OracleDriver):
    """The oracle, told nothing of the actors (it drives its plan as if the garage were empty of them)."""

    name = "oracle_blind"

    def reset(self, info):
        super().reset({**info, "actors": []})


def _figures(rows: list[dict], asked) -> dict:
    out = Counter(r["outcome"] for r in rows)
    feasible = [r for r in rows if r["feasible"] in ("1", "True", True, 1)]
    ok = sum(r["outcome"] == "success" for r in feasible)
    placed = {k: sum(int(r[k]) for r in rows) for k in ("pedestrians", "moving_cars", "clutter")}
    return {"tests": len(rows), "outcomes": dict(out), "feasible": len(feasible), "success": ok,
            "success_pct": round(100.0 * ok / len(feasible), 1) if feasible else None,
            "hits": dict(Counter(r["hit"] for r in rows if r["outcome"] == "collision")),
            "placed": placed, "asked": {k: getattr(asked, k) * len(rows) for k in placed}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tests", type=int, default=20)
    ap.add_argument("--tasks", nargs="+", default=["park", "avp"])
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("runs/bench_park_actors"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    garage = paint_garage("tiny_7x11", seed=1)
    figures: dict = {}
    for task in args.tasks:
        for name in SCENARIOS:
            for driver in ("oracle", "blind"):
                folder = args.out / task / name / driver
                drv = "oracle" if driver == "oracle" else f"{Path(__file__).resolve()}:BlindOracle"
                settings = CruiseSettings(drv, action_type="continuous", task=task, env={"scenario": name})
                run_cruise([garage], args.tests, settings, folder, compute=Compute(workers=args.workers, progress=False))
                f = _figures(read_tests(folder / "tests.csv"), load_scenario_config(name))
                figures.setdefault(task, {}).setdefault(name, {})[driver] = f
                print(f"{task:4s} {name:24s} {driver:6s} success {f['success']}/{f['feasible']} feasible "
                      f"({f['success_pct']}%), outcomes {f['outcomes']}, hits {f['hits']}, placed {f['placed']} "
                      f"of {f['asked']}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1) + "\n")


if __name__ == "__main__":
    main()
