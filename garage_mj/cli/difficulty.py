"""``garage-mj difficulty``: fit the route-aware difficulty on cruise results (the park difficulty on park and AVP
results, ``--task park``), score it, compute it for garages."""

from __future__ import annotations

import argparse
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import SHIPPED_ROUTE_MODELS, int_in, refuse_overwriting, seed, user_errors
from garage_mj.core.fsutil import write_json
from garage_mj.driving.difficulty.fit import driver_agreement, fit_runs, load_runs, score
from garage_mj.driving.difficulty.park import fit_park_runs, park_records, read_park_runs, score_park
from garage_mj.driving.difficulty.regression import r_text, too_few
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.scene.park_difficulty import (
    DEFAULT_PARK_MODEL,
    PARK_FEATURES,
    SHIPPED_PARK_MODELS,
    load_park_model,
)
from garage_mj.scene.route_difficulty import load_route_model
from garage_mj.scene.route_features import FEATURES, garage_features, mean_features

MAX_SHOWN = 1_000_000  # garages 'difficulty show -n' rates and prints (painted: ~10 ms each)
MAX_STALLS = 10_000  # stalls it lists per garage (a 64x64 garage has fewer)

FIT_EPILOG = """\
RESULTS are cruise run folders (garage-mj cruise --out): their tests.csv and garages.json. Runs of an
older garage-mj have no garages.json: pass --library, the library their garages came from. With
--task park they are park or AVP run folders (garage-mj cruise --task park|avp): their tests.csv alone.

examples:
  garage-mj cruise --library lib.sqlite --sample 40 --tests 20 --driver mypkg.drivers:MyDriver --out runs/mine
  garage-mj difficulty fit runs/mine --out my_route_difficulty.json
  garage-mj difficulty score runs/other --model my_route_difficulty.json
  garage-mj library ls lib.sqlite --route-difficulty 0.4 0.6
  garage-mj cruise --packs packs --task park --maneuver any --driver mypkg.drivers:MyParker --out runs/park
  garage-mj difficulty fit --task park runs/park --out my_park_difficulty.json
  garage-mj difficulty score --task park runs/park_other --model my_park_difficulty.json
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "difficulty",
        help="the route-aware difficulty: fit it on your driver's cruise results, score it, compute it",
        description=(
            "The route-aware difficulty of a garage is the expected failure rate of a cruise test,\n"
            "predicted from the planned route alone (length, turns, tightest curvature, swept clearance,\n"
            "stalls passed, junctions, goal side): a logistic regression with non-negative weights on\n"
            "those features, averaged over the garage's feasible target stalls. The shipped model\n"
            "(models/difficulty/route.json) is fitted on the built-in vision and waypoint drivers with\n"
            "discrete actions; 'fit' refits it on any driver's cruise results (see the README: it does\n"
            "not transfer to drivers that fail differently)."
        ),
        epilog=FIT_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    s = p.add_subparsers(dest="difficulty_command", metavar="ACTION", required=True)
    f = s.add_parser("fit", help="fit a route difficulty model on cruise results",
                     description="Fit a route difficulty model on the feasible tests of cruise runs and write it "
                                 "(JSON) with its fitting data beside it (<OUT stem>.fit.csv); prints the weights "
                                 "and the in-sample figures.",
                     epilog=FIT_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    f.add_argument("results", nargs="+", type=Path, metavar="RESULTS", help="cruise run folders")
    f.add_argument("--out", type=Path, required=True, help="model file to write (.json)")
    f.add_argument("--library", type=Path, help="library of the runs' garages (runs without garages.json)")
    f.add_argument("--features", help="comma-separated route (or park) features to use (default: all)")
    add_task(f)
    f.set_defaults(func=run_fit)
    c = s.add_parser("score", help="how well a route difficulty predicts other cruise results",
                     description="Per driver in RESULTS: per-garage Pearson r between success %% and the route "
                                 "difficulty (the expectation over each garage's feasible stalls) and the paper's "
                                 "difficulty, with 95%% bootstrap intervals, and the per-test AUC of each as a "
                                 "failure predictor. With several drivers, also how their per-garage success "
                                 "correlates and the best r one difficulty can reach with both drivers of each pair "
                                 "('between_drivers' in --json).")
    c.add_argument("results", nargs="+", type=Path, metavar="RESULTS", help="cruise run folders")
    c.add_argument("--model", type=Path, help=f"model file (default: the shipped one; {SHIPPED_ROUTE_MODELS}; with "
                                              f"--task park the shipped {DEFAULT_PARK_MODEL} park model)")
    c.add_argument("--library", type=Path, help="library of the runs' garages (runs without garages.json)")
    c.add_argument("--json", type=Path, help="also write the figures here")
    add_task(c)
    c.set_defaults(func=run_score)
    w = s.add_parser("show", help="the route difficulty of garages, and what makes each one hard",
                     description="Per garage: its route difficulty and the paper's, the feasible stalls, what makes "
                                 "it hard or easy against the average fitting test (each feature's weight x its mean over "
                                 "the stalls in standard deviations of the fitting data, largest first) and the hardest "
                                 "target stalls.",
                     epilog="GARAGES is a library file (with --map/-n), a garages JSON, a folder of asset packs, or a "
                            "shipped map name (painted garages, -n of them).\n"
                            "example: garage-mj difficulty show m5_13x13_aligned -n 2",
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    w.add_argument("garages", metavar="GARAGES", help="where the garages come from (see below)")
    w.add_argument("--map", help="only this map's garages (library)")
    w.add_argument("-n", type=int_in(1, MAX_SHOWN),
                   help=f"at most N garages (a seeded sample of a library; painted: N; 1 to {MAX_SHOWN:,})")
    w.add_argument("--seed", type=seed, default=0, help="seed of the sample or of the painting (default 0)")
    w.add_argument("--model", type=Path, help=f"model file (default: the shipped one; {SHIPPED_ROUTE_MODELS})")
    w.add_argument("--stalls", type=int_in(1, MAX_STALLS), default=3, metavar="K",
                   help=f"hardest stalls to list (1 to {MAX_STALLS:,}; default 3)")
    w.set_defaults(func=run_show)


def add_task(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", choices=("cruise", "park"), default="cruise",
                   help="cruise: the route difficulty of cruise runs (default); park: the park difficulty of park and "
                        "AVP runs (garage-mj cruise --task park|avp), scored beside HOPE's levels "
                        f"(features: {', '.join(PARK_FEATURES)}; shipped models: {', '.join(SHIPPED_PARK_MODELS)})")


def _print_score(score: dict) -> None:
    for driver, d in score.items():
        print(f"{driver}: {d['garages']} garages, {d['tests']} tests, success {d['success_pct']}%")
        for name, key in (("route difficulty", "route"), ("paper's difficulty", "paper")):
            m = d[key]
            lo, hi = m["r_ci95"]
            r = r_text(m["r"], d["garages"])  # over too few garages: says so, no number
            ci = f" [{lo:.3f}, {hi:.3f}]" if lo is not None and not too_few(d["garages"]) else ""
            a = "n/a" if m["auc"] is None else f"{m['auc']:.3f}"
            print(f"  {name:<19} per-garage r = {r}{ci}   per-test AUC = {a}")
        if d.get("attainable_r") is not None:  # the ceiling that the garages' test counts put on any r
            lo, hi = d["attainable_r_ci95"]
            ci = f" [{lo:.3f}, {hi:.3f}]" if lo is not None else ""
            print(f"  {'':<19} attainable |r| = {d['attainable_r']:.3f}{ci} (what each garage's number of "
                  "tests leaves to explain)")


def _inputs(args: argparse.Namespace) -> list[Path | None]:
    """The files 'difficulty fit' and 'score' read: the library, each run's tests.csv, garages.json and run.json."""
    return [args.library, getattr(args, "model", None),
            *(r / name for r in args.results for name in ("tests.csv", "garages.json", "run.json"))]


def _park_features(args: argparse.Namespace) -> tuple[str, ...]:
    """``--features`` of a park fit (default: all), checked; ``--library`` refused (a park run's tests.csv has all)."""
    if args.library is not None:
        raise UserError("--library finds the garages of a route fit; a park fit reads the runs' tests.csv alone: "
                        "leave it out")
    if not args.features:
        return PARK_FEATURES
    feats = tuple(x.strip() for x in args.features.split(",") if x.strip())
    bad = [x for x in feats if x not in PARK_FEATURES]
    if bad:
        raise UserError(f"unknown park features {bad}; choose among {', '.join(PARK_FEATURES)}")
    return feats


def _print_park_score(score: dict) -> None:
    for driver, d in score.items():
        print(f"{driver}: {d['garages']} garages (one per run), {d['tests']} driven tests, success {d['success_pct']}%")
        for name, key in (("park difficulty", "park"), ("HOPE's levels (0/1/2)", "levels")):
            m = d[key]
            lo, hi = m["r_ci95"]
            r = r_text(m["r"], d["garages"])
            ci = f" [{lo:.3f}, {hi:.3f}]" if lo is not None and not too_few(d["garages"]) else ""
            a = "n/a" if m["auc"] is None else f"{m['auc']:.3f}"
            print(f"  {name:<22} per-garage r = {r}{ci}   per-test AUC = {a}")
        if d.get("attainable_r") is not None:
            print(f"  {'':<22} attainable |r| = {d['attainable_r']:.3f} (what each garage's number of tests leaves "
                  "to explain)")
        print("  success by level: " + ", ".join(f"{k} {v['success_pct']}% of {v['tests']}"
                                                  for k, v in d["by_level"].items()))


def run_park_fit(args: argparse.Namespace) -> int:
    feats = _park_features(args)
    refuse_overwriting(args.out, "--out", _inputs(args))
    refuse_overwriting(args.out.with_suffix(".fit.csv"), "--out (its .fit.csv)", _inputs(args))
    model, _ = fit_park_runs(args.results, args.out, feats)
    print(model.describe())
    print(f"fitted on {model.fit['tests']} driven tests ({model.fit['failures']} failures) of {model.fit['garages']} "
          f"garages, drivers {', '.join(model.fit['drivers'])}; in sample:")
    _print_park_score(model.fit["in_sample"])
    print(f"wrote {args.out} and {args.out.with_suffix('.fit.csv')}")
    return 0


def run_park_score(args: argparse.Namespace) -> int:
    if args.library is not None:
        raise UserError("--library finds the garages of a route score; a park score reads the runs' tests.csv "
                        "alone: leave it out")
    read = read_park_runs(args.results)  # the runs first: a folder that is no park run is named before the model
    model = load_park_model(args.model)
    result = score_park(model, park_records(read, model.features))  # its features: an older run lacks newer ones
    _print_park_score(result)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, result, indent=1)
        print(f"wrote {args.json}")
    return 0


@user_errors
def run_fit(args: argparse.Namespace) -> int:
    if args.task == "park":
        return run_park_fit(args)
    feats = FEATURES
    if args.features:
        feats = tuple(x.strip() for x in args.features.split(",") if x.strip())
        bad = [x for x in feats if x not in FEATURES]
        if bad:
            raise UserError(f"unknown route features {bad}; choose among {', '.join(FEATURES)}")
    refuse_overwriting(args.out, "--out", _inputs(args))
    refuse_overwriting(args.out.with_suffix(".fit.csv"), "--out (its .fit.csv)", _inputs(args))
    model, records = fit_runs(args.results, args.out, args.library, feats)
    print(model.describe())
    print(f"fitted on {model.fit['tests']} tests ({model.fit['failures']} failures) of {model.fit['garages']} garages, "
          f"drivers {', '.join(model.fit['drivers'])}; in sample:")
    _print_score(model.fit["in_sample"])
    print(f"wrote {args.out} and {args.out.with_suffix('.fit.csv')}")
    return 0


@user_errors
def run_score(args: argparse.Namespace) -> int:
    if args.json is not None:
        refuse_overwriting(args.json, "--json", _inputs(args))
    if args.task == "park":
        return run_park_score(args)
    model = load_route_model(args.model)
    records, per_garage = load_runs(args.results, args.library, model, progress=True)
    result: dict = score(model, records, garage_route=per_garage)
    _print_score(result)
    if len(result) > 1:  # several drivers: can one difficulty predict them all?
        result["between_drivers"] = agreement = driver_agreement(records)
        print("between drivers (per-garage success % over the garages both drove):")
        for pair, a in agreement.items():
            r12 = "n/a" if a["r_between"] is None else f"{a['r_between']:.3f}"
            bound = "n/a" if a["best_joint_abs_r"] is None else f"{a['best_joint_abs_r']:.3f}"
            print(f"  {pair}: r = {r12} over {a['garages']} garages; no one difficulty reaches r -{bound} with both")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, result, indent=1)
        print(f"wrote {args.json}")
    return 0


@user_errors
def run_show(args: argparse.Namespace) -> int:
    import numpy as np

    from garage_mj.scene.garage_scene import GarageScene

    model = load_route_model(args.model)
    garages = load_garage_set(args.garages, map=args.map, n=args.n, seed=args.seed)
    print(f"route difficulty model {model.key} ({', '.join(model.fit.get('drivers', [])) or 'its own drivers'})")
    for src in garages:
        per_stall = garage_features(GarageScene(src.garage))
        feasible = {sid: f for sid, f in per_stall.items() if f is not None}
        if not feasible:
            print(f"{src.name}: no stall has a feasible cruise test (paper's difficulty {src.difficulty:.3f})")
            continue
        p = model.test_probability(list(feasible.values()))
        means = mean_features(per_stall)
        parts = sorted(((w * (means[k] - m) / sc, k) for k, w, m, sc in
                        zip(model.features, model.weights, model.mean, model.scale, strict=True) if w > 0),
                       reverse=True)
        print(f"{src.name}: route difficulty {float(np.mean(p)):.3f} (paper's {src.difficulty:.3f}), "
              f"{len(feasible)} of {len(per_stall)} stalls feasible")
        print("  against the average fitting test (weight x standardized mean; + harder, - easier): "
              + ", ".join(f"{k} {c:+.2f}" for c, k in parts))
        order = np.argsort(-p, kind="stable")[: args.stalls]
        ids = list(feasible)
        print("  hardest target stalls: " + ", ".join(
            f"{ids[i]} ({p[i]:.2f}: {feasible[ids[i]]['length']:.0f} m, {feasible[ids[i]]['turns']:.0f} turns, "
            f"tightness {feasible[ids[i]]['tightness']:.2f})" for i in order))
    return 0
