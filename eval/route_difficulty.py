"""Validation of the route-aware difficulty: fit on some garages and drivers, test on others.

Protocol (fixed before any result was seen; nothing is tuned on the held-out sets):

* **fit set**: ``--fit-per-map`` garages of each 13x13 map (m4, m5, m6, m7) from the DQN runs with
  training seeds ``--fit-run-seeds`` (default 0-3) of ``--library``, stratified by the paper's
  difficulty, ``--fit-tests`` cruise tests each with the fit drivers (default ``vision`` and
  ``waypoint``, the paper's discrete actions, occupancy 0.5). The route difficulty is fitted on
  these tests' outcomes (``garage-mj difficulty fit``).
* **held-out garages**: 50 m5 garages of the run with training seed ``--heldout-run-seed`` (default
  4; no fit garage comes from it), 50 tests each, exactly ``eval/paper_validation.py --run-seeds 4``.
* **held-out driver**: ``learned`` (the shipped deep-RL model, never in the fit) on the held-out
  garages; the fit drivers on the held-out garages are the garage-only hold-out.
* **leave one driver out** (``--lodo-drivers``, default ``vision,waypoint,learned``; added
  before any of its models was scored): the fit set is also driven by ``learned``, and for each of
  these drivers a model is fitted on the fit-set tests of the others only and scored on that
  driver's held-out tests, so both its garages and the driver are unseen by the model.

* **fresh held-out set** (``--only fresh`` collects it, ``--fresh-report`` scores it; fixed
  before any of its tests was scored): 50 more m5 garages of training seed 4 (stratified sample seed
  ``--fresh-sample-seed``, none of the first held-out set's), no earlier run drove any of them; ``learned``
  150 tests each (at 50 its attainable |r| is too low to judge r <= -0.8), ``vision`` and ``waypoint`` 50.
  The first held-out set has been seen, so it became development data: every model scored here
  is fitted on ``--dev-runs`` (the fit set of the three drivers and the first held-out set) with the 16
  route features (the 14 of the route and the paper's two garage terms, ``short_roads`` and ``few_way``):
  ``pooled`` on all three drivers, ``without_<driver>`` on the other two (leave one driver out),
  ``own_<driver>`` on that driver alone (the learned driver's is shipped as
  ``models/difficulty/learned.json``), next to the model shipped before and the paper's difficulty.
  The plan was also to ship ``pooled`` as ``models/difficulty/route.json``; it was not, because on
  the fresh set it predicted ``vision`` and ``waypoint`` worse than the model shipped before (the
  learned driver's failures, uncorrelated with theirs there, pull it away), so the default stayed. It also prints the bound on any single per-garage difficulty for two
  drivers at once: if their success % correlate by r12 over the garages, no one difficulty can
  reach r below -sqrt((1 + r12) / 2) with both (harder for both).

Next to each r it prints the largest |r| any per-garage difficulty can expect on those garages
(``attainable_r``): each garage's success % is measured on 50 tests, and only the spread between
garages beyond that binomial noise can follow a difficulty.

For each held-out (driver, set) it prints and writes the per-garage Pearson r between success %
and (a) the route difficulty, (b) the paper's difficulty, each with a 95 % bootstrap interval over
garages, and the per-test AUC of each as a failure predictor. Every cruise run is resumable
(re-run the same command); ``--reuse DRIVER=DIR`` copies the tests of an earlier identical run
(for example ``runs/paper_validation_vision``) instead of driving them again.

    .venv/bin/python eval/route_difficulty.py --library runs/paper_10pct/library.sqlite \\
        --out runs/route_difficulty --json docs/route_difficulty/validation.json
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from garage_mj.cli._common import positive_int, seed_list

FIT_MAPS = ("m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u")
HELDOUT_MAP = "m5_13x13_aligned"
FIT_DRIVERS = ("vision", "waypoint")
HELDOUT_DRIVERS = ("vision", "waypoint", "learned")
LODO_DRIVERS = ("vision", "waypoint", "learned")


def collect(library: Path, out: Path, drivers, maps, run_seeds, per_map: int, tests: int | dict[str, int], workers: int,
            tag: str, reuse: dict[str, Path] | None = None, action_type: str = "discrete", sample_seed: int = 0,
            exclude: frozenset[str] = frozenset()) -> dict[str, Path]:
    """Run (resumably) ``tests`` cruise tests (or ``tests[driver]``) of each driver on the garages; returns
    driver -> run folder. The garages: ``per_map`` of each map drawn with ``sample_seed``, none of ``exclude``."""
    from garage_mj.core.backends import Compute
    from garage_mj.driving.garage_set import GarageSet
    from garage_mj.driving.sources import CruiseSettings
    from garage_mj.reporting.cruise import run_cruise

    sources = []
    for m in maps:
        sources += list(GarageSet.from_library(library, map=m, run_seeds=run_seeds, n=per_map, seed=sample_seed,
                                               exclude=exclude))
    runs = {}
    for driver in drivers:
        run = out / f"{tag}_{driver}"
        if reuse and driver in reuse and not (run / "tests.csv").exists():
            run.mkdir(parents=True, exist_ok=True)
            for name in ("tests.csv", "run.json"):
                shutil.copy(reuse[driver] / name, run / name)
        n = tests[driver] if isinstance(tests, dict) else tests
        print(f"{tag}: {len(sources)} garages x {n} tests, driver {driver} -> {run}", flush=True)
        run_cruise(sources, n, CruiseSettings(driver, seed=0, action_type=action_type), run,
                   compute=Compute(workers=workers))
        runs[driver] = run
    return runs


def _two_fold(records: list[dict], features: tuple[str, ...]) -> dict:
    """A driver-specific refit, checked out of sample: garages split in two by hash, fit on each half and
    scored on the other; the per-garage r and AUC over both scored halves (route difficulty = mean over
    the garage's tests)."""
    from garage_mj.driving.difficulty.fit import garage_table
    from garage_mj.driving.difficulty.regression import auc, pearson
    from garage_mj.scene.route_difficulty import fit

    halves = [[r for r in records if int(r["garage_hash"][-1], 16) % 2 == k] for k in (0, 1)]
    rows, probs, failed = [], [], []
    for train, test in ((halves[0], halves[1]), (halves[1], halves[0])):
        try:
            m = fit(train, [r["failed"] for r in train], features)
        except ValueError:
            return {"r": None, "auc": None}
        rows += garage_table(m, test)
        probs += list(m.test_probability(test))
        failed += [bool(r["failed"]) for r in test]
    r = pearson([t["route_difficulty"] for t in rows], [t["success_pct"] for t in rows])
    a = auc(probs, failed)
    return {"r": round(r, 4) if r == r else None, "auc": round(a, 4) if a == a else None, "garages": len(rows)}


def _names(text: str) -> list[str]:
    """A comma-separated list of driver names ('' for none)."""
    return [d for d in text.split(",") if d]


def _driver_counts(text: str) -> dict[str, int]:
    """``vision=50,learned=150`` -> {driver: tests per garage}."""
    out = {}
    for item in _names(text):
        driver, _, n = item.partition("=")
        if not n.isdigit() or int(n) < 1:
            raise argparse.ArgumentTypeError(f"{item!r}: expected DRIVER=N with N >= 1")
        out[driver] = int(n)
    return out


def _heldout_hashes(args) -> frozenset[str]:
    """The garages of the (first) held-out set: the fresh set is drawn from the others."""
    from garage_mj.driving.garage_set import GarageSet

    return frozenset(GarageSet.from_library(args.library, map=HELDOUT_MAP, run_seeds=[args.heldout_run_seed],
                                            n=args.heldout_garages, seed=0).hashes)


def _reuse(items: list[str]) -> dict[str, Path]:
    out = {}
    for item in items:
        driver, _, path = item.partition("=")
        if not path or not (Path(path) / "tests.csv").is_file():
            raise SystemExit(f"--reuse {item!r}: expected DRIVER=DIR with DIR/tests.csv")
        out[driver] = Path(path)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--library", type=Path, required=True, help="DQN library with runs of seeds 0-4 of the 13x13 maps")
    p.add_argument("--out", type=Path, default=Path("runs/route_difficulty"))
    p.add_argument("--json", type=Path, help="write the figures here")
    p.add_argument("--fit-run-seeds", type=seed_list, default=[0, 1, 2, 3], metavar="K,K")
    p.add_argument("--fit-per-map", type=positive_int, default=12)
    p.add_argument("--fit-tests", type=positive_int, default=20)
    p.add_argument("--heldout-run-seed", type=int, default=4)
    p.add_argument("--heldout-garages", type=positive_int, default=50)
    p.add_argument("--heldout-tests", type=positive_int, default=50)
    p.add_argument("--heldout-drivers", default=",".join(HELDOUT_DRIVERS))
    p.add_argument("--heldout-continuous", default="vision", metavar="DRIVERS",
                   help="drivers also run on the held-out garages with their own continuous actions (another "
                        "behaviour than the fit's discrete one; '' for none; default vision)")
    p.add_argument("--reuse", nargs="*", default=[], metavar="DRIVER=DIR",
                   help="held-out runs done before with the same settings (e.g. vision=runs/paper_validation_vision)")
    p.add_argument("--lodo-drivers", type=_names, default=",".join(LODO_DRIVERS), metavar="DRIVERS",
                   help="leave-one-driver-out: these drivers also drive the fit set, and each is scored by a model "
                        "fitted on the others ('' for none)")
    p.add_argument("--fresh-sample-seed", type=int, default=1,
                   help="fresh held-out set (set B): the sample seed of its m5 garages of --heldout-run-seed, "
                        "drawn from those the held-out set above did not take (default 1)")
    p.add_argument("--fresh-garages", type=positive_int, default=50)
    p.add_argument("--fresh-tests", type=_driver_counts, default="learned=150,vision=50,waypoint=50",
                   metavar="DRIVER=N,...", help="tests per garage of each driver on the fresh set")
    p.add_argument("--dev-runs", type=_names, metavar="DIRS",
                   default="fit_vision,fit_waypoint,fit_learned,heldout_vision,heldout_waypoint,heldout_learned_150",
                   help="development runs (folders under --out) the fresh report fits its models on")
    p.add_argument("--fresh-report", action="store_true",
                   help="score the fresh held-out set (after --only fresh) and write --json; no other report")
    p.add_argument("--models-out", type=Path, help="with --fresh-report: also write the learned driver's own "
                   "model to DIR/learned.json (with its .fit.csv)")
    p.add_argument("--workers", type=positive_int, default=2)
    p.add_argument("--only", choices=("fit", "heldout", "fresh"), help="only collect this part's cruise tests")
    args = p.parse_args(argv)
    if args.heldout_run_seed in args.fit_run_seeds:
        p.error("--heldout-run-seed must not be one of --fit-run-seeds")
    if args.fresh_report:
        if args.only:
            p.error("--fresh-report collects nothing; run --only fresh first, then --fresh-report alone")
        return report_fresh(args)
    if args.only in (None, "fit"):
        collect(args.library, args.out, list(dict.fromkeys([*FIT_DRIVERS, *args.lodo_drivers])), FIT_MAPS, args.fit_run_seeds,
                args.fit_per_map, args.fit_tests, args.workers, "fit")
    if args.only in (None, "heldout"):
        collect(args.library, args.out, args.heldout_drivers.split(","), (HELDOUT_MAP,), [args.heldout_run_seed],
                args.heldout_garages, args.heldout_tests, args.workers, "heldout", _reuse(args.reuse))
        if args.heldout_continuous:
            collect(args.library, args.out, args.heldout_continuous.split(","), (HELDOUT_MAP,),
                    [args.heldout_run_seed], args.heldout_garages, args.heldout_tests, args.workers, "heldout_continuous",
                    action_type="continuous")
    if args.only == "fresh":
        collect(args.library, args.out, list(args.fresh_tests), (HELDOUT_MAP,), [args.heldout_run_seed],
                args.fresh_garages, args.fresh_tests, args.workers, "fresh", sample_seed=args.fresh_sample_seed,
                exclude=_heldout_hashes(args))
    if args.only is not None:
        return 0
    return report(args)


def report(args) -> int:
    """Fit on the fit runs, score on the held-out runs, print and write the figures.

    Its models are fitted on the shipped default model's features (the 14 of the route), as the protocol
    of held-out set A was: the garage terms added for set B belong to the fresh report only."""
    from garage_mj.driving.difficulty.fit import fit_runs, load_runs, score
    from garage_mj.scene.route_difficulty import load_route_model

    shipped = load_route_model()
    fit_dirs = [args.out / f"fit_{d}" for d in FIT_DRIVERS]
    model, _ = fit_runs(fit_dirs, args.out / "route.json", args.library, shipped.features, progress=False)
    print(model.describe())
    print(f"fitted on {model.fit['tests']} tests of {model.fit['garages']} garages; "
          f"{'the same model as' if model.key == shipped.key else 'NOT the same model as'} models/difficulty/route.json")
    held = {d: args.out / f"heldout_{d}" for d in args.heldout_drivers.split(",")}
    held.update({f"{d} (continuous)": args.out / f"heldout_continuous_{d}"
                 for d in filter(None, args.heldout_continuous.split(","))})
    held = {k: v for k, v in held.items() if (v / "tests.csv").is_file()}
    records, per_garage = load_runs(list(held.values()), args.library, model)
    scores, refit = {}, {}
    for label, run in held.items():
        records_of = [r for r in records if r["run"] == str(run)]
        scores[label] = next(iter(score(model, records_of, garage_route=per_garage).values()))
        refit[label] = _two_fold(records_of, shipped.features)
    lodo = _leave_one_driver_out(args, args.lodo_drivers, held, shipped.features)
    result = {"model_key": model.key, "fit": model.fit, "heldout": scores, "refit_two_fold": refit,
              "leave_one_driver_out": lodo,
              "protocol": {"fit_maps": list(FIT_MAPS), "fit_run_seeds": args.fit_run_seeds,
                           "fit_per_map": args.fit_per_map, "fit_tests": args.fit_tests, "fit_drivers": list(FIT_DRIVERS),
                           "heldout_map": HELDOUT_MAP, "heldout_run_seed": args.heldout_run_seed,
                           "heldout_garages": args.heldout_garages, "heldout_tests": args.heldout_tests,
                           "action_type": "discrete", "occupancy": 0.5}}
    print("held out (garages of another training seed; per-garage route difficulty over all feasible stalls):")
    for label, d in scores.items():
        driver = label.split()[0]
        tag = "held-out driver" if driver not in FIT_DRIVERS or "continuous" in label else "fit driver, held-out garages"
        print(f"  {label} ({tag}): {d['garages']} garages x {d['tests'] // max(1, d['garages'])} tests, "
              f"success {d['success_pct']}%")
        for name, key in (("route", "route"), ("paper", "paper")):
            m = d[key]
            print(f"    {name:<5} r = {m['r']} {m['r_ci95']}  AUC = {m['auc']}")
        print(f"    attainable |r| (binomial noise of {d['tests'] // max(1, d['garages'])} tests per garage): "
              f"{d['attainable_r']} {d['attainable_r_ci95']}")
        f = refit[label]
        print(f"    refit on this driver, two folds of garages (fit on one half, scored on the other): "
              f"route r = {f['r']}, AUC = {f['auc']}")
    if lodo:
        print("leave one driver out (fitted on the fit set's tests of the other drivers, scored on this driver's "
              "held-out tests):")
    for driver, d in lodo.items():
        m = d["route"]
        print(f"  {driver}: fitted on {'+'.join(d['fit_drivers'])} ({d['fit_tests']} tests): route r = {m['r']} "
              f"{m['r_ci95']}  AUC = {m['auc']}  (attainable |r| {d['attainable_r']})")
    _write_json(args.json, result)
    return 0


def report_fresh(args) -> int:
    """Fit the set-B models on the development runs and score them on the fresh held-out set."""

    from garage_mj.driving.difficulty.fit import driver_agreement, fit_runs, load_runs, score
    from garage_mj.scene.route_difficulty import load_route_model

    work = args.out / "models_s10"
    before = load_route_model()  # read before --models-out may replace it
    dev = [args.out / d for d in args.dev_runs]
    missing = [str(r) for r in dev if not (r / "tests.csv").is_file()]
    fresh = {d: args.out / f"fresh_{d}" for d in args.fresh_tests}
    missing += [str(r) for r in fresh.values() if not (r / "tests.csv").is_file()]
    if missing:
        raise SystemExit(f"missing runs {missing}; collect them first (--only fit / heldout / fresh)")
    drivers = list(args.fresh_tests)

    def dev_of(names):  # the development runs of these drivers
        return [r for r in dev if any(r.name == f"{t}_{d}" or r.name.startswith(f"{t}_{d}_")
                                      for d in names for t in ("fit", "heldout"))]

    shipped = {"own_learned": "learned.json"}  # written into --models-out when given

    def path(name):
        return args.models_out / shipped[name] if args.models_out and name in shipped else work / f"{name}.json"

    models = {"pooled": fit_runs(dev_of(drivers), path("pooled"), args.library, progress=False)[0]}
    for d in drivers:
        models[f"without_{d}"] = fit_runs(dev_of([o for o in drivers if o != d]), path(f"without_{d}"),
                                          args.library, progress=False)[0]
        models[f"own_{d}"] = fit_runs(dev_of([d]), path(f"own_{d}"), args.library, progress=False)[0]
    models["shipped_before"] = before
    for name, m in models.items():
        print(f"{name}: {m.fit.get('tests')} tests of {m.fit.get('drivers')}; weights "
              + ", ".join(f"{f} {w:.2f}" for f, w in m.coefficients() if w > 0))
    result: dict = {"protocol": {"fresh_sample_seed": args.fresh_sample_seed, "garages": args.fresh_garages,
                                 "tests": args.fresh_tests, "dev_runs": args.dev_runs, "map": HELDOUT_MAP,
                                 "run_seed": args.heldout_run_seed},
                    "models": {n: {"key": m.key, "fit": {k: m.fit.get(k) for k in ("tests", "failures", "drivers")},
                                   "coefficients": {f: round(float(w), 4) for f, w in m.coefficients()}}
                               for n, m in models.items()},
                    "scores": {}}
    outcomes: dict[str, list[dict]] = {}  # each driver's fresh records
    for d in drivers:
        result["scores"][d] = {}
        for name, m in models.items():
            if name.startswith(("without_", "own_")) and not name.endswith(f"_{d}"):
                continue  # another driver's left-out or own model
            records, per_garage = load_runs([fresh[d]], args.library, m)
            result["scores"][d][name] = next(iter(score(m, records, garage_route=per_garage).values()))
        outcomes[d] = records  # the same records under every model
        first = next(iter(result["scores"][d].values()))
        print(f"{d}: {first['garages']} garages x {first['tests'] // max(1, first['garages'])} tests, success "
              f"{first['success_pct']}%, attainable |r| {first['attainable_r']} {first['attainable_r_ci95']}")
        print(f"  paper's difficulty   r = {first['paper']['r']} {first['paper']['r_ci95']}  AUC = {first['paper']['auc']}")
        for name, sc in result["scores"][d].items():
            print(f"  {name:<20} r = {sc['route']['r']} {sc['route']['r_ci95']}  AUC = {sc['route']['auc']}")
    bounds = driver_agreement([r for rs in outcomes.values() for r in rs])
    for pair, a in bounds.items():
        print(f"one difficulty for {pair.replace('+', ' and ')}: their success % correlate by r {a['r_between']}, so no "
              f"single per-garage difficulty reaches r below -{a['best_joint_abs_r']} with both")
    result["single_difficulty_bound"] = bounds
    if args.models_out:
        print(f"wrote the learned driver's own model to {args.models_out / 'learned.json'}")
    _write_json(args.json, result)
    return 0


def _write_json(path: Path | None, result: dict) -> None:
    """Write ``result`` to ``path`` (``--json``; nothing when None), atomically."""

    from garage_mj.core.fsutil import write_json

    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, result, indent=1)
        print(f"wrote {path}")


def _leave_one_driver_out(args, drivers: list[str], held: dict[str, Path], features: tuple[str, ...]) -> dict:
    """Per driver: a model fitted on the fit-set runs of the other ``drivers``, scored on its held-out run."""
    from garage_mj.driving.difficulty.fit import fit_runs, load_runs, score

    out = {}
    for driver in drivers:
        others = [args.out / f"fit_{o}" for o in drivers if o != driver]
        missing = [str(r) for r in others if not (r / "tests.csv").is_file()]
        if driver not in held or missing:
            print(f"leave-one-driver-out {driver}: skipped, missing {missing or held.get(driver)}", flush=True)
            continue
        model, _ = fit_runs(others, args.out / f"route_without_{driver}.json", args.library, features, progress=False)
        records, per_garage = load_runs([held[driver]], args.library, model)
        scored = next(iter(score(model, records, garage_route=per_garage).values()))
        out[driver] = {"fit_drivers": [o for o in drivers if o != driver], "fit_tests": model.fit["tests"],
                       "model_key": model.key,
                       "coefficients": {n: round(float(w), 4) for n, w in model.coefficients()}, **scored}
    return out


if __name__ == "__main__":
    sys.exit(main())
