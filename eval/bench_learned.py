"""The learned cruise driver on garages it never trained on, next to ``vision`` and ``waypoint``.

The full benchmark (the README's Results table; resumable: re-run the same command after a Ctrl-C):

    MUJOCO_GL=egl .venv/bin/python eval/bench_learned.py --workers 2

A quick trial of the plumbing:

    MUJOCO_GL=egl .venv/bin/python eval/bench_learned.py --drivers vision,waypoint --tests 1 \\
        --sets tiny_7x11 --scenarios static --json /tmp/bench_learned.json

The held-out sets are committed JSON (``docs/learned_driver/heldout/``), made once from the 10%
protocol library (not in git) with ``--make-sets runs/paper_10pct/library.sqlite``; every set is
12 garages stratified by difficulty (seed 0) out of a library's filtered rows:

- ``m5_unseen_seed``: m5_13x13_aligned garages of generation run seed 4 (the shipped model trained
  on run seeds 0-2 and validated on run seed 3 of m5; ``--make-sets`` checks none of these is one of them);
- ``tiny_7x11``: a non-square map (7 rows x 11 columns);
- ``m7_13x13_u``: the U map, an interior obstacle wall up the middle.

Every set x scenario x driver is one cruise run (:func:`garage_mj.reporting.cruise.run_cruise`)
into ``OUT/<set>/<scenario>/<driver>/`` with ``--tests`` tests per garage, run seed ``--seed``,
the paper's discrete actions for every driver (passed explicitly: the hand-written built-ins are
made for continuous actions, which is said once per driver) and the same test seeds for every
driver, so all drivers get the same tests. Scenarios: ``static`` (parked cars only) and
``actors`` (1 pedestrian + 1 moving car + 1 clutter object per test, ``garage-mj cruise
--pedestrians 1 --moving-cars 1 --clutter 1``). ``--model PATH`` makes ``learned`` mean
``learned:PATH``.

The summary is read back from every run folder's ``tests.csv`` (so a resumed or partial run is
summarised in full): per set x scenario x driver, feasible tests, success % over feasible tests
with a 95% Wilson interval, failures by class (collision, timeout, deadlock, missed_goal), what
collisions hit most, and mean wall seconds per driven test; then the learned/vision wall-time
ratio per test over the tests both drove, per simulated second, and per test over the tests both
drove to the goal (the same work: ``vision`` crashes sooner), each also without the tests that start
a worker's driver (a one-off 2-3 s for ``learned``); the cost target (<= 1.3) is checked on the
last, the same work without the start-up; and the success targets
(static m5: >= 90%, static other maps: >= 80%). Printed as a markdown table, written to
``--json`` and a ``.md`` beside it. ``--summarize`` only reads the folders back.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from garage_mj.cli._common import positive_int
from garage_mj.core.backends import Compute
from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write, write_json
from garage_mj.driving.actors.config import load_scenario_config
from garage_mj.driving.garage_set import GarageSet
from garage_mj.driving.results import FAILURE_KINDS, paper_failures, read_tests

ROOT = Path(__file__).resolve().parent.parent
HELDOUT_DIR = ROOT / "docs" / "learned_driver" / "heldout"
DEFAULT_JSON = ROOT / "docs" / "learned_driver" / "bench_learned.json"
#: The held-out sets ``--make-sets`` draws from a library: name -> GarageSet.from_library filters.
HELDOUT = {
    "m5_unseen_seed": {"map": "m5_13x13_aligned", "run_seeds": [4]},
    "tiny_7x11": {"map": "tiny_7x11"},
    "m7_13x13_u": {"map": "m7_13x13_u"},
}
HELDOUT_N = 12  # garages per held-out set
HELDOUT_SEED = 0  # seed of the stratified sample
#: Run seeds of m5 the shipped model trained (0-2) and validated (3) on: held-out garages must avoid them.
SEEN_M5_RUN_SEEDS = (0, 1, 2, 3)
#: Scenario -> actors per test (``garage-mj cruise --pedestrians/--moving-cars/--clutter``); None: static.
SCENARIOS: dict[str, dict[str, int] | None] = {
    "static": None,
    "actors": {"pedestrians": 1, "moving_cars": 1, "clutter": 1},
}
DRIVERS = ("learned", "vision", "waypoint")
ACTION_TYPE = "discrete"  # the paper's protocol, for every driver
OCCUPANCY = 0.5  # share of stalls with a parked car (garage-mj cruise's default)
Z95 = 1.959964  # two-sided 95% normal quantile
#: The targets: learned success % over feasible static tests, and its wall time per test over vision's.
TARGET_M5 = 90.0
TARGET_OTHER = 80.0
TARGET_WALL_RATIO = 1.3


class BenchError(GarageMJError):
    """A benchmark setting the user can fix (unknown set or scenario, existing held-out file)."""


# -- statistics ---------------------------------------------------------------------------------------
def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """The Wilson score interval of a success share, in percent; None for no trials."""
    if n <= 0:
        return None
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return round(100 * max(0.0, centre - half), 1), round(100 * min(1.0, centre + half), 1)


def cell_stats(rows: Sequence[dict[str, str]]) -> dict[str, Any]:
    """Counts, success with its interval, failures, hits and timing of one run's test rows."""
    driven = [r for r in rows if r["outcome"] != "infeasible"]
    wins = sum(r["outcome"] == "success" for r in driven)
    failures = {k: sum(r["outcome"] == k for r in driven) for k in FAILURE_KINDS}
    hits: dict[str, int] = {}
    for r in driven:
        if r["outcome"] == "collision":
            hits[r["hit"] or "?"] = hits.get(r["hit"] or "?", 0) + 1
    walls = [float(r["wall_s"]) for r in driven]
    sims = [float(r["time"]) for r in driven]
    return {
        "tests": len(rows), "infeasible": len(rows) - len(driven), "feasible": len(driven), "successes": wins,
        "success_pct": round(100 * wins / len(driven), 1) if driven else None,
        "ci95_pct": wilson(wins, len(driven)),
        "failures": failures, "paper_failures": paper_failures(failures),
        "hits": dict(sorted(hits.items(), key=lambda kv: (-kv[1], kv[0]))),
        "wall_s_per_test": round(sum(walls) / len(walls), 3) if walls else None,
        "sim_s_per_test": round(sum(sims) / len(sims), 2) if sims else None,
    }


def wall_ratio(a: Sequence[dict[str, str]], b: Sequence[dict[str, str]]) -> dict[str, Any] | None:
    """Wall time of driver ``a`` over driver ``b`` on the tests both drove: per test, and per simulated second."""
    def driven(rows):
        return {(r["garage_hash"], r["test"]): r for r in rows if r["outcome"] != "infeasible"}

    da, db = driven(a), driven(b)
    common = sorted(set(da) & set(db))

    def total(keys, field):
        return [sum(float(d[k][field]) for k in keys) for d in (da, db)]

    def per_test(keys):
        wall = total(keys, "wall_s")
        return round(wall[0] / wall[1], 3) if keys and wall[1] > 0 else None

    def per_sim(keys):
        wall, sim = total(keys, "wall_s"), total(keys, "time")
        return round((wall[0] / sim[0]) / (wall[1] / sim[1]), 3) if keys and min(sim) > 0 and wall[1] > 0 else None

    if per_test(common) is None:
        return None
    # the same work: tests both drove to the goal (a driver that crashes early ends its tests sooner); and
    # each figure again without the tests that carry a worker's start-up (flagged by start_up_flagged)
    def warm(keys):
        return [k for k in keys if not (da[k].get("start_up") or db[k].get("start_up"))]

    done = [k for k in common if da[k]["outcome"] == "success" and db[k]["outcome"] == "success"]
    done_warm = warm(done)
    return {"tests": len(common), "per_test": per_test(common),
            "per_sim_second": per_sim(common), "per_sim_second_warm": per_sim(warm(common)),
            "both_succeeded": len(done), "per_test_both_succeeded": per_test(done),
            "both_succeeded_warm": len(done_warm), "per_test_both_succeeded_warm": per_test(done_warm)}


def start_up_flagged(rows: Sequence[dict[str, str]], workers: int) -> list[dict[str, Any]]:
    """``rows`` with ``start_up`` set on the ``workers`` slowest: a run's first test in each worker process also
    starts the driver (for ``learned``, 2-3 s of importing torch and loading the model), the rest take under 1 s."""
    slow = set(sorted(range(len(rows)), key=lambda i: -float(rows[i]["wall_s"] or 0))[:workers])
    return [{**r, "start_up": i in slow} for i, r in enumerate(rows)]


# -- the held-out sets --------------------------------------------------------------------------------
def make_sets(library: Path, force: bool) -> int:
    """Write the held-out sets of :data:`HELDOUT` from ``library`` into :data:`HELDOUT_DIR`."""
    paths = {name: HELDOUT_DIR / f"{name}.json" for name in HELDOUT}
    there = [str(p) for p in paths.values() if p.exists()]
    if there and not force:
        raise BenchError(f"{', '.join(there)} exist(s); pass --force to draw the held-out sets again")
    sets = {name: GarageSet.from_library(library, n=HELDOUT_N, seed=HELDOUT_SEED, **filters)
            for name, filters in HELDOUT.items()}
    seen = GarageSet.from_library(library, map=HELDOUT["m5_unseen_seed"]["map"], run_seeds=SEEN_M5_RUN_SEEDS)
    overlap = set(sets["m5_unseen_seed"].hashes) & set(seen.hashes)
    if overlap:
        raise BenchError(f"{len(overlap)} m5_unseen_seed garage(s) are also garages of run seeds "
                         f"{SEEN_M5_RUN_SEEDS} in {library}; it is not held out: check the library's run names")
    for name, s in sets.items():
        s.to_json(paths[name])
        diff = [x.difficulty for x in s]
        print(f"{paths[name].relative_to(ROOT)}: {len(s)} garages, difficulty {min(diff):.3f}-{max(diff):.3f} "
              f"({s.origin})")
    print(f"m5_unseen_seed shares no garage with the {len(seen)} m5 garages of run seeds "
          f"{','.join(map(str, SEEN_M5_RUN_SEEDS))}")
    return 0


def load_set(name: str) -> GarageSet:
    """A held-out set by name (``docs/learned_driver/heldout/<name>.json``) or a set JSON file's path."""
    path = Path(name) if name.endswith(".json") else HELDOUT_DIR / f"{name}.json"
    if not path.is_file() and not name.endswith(".json"):
        have = sorted(p.stem for p in HELDOUT_DIR.glob("*.json"))
        raise BenchError(f"no held-out set {name!r} in {HELDOUT_DIR} (there: {', '.join(have) or 'none'}); make "
                         "them with --make-sets LIBRARY or give a garage-set .json")
    return GarageSet.from_json(path)


# -- the runs -----------------------------------------------------------------------------------------
def scenario_env(scenario: str) -> dict[str, Any]:
    """The drive env settings of a scenario, as ``garage-mj cruise`` passes them (same run.json, resumable by it)."""
    counts = SCENARIOS[scenario]
    if counts is None:
        return {}
    cfg = load_scenario_config(None, **counts)
    data = {f: getattr(cfg, f) for f in cfg.__dataclass_fields__}
    return {"scenario": {k: list(v) if isinstance(v, tuple) else v for k, v in data.items()}}


def driver_spec(name: str, model: Path | None) -> str:
    return f"learned:{model}" if name == "learned" and model is not None else name


def check_drivers(specs: dict[str, str]) -> dict[str, Any]:
    """Load every driver once here (a missing model fails before any test) and choose its action type,
    saying once per driver when the paper's discrete actions are not its own."""
    from garage_mj.driving.drivers import choose_action_type, load_driver

    choices = {}
    for name, spec in specs.items():
        load_driver(spec)
        choices[name] = choose_action_type(spec, ACTION_TYPE, warn=False)
        if choices[name].mismatch:
            why = choices[name].mismatch.replace("; leave out --action-type to use its own", "")
            print(f"note (the paper's protocol: discrete actions for every driver): {why}")
    return choices


def run_all(sets: dict[str, GarageSet], scenarios: list[str], specs: dict[str, str], args) -> None:
    from garage_mj.driving.sources import CruiseSettings
    from garage_mj.reporting.cruise import run_cruise

    choices = check_drivers(specs)
    cells = [(s, c, d) for s in sets for c in scenarios for d in specs]
    for k, (set_name, scen, drv) in enumerate(cells, 1):
        srcs = list(sets[set_name])[: args.garages]
        out = args.out / set_name / scen / drv
        print(f"[{k}/{len(cells)}] {set_name} / {scen} / {specs[drv]}: {len(srcs)} garages x {args.tests} tests "
              f"-> {out}", flush=True)
        start = time.perf_counter()
        res = run_cruise(srcs, args.tests,
                         CruiseSettings(specs[drv], seed=args.seed, occupancy=OCCUPANCY, env=scenario_env(scen)),
                         out, compute=Compute(workers=args.workers, progress=not args.quiet),
                         choice=choices[drv])
        s = res.stats
        print(f"  success {s['success_pct']}% of {s['feasible']} feasible ({s['infeasible']} infeasible), "
              f"failures {s['failures']}; {res.tests_run} new tests in {time.perf_counter() - start:.0f} s",
              flush=True)


# -- the summary --------------------------------------------------------------------------------------
def read_cell(out: Path, hashes: set[str], tests: int) -> tuple[list[dict[str, str]], dict[str, Any]] | None:
    """The rows of a run folder for these garages and test indices, and its run.json; None if never run."""
    if not (out / "tests.csv").is_file():
        return None
    rows = [r for r in read_tests(out / "tests.csv") if r["garage_hash"] in hashes and int(r["test"]) < tests]
    run = json.loads((out / "run.json").read_text()) if (out / "run.json").is_file() else {}
    return rows, run


def summarize(sets: dict[str, GarageSet], scenarios: list[str], drivers: list[str], args) -> dict[str, Any]:
    cells, ratios, rows_of = [], [], {}
    for set_name, gs in sets.items():
        srcs = list(gs)[: args.garages]
        hashes = {s.hash for s in srcs}
        for scen in scenarios:
            for drv in drivers:
                got = read_cell(args.out / set_name / scen / drv, hashes, args.tests)
                if got is None:
                    print(f"note: {set_name} / {scen} / {drv} was never run ({args.out / set_name / scen / drv})")
                    continue
                rows, run = got
                rows_of[set_name, scen, drv] = start_up_flagged(rows, args.workers)
                cells.append({"set": set_name, "scenario": scen, "driver": drv, "spec": run.get("driver", drv),
                              "action_type": run.get("action_type"), "expected_tests": len(srcs) * args.tests,
                              **cell_stats(rows)})
            if (set_name, scen, "learned") in rows_of and (set_name, scen, "vision") in rows_of:
                r = wall_ratio(rows_of[set_name, scen, "learned"], rows_of[set_name, scen, "vision"])
                if r is not None:
                    ratios.append({"set": set_name, "scenario": scen, **r})
    def tagged(key):  # a test is (set, scenario, garage, test): static and actors runs share garages and tests
        return [{**r, "garage_hash": f"{key[0]}/{key[1]}/{r['garage_hash']}"} for r in rows_of[key]]

    pairs = [(tagged(k), tagged(k[:2] + ("vision",))) for k in rows_of
             if k[2] == "learned" and k[:2] + ("vision",) in rows_of]
    overall = wall_ratio([r for a, _ in pairs for r in a], [r for _, b in pairs for r in b]) if pairs else None
    targets = []
    for c in cells:
        if c["driver"] == "learned" and c["scenario"] == "static" and c["success_pct"] is not None:
            want = TARGET_M5 if c["set"].startswith("m5") else TARGET_OTHER
            targets.append({"what": f"learned success, static {c['set']}", "value": c["success_pct"],
                            "target": f">= {want:g}%", "met": c["success_pct"] >= want})
    if overall is not None and overall["per_test_both_succeeded_warm"] is not None:
        # per test on the same work: the tests both drove to the goal, without a worker's one-off start-up
        same = overall["per_test_both_succeeded_warm"]
        targets.append({"what": "learned / vision wall time per test both drove to the goal (no start-up)",
                        "value": same, "target": f"<= {TARGET_WALL_RATIO:g}", "met": same <= TARGET_WALL_RATIO})
    return {"format": "garage-mj bench_learned", "version": 1,
            "command": "eval/bench_learned.py " + " ".join(args.argv),
            "settings": {"tests_per_garage": args.tests, "seed": args.seed, "workers": args.workers,
                         "action_type": ACTION_TYPE, "occupancy": OCCUPANCY, "garages_per_set": args.garages,
                         "scenarios": {s: SCENARIOS[s] for s in scenarios}},
            "sets": {n: {"origin": gs.origin, "garages": len(list(gs)[: args.garages])} for n, gs in sets.items()},
            "cells": cells, "wall_ratio_learned_vision": {"per_cell": ratios, "overall": overall},
            "targets": targets}


def _pct(c: dict[str, Any]) -> str:
    if c["success_pct"] is None:
        return "n/a"
    lo, hi = c["ci95_pct"]
    return f"{c['success_pct']:.1f} [{lo:.1f}, {hi:.1f}]"


def markdown(report: dict[str, Any]) -> str:
    """The summary as markdown: a table per cell, the wall-time ratios and the targets."""
    st = report["settings"]
    lines = [f"Held-out garages, {st['tests_per_garage']} tests per garage, seed {st['seed']}, "
             f"{st['action_type']} actions for every driver, {st['workers']} workers. Success over feasible tests "
             "with a 95% Wilson interval; most hit: what collisions hit; wall s / test: mean over driven tests "
             "(the env's reset included).", "",
             "| set | scenario | driver | feasible / tests | success % [95% CI] | collision | timeout | deadlock "
             "| missed_goal | most hit | wall s / test |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in report["cells"]:
        f = c["failures"]
        hit = ", ".join(f"{k} {v}" for k, v in list(c["hits"].items())[:3]) or "-"
        part = "" if c["tests"] == c["expected_tests"] else f" (of {c['expected_tests']})"
        wall = "-" if c["wall_s_per_test"] is None else f"{c['wall_s_per_test']:.2f}"
        lines.append(f"| {c['set']} | {c['scenario']} | {c['driver']} | {c['feasible']} / {c['tests']}{part} | "
                     f"{_pct(c)} | {f['collision']} | {f['timeout']} | {f['deadlock']} | {f['missed_goal']} | "
                     f"{hit} | {wall} |")
    ratio = report["wall_ratio_learned_vision"]
    if ratio["overall"] is not None:
        o = ratio["overall"]
        lines += ["", f"learned / vision wall time per test: {o['per_test']:.2f}x over {o['tests']} tests both "
                      f"drove; per simulated second: {o['per_sim_second']}x "
                      f"({o['per_sim_second_warm']}x without the tests that start a worker's driver); "
                      f"per test over the {o['both_succeeded']} tests both drove to the goal: {o['per_test_both_succeeded']}x, "
                      f"{o['per_test_both_succeeded_warm']}x over the {o['both_succeeded_warm']} of them that do not start a "
                      "worker's driver"]
        lines += [f"- {r['set']} / {r['scenario']}: {r['per_test']:.2f}x per test, {r['per_sim_second']}x per "
                  f"simulated second ({r['tests']} tests); {r['per_test_both_succeeded']}x per test both drove to the "
                  f"goal ({r['both_succeeded']})" for r in ratio["per_cell"]]
        lines += ["Each run's first test in each worker process includes starting the driver (for `learned`: "
                  "importing torch and loading the model, 2-3 s); taken as the run's `--workers` slowest tests."]
    if report["targets"]:
        lines += ["", "Targets:"]
        lines += [f"- {t['what']}: {t['value']} (target {t['target']}): {'met' if t['met'] else 'NOT met'}"
                  for t in report["targets"]]
    return "\n".join(lines) + "\n"


# -- the command --------------------------------------------------------------------------------------
def _names(text: str, known: Sequence[str] | None, what: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"{what} {text!r}: give a comma-separated list without repeats")
    bad = [n for n in names if known is not None and n not in known]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown {what} {', '.join(bad)}; known: {', '.join(known)}")
    return names


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--make-sets", type=Path, metavar="LIBRARY",
                   help="only write the held-out sets from this library (runs/paper_10pct/library.sqlite) into "
                        "docs/learned_driver/heldout/")
    p.add_argument("--force", action="store_true", help="with --make-sets: overwrite existing set files")
    p.add_argument("--sets", type=lambda t: _names(t, None, "set"), default=list(HELDOUT),
                   help=f"held-out set names or garage-set .json files (default {','.join(HELDOUT)})")
    p.add_argument("--scenarios", type=lambda t: _names(t, list(SCENARIOS), "scenario"), default=list(SCENARIOS),
                   help="static, actors (1 pedestrian + 1 moving car + 1 clutter per test); default both")
    p.add_argument("--drivers", type=lambda t: _names(t, None, "driver"), default=list(DRIVERS),
                   help=f"driver names (built-ins), each run into OUT/<set>/<scenario>/<driver>/ (default {','.join(DRIVERS)})")
    p.add_argument("--model", type=Path, metavar="PATH", help="a train-driver model zip: learned means learned:PATH")
    p.add_argument("--tests", type=positive_int, default=4, help="tests per garage (default 4)")
    p.add_argument("--garages", type=positive_int, default=None, metavar="N",
                   help="only the first N garages of each set (default all)")
    p.add_argument("--workers", type=positive_int, default=2, help="worker processes per run (default 2)")
    p.add_argument("--seed", type=int, default=0, help="run seed, the same for every driver (default 0)")
    p.add_argument("--out", type=Path, default=Path("runs/bench_learned"),
                   help="root of the run folders OUT/<set>/<scenario>/<driver>/ (default runs/bench_learned)")
    p.add_argument("--json", type=Path, default=DEFAULT_JSON,
                   help="summary JSON; a .md of the table is written beside it (default "
                        "docs/learned_driver/bench_learned.json)")
    p.add_argument("--summarize", action="store_true", help="run nothing: summarise the run folders there are")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parser().parse_args(argv)
    args.argv = argv
    try:
        if args.make_sets is not None:
            return make_sets(args.make_sets, args.force)
        if args.model is not None and not args.model.is_file():
            raise BenchError(f"--model {args.model}: no such file; give a model zip of garage-mj train-driver")
        specs = {d: driver_spec(d, args.model) for d in args.drivers}
        if any(":" in d or "/" in d for d in specs):
            raise BenchError(f"--drivers {','.join(args.drivers)}: give driver names (each names a run folder); "
                             "a learned model goes in --model PATH")
        sets = {Path(n).stem: load_set(n) for n in args.sets}
        if not args.summarize:
            run_all(sets, args.scenarios, specs, args)
        report = summarize(sets, args.scenarios, list(specs), args)
    except GarageMJError as exc:
        print(f"bench_learned: error: {exc}", file=sys.stderr)
        return 2
    text = markdown(report)
    print(text, end="")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    write_json(args.json, report, indent=1)
    md = args.json.with_suffix(".md")
    atomic_write(md, f"# Learned driver on held-out garages\n\n`{report['command']}`\n\n{text}")
    print(f"wrote {args.json} and {md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
