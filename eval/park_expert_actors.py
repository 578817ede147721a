"""How often is the parking expert itself too late for the actors? The tests a park benchmark drove, driven again by
the expert the learned parking driver imitates, by its own labels.

    MUJOCO_GL=egl .venv/bin/python eval/park_expert_actors.py RUNS [--scenario park_mixed]
        [--foresight present trajectory] [--json OUT.json]

``RUNS`` is a park driver's run folders of ``eval/bench_learned_park.py`` (e.g.
``runs/bench_learned_park_large/park/learned_park``: one folder per set, geometry and actor scenario). For every
driven test of the runs with ``--scenario`` (``none``: the static ones), the same test (its run's settings and
garage, its seed) is driven by the expert of ``garage-mj train-driver --task park``
(:class:`~garage_mj.driving.learning.fleet_env.FleetDriveEnv` with ``expert=True``, the park route and guide of the
shipped model), each step the park command the expert labels, once per ``--foresight``: ``present`` (it yields
only where an actor is now, what the cameras show: the shipped model's expert) and ``trajectory`` (where an actor
will walk: the oracle's knowledge). Reports each one's outcomes (success, collisions by what was hit) beside the
run's own driver's on the same tests, and how many of the driver's collisions the expert also had. Every test is
checked to be the run's (the same target stall).
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from collections import Counter
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.fsutil import write_json
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.learning.fleet_env import FleetDriveEnv
from garage_mj.driving.sim.outcomes import NOT_DRIVEN
from garage_mj.driving.sources import CruiseSettings


def _runs(root: Path, scenario: str) -> list[Path]:
    """The run folders under ``root`` whose actor scenario is ``scenario`` (from their run.json)."""
    found = []
    for run in sorted(p.parent for p in root.glob("*/run.json")):
        env = json.loads((run / "run.json").read_text()).get("env") or {}
        if (env.get("scenario") or "none") == scenario:
            found.append(run)
    return found


def drive_by_labels(run: Path, foresight: str) -> list[dict]:
    """The driven tests of ``run`` driven again by the expert's labels: per test, the run's and the expert's outcome."""
    settings = CruiseSettings.from_stored(json.loads((run / "run.json").read_text()))
    sources = {s.hash: s for s in load_garage_set(str(run / "garages.json"))}
    rows = [r for r in csv.DictReader((run / "tests.csv").open(newline="")) if r["outcome"] not in NOT_DRIVEN]
    env_kwargs = {k: v for k, v in (settings.env or {}).items() if k != "sensors"}
    env_kwargs.update(task=settings.task, maneuver=settings.maneuver, occupancy=settings.occupancy)
    out = []
    by_garage: dict[str, list[dict]] = {}
    for r in rows:
        by_garage.setdefault(r["garage_hash"], []).append(r)
    for garage_hash, tests in by_garage.items():
        fleet = FleetDriveEnv([sources[garage_hash]], cache_size=1, expert=True, env_kwargs=env_kwargs,
                              park_route=True, park_guide=True, actor_foresight=foresight)
        try:
            for r in tests:
                obs, info = fleet.reset(options={"garage": 0, "test_seed": int(r["seed"])})
                if str(info["target_stall"]) != r["target_stall"]:
                    raise SystemExit(f"{run}: test {r['test']} drew stall {info['target_stall']}, the run's was "
                                     f"{r['target_stall']}: not the same test")
                while True:
                    obs, _, term, trunc, info = fleet.step(info["expert_action"])
                    if term or trunc:
                        break
                out.append({"run": run.name, "test": r["test"], "driver": r["outcome"], "driver_hit": r["hit"],
                            "expert": info["outcome"], "expert_hit": info["hit"] or ""})
        finally:
            fleet.close()
    return out


def summary(rows: list[dict], who: str) -> dict:
    """Outcomes of ``who`` (``driver`` or ``expert``) over ``rows``: counts, success and collision rates, hits."""
    n = len(rows)
    outcomes = Counter(r[who] for r in rows)
    hits = Counter(r[f"{who}_hit"] for r in rows if r[who] == "collision")
    return {"tests": n, "outcomes": dict(outcomes), "success_pct": round(100 * outcomes["success"] / n, 1) if n else None,
            "collision_pct": round(100 * outcomes["collision"] / n, 1) if n else None, "hits": dict(hits)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", type=Path, help="a park driver's run folders of eval/bench_learned_park.py")
    ap.add_argument("--scenario", default="park_mixed", help="the runs' actor scenario (none: the static runs)")
    ap.add_argument("--foresight", nargs="+", default=["present", "trajectory"], choices=("present", "trajectory"))
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    prov = provenance(argv)
    runs = _runs(args.runs, args.scenario)
    if not runs:
        raise SystemExit(f"no run of scenario {args.scenario!r} under {args.runs}")
    result = {"runs": str(args.runs), "scenario": args.scenario, "by_foresight": {}, "provenance": prov}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
    for foresight in args.foresight:
        t0 = time.perf_counter()
        rows = [row for run in runs for row in drive_by_labels(run, foresight)]
        both = sum(r["driver"] == "collision" and r["expert"] == "collision" for r in rows)
        result["by_foresight"][foresight] = {
            "driver": summary(rows, "driver"), "expert": summary(rows, "expert"),
            "driver_collisions_the_expert_also_had": both, "wall_s": round(time.perf_counter() - t0, 1)}
        e, d = result["by_foresight"][foresight]["expert"], result["by_foresight"][foresight]["driver"]
        print(f"expert ({foresight}): {e['success_pct']}% parked, {e['collision_pct']}% collisions {e['hits']}; the "
              f"run's driver {d['success_pct']}%, {d['collision_pct']}%; both collided in {both} of {len(rows)}",
              flush=True)
        if args.json:  # after each foresight: a stopped run keeps what it measured
            write_json(args.json, result, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
