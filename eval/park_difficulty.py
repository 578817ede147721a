"""Validation of the park difficulty: fit it on one driver's park tests over some garages, score it on others.

Protocol (fixed before any result was seen; nothing is tuned on the held-out sets):

* **geometries**: ``--geometries`` (default ``default tight angled60 parallel parallel_short``, the grid of
  ``eval/bench_park.py``), each a park run of its own (``garage-mj cruise --task park --maneuver any``, the named
  geometry's world, parked fleet and jitter; occupancy 0.5; the sedan); a garage that cannot be built in a geometry
  is left out of that geometry's run.
* **fit set**: ``--fit-garages`` m5_13x13_aligned garages painted with seed 0 (``painted_sources``), ``--fit-tests``
  park tests each in every geometry, run seed 0. The park difficulty is fitted on their feasible tests
  (``garage-mj difficulty fit --task park``).
* **held-out set**: ``--heldout-garages`` m5_13x13_aligned garages painted with seed 1 (none of the fit set's) and as
  many m7_13x13_u garages painted with seed 0, ``--heldout-tests`` park tests each in every geometry, run seed 1.
* **score** (``garage-mj difficulty score --task park``): per-test AUC of the park difficulty and of HOPE's levels
  (normal 0, complex 1, extreme 2) as failure predictors, and the per-garage Pearson r of each with success %
  (a garage in one geometry is one point; 95 % bootstrap interval over them), on the held-out set; the same
  within each geometry, and for a baseline fitted the same way on the geometry's features alone
  (:data:`GEOMETRY_FEATURES`: how much the plan, the start and the maneuver add to the geometry).

``--scenarios`` (default ``none``) adds, per geometry, a run of the same garages and test seeds with the actors of
each named scenario (``park_mixed``: a pedestrian behind or beside the stall, a car pulling out, clutter) to both
sets, so that the fit sees the ``actors`` feature vary; the held-out figures are then given per scenario too.

Each run is a ``garage-mj cruise`` run folder under ``--out/<driver>/<set>/<map>_<geometry>`` (with actors
``..._<geometry>_<scenario>``; resumable: a re-run drives only the tests not there yet). ``--driver`` names the
driver (default ``park_assist``; the learned parking model: ``learned:park``); ``--model-out`` the model file to
write (default ``runs/park_difficulty/<driver>.json``; the shipped park_assist model:
``models/difficulty/park_assist.json``), ``--json`` the figures.

    MUJOCO_GL=egl .venv/bin/python eval/park_difficulty.py --driver park_assist \\
        --model-out models/difficulty/park_assist.json --json docs/park_difficulty.json
    MUJOCO_GL=egl .venv/bin/python eval/park_difficulty.py --driver learned:park --scenarios none park_mixed \\
        --workers 2 --model-out models/difficulty/learned_park.json --json docs/park_difficulty_learned_park.json
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

from _provenance import provenance  # eval/_provenance.py: command, date, machine, commit

from garage_mj.core.backends import Compute
from garage_mj.core.fsutil import write_json
from garage_mj.driving.actors.config import SCENARIOS
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sources import CruiseSettings, CruiseSource, painted_sources
from garage_mj.scene.stalls import stall_layout
from garage_mj.scene.world import GeometryError, world_with

GEOMETRIES = ("default", "tight", "angled60", "parallel", "parallel_short")
#: The features a park geometry alone decides (the baseline the park difficulty is compared with).
GEOMETRY_FEATURES = ("tight_bay", "narrow_aisle", "angled", "parallel", "jitter", "mixed_fleet")
FIT_MAP, HELDOUT_MAPS = "m5_13x13_aligned", (("m5_13x13_aligned", 1), ("m7_13x13_u", 0))


def slug(driver: str) -> str:
    """A driver spec as a folder name (``learned:park`` -> ``learned_park``)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", driver)


def run_name(map_name: str, geometry: str, scenario: str = "none") -> str:
    """A run's folder name: ``<map>_<geometry>``, with actors ``<map>_<geometry>_<scenario>``."""
    return f"{map_name}_{geometry}" if scenario == "none" else f"{map_name}_{geometry}_{scenario}"


def buildable(sources: list[CruiseSource], geometry: str) -> list[CruiseSource]:
    """The sources whose stalls lay out in ``geometry`` (a garage that cannot be built there is left out)."""
    world = world_with(PARK_GEOMETRIES[geometry].world)
    out = []
    for s in sources:
        try:
            if stall_layout(s.garage, world).stalls:
                out.append(s)
        except GeometryError:
            continue
    return out


def collect(args: argparse.Namespace, name: str, maps: list[tuple[str, int, int]], tests: int,
            run_seed: int) -> list[Path]:
    """Drive one set: ``maps`` as (map, paint seed, garages); one run per (map, geometry). The run folders."""
    runs = []
    for map_name, paint_seed, n in maps:
        sources = painted_sources(map_name, n, seed=paint_seed)
        if name == "heldout" and map_name == FIT_MAP:  # never a fit garage
            fit_hashes = {s.hash for s in painted_sources(FIT_MAP, args.fit_garages, seed=0)}
            sources = [s for s in sources if s.hash not in fit_hashes]
        for geometry, scenario in ((g, sc) for g in args.geometries for sc in args.scenarios):
            srcs = buildable(sources, geometry)
            out = args.out / slug(args.driver) / name / run_name(map_name, geometry, scenario)
            start = time.perf_counter()
            env = PARK_GEOMETRIES[geometry].env_kwargs()
            if scenario != "none":
                env["scenario"] = scenario
            settings = CruiseSettings(driver=args.driver, task="park", maneuver="any", occupancy=0.5, env=env,
                                      seed=run_seed)
            result = run_cruise(srcs, tests, settings, out, compute=Compute(workers=args.workers, progress=False),
                                route_model=False, park_model=False)
            done = [r for r in result.rows if r["feasible"] == "1"]
            ok = sum(r["outcome"] == "success" for r in done)
            print(f"{name} {map_name} {geometry} {scenario}: {len(srcs)} garages, {result.tests_run} new tests, "
                  f"{ok}/{len(done)} driven tests parked ({time.perf_counter() - start:.0f} s)", flush=True)
            runs.append(out)
    return runs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--driver", default="park_assist", help="the parking driver (default park_assist)")
    ap.add_argument("--geometries", nargs="+", default=list(GEOMETRIES), choices=tuple(PARK_GEOMETRIES))
    ap.add_argument("--fit-garages", type=int, default=30, help="m5 garages of the fit set (default 30)")
    ap.add_argument("--fit-tests", type=int, default=4, help="park tests per fit garage and geometry (default 4)")
    ap.add_argument("--heldout-garages", type=int, default=8, help="garages per held-out map (default 8)")
    ap.add_argument("--heldout-tests", type=int, default=6, help="park tests per held-out garage and geometry (6)")
    ap.add_argument("--workers", type=int, default=1,
                    help="worker processes per run (default 1; the tests and figures are the same for any count)")
    ap.add_argument("--scenarios", nargs="+", default=["none"], choices=("none", *sorted(SCENARIOS)),
                    help="actors: none (the default) and/or named scenarios, each a run per geometry of both sets")
    ap.add_argument("--only", choices=("collect", "fit", "score"), help="one step alone (default: all three)")
    ap.add_argument("--out", type=Path, default=Path("runs/park_difficulty"), help="where the runs go")
    ap.add_argument("--model-out", type=Path, help="the model to write (default OUT/<driver>.json)")
    ap.add_argument("--json", type=Path, help="write the held-out figures here (e.g. docs/park_difficulty.json)")
    args = ap.parse_args(argv)
    model_out = args.model_out or args.out / f"{slug(args.driver)}.json"
    steps = (args.only,) if args.only else ("collect", "fit", "score")
    fit_maps = [(FIT_MAP, 0, args.fit_garages)]
    heldout_maps = [(m, seed, args.heldout_garages) for m, seed in HELDOUT_MAPS]
    if "collect" in steps:
        collect(args, "fit", fit_maps, args.fit_tests, run_seed=0)
        collect(args, "heldout", heldout_maps, args.heldout_tests, run_seed=1)
    base = args.out / slug(args.driver)
    fit_runs = [base / "fit" / run_name(m, g, sc) for m, _, _ in fit_maps for g in args.geometries
                for sc in args.scenarios]
    kinds = {str(base / "heldout" / run_name(m, g, sc)): (g, sc) for m, _, _ in heldout_maps
             for g in args.geometries for sc in args.scenarios}  # each held-out run's (geometry, scenario)
    heldout_runs = [Path(run) for run in kinds]
    from garage_mj.driving.difficulty.park import fit_park_runs, load_park_runs, score_park
    from garage_mj.scene.park_difficulty import fit_park, load_park_model

    if "fit" in steps:
        model, records = fit_park_runs(fit_runs, model_out)
        print(model.describe())
        print(f"fitted on {model.fit['tests']} tests ({model.fit['failures']} failures); wrote {model_out}")
    if "score" in steps:
        model = load_park_model(model_out)
        records = load_park_runs(heldout_runs)
        figures = score_park(model, records)
        # within one geometry the levels hardly vary: does the park difficulty still tell tests apart there?
        within, by_scenario = {}, {}
        for g in args.geometries:
            recs = [r for r in records if kinds[r["run"]][0] == g]
            if recs:
                within[g] = {d: {k: v for k, v in f.items() if k in ("tests", "success_pct", "park", "levels")}
                             for d, f in score_park(model, recs).items()}
        if len(args.scenarios) > 1:  # with and without actors apart
            for sc in args.scenarios:
                recs = [r for r in records if kinds[r["run"]][1] == sc]
                if recs:
                    by_scenario[sc] = score_park(model, recs)
        # how much of it is the geometry: the same fit on the fit set with the geometry's features alone
        fit_recs = load_park_runs(fit_runs)
        geo = fit_park(fit_recs, [r["failed"] for r in fit_recs], GEOMETRY_FEATURES)
        baseline = {d: {"features": list(GEOMETRY_FEATURES), **f["park"]} for d, f in score_park(geo, records).items()}
        figures = {"all_geometries": figures, "within_geometry": within, "geometry_only_baseline": baseline}
        if by_scenario:
            figures["by_scenario"] = by_scenario
        print(json.dumps(figures, indent=1))
        if args.json:
            write_json(args.json, {
                "what": "the park difficulty against HOPE's levels as predictors of a driver's park failures, on "
                        "held-out garages",
                "provenance": provenance(),
                "settings": {"driver": args.driver, "geometries": list(args.geometries), "fit_map": FIT_MAP,
                             "fit_garages": args.fit_garages, "fit_tests": args.fit_tests,
                             "heldout_maps": [f"{m} (painted seed {s})" for m, s in HELDOUT_MAPS],
                             "heldout_garages_per_map": args.heldout_garages, "heldout_tests": args.heldout_tests,
                             "scenarios": list(args.scenarios), "occupancy": 0.5, "maneuver": "any",
                             "vehicle": "sedan", "workers": args.workers},
                "model": {"file": str(model_out), "key": model.key, "fit": {k: v for k, v in model.fit.items()
                                                                             if k != "runs"},
                          "weights": dict(model.coefficients())},
                "heldout": figures,
            }, indent=1)
            print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
