"""What are generated garages worth for training? One budget, three curricula, >= 3 seeds.

The experiment (resumable: re-run the same command after a Ctrl-C; every training run and every
evaluation continues where it stopped):

    MUJOCO_GL=egl .venv/bin/python eval/compare_curricula.py --workers 2

A quick trial of the plumbing (minutes; into /tmp):

    MUJOCO_GL=egl .venv/bin/python eval/compare_curricula.py --garages tiny_7x11 -n 4 --validation tiny_7x11 \\
        --iterations 1 --steps 100 --val-tests 2 --seeds 0 --curricula uniform,difficulty --sets tiny_7x11 \\
        --garages-per-set 2 --tests 1 --scenarios static --workers 1 --out /tmp/cc --json /tmp/cc/cc.json

Training. Every curriculum x seed gets the same budget (``--iterations`` DAgger iterations of
``--steps`` env steps, ``--workers`` driving processes; every other key is
:class:`~garage_mj.driving.learning.train.DriverTrainConfig`'s default) on the same training garages
and the same validation garages, into ``OUT/<curriculum>_s<seed>/`` (a ``garage-mj train-driver``
run folder). What the curricula draw (:mod:`garage_mj.driving.learning.train`):

- ``uniform``: every training garage equally often;
- ``difficulty``: iteration ``i`` of ``n`` draws from the easiest ``(i + 1) / n`` of the set, by the
  library's difficulty (easy to hard);
- ``hunt`` (the adversarial arm, unsupervised environment design): before each iteration
  after the first, ``garage-mj hunt`` against the current model searches mutated garages of the
  set's map for ones it fails on; the worst join the draw with half its weight;
- ``adversarial`` (not in the default comparison): failure-prioritised replay; the garages where the
  model itself failed most in its last iteration's drives are drawn more (weight
  ``1 + 4 * failure rate``); it re-weights the same training garages and makes no new ones.

Training garages: ``--garages`` (default ``models/drivers/cruise_m5_garages.json``, the shipped
model's set): a garage-set JSON, a library ``.sqlite`` filtered by ``--map``/``--run-seeds``/``-n``
(seeded by ``--set-seed``, the same set for every run), a folder of packs or a shipped map name;
validation garages likewise with ``--validation`` (default ``models/drivers/cruise_m5_validation.json``)
and ``--validation-run-seeds``/``--validation-n``.

Evaluation. Every finished model drives the held-out sets (``docs/learned_driver/heldout/*.json``,
:mod:`eval.bench_learned`'s), ``--tests`` tests per garage, run seed ``--eval-seed``, the paper's
discrete actions, the same tests for every model, static and/or with actors (1 pedestrian + 1
moving car + 1 clutter), each a cruise run into ``OUT/eval/<set>/<scenario>/<curriculum>_s<seed>/``.

Summary (read back from the folders, so a resumed or partial experiment is summarised in full):
per curriculum x set x scenario, success % over feasible tests of every seed, their mean with a
95% t-interval over seeds (the training seed is the unit of replication), the pooled success over
all seeds' tests with its 95% Wilson interval, and the training wall time; then every pair of
curricula per set x scenario: the difference of means with its 95% Welch interval, and whether it
is within the intervals (the interval holds 0: no difference shown) or beyond them. Printed as
markdown, written to ``--json`` and a ``.md`` beside it. ``--summarize`` only reads back.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from garage_mj.cli._common import positive_int, seed_list
from garage_mj.core.backends import Compute
from garage_mj.core.config import load_config
from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import FolderLock, atomic_write, write_json
from garage_mj.driving.garage_set import GarageSet, load_garage_set
from garage_mj.driving.learning.train import CURRICULA, MANIFEST, MODEL, DriverTrainConfig

COMPARED = ("uniform", "difficulty", "hunt")  # the three arms compared

try:  # run as a script: eval/ is on sys.path
    import bench_learned as bench
except ModuleNotFoundError as exc:  # imported as eval.compare_curricula
    if exc.name != "bench_learned":
        raise
    from eval import bench_learned as bench

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_GARAGES = ROOT / "models" / "drivers" / "cruise_m5_garages.json"
DEFAULT_VALIDATION = ROOT / "models" / "drivers" / "cruise_m5_validation.json"
DEFAULT_OUT = ROOT / "runs" / "compare_curricula"
DEFAULT_JSON = ROOT / "docs" / "learned_driver" / "compare_curricula.json"
#: The budget every curriculum x seed trains with (the rest: DriverTrainConfig's defaults).
ITERATIONS = 4  # DAgger iterations
STEPS = 3000  # [env steps] per iteration
SEEDS = (0, 1, 2)
CONFIDENCE = 0.95


class CompareError(GarageMJError):
    """A setting of the curriculum comparison the user can fix (missing garages, a run with other settings)."""


# -- statistics ---------------------------------------------------------------------------------------
def t_interval(values: Sequence[float], confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """The t-interval of the mean of ``values`` (percent, clipped to 0-100); None under two values."""
    from scipy.stats import t

    n = len(values)
    if n < 2:
        return None
    mean = sum(values) / n
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = float(t.ppf(0.5 + confidence / 2, n - 1)) * sd / math.sqrt(n)
    return round(max(0.0, mean - half), 1), round(min(100.0, mean + half), 1)


def welch_difference(a: Sequence[float], b: Sequence[float],
                     confidence: float = CONFIDENCE) -> tuple[float, tuple[float, float] | None]:
    """Mean of ``a`` minus mean of ``b`` and its Welch t-interval (None under two values on a side)."""
    from scipy.stats import t

    ma, mb = sum(a) / len(a), sum(b) / len(b)
    diff = ma - mb
    if len(a) < 2 or len(b) < 2:
        return round(diff, 1), None
    va = sum((v - ma) ** 2 for v in a) / (len(a) - 1) / len(a)
    vb = sum((v - mb) ** 2 for v in b) / (len(b) - 1) / len(b)
    se = math.sqrt(va + vb)
    if se == 0.0:
        return round(diff, 1), (round(diff, 1), round(diff, 1))
    df = (va + vb) ** 2 / ((va ** 2 / (len(a) - 1) if va else 0.0) + (vb ** 2 / (len(b) - 1) if vb else 0.0))
    half = float(t.ppf(0.5 + confidence / 2, df)) * se
    return round(diff, 1), (round(diff - half, 1), round(diff + half, 1))


def _overlap(x: Sequence[float] | None, y: Sequence[float] | None) -> bool | None:
    if x is None or y is None:
        return None
    return x[0] <= y[1] and y[0] <= x[1]


# -- training -----------------------------------------------------------------------------------------
def run_name(curriculum: str, seed: int) -> str:
    return f"{curriculum}_s{seed}"


def train_config(args: argparse.Namespace, curriculum: str) -> DriverTrainConfig:
    data: dict[str, Any] = {"iterations": args.iterations, "steps_per_iteration": args.steps,
                            "n_envs": args.workers, "curriculum": curriculum}
    if args.val_tests is not None:
        data["val_tests"] = args.val_tests
    try:
        return load_config(DriverTrainConfig, data)
    except ValueError as exc:
        raise CompareError(f"driver training config: {exc}") from None


def _is_library(spec: str) -> bool:
    path = Path(spec)
    return path.is_file() and path.suffix != ".json"


def training_sets(args: argparse.Namespace) -> tuple[GarageSet, GarageSet]:
    """The training and validation garages, the same for every curriculum and seed."""
    garages = args.garages or (str(DEFAULT_GARAGES) if DEFAULT_GARAGES.is_file() else None)
    if garages is None:
        raise CompareError(f"--garages: give the training garages (a library .sqlite with --map/--run-seeds/-n, "
                           f"a garage-set .json, a pack folder or a map name); the default {DEFAULT_GARAGES} "
                           "is not there")
    validation = args.validation or (str(DEFAULT_VALIDATION) if DEFAULT_VALIDATION.is_file() else None)
    if validation is None:
        raise CompareError(f"--validation: give the validation garages (as --garages); the default "
                           f"{DEFAULT_VALIDATION} is not there")
    train = load_garage_set(garages, map=args.map, run_seeds=args.run_seeds, n=args.n, seed=args.set_seed)
    val = load_garage_set(validation, map=args.map if _is_library(validation) else None,
                          run_seeds=args.validation_run_seeds, n=args.validation_n, seed=args.set_seed + 1)
    overlap = set(train.hashes) & set(val.hashes)
    if overlap:
        print(f"note: {len(overlap)} validation garage(s) are also training garages")
    return train, val


def train_all(args: argparse.Namespace) -> None:
    """Train (or continue) every curriculum x seed, seed by seed, so a stopped experiment has whole seeds."""
    from garage_mj.driving.learning.train import train_driver

    train, val = training_sets(args)
    print(f"training on {len(train)} garages ({train.origin}); validating on {len(val)} ({val.origin})")
    runs = [(c, s) for s in args.seeds for c in args.curricula]
    for k, (curriculum, seed) in enumerate(runs, 1):
        cfg = train_config(args, curriculum)
        out = args.out / run_name(curriculum, seed)
        if (out / MODEL).is_file():
            print(f"[{k}/{len(runs)}] {run_name(curriculum, seed)}: trained ({out / MODEL})")
            continue
        print(f"[{k}/{len(runs)}] {run_name(curriculum, seed)}: {cfg.iterations} iterations x "
              f"{cfg.steps_per_iteration} steps, {cfg.n_envs} workers -> {out}", flush=True)
        start = time.perf_counter()
        with FolderLock(out, "eval/compare_curricula.py"):
            train_driver(train, out, validation=val, config=cfg, seed=seed, resume=True, progress=not args.quiet)
        print(f"  done in {time.perf_counter() - start:.0f} s", flush=True)


def read_training(out: Path) -> dict[str, Any] | None:
    """What a training run folder says about itself; None if it was never started."""
    path = out / MANIFEST
    if not path.is_file():
        return None
    try:
        run = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise CompareError(f"{path} is not readable JSON ({exc}); remove the folder to train it again") from None
    state = run.get("state", {})
    curve = state.get("curve", [])
    last = curve[-1] if curve else {}
    return {"iterations_done": state.get("iterations_done", 0), "iterations": run["config"]["iterations"],
            "steps_per_iteration": run["config"]["steps_per_iteration"], "n_envs": run["config"]["n_envs"],
            "wall_s": round(float(state.get("wall_s", 0.0)), 1), "finished": (out / MODEL).is_file(),
            "last_val_success": last.get("val_success", ""), "garages": run.get("garages"),
            "validation": run.get("validation"), "train_garages": len(run.get("garage_hashes", [])),
            "garage_hashes": run.get("garage_hashes", [])}


# -- evaluation ---------------------------------------------------------------------------------------
def eval_all(args: argparse.Namespace, sets: dict[str, GarageSet]) -> None:
    """Every finished model on every held-out set x scenario (resumable cruise runs)."""
    from garage_mj.driving.sources import CruiseSettings
    from garage_mj.reporting.cruise import run_cruise

    models = {run_name(c, s): args.out / run_name(c, s) / MODEL for s in args.seeds for c in args.curricula}
    missing = [name for name, path in models.items() if not path.is_file()]
    if missing:
        print(f"note: not evaluated, training not finished: {', '.join(missing)}")
    specs = {name: f"learned:{path}" for name, path in models.items() if path.is_file()}
    if not specs:
        return
    choices = bench.check_drivers(specs)
    cells = [(name, s, c) for name in specs for s in sets for c in args.scenarios]
    for k, (name, set_name, scen) in enumerate(cells, 1):
        srcs = list(sets[set_name])[: args.garages_per_set]
        out = args.out / "eval" / set_name / scen / name
        print(f"[{k}/{len(cells)}] {name} on {set_name} / {scen}: {len(srcs)} garages x {args.tests} tests "
              f"-> {out}", flush=True)
        settings = CruiseSettings(specs[name], seed=args.eval_seed, occupancy=bench.OCCUPANCY,
                                  env=bench.scenario_env(scen))
        res = run_cruise(srcs, args.tests, settings, out,
                         compute=Compute(workers=args.workers, progress=not args.quiet), choice=choices[name])
        s = res.stats
        print(f"  success {s['success_pct']}% of {s['feasible']} feasible; {res.tests_run} new tests", flush=True)


# -- the summary --------------------------------------------------------------------------------------
def summarize(args: argparse.Namespace, sets: dict[str, GarageSet]) -> dict[str, Any]:
    training = []
    for c in args.curricula:
        for s in args.seeds:
            info = read_training(args.out / run_name(c, s))
            if info is None:
                print(f"note: {run_name(c, s)} was never trained ({args.out / run_name(c, s)})")
                continue
            training.append({"curriculum": c, "seed": s, **info})
    wall = {c: [t["wall_s"] for t in training if t["curriculum"] == c and t["finished"]] for c in args.curricula}
    cells = []
    for set_name, gs in sets.items():
        srcs = list(gs)[: args.garages_per_set]
        hashes = {x.hash for x in srcs}
        for scen in args.scenarios:
            for c in args.curricula:
                per_seed, rows_all = [], []
                for s in args.seeds:
                    got = bench.read_cell(args.out / "eval" / set_name / scen / run_name(c, s), hashes, args.tests)
                    if got is None:
                        continue
                    rows, _ = got
                    st = bench.cell_stats(rows)
                    rows_all += rows
                    per_seed.append({"seed": s, "tests": st["tests"], "feasible": st["feasible"],
                                     "successes": st["successes"], "success_pct": st["success_pct"],
                                     "failures": st["failures"]})
                if not per_seed:
                    continue
                pcts = [p["success_pct"] for p in per_seed if p["success_pct"] is not None]
                pooled = bench.cell_stats(rows_all)
                cells.append({
                    "set": set_name, "scenario": scen, "curriculum": c, "per_seed": per_seed,
                    "expected_tests_per_seed": len(srcs) * args.tests,
                    "mean_pct": round(sum(pcts) / len(pcts), 1) if pcts else None,
                    "t95_pct": t_interval(pcts), "seeds": len(pcts),
                    "pooled": {"feasible": pooled["feasible"], "successes": pooled["successes"],
                               "success_pct": pooled["success_pct"], "wilson95_pct": pooled["ci95_pct"],
                               "failures": pooled["failures"], "hits": pooled["hits"]},
                    "train_wall_s_mean": round(sum(wall[c]) / len(wall[c]), 1) if wall[c] else None})
    notes = []
    budget = (args.iterations, args.steps, args.workers)
    other = sorted({run_name(t["curriculum"], t["seed"]) for t in training
                    if (t["iterations"], t["steps_per_iteration"], t["n_envs"]) != budget})
    if other:
        notes.append(f"{', '.join(other)} trained with another budget than the flags say (iterations, steps, "
                     "workers); the training table shows theirs")
    seen = set().union(*(t["garage_hashes"] for t in training)) if training else set()
    for set_name, gs in sets.items():
        shared = seen & {x.hash for x in list(gs)[: args.garages_per_set]}
        if shared:
            notes.append(f"{len(shared)} garage(s) of held-out set {set_name} are training garages: not held out")
    for n in notes:
        print(f"note: {n}")
    for t in training:
        del t["garage_hashes"]
    return {"format": "garage-mj compare_curricula", "version": 1,
            "command": "eval/compare_curricula.py " + " ".join(args.argv),
            "settings": {"budget": {"iterations": args.iterations, "steps_per_iteration": args.steps,
                                    "n_envs": args.workers, "val_tests": args.val_tests,
                                    "other": "DriverTrainConfig defaults"},
                         "seeds": args.seeds, "curricula": args.curricula, "tests_per_garage": args.tests,
                         "eval_seed": args.eval_seed, "action_type": "discrete", "occupancy": bench.OCCUPANCY,
                         "garages_per_set": args.garages_per_set,
                         "scenarios": {s: bench.SCENARIOS[s] for s in args.scenarios}, "confidence": CONFIDENCE},
            "sets": {n: {"origin": gs.origin, "garages": len(list(gs)[: args.garages_per_set])}
                     for n, gs in sets.items()},
            "training": training, "cells": cells, "comparisons": comparisons(cells), "notes": notes}


def comparisons(cells: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every pair of curricula per set x scenario: the difference of mean success over seeds and its verdict."""
    out = []
    by = {(c["set"], c["scenario"], c["curriculum"]): c for c in cells}
    groups = dict.fromkeys((c["set"], c["scenario"]) for c in cells)
    for set_name, scen in groups:
        have = [c for c in cells if (c["set"], c["scenario"]) == (set_name, scen)]
        for a, b in itertools.combinations([c["curriculum"] for c in have], 2):
            ca, cb = by[set_name, scen, a], by[set_name, scen, b]
            pa = [p["success_pct"] for p in ca["per_seed"] if p["success_pct"] is not None]
            pb = [p["success_pct"] for p in cb["per_seed"] if p["success_pct"] is not None]
            if not pa or not pb:
                continue
            diff, ci = welch_difference(pa, pb)
            wilson_overlap = _overlap(ca["pooled"]["wilson95_pct"], cb["pooled"]["wilson95_pct"])
            if ci is not None:
                within = ci[0] <= 0.0 <= ci[1]
                basis = "seeds"
            else:
                within = bool(wilson_overlap)
                basis = "pooled Wilson intervals (too few seeds for an interval over seeds)"
            out.append({"set": set_name, "scenario": scen, "a": a, "b": b, "diff_pct": diff, "welch95_pct": ci,
                        "t_intervals_overlap": _overlap(ca["t95_pct"], cb["t95_pct"]),
                        "wilson_intervals_overlap": wilson_overlap, "within_intervals": within, "basis": basis})
    return out


def _ci(ci: Sequence[float] | None) -> str:
    return "n/a" if ci is None else f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def markdown(report: dict[str, Any]) -> str:
    """The summary as markdown: the training runs, the success table and the verdict on every difference."""
    st = report["settings"]
    b = st["budget"]
    lines = [f"Budget per run: {b['iterations']} DAgger iterations x {b['steps_per_iteration']} env steps, "
             f"{b['n_envs']} workers, other settings DriverTrainConfig's defaults; training seeds "
             f"{', '.join(map(str, st['seeds']))}. Held-out tests: {st['tests_per_garage']} per garage, run seed "
             f"{st['eval_seed']}, {st['action_type']} actions, the same tests for every model.", "",
             "| curriculum | seed | iterations | train wall min | last validation success |",
             "|---|---|---|---|---|"]
    for t in report["training"]:
        state = f"{t['iterations_done']} / {t['iterations']}" + ("" if t["finished"] else " (not finished)")
        lines.append(f"| {t['curriculum']} | {t['seed']} | {state} | {t['wall_s'] / 60:.1f} | "
                     f"{t['last_val_success'] if t['last_val_success'] != '' else '-'} |")
    lines += ["", "Success % over feasible held-out tests: per training seed, their mean with a 95% t-interval over "
              "seeds, and all seeds' tests pooled with a 95% Wilson interval.", "",
              "| set | scenario | curriculum | per seed | mean [95% t over seeds] | pooled [95% Wilson] "
              "| feasible / tests | train wall min (mean) |",
              "|---|---|---|---|---|---|---|---|"]
    for c in report["cells"]:
        seeds = ", ".join(f"s{p['seed']} " + ("n/a" if p["success_pct"] is None else f"{p['success_pct']:.1f}")
                          for p in c["per_seed"])
        feas = sum(p["feasible"] for p in c["per_seed"])
        tests = sum(p["tests"] for p in c["per_seed"])
        expected = c["expected_tests_per_seed"] * len(st["seeds"])
        part = "" if tests == expected else f" (of {expected})"
        mean = "n/a" if c["mean_pct"] is None else f"{c['mean_pct']:.1f}"
        pooled = "n/a" if c["pooled"]["success_pct"] is None else f"{c['pooled']['success_pct']:.1f}"
        wall = "-" if c["train_wall_s_mean"] is None else f"{c['train_wall_s_mean'] / 60:.1f}"
        lines.append(f"| {c['set']} | {c['scenario']} | {c['curriculum']} | {seeds} | {mean} {_ci(c['t95_pct'])} | "
                     f"{pooled} {_ci(c['pooled']['wilson95_pct'])} | {feas} / {tests}{part} | {wall} |")
    comps = report["comparisons"]
    if comps:
        lines += ["", "Differences of mean success (points; a minus b) with a 95% Welch interval over seeds. "
                  "Within the intervals: the interval holds 0, so these seeds show no difference."]
        for d in comps:
            head = f"- {d['set']} / {d['scenario']}: {d['a']} - {d['b']} = {d['diff_pct']:+.1f} points"
            if d["welch95_pct"] is not None:
                head += f", 95% interval {_ci(d['welch95_pct'])}"
            verdict = ("within the intervals (no difference shown)" if d["within_intervals"]
                       else f"beyond the intervals ({d['a'] if d['diff_pct'] > 0 else d['b']} better)")
            lines.append(f"{head}: {verdict}" + ("" if d["basis"] == "seeds" else f", by {d['basis']}"))
        beyond = [d for d in comps if not d["within_intervals"]]
        if beyond:
            lines += ["", f"{len(comps) - len(beyond)} of {len(comps)} differences are within the intervals; beyond "
                          "them: " + "; ".join(f"{d['set']} / {d['scenario']}: {d['a']} vs {d['b']}" for d in beyond)]
        else:
            lines += ["", f"All {len(comps)} differences are within the intervals: no curriculum is shown better "
                          "than another."]
    if report["notes"]:
        lines += ["", "Notes:"] + [f"- {n}" for n in report["notes"]]
    return "\n".join(lines) + "\n"


# -- the command --------------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("training")
    g.add_argument("--garages", metavar="GARAGES",
                   help="training garages: a garage-set .json, a library .sqlite (with --map/--run-seeds/-n), a "
                        "pack folder or a map name (default models/drivers/cruise_m5_garages.json)")
    g.add_argument("--map", help="library: keep only this map's garages")
    g.add_argument("--run-seeds", type=seed_list, metavar="K,K", help="library: keep only these generation runs' seeds")
    g.add_argument("-n", type=positive_int, metavar="N", help="library or map: N garages (seeded by --set-seed)")
    g.add_argument("--validation", metavar="GARAGES",
                   help="validation garages, as --garages (default models/drivers/cruise_m5_validation.json)")
    g.add_argument("--validation-run-seeds", type=seed_list, metavar="K,K", help="library: the validation runs' seeds")
    g.add_argument("--validation-n", type=positive_int, metavar="N", help="library or map: N validation garages")
    g.add_argument("--set-seed", type=int, default=0, help="seed of the garage samples, the same for every run "
                   "(default 0; validation: +1)")
    g.add_argument("--curricula", type=lambda t: bench._names(t, list(CURRICULA), "curriculum"),
                   default=list(COMPARED),
                   help=f"curricula to compare, of {','.join(CURRICULA)} (default {','.join(COMPARED)})")
    g.add_argument("--seeds", type=seed_list, default=list(SEEDS), help="training seeds (default 0,1,2)")
    g.add_argument("--iterations", type=positive_int, default=ITERATIONS,
                   help=f"DAgger iterations (default {ITERATIONS})")
    g.add_argument("--steps", type=positive_int, default=STEPS, help=f"env steps per iteration (default {STEPS})")
    g.add_argument("--val-tests", type=int, default=None, metavar="N",
                   help="validation tests per iteration (default DriverTrainConfig's)")
    e = p.add_argument_group("evaluation")
    e.add_argument("--sets", type=lambda t: bench._names(t, None, "set"), default=list(bench.HELDOUT),
                   help=f"held-out set names or garage-set .json files (default {','.join(bench.HELDOUT)})")
    e.add_argument("--garages-per-set", type=positive_int, default=None, metavar="N",
                   help="only the first N garages of each held-out set (default all)")
    e.add_argument("--scenarios", type=lambda t: bench._names(t, list(bench.SCENARIOS), "scenario"),
                   default=list(bench.SCENARIOS),
                   help="static, actors (1 pedestrian + 1 moving car + 1 clutter per test); default both")
    e.add_argument("--tests", type=positive_int, default=4, help="tests per garage (default 4)")
    e.add_argument("--eval-seed", type=int, default=0, help="run seed of the held-out tests (default 0)")
    p.add_argument("--workers", type=positive_int, default=2,
                   help="worker processes, training and cruise (default 2)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT,
                   help="root of the run folders OUT/<curriculum>_s<seed>/ and OUT/eval/ "
                        "(default runs/compare_curricula)")
    p.add_argument("--json", type=Path, default=DEFAULT_JSON,
                   help="summary JSON; a .md beside it (default docs/learned_driver/compare_curricula.json)")
    p.add_argument("--summarize", action="store_true", help="run nothing: summarise the folders there are")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parser().parse_args(argv)
    args.argv = argv
    try:
        if args.val_tests is not None and args.val_tests < 0:
            raise CompareError(f"--val-tests {args.val_tests}: give 0 (no validation curve) or more")
        sets = {Path(n).stem: bench.load_set(n) for n in args.sets}
        if not args.summarize:
            train_all(args)
            eval_all(args, sets)
        report = summarize(args, sets)
    except KeyboardInterrupt:
        print("compare_curricula: interrupted; run the same command again to continue where it stopped",
              file=sys.stderr)
        return 130
    except GarageMJError as exc:
        print(f"compare_curricula: error: {exc}", file=sys.stderr)
        return 2
    text = markdown(report)
    print(text, end="")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    write_json(args.json, report, indent=1)
    md = args.json.with_suffix(".md")
    atomic_write(md, f"# What generated garages are worth for training: curricula compared\n\n"
                     f"`{report['command']}`\n\n{text}")
    print(f"wrote {args.json} and {md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
